// The edge-point KLT features plugin (docs/user-guide.md, Image sequences): images in, 2D tracks out.
#include <imr/sdk/plugin.hpp>

#include <opencv2/imgproc.hpp>
#include <string>

#include "edge_klt_tracker.hpp"

namespace imr::edge_klt {
namespace {

class EdgeKltFeatures : public imr::sdk::Features {
 public:
  static constexpr const char* kId = "org.imr.features.edge_klt";
  static constexpr const char* kVersion = "1.0.0";
  static constexpr const char* kDescription =
      "Edge points (Canny, one per grid cell) or Shi-Tomasi corners, tracked with pyramidal "
      "Lucas-Kanade and a forward-backward check; replenished at keyframes (OpenCV)";
  static constexpr const char* kParamsSchema = R"json({
    "detector": {"type": "string", "default": "edge", "enum": ["edge", "shi_tomasi"],
      "description": "edge: strongest Canny edge pixel per grid cell (paper); shi_tomasi: corners"},
    "max_features": {"type": "integer", "default": 1500, "minimum": 1, "maximum": 1000000,
      "description": "tracks alive at once, at most"},
    "grid_cell_size": {"type": "integer", "default": 16, "minimum": 2, "maximum": 4096,
      "description": "pixels; a cell holding a track gets no new feature"},
    "canny_low": {"type": "number", "default": 50.0, "minimum": 0.0,
      "description": "Canny lower hysteresis threshold (L2 norm of the 3x3 Sobel gradient)"},
    "canny_high": {"type": "number", "default": 150.0, "minimum": 0.0,
      "description": "Canny upper hysteresis threshold (>= canny_low)"},
    "min_distance": {"type": "number", "default": 8.0, "minimum": 0.0,
      "description": "pixels between a new feature and any other feature"},
    "border": {"type": "integer", "default": 8, "minimum": 0,
      "description": "pixels along the image border where features are not kept"},
    "shi_tomasi_quality": {"type": "number", "default": 0.01, "minimum": 1e-9, "maximum": 1.0,
      "description": "shi_tomasi: minimum corner quality relative to the best corner"},
    "shi_tomasi_block_size": {"type": "integer", "default": 3, "minimum": 2, "maximum": 31,
      "description": "shi_tomasi: neighbourhood of the corner measure, pixels"},
    "corner_fallback": {"type": "boolean", "default": true,
      "description": "edge: a free grid cell without an edge pixel (weak texture such as asphalt) takes its strongest corner instead, if it reaches corner_min_eigen"},
    "corner_min_eigen": {"type": "number", "default": 3e-5, "minimum": 0.0,
      "description": "corner_fallback: minimum eigenvalue of the gradient matrix over corner_block_size pixels (cv::cornerMinEigenVal, 3x3 Sobel, 8-bit), at least"},
    "corner_block_size": {"type": "integer", "default": 5, "minimum": 2, "maximum": 31,
      "description": "corner_fallback: neighbourhood of the corner measure, pixels"},
    "lk_window": {"type": "integer", "default": 21, "minimum": 3, "maximum": 201,
      "description": "Lucas-Kanade window side, pixels"},
    "lk_levels": {"type": "integer", "default": 3, "minimum": 0, "maximum": 10,
      "description": "pyramid levels above the full image (0: single level)"},
    "lk_max_iterations": {"type": "integer", "default": 30, "minimum": 1, "maximum": 1000,
      "description": "Lucas-Kanade iterations per level, at most"},
    "lk_epsilon": {"type": "number", "default": 0.01, "minimum": 0.0,
      "description": "Lucas-Kanade stops when its update is below this, pixels"},
    "lk_min_eigen": {"type": "number", "default": 1e-4, "minimum": 0.0,
      "description": "drop a track whose window's normalised minimum eigenvalue is below this"},
    "fb_max_error": {"type": "number", "default": 1.0, "minimum": 0.0,
      "description": "forward-backward check: max distance, pixels, between a track's position and where tracking it back to the previous frame lands"}
  })json";

  EdgeKltFeatures(const imr::sdk::Params& params, const imr::sdk::Host& host)
      : tracker_(Options(params)) {
    host.Debug(std::string(kId) + ": created");
  }

