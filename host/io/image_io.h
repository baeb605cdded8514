// Decoding one image file into plain 8-bit pixels for the image front end (host/pipeline/front_end.h). OpenCV's
// imgcodecs does the decoding inside image_io.cc only: no OpenCV type crosses this header, so the
// rest of the host never compiles against OpenCV.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace imr::io {

// 8-bit pixels, rows top to bottom; what the features plugin's imr_image_view points at.
struct Image {
  int width = 0;
  int height = 0;
  int channels = 0;          // 1 (gray) or 3 (BGR, OpenCV's order)
  int64_t stride_bytes = 0;  // bytes between rows (width * channels: rows are packed)
  std::vector<uint8_t> pixels;
};

struct ImageSize {
  int width = 0;
  int height = 0;
};

// What an image may be, checked on the size its header declares before a pixel is decoded (a
// 1 MB PNG can declare 30000 x 30000 and decode for seconds into gigabytes); for formats other
// than PNG and JPEG, after decoding.
struct ImageLimits {
  int64_t max_pixels = 0;       // 0: only the decoder's own limit (kDecoderMaxPixels)
  std::string max_pixels_name;  // the option that sets it, for messages
  ImageSize expected{};         // width 0: any size
  std::string expected_name;    // whose size that is, e.g. "the sequence's first"
};
// OpenCV's own limit (OPENCV_IO_MAX_IMAGE_PIXELS' default): larger images it refuses.
inline constexpr int64_t kDecoderMaxPixels = int64_t{1} << 30;
// Throws "<path>: image is 30000x30000 (900 megapixels), more than <max_pixels_name>" or
// "<path>: image is 400x120, <expected_name> is 414x125" when `size` breaks `limits`.
void CheckImageSize(const std::string& path, const ImageSize& size, const ImageLimits& limits);

// Decodes PNG, JPEG (and whatever else imgcodecs reads). 16-bit images are scaled to 8 bits and
// alpha is dropped: BGRA becomes BGR (OpenCV decodes a gray + alpha PNG as BGRA, so it comes out
// as BGR with equal channels), 2-channel gray + alpha becomes gray. Throws std::runtime_error
// naming the file: "<path>: no such file", "cannot decode <path> (not a PNG/JPEG, or truncated)",
// or CheckImageSize's message.
Image ReadImage(const std::string& path, const ImageLimits& limits = {});

// The size only, from the PNG IHDR chunk or the JPEG frame header (a few bytes, no decoding);
// other formats are decoded (within `limits`). Throws like ReadImage; `limits` are checked.
ImageSize ReadImageSize(const std::string& path, const ImageLimits& limits = {});

// Writes `image` in the format of the path's extension (.png, .jpg, ...): for tests and debug
// output. Throws std::runtime_error naming the file when it cannot.
void WriteImage(const std::string& path, const Image& image);

}  // namespace imr::io
