#include "host/pipeline/report.h"

#include "host/eval/evaluate.h"
#include "host/eval/mesh_stats.h"
#include "host/io/engine_options.h"
#include "host/pipeline/run.h"
#include "host/util/sha256.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace imr::pipeline {
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

// forget: the live part over the run, at most 200 of the engine's samples (evenly chosen, the
// last one always): [update, live cells, points kept, vertices].
json LiveSamplesJson(const std::vector<engine::EngineStats::LiveSample>& samples) {
  json out = json::array();
  const size_t n = samples.size(), keep = std::min<size_t>(n, 200);
  for (size_t i = 0; i < keep; ++i) {
    const auto& x = samples[keep == n ? i : (i + 1) * n / keep - 1];
    out.push_back({x.update, x.live_cells, x.points, x.vertices});
  }
  return out;
}


// What the sequence was made from, by content: SHA-256 of each file of the source (a file, or the
// files directly in its folder: calibration, poses, times) and, for image sequences, one digest
// over every image in frame order (the hash of their hashes), so a report says which bytes it
// describes.
json InputChecksums(const std::string& source, const ImageFrontEndSource* front_end) {
  json files = json::object();
  std::error_code ec;
  const fs::path root = front_end != nullptr ? fs::path(front_end->sequence().root) : fs::path(source);
  if (fs::is_regular_file(root, ec)) {
    files[root.filename().string()] = Sha256File(root);
  } else if (fs::is_directory(root, ec)) {
    std::vector<fs::path> list;
    for (const auto& e : fs::directory_iterator(root, ec))
      if (e.is_regular_file()) list.push_back(e.path());
    std::sort(list.begin(), list.end());
    for (const auto& f : list) files[f.filename().string()] = Sha256File(f);
  }
  json j = {{"algorithm", "sha256"}, {"files", files}};
  if (front_end != nullptr) {
    Sha256 all;
    const auto& frames = front_end->sequence().frames;
    for (const io::ImageFrame& f : frames) all.Update(Sha256File(f.image_path));
    j["images"] = {{"count", frames.size()}, {"sha256_of_sha256s", all.HexDigest()}};
  }
  return j;
}

}  // namespace

json PluginJson(const plugin::PluginInfo& info, const json& params) {
  return {{"id", info.id()},     {"version", info.version()}, {"kind", info.kind()},
          {"abi", info.abi()},   {"file", info.file.string()}, {"params", params}};
}

