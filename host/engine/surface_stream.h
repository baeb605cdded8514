// The exported surface made from the engine's SurfaceParts as they come (DESIGN.md section 10; no
// CGAL here). ExtractMesh fixes the filtered dO up as a whole: pinched vertices split, small holes
// filled, optional smoothing (FinishExportedMesh). SurfaceStream makes each fix-up as soon as the
// part of the surface it needs can no longer change, and releases the triangles whose fix-ups
// are done, so what it holds is bounded by the seam between the final and the live part, not by
// the length of the drive:
//   - a vertex's fans are split when the vertex is completed (every triangle around it given);
//   - a hole (a boundary loop of at most fill_holes_max_edges edges and fill_holes_perimeter in
//     length) is closed when its last vertex is completed, with the same fan around the same
//     centroid as FillSmallHoles (the same floating-point sums, from the vertex the whole mesh's
//     canonical order puts first);
//   - a triangle is released when its three vertices are split; a boundary vertex is forgotten
//     once its loop is known to be too long or too wide to be filled, or has been filled.
// The union of everything released (MergeSurfaceParts, then CanonicalizeMesh) is exactly
// FinishExportedMesh(MergeSurfaceParts(parts)) without smoothing, for any cut into parts.
//
// Small components (min_component_area > 0): a piece is weighed once it is whole, all its vertices
// completed. Until then the released triangles of a piece whose area so far is under the
// threshold are held back (with their vertices' completions); once the piece reaches it they go
// out with the next release, and a piece completed under it is dropped. The union of what is
// released stays FinishExportedMesh's, dropped pieces included, for any cut into parts; what is
// held is at most the open pieces under the threshold.
//
// Smoothing (smoothing_iterations > 0) is local to each Add: the triangles released by one part
// are smoothed as one mesh whose boundary stays fixed (SmoothTaubin), so a vertex with triangles
// released by an earlier part, or still held, keeps its position, and a vertex is written once
// with one position. With one part (no forgetting) that is FinishExportedMesh's smoothing, bit
// for bit; with several, the vertices along each seam between parts are not smoothed.
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "host/engine/engine.h"

namespace imr::engine {

struct SurfaceStreamOptions {
  bool split_pinched = true;          // SplitPinchedVertices (EngineOptions: steiner_export not
                                      // none: the filtered dO may pinch).
  double fill_holes_perimeter = 16.0; // FillSmallHoles' max_perimeter (metres; 0: no filling).
  int fill_holes_max_edges = 64;      // FillSmallHoles' max_edges.
  int smoothing_iterations = 0;       // SmoothTaubin per released part (see above); 0: none.
  double min_component_area = 0.0;    // DropSmallComponents' min_area (square metres; 0: keep
                                      // every piece; see above).

  // What FinishExportedMesh does with these engine options.
  static SurfaceStreamOptions FromEngine(const EngineOptions& options);
  // Empty when usable, else which field and why.
  std::string Check() const;
};

struct SurfaceStreamStats {
  int64_t parts = 0;               // Add calls
  int64_t triangles_in = 0;        // triangles of the parts
  int64_t triangles_released = 0;  // released, hole fans included
  int64_t vertices_released = 0;   // distinct vertices released (split copies, hole centres)
  int64_t holes_filled = 0;
  int64_t vertices_split = 0;      // copies made for the extra fans of pinched vertices
  int64_t held_triangles = 0;      // held now (waiting for a vertex to be completed)
  int64_t held_vertices = 0;       // vertices held now (of held triangles, open boundaries)
  int64_t peak_held_triangles = 0;
  int64_t peak_held_vertices = 0;
  DroppedComponents dropped;       // small components dropped (min_component_area)
  int64_t held_small_triangles = 0;  // released by the fix-ups, held now in pieces still small
  int64_t peak_held_small_triangles = 0;
};

class SurfaceStream {
 public:
  explicit SurfaceStream(const SurfaceStreamOptions& options);
  ~SurfaceStream();
  SurfaceStream(const SurfaceStream&) = delete;
  SurfaceStream& operator=(const SurfaceStream&) = delete;

  // Takes the run's next part. "" or why it does not fit (a vertex at two positions, an index
  // out of range, a completed key no part named); after an error the stream is unusable.
  std::string Add(const SurfacePart& part);
  // What the Add calls since the last call released, as one part: its vertices keyed by the
  // stream's own keys (a split vertex's fans and a hole's centre are vertices of their own, so
  // engine keys are not kept), `completed` the keys no later released part names.
  SurfacePart TakeReleased();
  // After the last part: "" when everything was released, else what is still held (a vertex
  // never completed).
  std::string Finish() const;

  const SurfaceStreamStats& stats() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace imr::engine