  std::span<const imr_track_observation> ProcessFrame(const imr_camera& /*camera*/,
                                                     const imr_image_view& image,
                                                     bool is_keyframe) override {
    const auto& tracks = tracker_.Process(Gray(image), is_keyframe);
    return {tracks.data(), tracks.size()};
  }

 private:
  static TrackerOptions Options(const imr::sdk::Params& params) {
    const imr::sdk::Params& p = params;  // checked, defaults filled (plugin.hpp)
    TrackerOptions o;
    o.detector = p.Get<std::string>("detector") == "edge" ? Detector::kEdge : Detector::kShiTomasi;
    o.max_features = p.Get<int>("max_features");
    o.grid_cell_size = p.Get<int>("grid_cell_size");
    o.canny_low = p.Get<double>("canny_low");
    o.canny_high = p.Get<double>("canny_high");
    o.min_distance = p.Get<double>("min_distance");
    o.border = p.Get<int>("border");
    o.shi_tomasi_quality = p.Get<double>("shi_tomasi_quality");
    o.shi_tomasi_block_size = p.Get<int>("shi_tomasi_block_size");
    o.corner_fallback = p.Get<bool>("corner_fallback");
    o.corner_min_eigen = p.Get<double>("corner_min_eigen");
    o.corner_block_size = p.Get<int>("corner_block_size");
    o.lk_window = p.Get<int>("lk_window");
    o.lk_levels = p.Get<int>("lk_levels");
    o.lk_max_iterations = p.Get<int>("lk_max_iterations");
    o.lk_epsilon = p.Get<double>("lk_epsilon");
    o.lk_min_eigen = p.Get<double>("lk_min_eigen");
    o.fb_max_error = p.Get<double>("fb_max_error");
    if (const std::string error = o.Check(); !error.empty())
      throw imr::sdk::InvalidArgument("params." + error);
    return o;
  }

  // The image as 8-bit gray, wrapping the host's pixels when they already are.
  cv::Mat Gray(const imr_image_view& image) {
    using imr::sdk::InvalidArgument;
    if (image.struct_size < IMR_IMAGE_VIEW_SIZE_1_0)  // its 1.0 size: a host of any minor
      throw InvalidArgument("image.struct_size: " + std::to_string(image.struct_size) +
                            ", expected at least " + std::to_string(IMR_IMAGE_VIEW_SIZE_1_0));
    if (image.width <= 0 || image.height <= 0)
      throw InvalidArgument("image.width/height: expected positive, got " +
                            std::to_string(image.width) + "x" + std::to_string(image.height));
    if (image.channels != 1 && image.channels != 3)
      throw InvalidArgument("image.channels: expected 1 (gray) or 3 (BGR), got " +
                            std::to_string(image.channels));
    if (image.pixels == nullptr) throw InvalidArgument("image.pixels: null");
    const int64_t row_bytes = static_cast<int64_t>(image.width) * image.channels;
    if (image.stride_bytes < row_bytes)
      throw InvalidArgument("image.stride_bytes: " + std::to_string(image.stride_bytes) +
                            " is less than a row (" + std::to_string(row_bytes) + " bytes)");
    if (!size_.empty() && (image.width != size_.width || image.height != size_.height))
      throw InvalidArgument("image.width/height: " + std::to_string(image.width) + "x" +
                            std::to_string(image.height) + " differs from the sequence's " +
                            std::to_string(size_.width) + "x" + std::to_string(size_.height));
    size_ = cv::Size(image.width, image.height);
    const cv::Mat wrapped(image.height, image.width, image.channels == 1 ? CV_8UC1 : CV_8UC3,
                          const_cast<uint8_t*>(image.pixels),
                          static_cast<std::size_t>(image.stride_bytes));
    if (image.channels == 1) return wrapped;
    cv::cvtColor(wrapped, converted_, cv::COLOR_BGR2GRAY);  // converted_ never wraps host memory
    return converted_;
  }

  EdgeKltTracker tracker_;
  cv::Size size_;
  cv::Mat converted_;
};

}  // namespace
}  // namespace imr::edge_klt

IMR_PLUGIN_EXPORT(imr::edge_klt::EdgeKltFeatures)