json EvaluateAgainstTruth(const json& options, const engine::Mesh& mesh,
                          const ImageFrontEndSource* front_end) {
  eval::TriangleMesh m;
  for (std::size_t i = 0; i + 2 < mesh.vertices.size(); i += 3)
    m.vertices.push_back({mesh.vertices[i], mesh.vertices[i + 1], mesh.vertices[i + 2]});
  for (std::size_t i = 0; i + 2 < mesh.faces.size(); i += 3)
    m.triangles.push_back({mesh.faces[i], mesh.faces[i + 1], mesh.faces[i + 2]});
  eval::EvaluationOptions o;
  const double tau = options.at("tau").get<double>();
  if (std::find(o.taus.begin(), o.taus.end(), tau) == o.taus.end()) o.taus.push_back(tau);
  std::sort(o.taus.begin(), o.taus.end());
  o.max_ray_length = options.at("max_ray_length").get<double>();
  o.crop = options.at("crop").get<bool>();
  o.precision_samples = 200000;  // per sequence in a batch: enough for 3 digits
  // "velodyne": the image sequence's scans; anything else names a point cloud or a mesh.
  const std::string truth_name = options.at("truth").get<std::string>();
  const bool velodyne = truth_name == "velodyne";
  if (velodyne && (front_end == nullptr || !front_end->sequence().has_lidar))
    throw std::runtime_error("evaluation.truth \"velodyne\": the sequence has no Velodyne scans");
  const eval::Truth truth =
      eval::LoadTruth(velodyne ? std::string() : truth_name,
                      front_end != nullptr ? &front_end->sequence() : nullptr,
                      options.at("scan_step").get<int>(), o);
  const json& t = truth.description;
  std::vector<io::CameraGeometry> cameras;
  if (front_end != nullptr)
    for (const io::ImageFrame& f : front_end->sequence().frames) cameras.push_back(f.camera);
  const eval::Evaluation e = eval::Evaluate(m, truth.points, cameras, o, false, &truth.scanner_views);
  const std::size_t k = static_cast<std::size_t>(
      std::find(e.taus.begin(), e.taus.end(), tau) - e.taus.begin());
  auto stats = [](const eval::DistanceStats& d) {
    return json{{"count", d.count}, {"mean", d.mean}, {"median", d.median},
                {"rms", d.rms}, {"p90", d.p90}, {"max", d.max}};
  };
  json out = {{"reference", "ground truth (" + t.value("source", std::string()) + ")"},
             {"mean_truth_to_mesh", e.truth_to_mesh.mean},
             {"median_truth_to_mesh", e.truth_to_mesh.median},
             {"tau", tau},
             {"completeness", k < e.completeness.size() ? e.completeness[k] : 0.0},
             {"precision", k < e.precision.size() ? e.precision[k] : 0.0},
             {"evaluation",
              {{"truth", t},
               {"crop", {{"applied", e.cropped}, {"rule", e.crop_note},
                         {"truth_kept", e.truth_crop.kept}, {"truth_input", e.truth_crop.input}}},
               {"truth_to_mesh", stats(e.truth_to_mesh)},
               {"mesh_to_truth", stats(e.mesh_to_truth)},
               {"taus", e.taus},
               {"completeness", e.completeness},
               {"precision", e.precision},
               {"seconds", e.seconds_crop + e.seconds_truth_to_mesh + e.seconds_mesh_to_truth}}}};
  // A laser scanner's truth: precision also over the area it could have measured (eval/README.md).
  if (e.scanner_view)
    out["evaluation"]["scanner_view"] = {{"samples", e.samples_in_scanner_view},
                                         {"precision", e.precision_in_scanner_view}};
  return out;
}

bool MostPointsRefused(const engine::EngineStats& s) {
  const int64_t entered = s.points_inserted + s.points_reentered;
  const int64_t refused = s.points_dropped + s.points_duplicate - s.points_reentered;
  return refused > 0 && 2 * refused > entered + refused;
}

std::string RefusedPointsWarning(const engine::EngineStats& s, const engine::Mesh& mesh) {
  if (!MostPointsRefused(s)) return {};
  std::size_t steiner_only = 0;
  if (mesh.point_ids.size() * 3 == mesh.vertices.size())
    for (std::size_t f = 0; f + 2 < mesh.faces.size(); f += 3)
      if (mesh.point_ids[mesh.faces[f]] < 0 && mesh.point_ids[mesh.faces[f + 1]] < 0 &&
          mesh.point_ids[mesh.faces[f + 2]] < 0)
        ++steiner_only;
  return "most points never entered the mesh: " + std::to_string(s.points_duplicate) +
         " new points were at the position of a point already in it and " +
         std::to_string(s.points_dropped) +
         " were dropped (their conflict zone met the reconstructed volume); " +
         std::to_string(s.points_reentered) + " of them entered later, as they moved, against " +
         std::to_string(s.points_inserted) + " inserted at once; " + std::to_string(steiner_only) +
         " of the mesh's " + std::to_string(mesh.faces.size() / 3) +
         " triangles touch no data point (Steiner grid only). Are the points' positions right?";
}

