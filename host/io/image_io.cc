// The one host translation unit that includes OpenCV (imgcodecs): see image_io.h.
#include "host/io/image_io.h"

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include <array>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <stdexcept>

namespace imr::io {
namespace {
namespace fs = std::filesystem;

void CheckIsFile(const std::string& path) {
  std::error_code ec;
  const fs::file_status s = fs::status(path, ec);
  if (!fs::exists(s)) throw std::runtime_error(path + ": no such file");
  if (fs::is_directory(s)) throw std::runtime_error(path + ": is a folder, not an image file");
}

[[noreturn]] void FailDecode(const std::string& path, const std::string& detail = "") {
  throw std::runtime_error("cannot decode " + path + " (not a PNG/JPEG, or truncated)" +
                           (detail.empty() ? "" : ": " + detail));
}

uint32_t BigEndian32(const unsigned char* p) {
  return (uint32_t{p[0]} << 24) | (uint32_t{p[1]} << 16) | (uint32_t{p[2]} << 8) | p[3];
}
int BigEndian16(const unsigned char* p) { return (p[0] << 8) | p[1]; }

// PNG: 8-byte signature, then the IHDR chunk (length, "IHDR", width, height, ...) by the standard.
bool PngSize(std::istream& in, const std::string& path, ImageSize* size) {
  static const unsigned char kSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  std::array<unsigned char, 24> h{};
  in.read(reinterpret_cast<char*>(h.data()), 8);
  if (in.gcount() < 8 || std::memcmp(h.data(), kSignature, 8) != 0) return false;
  in.read(reinterpret_cast<char*>(h.data()) + 8, 16);
  if (in.gcount() < 16 || std::memcmp(h.data() + 12, "IHDR", 4) != 0)
    FailDecode(path, "no IHDR chunk after the PNG signature");
  const uint32_t w = BigEndian32(h.data() + 16), ht = BigEndian32(h.data() + 20);
  // PNG sizes are at most 2^31 - 1 per side.
  if (w == 0 || ht == 0 || w > 0x7fffffffu || ht > 0x7fffffffu)
    FailDecode(path, "IHDR gives a size of " + std::to_string(w) + "x" + std::to_string(ht));
  size->width = static_cast<int>(w);
  size->height = static_cast<int>(ht);
  return true;
}

// JPEG: walk the marker segments up to the first start-of-frame (SOF0..SOF15 except DHT C4,
// JPG C8, DAC CC), whose payload is precision, height, width.
bool JpegSize(std::istream& in, const std::string& path, ImageSize* size) {
  in.clear();
  in.seekg(0);
  unsigned char soi[2] = {0, 0};
  in.read(reinterpret_cast<char*>(soi), 2);
  if (in.gcount() < 2 || soi[0] != 0xff || soi[1] != 0xd8) return false;
  for (;;) {
    int c = in.get();
    if (c == EOF) FailDecode(path, "no JPEG frame header before the end of the file");
    if (c != 0xff) continue;
    int marker = in.get();
    while (marker == 0xff) marker = in.get();  // fill bytes
    if (marker == EOF) FailDecode(path, "no JPEG frame header before the end of the file");
    if (marker == 0x01 || (marker >= 0xd0 && marker <= 0xd9)) continue;  // no length field
    unsigned char len_bytes[2];
    in.read(reinterpret_cast<char*>(len_bytes), 2);
    if (in.gcount() < 2) FailDecode(path, "JPEG segment cut short");
    const int length = BigEndian16(len_bytes);
    if (length < 2) FailDecode(path, "JPEG segment of length " + std::to_string(length));
    const bool sof =
        marker >= 0xc0 && marker <= 0xcf && marker != 0xc4 && marker != 0xc8 && marker != 0xcc;
    if (sof) {
      unsigned char f[5];
      in.read(reinterpret_cast<char*>(f), 5);
      if (in.gcount() < 5) FailDecode(path, "JPEG frame header cut short");
      size->height = BigEndian16(f + 1);
      size->width = BigEndian16(f + 3);
      if (size->width == 0 || size->height == 0)
        FailDecode(path, "JPEG frame header gives a size of " + std::to_string(size->width) + "x" +
                             std::to_string(size->height));
      return true;
    }
    in.seekg(length - 2, std::ios::cur);
  }
}

// The header's size, for PNG and JPEG; false for other formats.
bool HeaderSize(const std::string& path, ImageSize* size) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error(path + ": cannot open for reading");
  return PngSize(in, path, size) || JpegSize(in, path, size);
}

}  // namespace

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

