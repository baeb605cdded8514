// Edges of the exported surface flipped where the other diagonal lies smoother (issue 45; no
// CGAL here).
//
// Between sparse points the carving often joins four points by the diagonal that makes a ridge
// or a fold where the other diagonal of the same four points would lie smooth: the triangles are
// wrong, not the vertices, and moving vertices cannot mend it. This pass is the data-dependent
// triangulation of Dyn, Levin and Rippa (1990): edge swaps that lower the angles between the
// normals of neighbouring faces ("ABN"), a local optimisation over every interior edge. An edge is
// flipped when that lowers the sum of those angles over the five edges the flip touches (the edge
// and the four around its two faces) by at least `min_gain_degrees`:
//   - vertices, their positions and point ids stay; the boundary stays; the number of faces stays;
//   - each new face keeps the orientation of the pair it replaces and of the faces around them
//     (its normal within 90 degrees of their normals' sum), and no new face has an angle under
//     `min_angle_degrees` unless the old pair had one as small;
//   - no new edge the mesh already has (a manifold stays a manifold);
//   - in a part of a streamed surface: no new edge between two vertices whose fans are open
//     (seam vertices: another part may hold that edge).
// A true corner stays: cutting it tilts both new faces against their neighbours, which costs more
// than the corner's edge. Each flip lowers the total, so the pass ends; it also stops after
// `max_flips_per_face` flips per face.
#pragma once

#include <cstdint>
#include <string>

#include "host/engine/engine.h"

namespace imr::engine {

struct EdgeFlipOptions {
  bool enabled = false;
  double min_gain_degrees = 20.0;  // A flip must lower the sum of the five angles by this much.
  double min_angle_degrees = 2.0;  // No new triangle with a smaller angle (unless the old pair
                                   // had one as small).
  int max_flips_per_face = 8;      // Bounds the work: at most this many flips per face.

  // The pass as the engine options ask for it (EngineOptions::flip_edges).
  static EdgeFlipOptions FromEngine(const EngineOptions& options);
  // Empty when usable, else which field and why.
  std::string Check() const;
};

struct EdgeFlipStats {
  int64_t flips = 0;
  int64_t edges = 0;                 // interior edges (between two faces) seen
  double degrees_sum_before = 0.0;   // the angles between their faces' normals, summed
  double degrees_sum_after = 0.0;

  EdgeFlipStats& operator+=(const EdgeFlipStats& o);
};

// The pass on a whole mesh (oriented, a 2-manifold with boundary).
EdgeFlipStats FlipEdges(Mesh* mesh, const EdgeFlipOptions& options);

// The pass on the triangles a SurfaceStream released: faces are rewritten in place (the same
// count, each face keeps its index), vertices and keys untouched; no new edge between two
// vertices whose fans in `part` are not one closed cycle.
EdgeFlipStats FlipEdges(SurfacePart* part, const EdgeFlipOptions& options);

}  // namespace imr::engine