std::string ForgettingWarning(const engine::EngineStats& s, const engine::EngineOptions& o) {
  if (s.forget_on_update == 0) return {};  // it never forgot (off, or auto that stayed off)
  std::vector<std::string> what;
  if (s.changes_refused_final > 0)
    what.push_back(std::to_string(s.changes_refused_final) +
                   " changes were refused where the surface was already handed out (" +
                   std::to_string(s.points_refused_final) + " new points, " +
                   std::to_string(s.changes_refused_final - s.points_refused_final) +
                   " moves and removals)");
  if (s.shrinks_blocked_final > 0)
    what.push_back(std::to_string(s.shrinks_blocked_final) +
                   " moves and insertions next to it failed (a final cell of the volume there could "
                   "not leave it)");
  if (s.updates_of_forgotten_points > 0)
    what.push_back(std::to_string(s.updates_of_forgotten_points) +
                   " updates (moves, removals) of points already forgotten were ignored");
  if (what.empty()) return {};
  std::string text = "forgetting (engine.forget) left input out of the mesh: ";
  for (std::size_t i = 0; i < what.size(); ++i) text += (i > 0 ? "; " : "") + what[i];
  char distance[64];
  std::snprintf(distance, sizeof distance, "%.6g", o.ForgetDistance());
  return text + ". The cameras came back to (or jumped), or points were refined or moved in, a "
         "place left more than engine.forget_distance (" + distance + ") behind: there the mesh "
         "differs from a run without forgetting; a larger forget_distance keeps places live "
         "longer, and engine.forget false keeps every place (memory grows with the drive)";
}

std::string SteinerGridWarning(const engine::EngineStats& s, const engine::EngineOptions& o) {
  const int64_t points = s.points_inserted + s.points_reentered;
  if (s.steiner_points < kSteinerWarnFloor ||
      static_cast<double>(s.steiner_points) <= kSteinerWarnRatio * static_cast<double>(points))
    return {};
  char text[640];
  std::snprintf(text, sizeof text,
                "the Steiner grid has %lld points for %lld data points (%.0f a point; more than "
                "%.0f makes the run slow and large): the grid covers every ray (up to "
                "max_ray_length %.6g) and steiner_margin %.6g around it in steps of "
                "steiner_spacing %.6g; a larger engine.steiner_spacing (or a smaller "
                "engine.steiner_margin or engine.max_ray_length) makes it smaller",
                static_cast<long long>(s.steiner_points), static_cast<long long>(points),
                static_cast<double>(s.steiner_points) / static_cast<double>(std::max<int64_t>(points, 1)),
                kSteinerWarnRatio, o.max_ray_length, o.steiner_margin, o.steiner_spacing);
  return text;
}

