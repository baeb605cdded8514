// Nearest distances for evaluation, behind a plain header: CGAL lives in distance.cc alone (one
// translation unit costs 10-15 s and 0.7 GB to compile). Both indexes are built once and then
// queried from many threads (std::thread, parallel.h); queries are read-only.
#pragma once

#include "host/eval/mesh_io.h"

#include <cstddef>
#include <memory>
#include <vector>

namespace imr::eval {

// Point-to-triangle distances to a mesh: CGAL AABB_tree of AABB_triangle_primitive over
// Simple_cartesian<double>, exact closest points (what CloudCompare's cloud-to-mesh distance
// computes, unsigned); queries run in Morton order, each hinted by the previous closest point. Triangles of zero area (repeated or collinear
// vertices) are left out: CGAL's closest-point query is undefined on them, and in a manifold mesh
// their points lie on the neighbouring triangles' edges anyway.
class MeshDistance {
 public:
  explicit MeshDistance(const TriangleMesh& mesh);  // throws std::invalid_argument: no triangle
  ~MeshDistance();
  MeshDistance(const MeshDistance&) = delete;
  MeshDistance& operator=(const MeshDistance&) = delete;

  std::size_t triangles() const;   // triangles in the tree
  std::size_t degenerate() const;  // zero-area triangles left out

  // Unsigned distance from each point to the nearest triangle, on `threads` threads (<= 0: all).
  std::vector<double> Distances(const std::vector<Vec3>& points, int threads) const;

  // The nearest point of the mesh to each point (exact), on `threads` threads.
  std::vector<Vec3> ClosestPoints(const std::vector<Vec3>& points, int threads) const;

 private:
  template <class Out>
  void Query(const std::vector<Vec3>& points, int threads, const Out& out) const;

  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Nearest-neighbour distances to a point set: CGAL Kd_tree (Search_traits_3), 1-nearest search.
class PointSetDistance {
 public:
  explicit PointSetDistance(const std::vector<Vec3>& points);  // throws: empty set
  ~PointSetDistance();
  PointSetDistance(const PointSetDistance&) = delete;
  PointSetDistance& operator=(const PointSetDistance&) = delete;

  // Distance from each query to its nearest point of the set, on `threads` threads.
  std::vector<double> Distances(const std::vector<Vec3>& queries, int threads) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace imr::eval
