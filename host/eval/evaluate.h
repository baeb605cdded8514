// Accuracy of a mesh against ground truth (`imr evaluate`; host/eval/README.md): the paper's measure, the
// mean distance from every ground-truth point to the nearest mesh triangle (CloudCompare's
// cloud-to-mesh distance), with median, RMS, 90th percentile and maximum; completeness and
// precision at several thresholds; ground truth cropped to the region the cameras saw.
// The JSON report's keys are documented in host/eval/README.md.
#pragma once

#include "host/eval/ground_truth.h"
#include "host/eval/mesh_io.h"
#include "host/io/camera_model.h"
#include "host/io/image_sequence.h"

#include <nlohmann/json.hpp>

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace imr::eval {

struct EvaluationOptions {
  // Thresholds tau (scene units) of completeness and precision.
  std::vector<double> taus = {0.05, 0.1, 0.2, 0.5};
  // Crop ground truth (and the mesh samples of precision) to the cameras' view, when cameras are
  // known (an image sequence); without cameras nothing is cropped and the report says so.
  bool crop = true;
  // Crop: greatest distance of a kept point from the centre of the camera that sees it (the
  // engine's max_ray_length); <= 0: no range limit.
  double max_ray_length = 30.0;
  // Ground truth given as a reference mesh: samples per unit of area (100 / m^2: about 10 cm apart).
  double truth_density = 100.0;
  // Precision: points sampled uniformly by area on the evaluated mesh.
  std::size_t precision_samples = 1000000;
  // Seed of both samplings (reference mesh, precision): the same numbers on every run.
  uint64_t seed = 1;
  // Worker threads for distances and the crop; <= 0: the hardware's concurrency.
  int threads = 0;

  // Empty when valid; otherwise what is wrong, e.g. "tau 0 is not positive".
  std::string Check() const;
};

struct DistanceStats {
  std::size_t count = 0;
  double mean = 0.0;
  double median = 0.0;
  double rms = 0.0;
  double p90 = 0.0;  // 90th percentile
  double max = 0.0;
};

// Statistics of `values` (taken by value: sorted inside). Percentiles interpolate linearly between
// the closest ranks (numpy's default): p(q) = v[floor(h)] + (h - floor(h)) (v[floor(h)+1] -
// v[floor(h)]), h = q (n - 1). All zero for no values.
DistanceStats Summarize(std::vector<double> values);

// Per tau, the share of `d` within it (d <= tau): completeness or precision. NaN for no values.
std::vector<double> SharesWithin(const std::vector<double>& d, const std::vector<double>& taus);

struct Evaluation {
  std::size_t mesh_vertices = 0;
  std::size_t mesh_triangles = 0;        // as read
  std::size_t degenerate_triangles = 0;  // zero-area, left out of the distances
  double mesh_area = 0.0;
  std::size_t truth_points = 0;          // ground-truth points given (before the crop)
  bool cropped = false;
  std::string crop_note;                 // the rule applied, or why nothing was cropped
  std::size_t cameras = 0;
  CropCounts truth_crop;                 // ground-truth points through the crop
  DistanceStats truth_to_mesh;           // kept ground-truth points -> mesh (the paper: mean)
  std::vector<double> taus;
  std::vector<double> completeness;      // per tau: share of kept truth points within tau of the mesh
  std::vector<double> precision;         // per tau: share of kept mesh samples within tau of truth
  std::size_t precision_samples = 0;     // mesh samples drawn
  CropCounts sample_crop;                // mesh samples through the crop
  DistanceStats mesh_to_truth;           // kept mesh samples -> nearest kept truth point
  // With scanner views (Velodyne truth): precision over the kept mesh samples some scan had
  // within its elevations and range (ground_truth.h), the area the truth could confirm at all.
  bool scanner_view = false;
  std::size_t samples_in_scanner_view = 0;
  std::vector<double> precision_in_scanner_view;  // per tau; NaN when no sample is in view
  int threads = 1;
  double seconds_crop = 0.0;
  double seconds_truth_to_mesh = 0.0;    // AABB tree build + queries
  double seconds_mesh_to_truth = 0.0;    // sampling + kd-tree build + queries
  std::vector<double> per_point;         // if asked: one per truth point, NaN where cropped
};

// Evaluates `mesh` against `truth`, cropped by `cameras` when options.crop and there are cameras.
// Throws std::runtime_error when the mesh has no triangle of non-zero area or no truth point is
// left after the crop.
// With `scanner_views` (a laser scanner's truth), precision is also given over the samples in
// their view.
Evaluation Evaluate(const TriangleMesh& mesh, const std::vector<Vec3>& truth,
                    const std::vector<io::CameraGeometry>& cameras,
                    const EvaluationOptions& options, bool per_point = false,
                    const std::vector<ScannerView>* scanner_views = nullptr);

// Ground truth as evaluated: its points and what a report says of them (its "truth": source,
// path, points, ...).
struct Truth {
  std::vector<Vec3> points;
  nlohmann::json description;
  std::vector<ScannerView> scanner_views;  // Velodyne truth: one per scan
};

// Reads the ground truth `imr evaluate` and a job's "evaluation" name: `path` is a point cloud
// (.ply without faces, .xyz/.txt/.asc) or a reference mesh (.ply, .obj, .gltf, .glb with faces;
// sampled by area at options.truth_density, seeded by options.seed); "" means the Velodyne scans
// of `sequence` (every scan_step-th frame's). Throws std::runtime_error naming the file on bad
// input, on a reference mesh that would give more than 2e8 samples, and when no point is found.
Truth LoadTruth(const std::string& path, const io::ImageSequence* sequence, int scan_step,
                const EvaluationOptions& options);

// What `imr evaluate` reads.
struct EvaluationInputs {
  std::string mesh;      // the mesh: .obj, .ply, .gltf, .glb
  // Ground truth: a point cloud (.ply without faces, .xyz/.txt/.asc) or a reference mesh (.ply,
  // .obj, .gltf, .glb with faces; sampled by area). "" = the Velodyne scans of `sequence`.
  std::string truth;
  // A KITTI sequence: raw (a drive folder) or odometry (a folder with calib.txt); its cameras crop
  // the ground truth and, when `truth` is "", its Velodyne scans are the ground truth.
  std::string sequence;
  io::ImageSequenceOptions sequence_options;  // frame selection, camera
  int scan_step = 1;                          // Velodyne ground truth: every n-th frame's scan
  std::string per_point;                      // "" or a file: one distance per truth point
  // In memory rather than read from files (the Python module's arrays: no temporary copy of the
  // caller's data on disk). When set, `mesh` / `truth` only name them in messages and the report.
  const TriangleMesh* mesh_data = nullptr;
  const std::vector<Vec3>* truth_points = nullptr;
};

// Reads the inputs, evaluates, writes the per-point file (atomically) when asked, and returns the
// report (README.md); for a sequence imr-synth made (its ground_truth/scene.json), the report
// has the road surface's completeness too (synthetic_truth.h). Throws std::runtime_error naming the file and the problem on bad input.
// `read_sequence` reads inputs.sequence (the CLI passes ReadKittiSequence; tests their own).
using SequenceReader = io::ImageSequence (*)(const std::string& path,
                                             const io::ImageSequenceOptions& options);
nlohmann::json EvaluateFiles(const EvaluationInputs& inputs, const EvaluationOptions& options,
                             SequenceReader read_sequence = nullptr);

// The report for people: a few aligned lines.
std::string FormatReport(const nlohmann::json& report);

// KITTI raw when `path` has image_0X/data or velodyne_points, else KITTI odometry when it holds
// calib.txt (io/image_sequence.h). In its own
// translation unit (kitti_sequence.cc): only what calls it links the KITTI readers.
io::ImageSequence ReadKittiSequence(const std::string& path, const io::ImageSequenceOptions& options);

}  // namespace imr::eval
