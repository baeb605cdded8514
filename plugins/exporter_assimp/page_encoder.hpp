// The atlas pages' encoder (page_encoder.cc, OpenCV's imgcodecs), loaded on first use from the
// folder beside the plugin: <plugins>/org.imr.exporter.assimp/page_encoder.so.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

// The module's one symbol: `width` x `height` BGR pixels (OpenCV's order: no converted copy) as
// `format` ("png" or "jpg"); false with `error` set when it cannot.
extern "C" bool imr_assimp_encode_page(const uint8_t* bgr, int width, int height, const char* format,
                                       int jpeg_quality, std::vector<uint8_t>* out, std::string* error);

namespace imr::exporter_assimp {

// Encodes through the module (loaded once); throws std::runtime_error naming the module when it
// cannot be loaded, or the page when it cannot be encoded.
std::vector<uint8_t> EncodeAtlasPage(const uint8_t* bgr, int width, int height,
                                     const std::string& format, int jpeg_quality);

}  // namespace imr::exporter_assimp
