// The image codecs: the one place the host uses OpenCV (imgcodecs), built as a module of its own
// (lib/imr/libimr_image_codecs.so) that image_io.cc loads the first time an image is decoded or
// written. Linking imgcodecs costs every imr process ~50 MB of resident memory at start (its
// codecs' libraries, GDAL's among them), which runs on SfM, SLAM or synthetic input never use.
#include "host/io/image_codecs.h"

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include <cstring>
#include <stdexcept>
#include <string>

namespace imr::io {
namespace {

[[noreturn]] void FailDecode(const std::string& path, const std::string& detail = "") {
  throw std::runtime_error("cannot decode " + path + " (not a PNG/JPEG, or truncated)" +
                           (detail.empty() ? "" : ": " + detail));
}

void Decode(const std::string& path, const std::string& bytes, const ImageLimits& limits,
            Image* out) {
  if (bytes.empty()) FailDecode(path, "the file is empty");
  cv::Mat m;
  try {
    const cv::Mat encoded(1, static_cast<int>(bytes.size()), CV_8UC1,
                          const_cast<char*>(bytes.data()));
    m = cv::imdecode(encoded, cv::IMREAD_UNCHANGED);
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
  *out = std::move(image);
}

void Encode(const std::string& path, const Image& image) {
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

// Exceptions stay on this side of the module's boundary: their message crosses.
template <typename F>
std::string Guarded(F&& f) {
  try {
    f();
    return {};
  } catch (const std::exception& e) {
    return e.what();
  }
}

const ImageCodecs kCodecs = {
    ImageCodecs::kVersion,
    [](const std::string& path, const std::string& bytes, const ImageLimits& limits, Image* out) {
      return Guarded([&] { Decode(path, bytes, limits, out); });
    },
    [](const std::string& path, const Image& image) { return Guarded([&] { Encode(path, image); }); },
};

}  // namespace
}  // namespace imr::io

extern "C" __attribute__((visibility("default"))) const imr::io::ImageCodecs* imr_image_codecs() {
  return &imr::io::kCodecs;
}
