// Planar regions of the exported surface triangulated again (issue 45; no CGAL here).
//
// Between sparse, noisy points the carving's sheet folds over itself: on a flat façade two
// neighbouring faces often meet at more than 170° (docs/refinement.md, "folds"). Moving vertices
// flattens such a sheet but cannot unfold it, and an edge flip reaches only the folds one flip
// from flat. This pass finds regions of the surface whose vertices all lie within a tolerance of
// one plane, projects them onto it and replaces the region's triangles with the constrained
// Delaunay triangulation of the same vertices inside the same boundary loops:
//   - the region's boundary (its edges, its vertices and their positions) stays, so the faces
//     around it, and the seams with parts written earlier or later, still meet it;
//   - every vertex stays (the same point ids, no vertex dropped or added, so the same number of
//     faces); only vertices whose whole fan lies in the region move, onto the plane;
//   - the faces keep the region's orientation (toward free space);
//   - where the projection would not give back a manifold with the same boundary (a loop that
//     crosses itself in the plane, two vertices at one place, a vertex outside its loops: a fold
//     over the region's edge; a new edge the mesh has elsewhere), the faces at the vertices in
//     question leave the region and the rest is tried again, a few times, else left as it was.
// Regions grow from the flattest faces (their neighbourhood's least-squares plane), across
// edges, while every vertex of a face is within the tolerance of the seed's plane. In a part of a
// streamed surface, the edges at its seam vertices stay as well, and no edge joins two of them
// anew (another part may hold it): plane_retriangulation_test checks both on random cuts.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "host/engine/engine.h"

namespace imr::engine {

struct PlaneRetriangulationOptions {
  double tolerance = 0.0;  // A region's vertices lie within this many median edge lengths (of the
                           // mesh given) of its plane; 0: off.
  int min_faces = 8;       // Regions with fewer faces stay as they are.
  int max_faces = 20000;   // A region grows to at most this many faces (bounds one triangulation).

  // The pass as the engine options ask for it (EngineOptions::retriangulate_planes).
  static PlaneRetriangulationOptions FromEngine(const EngineOptions& options);
  bool enabled() const { return tolerance > 0.0; }
  // Empty when usable, else which field and why.
  std::string Check() const;
};

struct PlaneRetriangulationStats {
  int64_t regions = 0;          // regions triangulated again
  int64_t faces = 0;            // their faces
  int64_t vertices_moved = 0;   // vertices projected onto their region's plane
  int64_t regions_refused = 0;  // regions found but left (see the header's list)
  double max_move = 0.0;        // largest projection (mesh units)

  PlaneRetriangulationStats& operator+=(const PlaneRetriangulationStats& o);
};

// The pass on a whole mesh (oriented, a 2-manifold with boundary): a vertex may move when its
// fan is closed (not on the mesh's boundary).
PlaneRetriangulationStats RetriangulatePlanes(Mesh* mesh, const PlaneRetriangulationOptions& options);

// The pass on the triangles a SurfaceStream released: only vertices whose closed fan lies wholly
// in `part` may move (every other vertex has, or will have, faces in other parts, written with
// its position); faces are replaced in place, vertices and keys keep their order.
PlaneRetriangulationStats RetriangulatePlanes(SurfacePart* part,
                                              const PlaneRetriangulationOptions& options);

}  // namespace imr::engine