json EngineStatsJson(const engine::EngineStats& s) {
  const auto& t = s.time;
  // Every counter engine::EngineStats keeps (REPORT.md lists them).
  return {{"seconds", {{"steiner", t.steiner}, {"shrink", t.shrink}, {"move", t.move},
                       {"insert", t.insert}, {"cast", t.cast}, {"threaded", t.threaded},
                       {"scan", t.scan}, {"grow", t.grow}, {"extract", t.extract},
                       {"total", t.total}}},
          {"keyframes", s.updates},
          {"rays_cast", s.rays_cast},
          {"rays_cast_backward", s.rays_cast_backward},
          {"rays_skipped_too_long", s.rays_skipped_too_long},
          {"rays_truncated_to_camera", s.rays_truncated_to_camera},
          {"rays_truncated", s.rays_truncated},
          {"rays_uncast_listed", s.rays_uncast_listed},
          {"rays_rewalked", s.rays_rewalked},
          {"rays_rewalked_exact", s.rays_rewalked_exact},
          {"rays_walked_exact", s.rays_walked_exact},
          {"cells_rewalked", s.cells_rewalked},
          {"ray_mismatches", s.ray_mismatches},
          {"cells_traversed", s.cells_traversed},
          {"cells_weighted", s.cells_weighted},
          {"points_inserted", s.points_inserted},
          {"points_moved", s.points_moved},
          {"moves_skipped", s.moves_skipped},
          {"points_dropped", s.points_dropped},
          {"points_duplicate", s.points_duplicate},
          {"moves_duplicate", s.moves_duplicate},
          {"moves_in_place", s.moves_in_place},
          {"moves_planned_ahead", s.moves_planned_ahead},
          {"moves_replanned", s.moves_replanned},
          {"moves_below_min", s.moves_below_min},
          {"points_reentered", s.points_reentered},
          {"points_removed", s.points_removed},
          {"observations_over_limit", s.observations_over_limit},
          {"steiner_points", s.steiner_points},
          {"steiner_dropped", s.steiner_dropped},
          {"cells_grown", s.cells_grown},
          {"cells_opened", s.cells_opened},
          {"camera_regrowths", s.camera_regrowths},
          {"camera_cells_regrown", s.camera_cells_regrown},
          {"cells_shrunk", s.cells_shrunk},
          {"policy_calls", s.policy_calls},
          {"rays_scan_cells", s.rays_scan_cells},
          {"vertices", s.vertices},
          {"cells", s.cells},
          {"cells_in_o", s.cells_in_o},
          {"cameras_in_o",
           {{"checked", s.cameras_checked},
            {"inside", s.cameras_in_o},
            {"share", s.cameras_checked > 0 ? static_cast<double>(s.cameras_in_o) / s.cameras_checked : 0.0}}},
          {"forget",
           {{"on_from_update", s.forget_on_update},
            {"steps_held", s.forget_steps_held},
            {"camera_spread", s.forget_camera_spread},
            {"point_spread", s.forget_point_spread},
            {"camera_step", s.forget_camera_step},
            {"steps", s.forget_steps},
            {"cells_finalized", s.cells_finalized},
            {"cells_final", s.cells_final},
            {"final_cells_replaced", s.final_cells_replaced},
            {"rebuilds", s.rebuilds},
            {"rebuilds_abandoned", s.rebuilds_abandoned},
            {"vertices_forgotten", s.vertices_forgotten},
            {"points_forgotten", s.points_forgotten},
            {"point_records_freed", s.point_records_freed},
            {"updates_of_forgotten_points", s.updates_of_forgotten_points},
            {"changes_refused_final", s.changes_refused_final},
            {"points_refused_final", s.points_refused_final},
            {"shrinks_blocked_final", s.shrinks_blocked_final},
            {"components_started", s.components_started},
            {"parts", s.parts},
            {"part_triangles", s.part_triangles},
            {"seconds", t.forget},
            {"rebuild_seconds", t.rebuild},
            {"live", LiveSamplesJson(s.live_samples)}}}};
}

// Peak and final RSS, and the engine's bytes by structure.
json MemoryJson(const ReportInputs& in) {
  const engine::EngineMemory& m = in.engine_memory;
  json heap = nullptr;
  if (!in.final_heap.allocator.empty())
    heap = {{"allocator", in.final_heap.allocator},
            {"allocated", in.final_heap.allocated},
            {"resident", in.final_heap.resident}};
  json j = {{"peak_rss_bytes", in.peak_rss_bytes},
          {"final_rss_bytes", in.final_rss_bytes},
          {"final_heap_bytes", heap},
          {"engine_bytes",
           {{"total", m.Total()},
            {"cells", m.cells},
            {"vertices", m.vertices},
            {"ray_entries", m.ray_entries},
            {"points", m.points},
            {"ray_batch_lists", m.ray_batch_lists},
            {"steiner_nodes", m.steiner_nodes},
            {"cameras", m.cameras}}},
          {"ray_entries",
           {{"held", m.ray_entries_used}, {"live", m.ray_entries_live}}}};
  if (!in.export_recorder.is_null()) j["export_recorder"] = in.export_recorder;
  return j;
}

