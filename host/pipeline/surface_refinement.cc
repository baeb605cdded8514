#include "host/pipeline/surface_refinement.h"

#include "host/eval/mesh_stats.h"
#include "host/plugin/host_services.h"
#include "host/plugin/keyframe_images.h"

#include <chrono>
#include <cmath>
#include <cstring>
#include <optional>
#include <stdexcept>
#include <string>

namespace imr::pipeline {

namespace {

double SecondsSince(std::chrono::steady_clock::time_point t) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
}

// A Steiner point's key: its position, bit for bit (they never move).
uint64_t PositionHash(const double* p) {
  uint64_t h = 1469598103934665603ull;
  for (int k = 0; k < 3; ++k) {
    uint64_t bits;
    std::memcpy(&bits, &p[k], sizeof(bits));
    h = (h ^ bits) * 1099511628211ull;
    h ^= h >> 29;
  }
  return h;
}

bool Same(const std::array<double, 3>& a, const double* p) {
  return a[0] == p[0] && a[1] == p[1] && a[2] == p[2];
}

// What the plugin says it did, checked before anything of it is used, as a mesh: its vertices
// (the request's first, each FIXED one where it was), and its faces when it subdivided (a
// manifold with as many boundary loops as `mesh`), else `mesh`'s, moved out of it.
engine::Mesh RefinedMesh(const imr_refine_result& result, engine::Mesh& mesh,
                         const std::vector<uint8_t>& flags, bool streamed, const std::string& where) {
  const std::size_t n = mesh.vertices.size() / 3;
  if (result.vertices == nullptr || result.vertex_count < n ||
      (result.faces == nullptr && result.vertex_count != n))
    throw std::runtime_error(where + ": refine returned " + std::to_string(result.vertex_count) +
                             " vertices for " + std::to_string(n) +
                             (result.faces == nullptr ? " (and no faces)" : ""));
  for (uint64_t i = 0; i < 3 * result.vertex_count; ++i)
    if (!std::isfinite(result.vertices[i]))
      throw std::runtime_error(where + ": refine returned a non-finite coordinate for vertex " +
                               std::to_string(i / 3));
  for (std::size_t i = 0; i < n; ++i)
    if ((flags[i] & IMR_REFINE_VERTEX_FIXED) != 0 &&
        !Same({mesh.vertices[3 * i], mesh.vertices[3 * i + 1], mesh.vertices[3 * i + 2]},
              &result.vertices[3 * i]))
      throw std::runtime_error(where + ": refine moved vertex " + std::to_string(i) +
                               ", which was flagged FIXED (written already)");
  if (streamed && result.faces != nullptr)
    throw std::runtime_error(where + ": refine subdivided the surface, which a run that writes it "
                             "in parts (engine.forget, output.tiles) cannot take: turn the "
                             "plugin's subdivision off, or set engine.forget false (its default, "
                             "auto, forgets once the cameras travel)");
  engine::Mesh refined;
  refined.vertices.assign(result.vertices, result.vertices + 3 * result.vertex_count);
  refined.point_ids = mesh.point_ids;
  refined.point_ids.resize(result.vertex_count, -1);
  if (result.faces == nullptr) {
    refined.faces = std::move(mesh.faces);
    return refined;
  }
  refined.faces.assign(result.faces, result.faces + 3 * result.face_count);
  for (uint32_t f : refined.faces)
    if (f >= result.vertex_count)
      throw std::runtime_error(where + ": refine returned a face naming vertex " +
                               std::to_string(f) + " of " + std::to_string(result.vertex_count));
  const engine::ManifoldCheckResult check = engine::CheckMesh(refined, /*closed=*/false);
  if (!check.ok)
    throw std::runtime_error(where + ": the subdivided surface is not a manifold: " + check.message);
  const int64_t before = eval::ComputeMeshStatistics(mesh.vertices, mesh.faces).boundary_loops;
  const int64_t after = eval::ComputeMeshStatistics(refined.vertices, refined.faces).boundary_loops;
  if (before != after)
    throw std::runtime_error(where + ": the subdivided surface has " + std::to_string(after) +
                             " boundary loops, the surface it was given " + std::to_string(before));
  return refined;
}

}  // namespace

nlohmann::json SurfaceRefinementStats::ToJson() const {
  return {{"calls", calls},
          {"vertices_sent", vertices_sent},
          {"vertices_changed", vertices_changed},
          {"vertices_moved", vertices_moved},
          {"vertices_added", vertices_added},
          {"vertices_kept", vertices_kept},
          {"mean_move", mean_move},
          {"max_move", max_move},
          {"seconds", seconds},
          {"call_seconds", call_seconds}};
}

