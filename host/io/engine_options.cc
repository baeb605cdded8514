#include "host/io/engine_options.h"

#include <type_traits>

namespace imr::io {
using nlohmann::json;
using engine::EngineOptions;

namespace {

// The values of each enum the options use, in the order the schema lists them.
template <typename E>
std::vector<E> EnumValues();
template <>
std::vector<engine::ForgetMode> EnumValues() {
  return {engine::ForgetMode::kAuto, engine::ForgetMode::kOn, engine::ForgetMode::kOff};
}
template <>
std::vector<engine::LongRays> EnumValues() {
  return {engine::LongRays::kSkip, engine::LongRays::kNearCamera};
}
template <>
std::vector<engine::VisibilityMode> EnumValues() {
  return {engine::VisibilityMode::kWeights, engine::VisibilityMode::kRays,
          engine::VisibilityMode::kExact};
}
template <>
std::vector<engine::SteinerExportRule> EnumValues() {
  return {engine::SteinerExportRule::kNone, engine::SteinerExportRule::kAllSteiner,
          engine::SteinerExportRule::kAnySteiner, engine::SteinerExportRule::kOpenSteiner};
}

// A row of the table: the schema entry follows from the member's type (double: number, int:
// integer, bool: boolean, an enum: string with its names), its default from EngineOptions{}.
// `bounds`: {"minimum": ..., "maximum": ...} in the member's JSON type (1 for an integer).
template <typename T>
EngineOption Option(const char* name, T EngineOptions::*member, json bounds, const char* unit,
                    const char* description) {
  const EngineOptions defaults;
  json s = std::move(bounds);
  if constexpr (std::is_enum_v<T>) {
    s["type"] = "string";
    s["default"] = engine::ToString(defaults.*member);
    for (T v : EnumValues<T>()) s["enum"].push_back(engine::ToString(v));
  } else {
    s["type"] = std::is_same_v<T, bool> ? "boolean" : std::is_integral_v<T> ? "integer" : "number";
    s["default"] = defaults.*member;
  }
  if (*unit) s["unit"] = unit;
  s["description"] = description;
  EngineOption o{name, std::move(s), {}, {}};
  o.read = [member](const json& v, EngineOptions* options) {
    if constexpr (std::is_enum_v<T>)
      engine::FromString(v.get<std::string>(), &(options->*member));  // the schema checked it
    else
      options->*member = v.get<T>();
  };
  o.write = [member](const EngineOptions& options) -> json {
    if constexpr (std::is_enum_v<T>)
      return engine::ToString(options.*member);
    else
      return options.*member;
  };
  return o;
}

const json kNone = json::object();
json Min(json v) { return {{"minimum", std::move(v)}}; }

std::vector<EngineOption> MakeTable() {
  using E = EngineOptions;
  std::vector<EngineOption> t = {
      Option("steiner_spacing", &E::steiner_spacing, Min(1e-9), "m",
             "Steiner grid step (paper: 5 m)"),
      Option("steiner_margin", &E::steiner_margin, Min(0.0), "m",
             "the grid covers every ray (and each camera's step) with this much of it on every side "
             "(at least one step of steiner_spacing)"),
      Option("w1", &E::w1, Min(0.0), "", "weight added to cells a ray traverses"),
      Option("w2", &E::w2, Min(0.0), "", "weight added to their neighbours"),
      Option("w3", &E::w3, Min(0.0), "", "weight added to the neighbours' neighbours"),
      Option("free_threshold", &E::free_threshold, Min(0.0), "",
             "T_w: a cell is free space when its weight exceeds it"),
      Option("window", &E::window, Min(1), "cameras",
             "W: a move re-casts the rays of the last W cameras"),
      Option("max_ray_length", &E::max_ray_length, Min(1e-9), "m",
             "rays longer than this are not cast whole"),
      Option("long_rays", &E::long_rays, kNone, "",
             "a ray longer than max_ray_length carves nothing (skip) or its max_ray_length next "
             "to the camera (near_camera)"),
      Option("visibility_mode", &E::visibility_mode, kNone, "",
             "weights (the paper's transfer policy), rays (Lovi et al.) or exact (per-cell ray "
             "sets, re-walked locally)"),
      Option("rays_per_cell", &E::rays_per_cell, Min(1), "rays",
             "K of the forgetting heuristic (rays mode)"),
      Option("exact_min_rays", &E::exact_min_rays, Min(1), "rays",
             "exact mode: a cell is free space when at least this many rays cross it"),
      Option("regrow_radius", &E::regrow_radius, Min(0.0), "m",
             "after each keyframe, O is labelled again in weight order within this distance of "
             "moved and new points; 0: off"),
      Option("camera_path", &E::camera_path, {{"minimum", 0}, {"maximum", 100000}}, "cameras",
             "after each keyframe, the cells holding the last this many camera centres and the "
             "segments between them join O (the vehicle drove there: free space), each with the "
             "free cells around it that keep the surface a manifold; 0: off"),
      Option("camera_path_repair", &E::camera_path_repair, {{"minimum", 0}, {"maximum", 64}},
             "rounds", "camera_path: how many rounds of free cells around a vertex a path cell "
             "left irregular may join with it"),
      Option("camera_path_radius", &E::camera_path_radius, Min(0.0), "m",
             "camera_path: a camera whose cell is still outside O after grow has O peeled within "
             "this distance of its cell's vertices and grown again from its cell; 0: never"),
      Option("min_move_fraction", &E::min_move_fraction, {{"minimum", 0.0}, {"maximum", 1.0}}, "",
             "a move shorter than this fraction of the distance from the point to its nearest "
             "neighbouring vertex is not made (the vertex and its rays stay); 0: every move "
             "(trade-off measured in docs/engine.md)"),
      Option("steiner_export", &E::steiner_export, kNone, "",
             "which triangles touching Steiner points the exported mesh drops: none; all_steiner, "
             "those between three; any_steiner, those with one; open_steiner, all_steiner's and "
             "the regions of triangles with one whose rim mostly borders nothing (sheets into the "
             "sky; whole meshes only)"),
      Option("open_steiner_crease", &E::open_steiner_crease, {{"minimum", 1.0}, {"maximum", 180.0}},
             "deg",
             "open_steiner: triangles with a Steiner vertex join one region only across edges "
             "where their normals differ by at most this, and a rim edge against another region "
             "counts as open (a sheet meeting a truck's side at a crease is weighed alone); 180: "
             "joined across any angle"),
      Option("fill_holes_perimeter", &E::fill_holes_perimeter, Min(0.0), "m",
             "export: close holes with a perimeter up to this (0: none)"),
      Option("smoothing_iterations", &E::smoothing_iterations, Min(0), "steps",
             "export: Taubin smoothing steps, boundary fixed (0: none)"),
      Option("min_component_area", &E::min_component_area, Min(0.0), "x steiner_spacing^2",
             "export: connected pieces of the surface with less area are dropped (specks stray "
             "points leave in free space; 0: keep every piece)"),
      Option("retriangulate_planes", &E::retriangulate_planes, Min(0.0), "x median edge",
             "export, after the mesh_refiner: regions of the surface within this distance of one "
             "plane are triangulated again on it (folds of the sheet taken out; boundary and "
             "vertices kept); 0: off"),
      Option("flip_edges", &E::flip_edges, kNone, "",
             "export, after retriangulate_planes: interior edges flipped where the other "
             "diagonal of their two triangles lowers the angles between neighbouring faces "
             "(folds and ridges between sparse points; vertices and boundary kept)"),
      Option("filter_normals", &E::filter_normals, Min(0), "rounds",
             "export, after flip_edges: rounds of bilateral normal filtering (each face's normal "
             "the weighted mean of its neighbours' with similar normals, then the vertices moved "
             "to fit them: roughness taken out, corners kept; boundary and faces kept); 0: off"),
      Option("filter_normals_spatial", &E::filter_normals_spatial, Min(1e-9),
             "x median edge", "filter_normals: sigma of the Gaussian on the distance between two "
             "faces' centroids"),
      Option("filter_normals_range", &E::filter_normals_range, Min(1e-9), "",
             "filter_normals: sigma of the Gaussian on the difference of two faces' unit normals "
             "(0 .. 2; 1.41 at a right angle): smaller keeps more edges"),
      Option("mesh_pass_rounds", &E::mesh_pass_rounds, {{"minimum", 1}, {"maximum", 16}}, "rounds",
             "export: times retriangulate_planes, flip_edges and filter_normals run in turn (a "
             "second round triangulates again the planes the normal filter flattened)"),
      Option("drop_back_faces", &E::drop_back_faces, kNone, "",
             "export of a whole mesh (a run that forgot nothing), after the passes: faces the "
             "keyframes see from behind more than from the front are dropped (sheets closing "
             "over where the cameras looked); inputs without intrinsics and forgetting runs "
             "keep them"),
      Option("transfer_on_insert", &E::transfer_on_insert, kNone, "",
             "cells made by inserting a new point get weights from the policy; false: they "
             "start at 0 and the point's own rays weight them (measured: far better "
             "completeness with nearest)"),
      Option("transfer_camera_side", &E::transfer_camera_side, kNone, "",
             "cells behind an inserted or moved point, seen from its cameras, start at 0 "
             "instead of taking the policy's weight"),
      Option("nonnegative_weights", &E::nonnegative_weights, kNone, "",
             "a backward cast never takes a cell's weight below 0"),
      Option("steiner_jitter", &E::steiner_jitter, json{{"minimum", 0.0}, {"maximum", 0.25}},
             "x steiner_spacing",
             "Steiner points move off their grid nodes by up to this fraction of "
             "steiner_spacing (avoids cospherical cells)"),
      Option("shrink_radius", &E::shrink_radius, Min(0.0), "m",
             "enclosing set E: cells within this distance"),
      Option("shrink_passes", &E::shrink_passes, Min(1), "passes", "passes of shrink over E"),
      Option("check_invariants", &E::check_invariants, kNone, "",
             "full manifold check after every keyframe (slow)"),
      Option("filtered_walk", &E::filtered_walk, kNone, "",
             "rays are walked with double-precision tests on terms cached per vertex, CGAL's "
             "exact walk where a test is within rounding (the same cells); false: CGAL's walk "
             "for every ray"),
      Option("planned_moves", &E::planned_moves, kNone, "",
             "exact mode on more than one thread: a keyframe's moves are planned on the "
             "threads and made in order (the same cells as false, which makes each with "
             "CGAL's vertex removal and insertion)"),
      Option("forget", &E::forget, kNone, "",
             "long drives: the part of the scene the cameras have left behind (forget_distance "
             "behind every one of the last `window` cameras) is final: its surface is "
             "handed out (tiles) and its cells, rays and points leave memory. true or false "
             "(also as JSON booleans); auto: on once the cameras travel (one after the other "
             "along a path, not around what they look at: their centres spread at most twice "
             "as far as the points), off for an object ring or a model in one update"),
      Option("forget_distance", &E::forget_distance, Min(0.0), "m",
             "forget: how far behind the cameras a cell is final; 0: max_ray_length + "
             "steiner_margin + shrink_radius + steiner_spacing (which engine.scale auto scales)"),
      Option("forget_step", &E::forget_step, Min(0.0), "m",
             "forget: forgetting runs each time the newest camera has moved this far; 0: 2 x "
             "steiner_spacing"),
      Option("threads", &E::num_threads, json{{"minimum", 0}, {"maximum", 1024}}, "threads",
             "threads casting rays and planning moves (exact mode); 0: every core the process "
             "may run on (its affinity mask: taskset, Slurm's --cpus-per-task); the mesh is the "
             "same for any number"),
  };
  // Not a field of the engine: the pipeline scales the lengths before the engine starts.
  EngineOption scale;
  scale.name = "scale";
  scale.schema = {
      {"type", "string"},
      {"enum", {"auto", "metric"}},
      {"description",
       "lengths in scene units (steiner_spacing, steiner_margin, max_ray_length, shrink_radius, "
       "regrow_radius, camera_path_radius, fill_holes_perimeter): auto scales those the job does not set by the "
       "median ray of the first keyframes / 25, or, for cameras along a path that see less than their rays "
       "say, every one but max_ray_length by the extent each camera sees / 11.4 (docs/interop.md); metric "
       "keeps the defaults (a street in metres). "
       "Default: auto for colmap, openmvg, slam_json and middlebury, metric for the others"}};
  t.push_back(std::move(scale));
  return t;
}

}  // namespace

const std::vector<EngineOption>& EngineOptionTable() {
  static const std::vector<EngineOption> table = MakeTable();
  return table;
}

const json& EngineOptionsSchema() {
  static const json schema = [] {
    json s = json::object();
    for (const EngineOption& o : EngineOptionTable()) s[o.name] = o.schema;
    return s;
  }();
  return schema;
}

bool EngineOptionsFromJson(const json& given, EngineOptions* o, std::vector<Problem>* problems) {
  // "forget" was a boolean before "auto": true and false stay the words they were.
  json j = given;
  if (j.is_object() && j.contains("forget") && j["forget"].is_boolean())
    j["forget"] = j["forget"].get<bool>() ? "true" : "false";
  const std::size_t before = problems->size();
  ValidateAgainstSchema(EngineOptionsSchema(), j, "engine", problems);
  if (problems->size() != before) return false;
  const json v = WithDefaults(EngineOptionsSchema(), j);
  for (const EngineOption& option : EngineOptionTable())
    if (option.read) option.read(v[option.name], o);
  if (const std::string error = o->Check(); !error.empty()) {
    problems->push_back({"engine", error});
    return false;
  }
  return true;
}

json EngineOptionsToJson(const EngineOptions& o) {
  json j = json::object();
  for (const EngineOption& option : EngineOptionTable())
    if (option.write) j[option.name] = option.write(o);
  return j;
}

}  // namespace imr::io
