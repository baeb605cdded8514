// Between image_io.cc and the image codec module (image_codecs.cc, OpenCV's imgcodecs), which
// is loaded on first use: the host and the module are built together, so C++ types cross.
#pragma once

#include "host/io/image_io.h"

#include <string>

namespace imr::io {

struct ImageCodecs {
  static constexpr int kVersion = 2;  // the module's and the host's must be equal
  int version = kVersion;
  // ReadImage's decoding after the header checks, of the file's bytes (read by the host through
  // the open rule, host/util/input_file.h: OpenCV's imread would wait on a FIFO); `path` names
  // the file in messages. "" when `out` is filled, else the message.
  std::string (*decode)(const std::string& path, const std::string& bytes,
                        const ImageLimits& limits, Image* out);
  // WriteImage's encoding after the argument checks: "" or the message.
  std::string (*encode)(const std::string& path, const Image& image);
};

}  // namespace imr::io

// The module's one symbol.
extern "C" const imr::io::ImageCodecs* imr_image_codecs();
