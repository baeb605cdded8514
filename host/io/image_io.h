// Decoding one image file into plain 8-bit pixels for the front end (DESIGN §2). OpenCV's
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

// Decodes PNG, JPEG (and whatever else imgcodecs reads). 16-bit images are scaled to 8 bits and
// alpha is dropped: BGRA becomes BGR (OpenCV decodes a gray + alpha PNG as BGRA, so it comes out
// as BGR with equal channels), 2-channel gray + alpha becomes gray. Throws std::runtime_error
// naming the file: "<path>: no such file", "cannot decode <path> (not a PNG/JPEG, or truncated)".
Image ReadImage(const std::string& path);

// The size only, from the PNG IHDR chunk or the JPEG frame header (a few bytes, no decoding);
// other formats are decoded. Throws like ReadImage.
ImageSize ReadImageSize(const std::string& path);

// Writes `image` in the format of the path's extension (.png, .jpg, ...): for tests and debug
// output. Throws std::runtime_error naming the file when it cannot.
void WriteImage(const std::string& path, const Image& image);

}  // namespace imr::io
