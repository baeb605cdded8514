// Options, enums and Status helpers of the engine (no CGAL here).
#include <cmath>
#include <cstdio>
#include <sstream>

#include "host/engine/engine.h"

namespace imr::engine {
namespace {

// Resident memory per Steiner point, for the estimate in the message: the synthetic street (20
// frames) with steiner_spacing 0.9 placed 1.28 M Steiner points (9.0 M cells) and peaked at
// 1.44 GB (/usr/bin/time -v imr run, 2026-11-28): about 1.1 kB each.
constexpr double kSteinerBytesPerNode = 1100.0;

}  // namespace

std::string ToString(VisibilityMode mode) {
  switch (mode) {
    case VisibilityMode::kWeights: return "weights";
    case VisibilityMode::kRays: return "rays";
    case VisibilityMode::kExact: return "exact";
  }
  return "weights";
}

bool FromString(const std::string& s, VisibilityMode* mode) {
  if (s == "weights") *mode = VisibilityMode::kWeights;
  else if (s == "rays") *mode = VisibilityMode::kRays;
  else if (s == "exact") *mode = VisibilityMode::kExact;
  else return false;
  return true;
}

std::string ToString(SteinerExportRule rule) {
  switch (rule) {
    case SteinerExportRule::kNone: return "none";
    case SteinerExportRule::kAllSteiner: return "all_steiner";
    case SteinerExportRule::kAnySteiner: return "any_steiner";
    case SteinerExportRule::kOpenSteiner: return "open_steiner";
  }
  return "all_steiner";
}

bool FromString(const std::string& s, SteinerExportRule* rule) {
  if (s == "none") *rule = SteinerExportRule::kNone;
  else if (s == "all_steiner") *rule = SteinerExportRule::kAllSteiner;
  else if (s == "any_steiner") *rule = SteinerExportRule::kAnySteiner;
  else if (s == "open_steiner") *rule = SteinerExportRule::kOpenSteiner;
  else return false;
  return true;
}

std::string ToString(LongRays rule) {
  return rule == LongRays::kSkip ? "skip" : "near_camera";
}

bool FromString(const std::string& s, LongRays* rule) {
  if (s == "skip") *rule = LongRays::kSkip;
  else if (s == "near_camera") *rule = LongRays::kNearCamera;
  else return false;
  return true;
}

std::string ToString(ForgetMode mode) {
  return mode == ForgetMode::kOn ? "true" : mode == ForgetMode::kOff ? "false" : "auto";
}

bool FromString(const std::string& s, ForgetMode* mode) {
  if (s == "true") *mode = ForgetMode::kOn;
  else if (s == "false") *mode = ForgetMode::kOff;
  else if (s == "auto") *mode = ForgetMode::kAuto;
  else return false;
  return true;
}

double EngineOptions::SteinerNodesPerCamera() const {
  const double side = 2.0 * (max_ray_length + steiner_margin) / steiner_spacing + 2.0;
  return side * side * side;
}

std::string EngineOptions::CheckSteinerGrid() const {
  const bool lengths = std::isfinite(steiner_spacing) && steiner_spacing > 0.0 &&
                       std::isfinite(max_ray_length) && max_ray_length > 0.0 &&
                       std::isfinite(steiner_margin) && steiner_margin >= 0.0;
  if (!lengths || SteinerNodesPerCamera() <= kMaxSteinerNodesPerCamera) return {};
  char text[400];
  std::snprintf(text, sizeof(text),
                "the Steiner grid would have %.3g nodes around each camera (a cube of %.3g "
                "steps a side: 2 x (max_ray_length %g + steiner_margin %g) / steiner_spacing "
                "%g), about %.3g GB of memory, more than the %.0e allowed: raise "
                "steiner_spacing or lower max_ray_length or steiner_margin",
                SteinerNodesPerCamera(), std::cbrt(SteinerNodesPerCamera()), max_ray_length,
                steiner_margin, steiner_spacing,
                SteinerNodesPerCamera() * kSteinerBytesPerNode / 1e9, kMaxSteinerNodesPerCamera);
  return text;
}

std::string EngineOptions::Check() const {
  std::ostringstream e;
  auto finite_positive = [](double v) { return std::isfinite(v) && v > 0.0; };
  if (!finite_positive(steiner_spacing)) e << "steiner_spacing must be > 0; ";
  if (!std::isfinite(steiner_margin) || steiner_margin < 0.0) e << "steiner_margin must be >= 0; ";
  if (!std::isfinite(steiner_jitter) || steiner_jitter < 0.0 || steiner_jitter > 0.25)
    e << "steiner_jitter must be in [0, 0.25]; ";
  for (double o : steiner_origin)
    if (!std::isfinite(o)) e << "steiner_origin must be finite; ";
  if (!std::isfinite(w1) || !std::isfinite(w2) || !std::isfinite(w3) || w1 < 0 || w2 < 0 || w3 < 0)
    e << "w1, w2, w3 must be finite and >= 0; ";
  if (!std::isfinite(free_threshold)) e << "free_threshold must be finite; ";
  if (window < 1) e << "window must be >= 1; ";
  if (exact_min_rays < 1) e << "exact_min_rays must be >= 1; ";
  if (!std::isfinite(fill_holes_perimeter) || fill_holes_perimeter < 0.0)
    e << "fill_holes_perimeter must be >= 0; ";
  if (smoothing_iterations < 0) e << "smoothing_iterations must be >= 0; ";
  if (!std::isfinite(retriangulate_planes) || retriangulate_planes < 0.0)
    e << "retriangulate_planes must be >= 0 (median edge lengths; 0: off); ";
  if (filter_normals < 0) e << "filter_normals must be >= 0; ";
  if (mesh_pass_rounds < 1 || mesh_pass_rounds > 16) e << "mesh_pass_rounds must be in [1, 16]; ";
  if (!std::isfinite(filter_normals_spatial) || !(filter_normals_spatial > 0.0))
    e << "filter_normals_spatial must be > 0 (median edge lengths); ";
  if (!std::isfinite(filter_normals_range) || !(filter_normals_range > 0.0))
    e << "filter_normals_range must be > 0; ";
  if (!std::isfinite(min_component_area) || min_component_area < 0.0)
    e << "min_component_area must be >= 0 (x steiner_spacing^2; 0: keep every piece); ";
  if (!std::isfinite(open_steiner_crease) || open_steiner_crease < 1.0 || open_steiner_crease > 180.0)
    e << "open_steiner_crease must be in [1, 180] degrees (180: regions joined across any angle); ";
  if (!std::isfinite(regrow_radius) || regrow_radius < 0.0) e << "regrow_radius must be >= 0; ";
  if (camera_path < 0 || camera_path > 100000) e << "camera_path must be in [0, 100000]; ";
  if (camera_path_repair < 0 || camera_path_repair > 64)
    e << "camera_path_repair must be in [0, 64]; ";
  if (!std::isfinite(camera_path_radius) || camera_path_radius < 0.0)
    e << "camera_path_radius must be >= 0; ";
  if (!(min_move_fraction >= 0.0 && min_move_fraction <= 1.0))
    e << "min_move_fraction must be in [0, 1]; ";
  if (!finite_positive(max_ray_length)) e << "max_ray_length must be > 0; ";
  if (rays_per_cell < 1) e << "rays_per_cell must be >= 1; ";
  if (!std::isfinite(shrink_radius) || shrink_radius < 0.0) e << "shrink_radius must be >= 0; ";
  if (!std::isfinite(forget_distance) || forget_distance < 0.0)
    e << "forget_distance must be >= 0; ";
  if (!std::isfinite(forget_step) || forget_step < 0.0) e << "forget_step must be >= 0; ";
  // kAuto stays off in the rays mode (Forgetting::Armed).
  if (forget == ForgetMode::kOn && visibility_mode == VisibilityMode::kRays)
    e << "forget needs visibility_mode 'exact' or 'weights' (the rays mode is the paper's "
         "baseline, kept whole); ";
  if (shrink_passes < 1) e << "shrink_passes must be >= 1; ";
  if (!finite_positive(weight_unit) || weight_unit > 0.1) e << "weight_unit must be in (0, 0.1]; ";
  if (finite_positive(weight_unit) && std::isfinite(free_threshold) &&
      std::abs(free_threshold / weight_unit) > 1e15)
    e << "free_threshold / weight_unit too large for int64 weights; ";
  if (max_cells_per_ray < 1) e << "max_cells_per_ray must be >= 1; ";
  if (num_threads < 0 || num_threads > 1024) e << "num_threads must be in [0, 1024] (0: all cores); ";
  const std::string s = e.str();
  return s.empty() ? s : s.substr(0, s.size() - 2);
}

double EngineOptions::ForgetDistance() const {
  if (forget_distance > 0.0) return forget_distance;
  return max_ray_length + steiner_margin + shrink_radius + steiner_spacing;
}

double EngineOptions::MinComponentArea() const {
  return min_component_area * steiner_spacing * steiner_spacing;
}

double EngineOptions::ForgetStep() const {
  return forget_step > 0.0 ? forget_step : 2.0 * steiner_spacing;
}

}  // namespace imr::engine