SurfaceRefinement::SurfaceRefinement(const io::StageSpec& stage, plugin::LoadedInstance instance,
                                     const WatchedStage& watched)
    : stage_(stage), instance_(std::move(instance)), watched_(watched) {}

void SurfaceRefinement::OnKeyframe(const engine::Engine& engine, const ExportContext& context,
                                   StageWatch& watch, int64_t keyframes) {
  if (stage_.every_keyframes <= 0 || keyframes % stage_.every_keyframes != 0) return;
  const auto start = std::chrono::steady_clock::now();
  engine::Mesh mesh = engine.ExtractMesh();
  stats_.seconds += SecondsSince(start);  // Refine adds its own
  if (mesh.faces.empty()) return;
  Refine(&mesh, context, watch, /*final_call=*/false);
}

void SurfaceRefinement::Finish(engine::Mesh* mesh, const ExportContext& context, StageWatch& watch) {
  if (mesh->faces.empty()) return;
  Refine(mesh, context, watch, /*final_call=*/true);
}

void SurfaceRefinement::FinishLive(engine::Mesh live, double extract_seconds,
                                   const ExportContext& context, StageWatch& watch) {
  streamed_ = true;
  stats_.seconds += extract_seconds;
  if (live.faces.empty()) return;
  Refine(&live, context, watch, /*final_call=*/true);
}

void SurfaceRefinement::Freeze(engine::SurfacePart* part) {
  streamed_ = true;
  for (std::size_t i = 0; i < part->keys.size(); ++i) {
    double* p = &part->vertices[3 * i];
    auto w = written_.find(part->keys[i]);
    if (w == written_.end()) {
      Written entry{{p[0], p[1], p[2]}, part->point_ids[i], 0};
      const Kept* k = nullptr;
      if (entry.point_id >= 0) {
        auto it = kept_.find(entry.point_id);
        if (it != kept_.end()) k = &it->second;
        written_point_[entry.point_id] = part->keys[i];
      } else {
        entry.steiner_hash = PositionHash(p);
        auto it = kept_steiner_.find(entry.steiner_hash);
        if (it != kept_steiner_.end()) k = &it->second;
        written_steiner_[entry.steiner_hash] = part->keys[i];
      }
      if (k != nullptr && Same(k->engine, p)) entry.position = k->refined;
      w = written_.emplace(part->keys[i], entry).first;
    }
    p[0] = w->second.position[0], p[1] = w->second.position[1], p[2] = w->second.position[2];
  }
  // No later part or mesh names a complete vertex: what was kept for it can go.
  for (int64_t key : part->completed) {
    auto w = written_.find(key);
    if (w == written_.end()) continue;
    if (w->second.point_id >= 0) {
      written_point_.erase(w->second.point_id);
      kept_.erase(w->second.point_id);
    } else {
      written_steiner_.erase(w->second.steiner_hash);
      kept_steiner_.erase(w->second.steiner_hash);
    }
    written_.erase(w);
  }
}

uint8_t SurfaceRefinement::Place(int64_t point_id, double* p) const {
  if (const std::array<double, 3>* w = Frozen(point_id, p)) {
    p[0] = (*w)[0], p[1] = (*w)[1], p[2] = (*w)[2];
    return IMR_REFINE_VERTEX_FIXED;
  }
  const Kept* k = nullptr;
  if (point_id >= 0) {
    auto it = kept_.find(point_id);
    if (it != kept_.end()) k = &it->second;
  } else {
    auto it = kept_steiner_.find(PositionHash(p));
    if (it != kept_steiner_.end()) k = &it->second;
  }
  if (k == nullptr || !Same(k->engine, p)) return IMR_REFINE_VERTEX_CHANGED;
  p[0] = k->refined[0], p[1] = k->refined[1], p[2] = k->refined[2];
  return 0;
}

void SurfaceRefinement::ApplyRefined(engine::Mesh* mesh) const {
  for (std::size_t i = 0; i < mesh->point_ids.size(); ++i) Place(mesh->point_ids[i], &mesh->vertices[3 * i]);
}

const std::array<double, 3>* SurfaceRefinement::Frozen(int64_t point_id, const double* p) const {
  if (written_.empty()) return nullptr;
  int64_t key = 0;
  if (point_id >= 0) {
    auto it = written_point_.find(point_id);
    if (it == written_point_.end()) return nullptr;
    key = it->second;
  } else {
    auto it = written_steiner_.find(PositionHash(p));
    if (it == written_steiner_.end()) return nullptr;
    key = it->second;
  }
  return &written_.at(key).position;
}

