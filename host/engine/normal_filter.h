// Bilateral normal filtering of the exported surface (issue 45, "no crust"; no CGAL here).
//
// Between sparse, noisy points the carved surface is rough: neighbouring faces of a flat facade
// meet at 20-30 degrees. Taubin smoothing flattens it but rounds corners and small objects off
// too. This pass denoises while it keeps edges, after Zheng, Fu, Au and Tai (2011), "Bilateral
// Normal Filtering for Mesh Denoising", the local iterative scheme:
//   1. each face's normal becomes the area-weighted mean of the normals of the faces sharing a
//      vertex with it, weighted by a Gaussian on their centroids' distance (sigma_spatial) and
//      one on their normals' difference |n_i - n_j| (sigma_range): across a corner (|n_i - n_j|
//      = 1.41 at 90 degrees) the weight vanishes, so the corner's two sides are filtered apart;
//   2. the vertices are moved to fit the filtered normals, the iteration of Sun et al. (2007),
//      "Fast and effective feature-preserving mesh denoising":
//        x_v += 1/|F_v| sum_{f at v} n_f (n_f . (c_f - x_v)),   c_f the face's centroid.
// Both repeated `iterations` times. What stays:
//   - the faces, the vertex count and the point ids; the boundary's vertices bit for bit;
//   - a vertex moves only when its fan is one closed cycle in the faces given: on a whole mesh,
//     every vertex off the boundary; in a part of a streamed surface, only vertices whose whole
//     fan is in the part (a seam vertex was, or will be, written by another part with its
//     position; plane_retriangulation's rule);
//   - no face turns: a vertex update that would turn a face's normal more than
//     `max_turn_degrees` from its normal before the pass (or make it degenerate) is undone for
//     that face's vertices, for that step.
// Distances are relative to the median edge length of the faces given, so the pass works at any
// scale.
#pragma once

#include <cstdint>
#include <string>

#include "host/engine/engine.h"

namespace imr::engine {

struct NormalFilterOptions {
  int iterations = 0;            // Rounds of (filter the normals, move the vertices); 0: off.
  double sigma_spatial = 1.0;    // The spatial Gaussian's sigma, x the median edge length.
  double sigma_range = 0.35;     // The range Gaussian's sigma on |n_i - n_j| (unit normals, 0..2).
  int normal_passes = 1;         // Filter passes over the normals per round.
  int vertex_steps = 10;         // Vertex updates (Sun et al.) per round.
  double max_turn_degrees = 90.0;  // A face's normal never turns further from where it was.

  // The pass as the engine options ask for it (EngineOptions::filter_normals, ...).
  static NormalFilterOptions FromEngine(const EngineOptions& options);
  bool enabled() const { return iterations > 0; }
  // Empty when usable, else which field and why.
  std::string Check() const;
};

struct NormalFilterStats {
  int64_t iterations = 0;       // rounds run (the most over the parts)
  int64_t vertices_moved = 0;   // vertices whose position changed
  int64_t moves_reverted = 0;   // vertex updates undone because a face would have turned
  double max_move = 0.0;        // the largest move (mesh units)
  int64_t edges = 0;            // interior edges (between two faces) seen
  double degrees_sum_before = 0.0;  // the angles between their faces' normals, summed
  double degrees_sum_after = 0.0;

  NormalFilterStats& operator+=(const NormalFilterStats& o);
};

// The pass on a whole mesh (oriented, a 2-manifold with boundary): a vertex may move when its
// fan is closed (not on the mesh's boundary).
NormalFilterStats FilterNormals(Mesh* mesh, const NormalFilterOptions& options);

// The pass on the triangles a SurfaceStream released: only vertices whose closed fan lies wholly
// in `part` move; faces, keys and point ids untouched.
NormalFilterStats FilterNormals(SurfacePart* part, const NormalFilterOptions& options);

}  // namespace imr::engine
