// Accuracy of a triangle mesh against a known Scene (host/eval/README.md, both directions): mesh -> scene
// (precision: is what we built on a true surface?) and true points -> mesh (completeness: is what
// was seen covered?). Plain arrays in, no engine types.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "host/synthetic/scene.h"

namespace imr::synthetic {

struct MeshAccuracy {
  size_t triangles = 0;
  double area = 0.0;
  double mean_mesh_to_scene = 0.0;    // Area-weighted mean distance of the mesh to the scene.
  double precision = 0.0;             // Share of mesh area within tau of the scene.
  double mean_truth_to_mesh = 0.0;    // Mean distance of true points to the mesh (capped at cap).
  double completeness = 0.0;          // Share of true points within tau of the mesh.
  double tau = 0.0;
};

// Mesh -> scene over blocks of triangles, for a mesh never whole in memory (a long drive's, read
// back from disk): the same sums in the same triangle order as EvaluateMesh, so the same figures
// bit for bit as one call with the whole mesh. Result() has no truth -> mesh figures.
class MeshToScene {
 public:
  MeshToScene(const Scene& scene, double tau) : scene_(scene), tau_(tau) {}
  // vertices: packed xyz; faces: 3 indices into them per triangle.
  void AddTriangles(const std::vector<double>& vertices, const std::vector<uint32_t>& faces);
  MeshAccuracy Result() const;

 private:
  const Scene& scene_;
  double tau_;
  size_t triangles_ = 0;
  double sum_ = 0.0, within_ = 0.0, area_ = 0.0;
};

// EvaluateMesh over blocks of triangles, both directions, for a mesh never whole in memory: mesh
// -> scene as MeshToScene, truth -> mesh as each true point's running minimum over the blocks
// (the nearest triangle of the mesh is the nearest of the blocks' nearest), so the same figures
// bit for bit as one EvaluateMesh call with the whole mesh, the blocks given in the mesh's order.
// Holds the true points and a distance each; a block is searched from the points near its box.
class MeshAccuracyInBlocks {
 public:
  MeshAccuracyInBlocks(const Scene& scene, std::vector<Vec3> truth, double tau, double cap = 5.0);
  // vertices: packed xyz; faces: 3 indices into them per triangle.
  void AddTriangles(const std::vector<double>& vertices, const std::vector<uint32_t>& faces);
  MeshAccuracy Result() const;
  size_t truth_size() const { return truth_.size(); }

 private:
  MeshToScene mesh_to_scene_;
  std::vector<Vec3> truth_;
  std::vector<double> nearest_;  // per true point: its distance to the blocks so far, <= cap_
  double tau_, cap_;
};

// vertices: packed xyz; faces: 3 indices per triangle. Distances truth -> mesh are capped at `cap`.
MeshAccuracy EvaluateMesh(const Scene& scene, const std::vector<double>& vertices,
                          const std::vector<uint32_t>& faces, const std::vector<Vec3>& truth,
                          double tau, double cap = 5.0);

// Points on the scene's road surface: its Material::kGround rects (in the street canyon the
// carriageway, parking lanes and pavements), less the footprints of the boxes that stand on them
// (the ground under a parked car is no surface anyone sees). A jittered grid: one point, uniform,
// in each square of side 1 / sqrt(density) (density: points per unit area), the same for the same
// seed on any machine. Scene coordinates.
std::vector<Vec3> SampleRoadSurface(const Scene& scene, double density, uint64_t seed);

// Distance from p to the triangle (a, b, c).
double PointTriangleDistance(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c);

// Truth -> mesh, the one implementation of EvaluateMesh and the benchmarks' accuracy: for each
// point of `truth`, the distance to the nearest triangle (vertices packed xyz, 3 indices per
// face), capped at `cap`. Exact (PointTriangleDistance over every triangle within the cap), found
// through a hash grid of triangle bounding boxes with cells of side `cell`, searched ring by
// ring; a triangle spanning more than `max_span` cells along an axis is left out (an absurdly
// large one, which would fill the grid).
std::vector<double> TruthToMeshDistances(const std::vector<double>& vertices,
                                         const std::vector<uint32_t>& faces,
                                         const std::vector<Vec3>& truth, double cap, double cell,
                                         int64_t max_span);

}  // namespace imr::synthetic