// One call: the kept positions put back where the engine has not moved a vertex since, the
// plugin's answer checked and applied to `mesh` and remembered.
void SurfaceRefinement::Refine(engine::Mesh* mesh, const ExportContext& context, StageWatch& watch,
                               bool final_call) {
  const auto start = std::chrono::steady_clock::now();
  const std::string where = stage_.json_path + " (mesh_refiner " + stage_.plugin + ")";
  const std::size_t n = mesh->vertices.size() / 3;
  const std::vector<double> engine_positions = mesh->vertices;
  std::vector<uint8_t> flags(n, 0);
  int64_t kept = 0;
  for (std::size_t i = 0; i < n; ++i) {
    flags[i] = Place(mesh->point_ids[i], &mesh->vertices[3 * i]);
    if (flags[i] == 0) ++kept;
    if (flags[i] == IMR_REFINE_VERTEX_CHANGED) ++stats_.vertices_changed;
  }
  if (final_call) stats_.vertices_kept = kept;

  // A store per call: kept across calls it held every decoded keyframe (+155 MB on the default
  // job) and saved no measurable time (decoding is not where a call's time goes).
  std::optional<plugin::KeyframeImageStore> images_store;
  if (!context.image_paths.empty()) images_store.emplace(context.image_paths);
  plugin::KeyframeImageStore* images = images_store ? &*images_store : nullptr;
  imr_mesh_view view{};
  view.struct_size = sizeof(view);
  view.vertices = mesh->vertices.data();
  view.vertex_count = n;
  view.faces = mesh->faces.data();
  view.face_count = mesh->faces.size() / 3;
  view.point_ids = mesh->point_ids.data();
  imr_refine_request request{};
  request.mesh = &view;
  request.vertex_flags = flags.data();
  request.keyframes = context.keyframes.empty() ? nullptr : context.keyframes.data();
  request.keyframe_count = context.keyframes.size();
  request.recent_keyframes_begin = std::min(keyframes_at_last_call_, context.keyframes.size());
  request.keyframe_images = images != nullptr ? 1 : 0;
  request.final_call = final_call ? 1 : 0;
  imr_refine_result result{};
  {
    const plugin::ScopedKeyframeImages scope(images);
    watch.SetPosition(final_call ? "refining the surface after the last keyframe"
                                 : "refining the surface");
    const StageWatch::Call call = watch.Enter(watched_);
    try {
      instance_.instance.Refine(&request, &result);
    } catch (const std::exception& e) {
      // Ctrl-C, SIGTERM or SIGHUP: the refiner stopped as asked (IMR_CANCELLED); the run was
      // interrupted there, said as at a keyframe, not a failure of the plugin.
      if (plugin::CancelRequested())
        throw std::runtime_error(std::string("cancelled (signal) while ") +
                                 (final_call ? "refining the surface after the last keyframe"
                                             : "refining the surface") +
                                 " (" + where + ")");
      throw std::runtime_error(where + ": " + e.what());
    }
  }
  keyframes_at_last_call_ = context.keyframes.size();

  engine::Mesh refined = RefinedMesh(result, *mesh, flags, streamed_, where);

  // Remember where each vertex of the engine went; the added ones live for this mesh only. The
  // final mesh's figures: how far from the engine's positions, how many vertices added.
  double move_sum = 0.0, move_max = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    const double* e = &engine_positions[3 * i];
    const double* r = &refined.vertices[3 * i];
    const double d = std::sqrt((r[0] - e[0]) * (r[0] - e[0]) + (r[1] - e[1]) * (r[1] - e[1]) +
                               (r[2] - e[2]) * (r[2] - e[2]));
    move_sum += d;
    move_max = std::max(move_max, d);
    if (r[0] != mesh->vertices[3 * i] || r[1] != mesh->vertices[3 * i + 1] ||
        r[2] != mesh->vertices[3 * i + 2])
      ++stats_.vertices_moved;
    if ((flags[i] & IMR_REFINE_VERTEX_FIXED) != 0) continue;  // its position is the written one
    const Kept k{{e[0], e[1], e[2]}, {r[0], r[1], r[2]}};
    if (mesh->point_ids[i] >= 0)
      kept_[mesh->point_ids[i]] = k;
    else
      kept_steiner_[PositionHash(e)] = k;
  }
  if (final_call) {
    stats_.mean_move = n > 0 ? move_sum / static_cast<double>(n) : 0.0;
    stats_.max_move = move_max;
    stats_.vertices_added = static_cast<int64_t>(result.vertex_count - n);
  }
  stats_.vertices_sent += static_cast<int64_t>(n);
  ++stats_.calls;
  *mesh = std::move(refined);
  const double s = SecondsSince(start);
  stats_.seconds += s;
  stats_.call_seconds.push_back(s);
}

}  // namespace imr::pipeline
