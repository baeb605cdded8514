// Atlas pages encoded as PNG or JPEG by OpenCV's imgcodecs, in a module of the exporter's own
// (<plugins>/org.imr.exporter.assimp/page_encoder.so) that page_encoder.hpp loads the first time a
// page is encoded: linked into the plugin, imgcodecs and the libraries of its codecs took ~40 MB
// of every process that loaded the exporter, textured or not.
#include "page_encoder.hpp"

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include <exception>

extern "C" __attribute__((visibility("default"))) bool imr_assimp_encode_page(
    const uint8_t* bgr, int width, int height, const char* format, int jpeg_quality,
    std::vector<uint8_t>* out, std::string* error) {
  try {
    const cv::Mat page(height, width, CV_8UC3, const_cast<uint8_t*>(bgr));
    const std::string f = format;
    const std::vector<int> params = f == "png" ? std::vector<int>{cv::IMWRITE_PNG_COMPRESSION, 3}
                                               : std::vector<int>{cv::IMWRITE_JPEG_QUALITY, jpeg_quality};
    if (cv::imencode("." + f, page, *out, params)) return true;
    *error = "imencode failed";
  } catch (const std::exception& e) {
    *error = e.what();
  }
  return false;
}
