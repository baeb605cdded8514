#include "host/pipeline/scale.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <utility>

namespace imr::pipeline {
namespace {

using nlohmann::json;

// Every length of EngineOptions, by its job key.
const std::vector<std::pair<std::string, double engine::EngineOptions::*>>& LengthFields() {
  static const std::vector<std::pair<std::string, double engine::EngineOptions::*>> fields = {
      {"steiner_spacing", &engine::EngineOptions::steiner_spacing},
      {"steiner_margin", &engine::EngineOptions::steiner_margin},
      {"max_ray_length", &engine::EngineOptions::max_ray_length},
      {"shrink_radius", &engine::EngineOptions::shrink_radius},
      {"regrow_radius", &engine::EngineOptions::regrow_radius},
      {"camera_path_radius", &engine::EngineOptions::camera_path_radius},
      {"fill_holes_perimeter", &engine::EngineOptions::fill_holes_perimeter},
  };
  return fields;
}

// The rays decide how long a ray may be; the scene's own sizes may be smaller.
double FactorOf(const ScaleEstimate& e, const std::string& option) {
  return option == "max_ray_length" ? e.reach_factor : e.scene_factor;
}

// The q-quantile by nearest rank; reorders v.
double Quantile(std::vector<double>& v, double q) {
  if (v.empty()) return 0.0;
  const auto k = static_cast<std::size_t>(q * static_cast<double>(v.size() - 1) + 0.5);
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

// How far `points` spread: the median distance from their per-axis median (robust to outliers).
double Spread(const std::vector<engine::Vec3>& points) {
  engine::Vec3 median{};
  std::vector<double> v(points.size());
  for (int a = 0; a < 3; ++a) {
    for (std::size_t i = 0; i < points.size(); ++i) v[i] = points[i][a];
    median[a] = Quantile(v, 0.5);
  }
  for (std::size_t i = 0; i < points.size(); ++i)
    v[i] = std::hypot(points[i][0] - median[0], points[i][1] - median[1], points[i][2] - median[2]);
  return Quantile(v, 0.5);
}

std::string Number(double x) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3g", x);
  return buf;
}

}  // namespace

double RoundTo125(double x) {
  if (!(x > 0.0) || !std::isfinite(x)) return 1.0;
  const double decade = std::pow(10.0, std::floor(std::log10(x)));
  double best = decade, best_distance = std::abs(std::log(x / decade));
  for (double m : {2.0, 5.0, 10.0}) {
    const double d = std::abs(std::log(x / (m * decade)));
    if (d < best_distance) best = m * decade, best_distance = d;
  }
  return best;
}

double RoundToR10(double x) {
  if (!(x > 0.0) || !std::isfinite(x)) return 1.0;
  static constexpr double kR10[] = {1.0, 1.25, 1.6, 2.0, 2.5, 3.15, 4.0, 5.0, 6.3, 8.0};
  const double step = std::round(10.0 * std::log10(x));  // tenths of a decade
  const double decade = std::floor(step / 10.0);
  return kR10[static_cast<int>(step - 10.0 * decade)] * std::pow(10.0, decade);
}

const std::vector<std::string>& ScaledOptionNames() {
  static const std::vector<std::string> names = [] {
    std::vector<std::string> n;
    for (const auto& [name, field] : LengthFields()) n.push_back(name);
    return n;
  }();
  return names;
}

ScaleMode ScaleModeOf(const json& engine_json, const std::string& input_format) {
  if (engine_json.is_object() && engine_json.contains("scale") && engine_json["scale"].is_string())
    return engine_json["scale"] == "auto" ? ScaleMode::kAuto : ScaleMode::kMetric;
  for (const char* f : {"colmap", "openmvg", "slam_json", "middlebury"})
    if (input_format == f) return ScaleMode::kAuto;
  return ScaleMode::kMetric;
}

void ScaleProbe::Add(const engine::KeyframeUpdate& update) {
  ++keyframes_;
  for (const engine::Camera& c : update.cameras) centers_[c.id] = c.center;
  const auto measure = [&](const engine::Vec3& x, const std::vector<uint64_t>& camera_ids) {
    for (uint64_t id : camera_ids) {
      const auto it = centers_.find(id);
      if (it == centers_.end()) continue;
      const engine::Vec3& c = it->second;
      const double d = std::hypot(x[0] - c[0], x[1] - c[1], x[2] - c[2]);
      if (std::isfinite(d) && d > 0.0) {
        lengths_.push_back(d);
        seen_[id].push_back(x);
      }
    }
  };
  for (const engine::NewPoint& p : update.new_points) measure(p.position, p.camera_ids);
  // A moved point's new cameras: its later, usually closer views (a point enters far ahead of a
  // camera moving forward; its first rays alone would overstate the scale).
  for (const engine::MovedPoint& p : update.moved_points) measure(p.position, p.camera_ids);
}

bool ScaleProbe::Enough() const {
  return (keyframes_ >= kMinKeyframes && static_cast<int64_t>(lengths_.size()) >= kMinRays) ||
         keyframes_ >= kMaxKeyframes;
}

ScaleEstimate ScaleProbe::Estimate() const {
  ScaleEstimate e;
  e.keyframes = keyframes_;
  e.rays = static_cast<int64_t>(lengths_.size());
  if (lengths_.empty()) return e;
  std::vector<double> lengths = lengths_;  // one copy for both quantiles
  e.median_ray = Quantile(lengths, 0.5);
  e.p95_ray = Quantile(lengths, 0.95);
  e.ratio = e.median_ray / kReferenceMedianRay;
  e.factor = RoundTo125(e.ratio);
  e.scene_factor = e.reach_factor = e.factor;
  std::vector<double> extents;
  std::vector<engine::Vec3> all, centres;
  for (const auto& [camera, points] : seen_) {
    all.insert(all.end(), points.begin(), points.end());
    if (points.size() >= static_cast<std::size_t>(ScaleEstimate::kMinViewPoints)) {
      extents.push_back(Spread(points));
      centres.push_back(centers_.at(camera));
    }
  }
  e.views = static_cast<int64_t>(extents.size());
  if (!extents.empty()) {
    e.view_extent = Quantile(extents, 0.5);
    e.extent_ratio = e.view_extent / kReferenceViewExtent;
    e.camera_spread = Spread(centres);
    e.point_spread = Spread(all);
    e.around_an_object = e.camera_spread > kAroundAnObject * e.point_spread;
    if (!e.around_an_object && e.view_extent > 0.0 && e.extent_ratio < e.ratio) {
      e.scene_factor = RoundTo125(e.extent_ratio);
      e.decided_by = "view extent";
      if (e.scene_factor < e.factor)
        e.reach_factor = std::min(e.factor, RoundToR10(e.p95_ray / kReferenceP95Ray));
    }
  }
  return e;
}

engine::EngineOptions ScaledOptions(const engine::EngineOptions& base, const ScaleEstimate& estimate,
                                    const std::set<std::string>& explicit_keys) {
  const engine::EngineOptions metric;
  engine::EngineOptions o = base;
  for (const auto& [name, field] : LengthFields())
    if (!explicit_keys.count(name)) o.*field = metric.*field * FactorOf(estimate, name);
  return o;
}

engine::EngineOptions AutoScaledOptions(const engine::EngineOptions& base, const ScaleEstimate& estimate,
                                        const std::set<std::string>& explicit_keys, std::string* line) {
  if (estimate.rays == 0) {
    *line = "engine.scale auto: no ray to measure in the first " + std::to_string(estimate.keyframes) +
            " keyframes; the metric defaults are kept";
    return base;
  }
  const engine::EngineOptions o = ScaledOptions(base, estimate, explicit_keys);
  std::string error = o.Check();
  if (error.empty()) error = o.CheckSteinerGrid();
  if (!error.empty())
    throw std::runtime_error("engine.scale auto (median ray " + std::to_string(estimate.median_ray) +
                             ") gives unusable options: " + error +
                             "; set the engine's lengths in the job, or engine.scale \"metric\"");
  *line = ScaleLogLine(estimate, o, explicit_keys);
  return o;
}

json ScaleJson(ScaleMode mode, const ScaleEstimate& estimate, const engine::EngineOptions& chosen,
               const std::set<std::string>& explicit_keys) {
  json j = {{"mode", mode == ScaleMode::kAuto ? "auto" : "metric"}};
  if (mode == ScaleMode::kMetric) return j;
  j["from"] = {{"keyframes", estimate.keyframes}, {"rays", estimate.rays}};
  j["median_ray"] = estimate.median_ray;
  j["p95_ray"] = estimate.p95_ray;
  j["reference_median_ray"] = kReferenceMedianRay;
  j["ratio"] = estimate.ratio;
  j["factor"] = estimate.factor;
  j["view_extent"] = estimate.view_extent;
  j["views"] = estimate.views;
  j["reference_view_extent"] = kReferenceViewExtent;
  j["extent_ratio"] = estimate.extent_ratio;
  j["scene_factor"] = estimate.scene_factor;
  j["reach_factor"] = estimate.reach_factor;
  j["camera_spread"] = estimate.camera_spread;
  j["point_spread"] = estimate.point_spread;
  j["around_an_object"] = estimate.around_an_object;
  j["decided_by"] = estimate.decided_by;
  json set = json::object(), kept = json::array();
  for (const auto& [name, field] : LengthFields()) {
    if (explicit_keys.count(name)) kept.push_back(name);
    else set[name] = chosen.*field;
  }
  j["set"] = set;
  j["given_by_the_job"] = kept;
  return j;
}

std::string ScaleLogLine(const ScaleEstimate& estimate, const engine::EngineOptions& chosen,
                         const std::set<std::string>& explicit_keys) {
  std::string s = "engine.scale auto: median ray " + Number(estimate.median_ray) + " (" +
                  std::to_string(estimate.rays) + " rays of the first " +
                  std::to_string(estimate.keyframes) + " keyframes; the metric defaults assume " +
                  Number(kReferenceMedianRay) + "): ratio " + Number(estimate.ratio) + ", scale " +
                  Number(estimate.factor);
  if (estimate.views > 0)
    s += "; extent seen per camera " + Number(estimate.view_extent) + " (" +
         std::to_string(estimate.views) + " cameras; the defaults assume " +
         Number(kReferenceViewExtent) + "): ratio " + Number(estimate.extent_ratio);
  // Which figure decided, always said: a user reads it at the default verbosity (issue 47).
  if (estimate.scene_factor != estimate.factor)
    s += ", scale " + Number(estimate.scene_factor) + " for every length but max_ray_length (the " +
         estimate.decided_by + " decided)";
  else
    s += std::string(estimate.views > 0 ? ";" : ",") + " the " + estimate.decided_by +
         " decided every length" + (estimate.around_an_object ? " (cameras around an object)" : "");
  if (estimate.reach_factor != estimate.factor)
    s += "; max_ray_length from the 95th percentile ray " + Number(estimate.p95_ray) +
         " (the defaults assume " + Number(kReferenceP95Ray) + "): scale " + Number(estimate.reach_factor);
  s += ",";
  bool any = false;
  for (const auto& [name, field] : LengthFields()) {
    if (explicit_keys.count(name)) continue;
    s += std::string(any ? "," : "") + " " + name + " " + Number(chosen.*field);
    any = true;
  }
  if (!any) s += " every length given by the job";
  return s;
}

}  // namespace imr::pipeline