// The mesh: tiles only (its size from the surface stream), written in blocks from the spool, or
// written whole (with its topology and how much of it the cameras saw from behind).
json MeshJson(const ReportInputs& in) {
  json mesh_json;
  if (in.job->job.output.formats.empty() && in.streamed != nullptr) {
    // Tiles only: no single mesh was put together; its size from the surface stream.
    mesh_json = {{"vertices", in.streamed->stream.vertices_released},
                 {"faces", in.streamed->stream.triangles_released},
                 {"written", false},
                 {"manifold", nullptr},
                 {"boundary_closed_manifold", in.boundary_check.ok},
                 {"boundary_triangles", in.boundary_check.boundary_triangles}};
  } else if (in.mesh == nullptr) {
    // Written in blocks from the spool (streamed_surface.h): its counts, check and topology as
    // measured while it was spooled; no per-component list (that needs the mesh whole).
    const StreamedSurface& s = *in.streamed_mesh;
    mesh_json = {{"vertices", s.vertex_count()},
                 {"faces", s.face_count()},
                 {"written", true},
                 {"written_in_blocks", in.formats_streamed},
                 {"manifold", in.mesh_check.ok},
                 {"boundary_closed_manifold", in.boundary_check.ok},
                 {"boundary_triangles", in.boundary_check.boundary_triangles}};
    const std::array<double, 3> origin = ExportOrigin(s.bounds());
    mesh_json["export_origin"] = {origin[0], origin[1], origin[2]};
    mesh_json["stats"] = s.statistics().ToJson();
  } else {
    const engine::Mesh& mesh = *in.mesh;
    mesh_json = {{"vertices", mesh.vertices.size() / 3},
                 {"faces", mesh.faces.size() / 3},
                 {"written", true},
                 {"written_in_blocks", in.formats_streamed},
                 {"manifold", in.mesh_check.ok},
                 {"boundary_closed_manifold", in.boundary_check.ok},
                 {"boundary_triangles", in.boundary_check.boundary_triangles}};
    // PLY and glTF/GLB vertices are relative to it (0 near the origin): mesh_export.h.
    const std::array<double, 3> origin = ExportOrigin(mesh);
    mesh_json["export_origin"] = {origin[0], origin[1], origin[2]};
    // Topology of what was written: components, Euler characteristic, genus, boundary loops.
    mesh_json["stats"] = eval::ComputeMeshStatistics(mesh.vertices, mesh.faces).ToJson();
  }
  // Measured on the mesh in memory, or on the spooled one in blocks (run.cc).
  if (in.back_facing && mesh_json.value("written", false))
    mesh_json["back_facing"] = {{"views", in.back_facing->views},
                                {"pixels", in.back_facing->pixels},
                                {"back_pixels", in.back_facing->back_pixels},
                                {"share", in.back_facing->Share()}};
  // The pieces under engine.min_component_area the export dropped (whole components).
  const engine::DroppedComponents& d =
      in.streamed != nullptr ? in.streamed->stream.dropped : in.small_components_dropped;
  mesh_json["small_components_dropped"] = {{"components", d.components}, {"faces", d.faces}, {"vertices", d.vertices}, {"area", d.area}};
  // engine.drop_back_faces: the faces the keyframes saw from behind, dropped (a whole mesh only).
  mesh_json["back_faces_dropped"] = in.back_faces_dropped;
  // engine.retriangulate_planes: the planar regions triangulated again.
  const engine::PlaneRetriangulationStats& pl = in.streamed != nullptr ? in.streamed->planes : in.planes;
  mesh_json["planes_retriangulated"] = {{"regions", pl.regions},
                                        {"faces", pl.faces},
                                        {"vertices_moved", pl.vertices_moved},
                                        {"regions_refused", pl.regions_refused},
                                        {"max_move", pl.max_move}};
  // engine.flip_edges: the mean angle between neighbouring faces before and after.
  const engine::EdgeFlipStats& fl = in.streamed != nullptr ? in.streamed->flips : in.flips;
  const auto mean = [&](double sum) { return fl.edges > 0 ? sum / static_cast<double>(fl.edges) : 0.0; };
  mesh_json["edges_flipped"] = {{"flips", fl.flips},
                                {"edges", fl.edges},
                                {"mean_angle_before", mean(fl.degrees_sum_before)},
                                {"mean_angle_after", mean(fl.degrees_sum_after)}};
  // engine.filter_normals: the vertices it moved, and the mean angle between neighbouring faces.
  const engine::NormalFilterStats& nfs = in.streamed != nullptr ? in.streamed->normal_filter : in.normal_filter;
  const auto mean_nf = [&](double sum) { return nfs.edges > 0 ? sum / static_cast<double>(nfs.edges) : 0.0; };
  mesh_json["normal_filter"] = {{"iterations", nfs.iterations},
                                {"vertices_moved", nfs.vertices_moved},
                                {"moves_reverted", nfs.moves_reverted},
                                {"max_move", nfs.max_move},
                                {"edges", nfs.edges},
                                {"mean_angle_before", mean_nf(nfs.degrees_sum_before)},
                                {"mean_angle_after", mean_nf(nfs.degrees_sum_after)}};
  // The passes undone where they broke the surface (a whole mesh: 1; streamed: its pieces).
  const int64_t undone = in.streamed != nullptr ? in.streamed->pieces_undone : in.pieces_undone;
  mesh_json["passes_undone"] = {{"pieces", undone},
                                {"why", in.streamed != nullptr ? in.streamed->undone_why : in.undone_why}};
  return mesh_json;
}

