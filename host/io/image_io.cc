// Image files for the image front end: sizes from their headers here, pixels through the codec
// module (image_codecs.h), loaded on first use.
#include "host/io/image_io.h"

#include "host/io/image_codecs.h"

#include <boost/dll/runtime_symbol_info.hpp>
#include <boost/dll/shared_library.hpp>

#include <array>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace imr::io {
namespace {
namespace fs = std::filesystem;

void CheckIsFile(const std::string& path) {
  std::error_code ec;
  const fs::file_status s = fs::status(path, ec);
  if (!fs::exists(s)) throw std::runtime_error(path + ": no such file");
  if (fs::is_directory(s)) throw std::runtime_error(path + ": is a folder, not an image file");
}

// The codec module (image_codecs.cc), loaded once, on first use: beside the plugins' folder,
// <prefix>/lib/imr, in the build tree and after install alike (bin/ and tests/ are both one level
// under it), else where this build put it.
const ImageCodecs& Codecs() {
  static const ImageCodecs* const codecs = [] {
    const fs::path exe = boost::dll::program_location().native();
    const std::vector<fs::path> candidates = {
        exe.parent_path().parent_path() / "lib" / "imr" / IMR_IMAGE_CODECS_FILE,
        fs::path(IMR_IMAGE_CODECS_BUILD_PATH)};
    std::string tried;
    for (const fs::path& p : candidates) {
      if (!fs::exists(p)) {
        tried += (tried.empty() ? "" : ", ") + p.string();
        continue;
      }
      // Kept loaded for the process's life (the function table lives in it).
      static boost::dll::shared_library library;
      try {
        library.load(boost::dll::fs::path(p.string()), boost::dll::load_mode::rtld_now);
      } catch (const std::exception& e) {
        throw std::runtime_error("cannot load the image codecs " + p.string() + ": " + e.what());
      }
      const ImageCodecs* c = library.get<const ImageCodecs*()>("imr_image_codecs")();
      if (c == nullptr || c->version != ImageCodecs::kVersion)
        throw std::runtime_error(p.string() + ": image codecs of another imr build");
      return c;
    }
    throw std::runtime_error("the image codecs (" + std::string(IMR_IMAGE_CODECS_FILE) +
                             ", OpenCV) are not installed: looked for " + tried);
  }();
  return *codecs;
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

Image ReadImage(const std::string& path, const ImageLimits& limits) {
  CheckIsFile(path);
  // From the header first: nothing is decoded that would be refused.
  if (ImageSize declared; HeaderSize(path, &declared)) CheckImageSize(path, declared, limits);
  Image image;
  if (const std::string e = Codecs().decode(path, limits, &image); !e.empty())
    throw std::runtime_error(e);
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
  if (const std::string e = Codecs().encode(path, image); !e.empty())
    throw std::runtime_error(e);
}

}  // namespace imr::io
