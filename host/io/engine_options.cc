#include "host/io/engine_options.h"

namespace imr::io {
using nlohmann::json;

const json& EngineOptionsSchema() {
  static const json schema = [] {
    const engine::EngineOptions d;
    json s;
    s["steiner_spacing"] = {{"type", "number"}, {"default", d.steiner_spacing}, {"minimum", 1e-9},
                            {"description", "Steiner grid step, metres (paper: 5)"}};
    s["steiner_margin"] = {{"type", "number"}, {"default", d.steiner_margin}, {"minimum", 0.0},
                           {"description", "grid covers each camera +- (max_ray_length + margin)"}};
    s["w1"] = {{"type", "number"}, {"default", d.w1}, {"minimum", 0.0},
               {"description", "weight added to cells a ray traverses"}};
    s["w2"] = {{"type", "number"}, {"default", d.w2}, {"minimum", 0.0},
               {"description", "weight added to their neighbours"}};
    s["w3"] = {{"type", "number"}, {"default", d.w3}, {"minimum", 0.0},
               {"description", "weight added to the neighbours' neighbours"}};
    s["free_threshold"] = {{"type", "number"}, {"default", d.free_threshold}, {"minimum", 0.0},
                           {"description", "T_w: a cell is free space when its weight exceeds it"}};
    s["window"] = {{"type", "integer"}, {"default", d.window}, {"minimum", 1},
                   {"description", "W: a move re-casts the rays of the last W cameras"}};
    s["max_ray_length"] = {{"type", "number"}, {"default", d.max_ray_length}, {"minimum", 1e-9},
                           {"description", "rays longer than this (metres) are not cast"}};
    s["scale"] = {{"type", "string"},
                  {"enum", {"auto", "metric"}},
                  {"description", "lengths in scene units (steiner_spacing, steiner_margin, "
                                  "max_ray_length, shrink_radius, regrow_radius, "
                                  "fill_holes_perimeter): auto scales those the job does not set "
                                  "by the median ray of the first keyframes / 25; metric keeps "
                                  "the defaults (a street in metres). Default: auto for colmap, "
                                  "openmvg, slam_json and middlebury, metric for the others"}};
    s["long_rays"] = {{"type", "string"},
                      {"default", engine::ToString(d.long_rays)},
                      {"enum", {engine::ToString(engine::LongRays::kSkip),
                                engine::ToString(engine::LongRays::kNearCamera)}},
                      {"description", "a ray longer than max_ray_length carves nothing (skip) or "
                                      "its max_ray_length next to the camera (near_camera)"}};
    s["visibility_mode"] = {{"type", "string"},
                            {"default", engine::ToString(d.visibility_mode)},
                            {"enum", {engine::ToString(engine::VisibilityMode::kWeights),
                                      engine::ToString(engine::VisibilityMode::kRays),
                                      engine::ToString(engine::VisibilityMode::kExact)}},
                            {"description", "weights (the paper's transfer policy), rays (Lovi et "
                                            "al.) or exact (per-cell ray sets, re-walked locally)"}};
    s["rays_per_cell"] = {{"type", "integer"}, {"default", d.rays_per_cell}, {"minimum", 1},
                          {"description", "K of the forgetting heuristic (rays mode)"}};
    s["steiner_export"] = {
        {"type", "string"},
        {"default", engine::ToString(d.steiner_export)},
        {"enum", {engine::ToString(engine::SteinerExportRule::kNone),
                  engine::ToString(engine::SteinerExportRule::kAllSteiner),
                  engine::ToString(engine::SteinerExportRule::kAnySteiner)}},
        {"description", "which triangles touching Steiner points the exported mesh drops"}};
    s["fill_holes_perimeter"] = {
        {"type", "number"}, {"default", d.fill_holes_perimeter}, {"minimum", 0.0},
        {"description", "export: close holes with a perimeter up to this (metres; 0: none)"}};
    s["smoothing_iterations"] = {
        {"type", "integer"}, {"default", d.smoothing_iterations}, {"minimum", 0},
        {"description", "export: Taubin smoothing steps, boundary fixed (0: none)"}};
    s["transfer_on_insert"] = {
        {"type", "boolean"}, {"default", d.transfer_on_insert},
        {"description", "cells made by inserting a new point get weights from the policy (DESIGN "
                        "section 3 step 3); default false: they start at 0 and the point's own "
                        "rays weight them (measured: far better completeness with nearest)"}};
    s["transfer_camera_side"] = {
        {"type", "boolean"}, {"default", d.transfer_camera_side},
        {"description", "cells behind an inserted or moved point, seen from its cameras, start "
                        "at 0 instead of taking the policy's weight"}};
    s["nonnegative_weights"] = {
        {"type", "boolean"}, {"default", d.nonnegative_weights},
        {"description", "a backward cast never takes a cell's weight below 0"}};
    s["steiner_jitter"] = {
        {"type", "number"}, {"default", d.steiner_jitter}, {"minimum", 0.0}, {"maximum", 0.25},
        {"description", "Steiner points move off their grid nodes by up to this fraction of "
                        "steiner_spacing (avoids cospherical cells)"}};
    s["shrink_radius"] = {{"type", "number"}, {"default", d.shrink_radius}, {"minimum", 0.0},
                          {"description", "enclosing set E: cells within this distance, metres"}};
    s["shrink_passes"] = {{"type", "integer"}, {"default", d.shrink_passes}, {"minimum", 1},
                          {"description", "passes of shrink over E"}};
    s["check_invariants"] = {{"type", "boolean"}, {"default", d.check_invariants},
                             {"description", "full manifold check after every keyframe (slow)"}};
    s["regrow_radius"] = {{"type", "number"}, {"default", d.regrow_radius}, {"minimum", 0.0},
                          {"description", "after each keyframe, O is labelled again in weight "
                                          "order within this distance (metres) of moved and new "
                                          "points; 0: off"}};
    s["exact_min_rays"] = {{"type", "integer"}, {"default", d.exact_min_rays}, {"minimum", 1},
                           {"description", "exact mode: a cell is free space when at least this "
                                           "many rays cross it"}};
    return s;
  }();
  return schema;
}

bool EngineOptionsFromJson(const json& j, engine::EngineOptions* o, std::vector<Problem>* problems) {
  const std::size_t before = problems->size();
  ValidateAgainstSchema(EngineOptionsSchema(), j, "engine", problems);
  if (problems->size() != before) return false;
  const json v = WithDefaults(EngineOptionsSchema(), j);
  o->steiner_spacing = v["steiner_spacing"];
  o->steiner_margin = v["steiner_margin"];
  o->w1 = v["w1"];
  o->w2 = v["w2"];
  o->w3 = v["w3"];
  o->free_threshold = v["free_threshold"];
  o->window = v["window"];
  o->max_ray_length = v["max_ray_length"];
  engine::FromString(v["visibility_mode"].get<std::string>(), &o->visibility_mode);
  engine::FromString(v["long_rays"].get<std::string>(), &o->long_rays);
  o->rays_per_cell = v["rays_per_cell"];
  engine::FromString(v["steiner_export"].get<std::string>(), &o->steiner_export);
  o->fill_holes_perimeter = v["fill_holes_perimeter"];
  o->smoothing_iterations = v["smoothing_iterations"];
  o->transfer_on_insert = v["transfer_on_insert"];
  o->transfer_camera_side = v["transfer_camera_side"];
  o->nonnegative_weights = v["nonnegative_weights"];
  o->steiner_jitter = v["steiner_jitter"];
  o->shrink_radius = v["shrink_radius"];
  o->shrink_passes = v["shrink_passes"];
  o->check_invariants = v["check_invariants"];
  o->regrow_radius = v["regrow_radius"];
  o->exact_min_rays = v["exact_min_rays"];
  std::string error;
  if (!o->Check(&error)) {
    problems->push_back({"engine", error});
    return false;
  }
  return true;
}

json EngineOptionsToJson(const engine::EngineOptions& o) {
  return {{"steiner_spacing", o.steiner_spacing},
          {"steiner_margin", o.steiner_margin},
          {"w1", o.w1},
          {"w2", o.w2},
          {"w3", o.w3},
          {"free_threshold", o.free_threshold},
          {"window", o.window},
          {"max_ray_length", o.max_ray_length},
          {"visibility_mode", engine::ToString(o.visibility_mode)},
          {"long_rays", engine::ToString(o.long_rays)},
          {"rays_per_cell", o.rays_per_cell},
          {"steiner_export", engine::ToString(o.steiner_export)},
          {"fill_holes_perimeter", o.fill_holes_perimeter},
          {"smoothing_iterations", o.smoothing_iterations},
          {"transfer_on_insert", o.transfer_on_insert},
          {"transfer_camera_side", o.transfer_camera_side},
          {"nonnegative_weights", o.nonnegative_weights},
          {"steiner_jitter", o.steiner_jitter},
          {"shrink_radius", o.shrink_radius},
          {"shrink_passes", o.shrink_passes},
          {"regrow_radius", o.regrow_radius},
          {"exact_min_rays", o.exact_min_rays},
          {"check_invariants", o.check_invariants}};
}

}  // namespace imr::io