Image ReadImage(const std::string& path, const ImageLimits& limits) {
  CheckIsFile(path);
  // From the header first: nothing is decoded that would be refused.
  if (ImageSize declared; HeaderSize(path, &declared)) CheckImageSize(path, declared, limits);
  cv::Mat m;
  try {
    m = cv::imread(path, cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception& e) {
    FailDecode(path, e.what());
  }
  if (m.empty()) FailDecode(path);
  CheckImageSize(path, {m.cols, m.rows}, limits);  // formats without a header read above

  if (m.depth() == CV_16U) {
    cv::Mat m8;
    m.convertTo(m8, CV_8U, 255.0 / 65535.0);
    m = m8;
  } else if (m.depth() != CV_8U) {
    throw std::runtime_error(path + ": pixels are neither 8- nor 16-bit unsigned (OpenCV depth " +
                             std::to_string(m.depth()) + "); convert the image first");
  }
  const int in_channels = m.channels();
  if (in_channels < 1 || in_channels > 4)
    throw std::runtime_error(path + ": " + std::to_string(in_channels) +
                             " channels, expected 1 to 4");
  // Gray + alpha keeps the gray, BGRA keeps BGR: the alpha channel is dropped.
  const int channels = in_channels <= 2 ? 1 : 3;

  Image image;
  image.width = m.cols;
  image.height = m.rows;
  image.channels = channels;
  image.stride_bytes = static_cast<int64_t>(m.cols) * channels;
  image.pixels.resize(static_cast<std::size_t>(image.stride_bytes) * m.rows);
  for (int y = 0; y < m.rows; ++y) {
    const uint8_t* src = m.ptr<uint8_t>(y);
    uint8_t* dst = image.pixels.data() + static_cast<std::size_t>(y) * image.stride_bytes;
    if (in_channels == channels) {
      std::memcpy(dst, src, static_cast<std::size_t>(image.stride_bytes));
      continue;
    }
    for (int x = 0; x < m.cols; ++x)
      for (int c = 0; c < channels; ++c) dst[x * channels + c] = src[x * in_channels + c];
  }
  return image;
}

ImageSize ReadImageSize(const std::string& path, const ImageLimits& limits) {
  CheckIsFile(path);
  ImageSize size;
  if (HeaderSize(path, &size)) {
    CheckImageSize(path, size, limits);
    return size;
  }
  const Image image = ReadImage(path, limits);
  return {image.width, image.height};
}

void WriteImage(const std::string& path, const Image& image) {
  if (image.channels != 1 && image.channels != 3)
    throw std::runtime_error(path + ": cannot write an image of " + std::to_string(image.channels) +
                             " channels (1 or 3)");
  if (image.width <= 0 || image.height <= 0 ||
      image.stride_bytes < static_cast<int64_t>(image.width) * image.channels ||
      image.pixels.size() < static_cast<std::size_t>(image.stride_bytes) * image.height)
    throw std::runtime_error(path + ": image of " + std::to_string(image.width) + "x" +
                             std::to_string(image.height) + " has too few pixels for its stride");
  const cv::Mat m(image.height, image.width, image.channels == 1 ? CV_8UC1 : CV_8UC3,
                  const_cast<uint8_t*>(image.pixels.data()),
                  static_cast<std::size_t>(image.stride_bytes));
  bool ok = false;
  std::string detail;
  try {
    ok = cv::imwrite(path, m);
  } catch (const cv::Exception& e) {
    detail = std::string(": ") + e.what();
  }
  if (!ok) throw std::runtime_error("cannot write " + path + detail);
}

}  // namespace imr::io