// The surface streamed part by part (engine parts, held and released triangles, the spool).
json SurfacePartsJson(const StreamedSurfaceStats& ss) {
  return {{"parts", ss.engine_parts},
          {"triangles", ss.stream.triangles_in},
          {"triangles_released", ss.stream.triangles_released},
          {"vertices_released", ss.stream.vertices_released},
          {"holes_filled", ss.stream.holes_filled},
          {"vertices_split", ss.stream.vertices_split},
          {"peak_held_triangles", ss.stream.peak_held_triangles},
          {"peak_held_vertices", ss.stream.peak_held_vertices},
          {"peak_held_small_triangles", ss.stream.peak_held_small_triangles},
          {"spool_bytes", ss.spool_bytes},
          {"peak_seam_vertices", ss.peak_seam_vertices},
          {"seconds", ss.seconds},
          {"max_keyframe_seconds", ss.max_update_seconds}};
}

// The 3D Tiles written (in.tiles set), and how the keyframe images were served to them.
json TilesJson(const ReportInputs& in) {
  const TilesStats& t = *in.tiles;
  json tiles = {{"tileset", "tileset.json"},
          {"folder", "tiles"},
          {"count", t.tiles},
          {"triangles", t.triangles},
          {"vertices", t.vertices},
          {"bytes", t.bytes},
          {"open_tiles_peak", t.open_tiles_peak},
          {"seconds", t.seconds},
          {"tileset_writes", t.tileset_writes},
          {"tileset_bytes", t.tileset_bytes},
          {"keyframes_given", in.tile_images.keyframes}};
  if (!t.origin.is_null()) tiles["origin"] = t.origin;
  if (t.lod_tiles > 0 || t.lod_gathered > 0)
    tiles["lod"] = {{"count", t.lod_tiles},
                    {"triangles", t.lod_triangles},
                    {"bytes", t.lod_bytes},
                    {"gathered", t.lod_gathered},
                    {"tiles_per_level", t.tiles_per_level},
                    {"pending_triangles_peak", t.lod_pending_triangles_peak},
                    {"subtree_bytes", t.lod_tree_bytes},
                    {"seconds", t.lod_seconds}};
  const ExportImageStats& ti = in.tile_images;
  if (ti.store.requests > 0)
    tiles["image_service"] = {{"requests", ti.store.requests},
                              {"decodes", ti.store.decodes},
                              {"evictions", ti.store.evictions},
                              {"peak_bytes", ti.store.peak_bytes},
                              {"decode_seconds", ti.store.decode_seconds}};
  return tiles;
}

