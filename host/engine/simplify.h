// Mesh simplification by edge collapse (CGAL's Surface_mesh_simplification, Lindstrom-Turk), for
// the tiles' levels of detail (host/pipeline/tiles.h); CGAL stays in simplify.cc.
#pragma once

#include "host/engine/engine.h"

#include <cstdint>
#include <string>
#include <vector>

namespace imr::engine {

struct SimplifiedMesh {
  Mesh mesh;                     // the simplified mesh (point_ids as the input's)
  std::vector<uint32_t> source;  // per vertex of `mesh`: the input vertex it is (locked ones
                                 // keep their position; others may have moved)
  double error = 0.0;            // measured: the largest distance of an input vertex to `mesh`
};

// `mesh` (a 2-manifold with boundary; pinched vertices are split and locked first) collapsed
// towards `target_triangles`. A vertex with `locked[v]` keeps its position and stays (an edge
// between two locked vertices is never collapsed), so two meshes that lock the vertices of the
// seam they share still meet after it. Fewer triangles than asked may remain out of reach (locked
// vertices, collapses that would fold a triangle); a mesh that is not a 2-manifold with boundary
// comes back as it is (error 0).
// With `max_distance` > 0 no collapse puts a vertex further than that from `mesh` (Lindstrom-Turk
// may place one far off on a thin strip or the surface's edge: a spike).
SimplifiedMesh SimplifyMesh(const Mesh& mesh, const std::vector<char>& locked, int64_t target_triangles,
                            double max_distance = 0.0);

// The largest distance of `points` (packed xyz) to the triangles of `mesh` (0 for no points;
// infinity for a mesh without triangles).
double MaxDistanceToMesh(const std::vector<double>& points, const Mesh& mesh);

}  // namespace imr::engine
