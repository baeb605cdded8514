// The job's mesh_refiner stage (SDK 1.4, DESIGN.md section 10): the surface refined from the
// keyframe images by a plugin, every `every_keyframes` keyframes of the run and once at the end,
// before the exports and the evaluation. The carving is not touched: the refined positions are
// this stage's, kept between calls by vertex (its 3D point, or a Steiner point's position), and a
// vertex the reconstruction has not moved since keeps the position the last call gave it.
//
// A streamed run (engine.forget, output.tiles) writes the surface in the parts the engine hands
// out: each part's vertices take their refined positions before it goes to the tiles and the
// spool (Freeze), and keep them: a vertex handed out is FIXED in later calls (its other faces come
// later, at the position already written), and forgotten once complete. The last call refines
// what the engine still held, before its last part goes through Freeze (FinishLive).
#pragma once

#include "host/engine/engine.h"
#include "host/pipeline/mesh_export.h"
#include "host/pipeline/stage_watch.h"
#include "host/plugin/host_services.h"

#include <nlohmann/json.hpp>

#include <cstdint>
#include <unordered_map>
#include <vector>

namespace imr::pipeline {

struct SurfaceRefinementStats {
  int64_t calls = 0;                // refine calls, the final one included
  int64_t vertices_sent = 0;        // summed over calls
  int64_t vertices_changed = 0;     // of those, flagged changed (new or moved by the engine)
  int64_t vertices_moved = 0;       // moved by the plugin, summed over calls
  int64_t vertices_added = 0;       // by subdivision, in the final mesh
  int64_t vertices_kept = 0;        // positions of an earlier call carried into the final mesh
  double mean_move = 0.0;           // final mesh: mean distance from the engine's positions (m)
  double max_move = 0.0;            // final mesh: largest such distance (m)
  double seconds = 0.0;             // every call, the mesh's extraction for the calls included
  std::vector<double> call_seconds; // per call, in order

  nlohmann::json ToJson() const;
};

class SurfaceRefinement {
 public:
  SurfaceRefinement(const io::StageSpec& stage, plugin::LoadedInstance instance,
                    const WatchedStage& watched);

  // After each keyframe: a refine call on the current surface when the stage's schedule says.
  void OnKeyframe(const engine::Engine& engine, const ExportContext& context, StageWatch& watch,
                  int64_t keyframes);
  // The final call: `mesh` (the engine's last mesh) refined in place, checked (finite, a
  // manifold with the same boundary loops when the plugin subdivided). Throws naming the stage.
  void Finish(engine::Mesh* mesh, const ExportContext& context, StageWatch& watch);

  // A mesh of the engine (a snapshot) at the positions the calls so far gave its vertices.
  void ApplyRefined(engine::Mesh* mesh) const;

  // --- A streamed run ---
  // A part the engine hands out, before the surface stream: each vertex at its refined position
  // (the one it was written with, when an earlier part named it), then complete ones forgotten.
  void Freeze(engine::SurfacePart* part);
  // The final call on what the engine still holds, `live` (its ExtractMesh, taken with its last
  // part before the engine goes; `extract_seconds` its time), before that last part goes through
  // Freeze.
  void FinishLive(engine::Mesh live, double extract_seconds, const ExportContext& context,
                  StageWatch& watch);

  const SurfaceRefinementStats& stats() const { return stats_; }

 private:
  struct Kept {
    std::array<double, 3> engine;   // the engine's position when it was refined
    std::array<double, 3> refined;  // where the plugin put it
  };
  void Refine(engine::Mesh* mesh, const ExportContext& context, StageWatch& watch, bool final_call);
  // Puts the mesh vertex `point_id` at `p` where this stage has it: FIXED (written already, at
  // the position written), 0 (refined by an earlier call and not moved since, at its refined
  // position) or CHANGED (left where the engine has it).
  uint8_t Place(int64_t point_id, double* p) const;
  // The vertex handed out already (Freeze) that mesh vertex `point_id` at `p` is, or null.
  const std::array<double, 3>* Frozen(int64_t point_id, const double* p) const;

  const io::StageSpec& stage_;
  plugin::LoadedInstance instance_;
  WatchedStage watched_;
  std::unordered_map<int64_t, Kept> kept_;  // by point id; Steiner points by kept_steiner_
  std::unordered_map<uint64_t, Kept> kept_steiner_;  // by their position's hash
  std::size_t keyframes_at_last_call_ = 0;
  SurfaceRefinementStats stats_;
  // Streamed: the vertices handed out and not complete, by their key in the parts: where they
  // were written, and how a mesh vertex finds them (its point id, or its engine position's hash).
  struct Written {
    std::array<double, 3> position;
    int64_t point_id;
    uint64_t steiner_hash;
  };
  std::unordered_map<int64_t, Written> written_;
  std::unordered_map<int64_t, int64_t> written_point_;     // point id -> key
  std::unordered_map<uint64_t, int64_t> written_steiner_;  // position hash -> key
  bool streamed_ = false;
};

}  // namespace imr::pipeline
