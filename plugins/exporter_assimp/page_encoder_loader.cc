#include "page_encoder.hpp"

#include <boost/dll/runtime_symbol_info.hpp>
#include <boost/dll/shared_library.hpp>

#include <filesystem>
#include <stdexcept>

namespace imr::exporter_assimp {
namespace fs = std::filesystem;

// The encoder module beside this plugin (page_encoder.hpp), loaded on first use.
std::vector<uint8_t> EncodeAtlasPage(const uint8_t* bgr, int width, int height, const std::string& format,
                                     int jpeg_quality) {
  using Encode = decltype(imr_assimp_encode_page);
  static Encode* const encode = [] {
    const fs::path dir = boost::dll::this_line_location().parent_path().native();
    const fs::path module = dir / "org.imr.exporter.assimp" / "page_encoder.so";
    static boost::dll::shared_library library;  // loaded for the process's life
    try {
      library.load(boost::dll::fs::path(module.string()), boost::dll::load_mode::rtld_now);
      return &library.get<Encode>("imr_assimp_encode_page");
    } catch (const std::exception& e) {
      throw std::runtime_error("cannot load the atlas page encoder " + module.string() + ": " + e.what());
    }
  }();
  std::vector<uint8_t> bytes;
  std::string error;
  if (!encode(bgr, width, height, format.c_str(), jpeg_quality, &bytes, &error))
    throw std::runtime_error("cannot encode a " + std::to_string(width) + "x" +
                             std::to_string(height) + " atlas page as " + format + ": " + error);
  return bytes;
}

}  // namespace imr::exporter_assimp
