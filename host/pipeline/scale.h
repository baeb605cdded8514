// The scene's scale from the data (issue 16): the engine's lengths (Steiner grid, ray length,
// radii, hole perimeter) are tuned for a street in metres; models from other tools come in any
// unit. engine.scale "auto" measures the rays of the first keyframes (camera centre -> point) and
// scales every length the job does not set by (median ray) / kReferenceMedianRay, rounded to 1, 2
// or 5 times a power of ten.
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
};

// x rounded, in log scale, to the nearest of 1, 2, 5 times a power of ten: the lengths stay round,
// a median a few percent off changes nothing, and a model in millimetres gets exactly 1000 times
// the values of the same model in metres. 1 for x <= 0 or not finite.
double RoundTo125(double x);

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
  int keyframes_ = 0;
};

// `base` with every option of ScaledOptionNames() not in `explicit_keys` set to its metric default
// times estimate.factor.
engine::EngineOptions ScaledOptions(const engine::EngineOptions& base, const ScaleEstimate& estimate,
                                    const std::set<std::string>& explicit_keys);

// For the report and the log: the mode, what it was decided from, and the values chosen.
nlohmann::json ScaleJson(ScaleMode mode, const ScaleEstimate& estimate,
                         const engine::EngineOptions& chosen,
                         const std::set<std::string>& explicit_keys);
std::string ScaleLogLine(const ScaleEstimate& estimate, const engine::EngineOptions& chosen,
                         const std::set<std::string>& explicit_keys);

}  // namespace imr::pipeline