// Wall time per stage of the chain (reader -> features -> refiner -> engine -> exporter).
json StageSecondsJson(const ReportInputs& in) {
  json stages = json::object();
  if (in.front_end != nullptr) {
    const FrontEndStats& fe = in.front_end->stats();
    stages["read_images"] = fe.read_seconds;
    stages["features"] = fe.features_seconds;
    stages["refiner"] = fe.refiner_seconds;
    if (fe.dense_seconds > 0.0) stages["dense"] = fe.dense_seconds;
  }
  stages["engine"] = in.engine_seconds;
  stages["export"] = in.export_seconds;
  if (in.snapshots != nullptr && !in.snapshots->list().empty()) stages["snapshots"] = in.snapshots->seconds();
  if (in.tiles != nullptr) stages["tiles"] = in.tiles->seconds;
  if (in.refinement != nullptr) stages["mesh_refiner"] = in.refinement->seconds;
  if (!in.job->evaluation.is_null()) stages["evaluation"] = in.evaluation_seconds;
  return stages;
}

json BuildReport(const ReportInputs& in) {
  const engine::EngineStats& stats = *in.stats;
  json report;
  report["imr_version"] = Version();
  report["job"] = fs::absolute(in.job->job.file).lexically_normal().string();
  if (!in.job->job.overrides.empty()) report["overrides"] = in.job->job.overrides;  // imr run --set
  report["sequence"] = {{"name", in.sequence->name}, {"source", in.sequence->source}};
  report["input"] = {{"format", in.job->job.input.format}, {"options", in.job->input_options}};
  if (in.format->sequences_are_paths)
    report["input"]["checksums"] = InputChecksums(in.sequence->source, in.front_end);
  if (const json summary = in.source->Summary(); !summary.is_null())
    report["input"]["summary"] = summary;
  report["engine_options"] = io::EngineOptionsToJson(in.engine_options);
  report["engine_scale"] = ScaleJson(in.scale_mode, in.scale, in.engine_options, in.explicit_keys);
  report["plugins"] = in.plugins;
  report["engine"] = EngineStatsJson(stats);
  report["engine"]["keyframe_seconds"] = stats.keyframe_seconds;
  // Time of the move phase per moved point. The paper's per-move overhead, (T_mov - T_nonmov) /
  // N_mov, needs a second run with frozen points: imr-bench paper measures it.
  report["engine"]["move_seconds_per_moved_point"] =
      stats.points_moved > 0 ? stats.time.move / static_cast<double>(stats.points_moved) : 0.0;
  report["memory"] = MemoryJson(in);
  report["mesh"] = MeshJson(in);
  if (in.streamed != nullptr) report["surface_parts"] = SurfacePartsJson(*in.streamed);
  if (in.tiles != nullptr) report["tiles"] = TilesJson(in);
  if (in.refinement != nullptr) report["refinement"] = in.refinement->ToJson();
  if (!in.accuracy.is_null()) report["accuracy"] = in.accuracy;
  if (!in.accuracy_known_scene.is_null()) report["accuracy_known_scene"] = in.accuracy_known_scene;
  // What the exporters were given (SDK 1.1) and how the keyframe images were served to them.
  const ExportImageStats& ei = in.export_images;
  report["export_input"] = {{"keyframes", ei.keyframes}, {"keyframe_images", in.keyframe_images}};
  if (ei.store.requests > 0)
    report["export_input"]["image_service"] = {{"requests", ei.store.requests},
                                               {"decodes", ei.store.decodes},
                                               {"evictions", ei.store.evictions},
                                               {"peak_bytes", ei.store.peak_bytes},
                                               {"decode_seconds", ei.store.decode_seconds}};
  report["stage_seconds"] = StageSecondsJson(in);
  if (in.snapshots != nullptr && !in.snapshots->list().empty()) report["snapshots"] = in.snapshots->list();
  if (!in.exports.empty()) report["exports"] = in.exports;
  if (!in.warnings.empty()) report["warnings"] = in.warnings;
  if (in.checks != nullptr)
    report["invariant_checks"] = {{"every", in.checks->every()},
                                  {"count", in.checks->count()},
                                  {"seconds", in.checks->seconds()}};
  if (!in.trace.empty()) report["trace"] = fs::absolute(in.trace).string();
  report["files"] = in.files;
  report["seconds"] = in.seconds;
  return report;
}

}  // namespace imr::pipeline
