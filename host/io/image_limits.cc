// CheckImageSize: in the host (image_io.cc, on the header's size) and in the codec module
// (image_codecs.cc, on the decoded size of formats without a header read), so compiled into both.
#include "host/io/image_io.h"

#include <cstdint>
#include <stdexcept>
#include <string>

namespace imr::io {

void CheckImageSize(const std::string& path, const ImageSize& size, const ImageLimits& limits) {
  const int64_t pixels = int64_t{size.width} * size.height;
  const std::string is = path + ": image is " + std::to_string(size.width) + "x" +
                         std::to_string(size.height);
  const auto megapixels = [](int64_t p) { return std::to_string((p + 500000) / 1000000); };
  if (limits.max_pixels > 0 && pixels > limits.max_pixels)
    throw std::runtime_error(is + " (" + megapixels(pixels) + " megapixels), more than " +
                             limits.max_pixels_name);
  if (pixels > kDecoderMaxPixels)
    throw std::runtime_error(is + " (" + megapixels(pixels) + " megapixels), more than the " +
                             "image decoder reads (" + megapixels(kDecoderMaxPixels) + ")");
  if (limits.expected.width > 0 &&
      (size.width != limits.expected.width || size.height != limits.expected.height))
    throw std::runtime_error(is + ", " + limits.expected_name + " is " +
                             std::to_string(limits.expected.width) + "x" +
                             std::to_string(limits.expected.height));
}

}  // namespace imr::io
