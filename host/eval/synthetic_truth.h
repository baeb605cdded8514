// Ground truth of a sequence imr-synth made (ground_truth/scene.json): the analytic street and
// where it sits in the sequence's world frame; and the completeness of a mesh on the road surface
// alone (issue 14: the road, weakly textured, is what the image front end covers worst).
#pragma once

#include "host/eval/evaluate.h"
#include "host/eval/mesh_io.h"
#include "host/io/camera_model.h"
#include "host/synthetic/scene.h"

#include <cstddef>
#include <string>
#include <vector>

namespace imr::eval {

// A synthetic sequence's analytic scene and where it sits in the world frame of its poses.
struct SyntheticTruth {
  synthetic::Scene scene;
  io::Mat3 rotation = io::Identity3();  // scene -> world: x_w = R x_s + t
  io::Vec3 translation{};
  io::Vec3 ToScene(const io::Vec3& world) const;  // x_s = R^T (x_w - t)
  io::Vec3 ToWorld(const io::Vec3& scene) const;  // x_w = R x_s + t
};
// Reads scene.json; throws std::runtime_error naming the file and field.
SyntheticTruth ReadSyntheticTruth(const std::string& path);

struct RoadSurfaceEvaluation {
  std::size_t samples = 0;  // road samples drawn (synthetic::SampleRoadSurface), before the crop
  bool cropped = false;     // the crop of imr evaluate applied (options.crop and cameras given)
  CropCounts crop;          // the samples through that crop
  // Kept samples that no camera in range with the sample in its frustum sees unoccluded (the
  // ground behind parked cars): they count in `completeness`, which therefore cannot reach 1.
  std::size_t hidden = 0;
  std::vector<double> taus;
  std::vector<double> completeness;          // per tau: share of kept samples within tau of the mesh
  std::vector<double> completeness_visible;  // the same over the kept samples that are not hidden
  DistanceStats truth_to_mesh;               // kept samples -> mesh
};

// Completeness of `mesh` (world frame) on the road surface of `truth`: the road sampled at
// options.truth_density points per unit area (seed options.seed), cropped to `cameras` as imr
// evaluate crops its ground truth (options.crop, options.max_ray_length), each kept sample's
// distance to the mesh compared with options.taus. Throws std::invalid_argument on bad options
// or a mesh without a triangle of non-zero area, std::runtime_error when no sample is kept.
RoadSurfaceEvaluation EvaluateRoadSurface(const TriangleMesh& mesh, const SyntheticTruth& truth,
                                          const std::vector<io::CameraGeometry>& cameras,
                                          const EvaluationOptions& options);

}  // namespace imr::eval
