// Image files for the image front end: sizes from their headers here, pixels through the codec
// module (image_codecs.h), loaded on first use.
#include "host/io/image_io.h"

#include "host/io/image_codecs.h"
#include "host/util/input_file.h"

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

// What the open rule names in its refusals (host/util/input_file.h).
constexpr std::string_view kImageWhat = "an image file (PNG, JPEG)";
// The most bytes an image file may hold: far beyond any image within kDecoderMaxPixels.
constexpr uint64_t kMaxImageFileBytes = (uint64_t{1} << 31) - 1;  // cv::Mat sizes are int

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

// Why the PNG in `bytes` would fail inside libpng, or "": every chunk whole, a critical chunk's
// CRC right, up to IEND. libpng reports a truncated or corrupted file on stderr itself ("libpng error: Read
// Error") before OpenCV returns an empty image, so what it would find is found here first and
// said once, naming the file. Bytes that are no PNG give "".
std::string PngProblem(const std::string& bytes) {
  static const unsigned char kSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  if (bytes.size() < 8 || std::memcmp(bytes.data(), kSignature, 8) != 0) return {};
  static const std::array<uint32_t, 256> kCrcTable = [] {
    std::array<uint32_t, 256> t{};
    for (uint32_t n = 0; n < 256; ++n) {
      uint32_t c = n;
      for (int k = 0; k < 8; ++k) c = (c & 1) ? 0xedb88320u ^ (c >> 1) : c >> 1;
      t[n] = c;
    }
    return t;
  }();
  const auto* p = reinterpret_cast<const unsigned char*>(bytes.data());
  std::size_t at = 8;
  for (;;) {
    if (bytes.size() - at < 12)
      return "the file ends at byte " + std::to_string(bytes.size()) + " before the PNG's IEND "
             "chunk (truncated)";
    const uint32_t length = BigEndian32(p + at);
    const std::string type(bytes.data() + at + 4, 4);
    if (length > 0x7fffffffu || bytes.size() - at - 12 < length)
      return "the file ends at byte " + std::to_string(bytes.size()) + " inside its " + type +
             " chunk (truncated)";
    uint32_t crc = 0xffffffffu;
    for (std::size_t i = at + 4; i < at + 8 + length; ++i)
      crc = kCrcTable[(crc ^ p[i]) & 0xffu] ^ (crc >> 8);
    // libpng fails on a critical chunk's (upper-case first letter) bad CRC, and skips an
    // ancillary one with a warning: the same here.
    const bool critical = (p[at + 4] & 0x20) == 0;
    if (critical && (crc ^ 0xffffffffu) != BigEndian32(p + at + 8 + length))
      return "the " + type + " chunk at byte " + std::to_string(at) + " fails its CRC (corrupted)";
    at += 12 + length;
    if (type == "IEND") return {};
  }
}

// The header's size, for PNG and JPEG; false for other formats.
// Opened by the open rule: a FIFO, a device or a folder named as an image is refused by name.
bool HeaderSize(const std::string& path, ImageSize* size) {
  InputStream in(path, kImageWhat);
  return PngSize(in, path, size) || JpegSize(in, path, size);
}

}  // namespace

Image ReadImage(const std::string& path, const ImageLimits& limits) {
  // From the header first: nothing is decoded (or read whole) that would be refused.
  if (ImageSize declared; HeaderSize(path, &declared)) CheckImageSize(path, declared, limits);
  // The bytes through the open rule, decoded from memory: OpenCV's imread opens the name itself
  // (a FIFO swapped in after the check above would block it).
  const std::string bytes = ReadInputFile(path, kImageWhat, kMaxImageFileBytes);
  if (const std::string problem = PngProblem(bytes); !problem.empty()) FailDecode(path, problem);
  Image image;
  if (const std::string e = Codecs().decode(path, bytes, limits, &image); !e.empty())
    throw std::runtime_error(e);
  return image;
}

ImageSize ReadImageSize(const std::string& path, const ImageLimits& limits) {
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
