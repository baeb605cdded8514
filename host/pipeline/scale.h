// The scene's scale from the data (issue 16): the engine's lengths (Steiner grid, ray length,
// radii, hole perimeter) are tuned for a street in metres; models from other tools come in any
// unit. engine.scale "auto" measures two figures over the first keyframes: the rays (camera
// centre -> point) and the extent each camera sees (how far the points it sees spread). The
// rays scale max_ray_length, by (median ray) / kReferenceMedianRay; every other length the job
// does not set (the Steiner grid, the radii: the scene's own sizes) by the smaller of that ratio
// and (view extent) / kReferenceViewExtent: a scene seen from afar (a camera moving forward
// looking 70-100 units ahead at a street 12 wide) is smaller than its rays say (issue 37). Each
// ratio is rounded to 1, 2 or 5 times a power of ten.
#pragma once

#include "host/engine/engine.h"

#include <nlohmann/json.hpp>

#include <cstdint>
#include <set>
#include <string>
#include <unordered_map>
#include <vector>

namespace imr::pipeline {

enum class ScaleMode {
  kMetric,  // The defaults as they are: a street in metres.
  kAuto,    // Lengths scaled from the data.
};

// The median ray of the street stream the metric defaults were tuned on
// (../shared/data/street-stream: 25.2 m over the whole stream, 24.8 m as ScaleProbe measures its
// first five keyframes).
inline constexpr double kReferenceMedianRay = 25.0;
// The extent one camera sees on that stream (ScaleEstimate::view_extent: 11.38 over the 24
// cameras of its first five keyframes).
inline constexpr double kReferenceViewExtent = 11.4;
inline constexpr double kAroundAnObject = 2.0;
// The 95th percentile ray of that stream (37.5 m), which the metric max_ray_length (40) covers.
inline constexpr double kReferenceP95Ray = 37.5;

// The options in scene units, with their metric defaults (EngineOptions{}).
const std::vector<std::string>& ScaledOptionNames();

// The scale mode of a job's "engine" object: its "scale" ("auto" | "metric"), else auto for the
// formats whose units are unknown (colmap, openmvg, slam_json, middlebury), metric for the others.
// "scale" must be validated already (EngineOptionsSchema).
ScaleMode ScaleModeOf(const nlohmann::json& engine_json, const std::string& input_format);

struct ScaleEstimate {
  int keyframes = 0;         // updates looked at
  int64_t rays = 0;          // observations measured (a new point and one of its cameras)
  double median_ray = 0.0;   // their lengths
  double p95_ray = 0.0;
  double ratio = 1.0;        // median_ray / kReferenceMedianRay (1 when no ray was measured)
  double factor = 1.0;       // the ratio rounded to 1, 2 or 5 times a power of ten (RoundTo125)
  // max_ray_length's: factor, or when the view extent decides (below) and the scene's Steiner
  // grid gets finer than the rays' factor, the smaller p95_ray / kReferenceP95Ray rounded to
  // RoundToR10: the rays need reach no further than the street's do past their 95th percentile,
  // and the grid around each camera, of (max_ray_length / steiner_spacing)^3 nodes, stays small.
  double reach_factor = 1.0;
  // The extent seen per camera: for each camera that sees at least kMinViewPoints of the
  // measured points, the median distance of those points from their (per axis) median; the
  // median of that over the cameras.
  int64_t views = 0;          // cameras measured
  double view_extent = 0.0;   // 0 when no camera was
  double extent_ratio = 0.0;  // view_extent / kReferenceViewExtent (0 when not measured)
  // The other lengths': RoundTo125 of the smaller of ratio and extent_ratio (factor when the
  // extent was not measured), and which decided it ("rays" or "view extent").
  double scene_factor = 1.0;
  std::string decided_by = "rays";
  // Cameras around an object (a ring, an orbit: their centres spread more than
  // kAroundAnObject times as far as the points) see it across free space as wide as their rays
  // are long: there the rays decide every length. Along a path (a street), the free space is as
  // wide as what each camera sees, and the view extent may decide.
  double camera_spread = 0.0;  // Spread of the measured cameras' centres
  double point_spread = 0.0;   // Spread of the measured points
  bool around_an_object = false;
  static constexpr int kMinViewPoints = 20;
};

// x rounded, in log scale, to the nearest of 1, 2, 5 times a power of ten: the lengths stay round,
// a median a few percent off changes nothing, and a model in millimetres gets exactly 1000 times
// the values of the same model in metres. 1 for x <= 0 or not finite.
double RoundTo125(double x);
// x rounded, in log scale, to the nearest of the Renard R10 series (1, 1.25, 1.6, 2, 2.5, 3.15,
// 4, 5, 6.3, 8) times a power of ten. 1 for x <= 0 or not finite.
double RoundToR10(double x);

// Measures ray lengths over the first keyframes; Enough() once they decide the scale.
class ScaleProbe {
 public:
  void Add(const engine::KeyframeUpdate& update);
  // At least kMinKeyframes keyframes and kMinRays rays, or kMaxKeyframes keyframes whatever
  // their rays (a sparse sequence does not hold the engine back for long).
  bool Enough() const;
  ScaleEstimate Estimate() const;

  static constexpr int kMinKeyframes = 5;
  static constexpr int64_t kMinRays = 2000;
  static constexpr int kMaxKeyframes = 50;

 private:
  std::unordered_map<uint64_t, engine::Vec3> centers_;
  std::vector<double> lengths_;
  std::unordered_map<uint64_t, std::vector<engine::Vec3>> seen_;  // per camera, its points
  int keyframes_ = 0;
};

// `base` with every option of ScaledOptionNames() not in `explicit_keys` set to its metric default
// times estimate.factor.
engine::EngineOptions ScaledOptions(const engine::EngineOptions& base, const ScaleEstimate& estimate,
                                    const std::set<std::string>& explicit_keys);

// What engine.scale auto runs the engine with: ScaledOptions, checked (Check, CheckSteinerGrid:
// std::runtime_error naming the median ray and what to set when unusable), or `base` when no ray
// was measured. *line: the log's line (ScaleLogLine, or the warning that the defaults are kept).
engine::EngineOptions AutoScaledOptions(const engine::EngineOptions& base, const ScaleEstimate& estimate,
                                        const std::set<std::string>& explicit_keys, std::string* line);

// For the report and the log: the mode, what it was decided from, and the values chosen.
nlohmann::json ScaleJson(ScaleMode mode, const ScaleEstimate& estimate,
                         const engine::EngineOptions& chosen,
                         const std::set<std::string>& explicit_keys);
std::string ScaleLogLine(const ScaleEstimate& estimate, const engine::EngineOptions& chosen,
                         const std::set<std::string>& explicit_keys);

}  // namespace imr::pipeline
