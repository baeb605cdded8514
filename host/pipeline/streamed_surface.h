// The surface as the engine hands it out in parts (DESIGN.md section 10), for the run of one
// sequence when the engine forgets (engine.forget) or the job asks for tiles (output.tiles):
// after every update the engine's final parts go through the surface stream (pinched vertices
// split, small holes filled: host/engine/surface_stream.h), and what the stream releases goes to
// the tiles (tiles.h) and, when the job names mesh files, to a spool on disk: the single mesh's
// vertices and faces in file order, so that it is written at the end in blocks (SDK 1.3's mesh
// stream) and never sits in memory whole; or read back whole for an exporter that cannot stream.
//
// What the spool holds stays on disk; what memory holds is the seam: the vertices released and
// not yet completed (surface_stream.h), each with its normal sum and its link, which is checked
// when the vertex completes (the manifold check CheckMesh makes on a whole mesh, one vertex at a
// time), and the components and boundary loops still open (union-find over sets, each counted
// when its last vertex or boundary edge is closed).
#pragma once

#include "host/engine/engine.h"
#include "host/engine/edge_flips.h"
#include "host/engine/mesh_passes.h"
#include "host/engine/normal_filter.h"
#include "host/engine/plane_retriangulation.h"
#include "host/engine/surface_stream.h"
#include "host/eval/mesh_stats.h"
#include "host/pipeline/tiles.h"

#include <array>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <functional>
#include <memory>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

namespace imr::pipeline {

struct StreamedSurfaceStats {
  engine::SurfaceStreamStats stream;
  int64_t engine_parts = 0;        // parts the engine handed out (its last included)
  int64_t spool_bytes = 0;         // 0: no spool (tiles only)
  int64_t peak_seam_vertices = 0;  // vertices released and not yet completed, at most
  double seconds = 0.0;            // in Take and Finish: the stream, the spool, the tiles
  double max_update_seconds = 0.0; // the longest Take (one keyframe's parts)
  engine::PlaneRetriangulationStats planes;  // engine.retriangulate_planes, per released piece
  engine::EdgeFlipStats flips;               // engine.flip_edges, per released piece
  engine::NormalFilterStats normal_filter;   // engine.filter_normals, per released piece
  // Pieces written without the passes: they changed the piece's fans where other pieces meet
  // it (SameVertexLinks); the first one's message.
  int64_t pieces_undone = 0;
  std::string undone_why;
};

class StreamedSurface {
 public:
  // `spool` empty: no single mesh (tiles only); else an existing folder for the spool's files
  // (the caller removes it). `tiles` may be null (no tiles).
  StreamedSurface(const engine::EngineOptions& options, std::filesystem::path spool, TileWriter* tiles);
  ~StreamedSurface();
  // What each part goes through before the stream (the mesh_refiner stage's refined positions:
  // SurfaceRefinement::Freeze); none by default.
  void SetPartFilter(std::function<void(engine::SurfacePart*)> filter) { filter_ = std::move(filter); }
  // After each ApplyUpdate: the parts that became final. Throws when a part does not fit.
  void Take(engine::Engine& engine);
  // After the last update: the rest of the surface (the engine's FinishSurface, taken before the
  // engine goes: the last tiles decode keyframe images), the open tiles and the final tileset.
  void Finish(engine::SurfacePart last);

  // --- The single mesh, after Finish (spool given) ---
  uint64_t vertex_count() const { return next_vertex_; }
  uint64_t face_count() const { return faces_; }
  // Min xyz, max xyz of the vertices (zero when there are none).
  const std::array<double, 6>& bounds() const { return bounds_; }
  // Blocks of the mesh in file order (vertices in the order first released, faces as released):
  // `xyz` 3 per vertex, `point_ids` 1 per vertex, `normal_sums` 3 per vertex (the sum over the
  // vertex's faces, in face order, of (b - a) x (c - a)); each may be null. Throws naming the spool.
  void ReadVertices(uint64_t first, uint64_t count, double* xyz, int64_t* point_ids,
                    double* normal_sums) const;
  void ReadFaces(uint64_t first, uint64_t count, uint32_t* faces) const;
  // The triangles in face order, a block at a time: fn(vertices, faces), the vertices the block's
  // faces use (the range of the spool's between the lowest and highest index they name: vertices
  // are numbered as released, so a block's lie close together) and the faces indexing into them.
  void ForEachTriangleBlock(
      const std::function<void(const std::vector<double>&, const std::vector<uint32_t>&)>& fn) const;
  // The whole mesh, for an exporter that cannot take it in blocks, and for the evaluation; in
  // canonical order when `canonical` (the order ExtractMesh gives: with one part, the same bytes).
  engine::Mesh ReadMesh(bool canonical) const;
  // CheckMesh's verdict (closed = false), made one vertex at a time as vertices completed.
  const engine::ManifoldCheckResult& mesh_check() const { return check_; }
  // The topology of the mesh without its per-component list (which needs the mesh whole).
  const eval::MeshStatistics& statistics() const { return statistics_; }

  const StreamedSurfaceStats& stats() const { return stats_; }

 private:
  struct SeamVertex {
    uint32_t index = 0;
    uint32_t component = 0;  // its set in components_
    std::array<double, 3> normal_sum{};
    std::vector<std::pair<uint32_t, uint32_t>> link;  // per face at it: the opposite edge
  };
  // Union-find over sets of the mesh (components, boundary loops), each root with how much of
  // it is still open: its seam vertices, its boundary edges with one end complete. A set whose
  // count falls to 0 is complete and counted. Merged labels are dropped now and then (Compact*).
  struct OpenSet {
    uint32_t parent = 0;
    int64_t open = 0;
  };
  using OpenSets = std::unordered_map<uint32_t, OpenSet>;
  uint32_t NewSet(OpenSets& sets, int64_t open);
  static uint32_t FindSet(OpenSets& sets, uint32_t label);
  static uint32_t UnionSets(OpenSets& sets, uint32_t a, uint32_t b);
  void CloseBoundary(const SeamVertex& v, uint32_t first, uint32_t last);
  void CompactSets();
  void Feed(const engine::SurfacePart& part);
  void Spool(const engine::SurfacePart& released);
  void Complete(SeamVertex& v);
  void Fail(const std::string& what);

  engine::SurfaceStream stream_;
  engine::PlaneRetriangulationOptions planes_;
  engine::EdgeFlipOptions flips_;
  engine::NormalFilterOptions normal_filter_;
  int pass_rounds_ = 1;  // EngineOptions::mesh_pass_rounds
  std::function<void(engine::SurfacePart*)> filter_;
  std::filesystem::path spool_dir_;
  std::ofstream vertices_, faces_file_;
  int normals_fd_ = -1;  // written at each vertex's completion, at its index (pwrite)
  TileWriter* tiles_;
  StreamedSurfaceStats stats_;

  std::unordered_map<int64_t, SeamVertex> seam_;  // by the stream's key
  uint64_t next_vertex_ = 0, faces_ = 0;
  std::array<double, 6> bounds_{};
  OpenSets components_, loops_;
  uint32_t next_label_ = 0;
  // Per vertex index: the boundary edges to it whose other end completed first, as (that end,
  // its loop's label); matched when this vertex completes.
  std::unordered_map<uint32_t, std::vector<std::pair<uint32_t, uint32_t>>> loop_ends_;
  int64_t components_done_ = 0, loops_done_ = 0;
  int64_t boundary_edges_ = 0;
  double area_ = 0.0;
  engine::ManifoldCheckResult check_;
  eval::MeshStatistics statistics_;
};

}  // namespace imr::pipeline
