// Between image_io.cc and the image codec module (image_codecs.cc, OpenCV's imgcodecs), which
// is loaded on first use: the host and the module are built together, so C++ types cross.
#pragma once

#include "host/io/image_io.h"

#include <string>

namespace imr::io {

struct ImageCodecs {
  static constexpr int kVersion = 1;  // the module's and the host's must be equal
  int version = kVersion;
  // ReadImage's decoding after the header checks: "" when `out` is filled, else the message.
  std::string (*decode)(const std::string& path, const ImageLimits& limits, Image* out);
  // WriteImage's encoding after the argument checks: "" or the message.
  std::string (*encode)(const std::string& path, const Image& image);
};

}  // namespace imr::io

// The module's one symbol.
extern "C" const imr::io::ImageCodecs* imr_image_codecs();
