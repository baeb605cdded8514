// The Ceres refiner plugin (docs/user-guide.md, Image sequences): 2D tracks + cameras in; new, moved and removed
// 3D points out, at each keyframe.
#include <imr/sdk/plugin.hpp>

#include <string>

#include "point_refiner.hpp"

namespace imr::ceres_refiner {
namespace {

class CeresRefiner : public imr::sdk::Refiner {
 public:
  static constexpr const char* kId = "org.imr.refiner.ceres";
  static constexpr const char* kVersion = "1.0.0";
  static constexpr const char* kDescription =
      "Tracks triangulated by DLT once seen from enough parallax, each point refined on its "
      "reprojection error with fixed poses (Ceres, Huber); outliers removed";
  static constexpr const char* kParamsSchema = R"json({
    "min_keyframes": {"type": "integer", "default": 2, "minimum": 1, "maximum": 1000,
      "description": "keyframes that must observe a track before it is triangulated"},
    "min_views": {"type": "integer", "default": 2, "minimum": 2, "maximum": 1000,
      "description": "observations (frames, keyframes or not) a track's point must explain, at least"},
    "min_parallax_deg": {"type": "number", "default": 1.0, "minimum": 0.0, "maximum": 179.0,
      "description": "degrees between a track's rays (first observation to any other), at least, before it is triangulated"},
    "huber_px": {"type": "number", "default": 1.0, "minimum": 0.0,
      "description": "Huber loss scale of the refinement, pixels (0: plain least squares)"},
    "max_iterations": {"type": "integer", "default": 10, "minimum": 1, "maximum": 1000,
      "description": "Ceres iterations per point and keyframe, at most"},
    "max_reprojection_error": {"type": "number", "default": 2.0, "minimum": 1e-9,
      "description": "pixels; an observation farther from the refined point's projection is an outlier, and a point keeping one is removed"},
    "min_inlier_ratio": {"type": "number", "default": 0.5, "minimum": 0.0, "maximum": 1.0,
      "description": "share of a track's observations its point must explain"},
    "min_depth": {"type": "number", "default": 0.1, "minimum": 0.0,
      "description": "cheirality: depth of the point in every observing camera, at least (scene units)"},
    "max_distance": {"type": "number", "default": 100.0, "minimum": 1e-9,
      "description": "too far: distance from the point to its nearest observing camera, at most (scene units)"},
    "min_move": {"type": "number", "default": 0.01, "minimum": 0.0,
      "description": "a refined estimate is reported as moved only when it changed by more (scene units)"}
  })json";

  CeresRefiner(const imr::sdk::Params& params, const imr::sdk::Host& host)
      : refiner_(Options(params)), host_(host) {}

  void Refine(const imr_camera& camera, std::span<const imr_track_observation> observations,
              bool is_keyframe, imr::sdk::RefinerUpdate* update) override {
    refiner_.AddFrame(camera, observations, is_keyframe, update);
    if (is_keyframe)
      host_.Debug(std::string(kId) + ": keyframe " + std::to_string(camera.id) + ": " +
                  std::to_string(update->new_points.size()) + " new, " +
                  std::to_string(update->moved_points.size()) + " moved, " +
                  std::to_string(update->removed_ids.size()) + " removed, " +
                  std::to_string(refiner_.live_track_count()) + " live tracks");
  }

 private:
  static RefinerOptions Options(const imr::sdk::Params& params) {
    const imr::sdk::Params& p = params;  // checked, defaults filled (plugin.hpp)
    RefinerOptions o;
    o.min_keyframes = p.Get<int>("min_keyframes");
    o.min_views = p.Get<int>("min_views");
    o.min_parallax_deg = p.Get<double>("min_parallax_deg");
    o.huber_px = p.Get<double>("huber_px");
    o.max_iterations = p.Get<int>("max_iterations");
    o.max_reprojection_error = p.Get<double>("max_reprojection_error");
    o.min_inlier_ratio = p.Get<double>("min_inlier_ratio");
    o.min_depth = p.Get<double>("min_depth");
    o.max_distance = p.Get<double>("max_distance");
    o.min_move = p.Get<double>("min_move");
    if (const std::string error = o.Check(); !error.empty())
      throw imr::sdk::InvalidArgument("params." + error);
    return o;
  }

  PointRefiner refiner_;
  imr::sdk::Host host_;
};

}  // namespace
}  // namespace imr::ceres_refiner

IMR_PLUGIN_EXPORT(imr::ceres_refiner::CeresRefiner)
