// OpenMVS beside imr in `imr-bench quality --openmvs BIN_DIR`, scored by the same code: its
// RefineMesh (Vu et al.'s photometric mesh refinement) on imr's unrefined mesh and the same
// images (issue 34), and its whole pipeline on the same keyframes and images (issue 45:
// InterfaceCOLMAP -> DensifyPointCloud -> ReconstructMesh -> RefineMesh). OpenMVS is AGPL: it is
// built outside the repository by tools/bench/peers/build_openmvs.sh and only run as separate
// processes, each `nice -n 10` (it takes every core); none of its code is here.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

namespace imr::bench {

// Writes `out`/sparse/{cameras,images,points3D}.txt and `out`/images/ (one symbolic link per
// image) from the COLMAP text model `model` that `imr run --export-colmap` wrote, in the layout
// and the conventions InterfaceCOLMAP reads: cameras as PINHOLE (a SIMPLE_PINHOLE's focal length
// written twice; any distorted model is refused: OpenMVS wants undistorted images), image ids
// from 1 (imr writes them from 0; InterfaceCOLMAP subtracts one into an unsigned), the tracks'
// image ids likewise. Each image NAME is looked up in `image_dirs` in order. With
// `keyframe_every` > 1 only the keyframes' images are kept (the k-th image by id for k a multiple
// of it, and the last: the images imr's own refinement matches; a point keeps its other views,
// and goes when it has none). "" on success, else what is wrong.
std::string PrepareOpenMvsColmap(const std::filesystem::path& model,
                                 const std::vector<std::filesystem::path>& image_dirs,
                                 const std::filesystem::path& out, int keyframe_every = 1);

// Rewrites the mesh at `in` (any format host/eval reads) as a binary PLY of float x y z and
// "vertex_indices" faces, the only face property name OpenMVS's PLY reader knows (imr's PLY,
// written by assimp, names it "vertex_index"). Throws std::runtime_error.
void WriteOpenMvsPly(const std::filesystem::path& in, const std::filesystem::path& out);

struct OpenMvsResult {
  bool ok = false;
  std::string error;              // why not, naming the log to read
  double interface_seconds = 0.0;  // InterfaceCOLMAP
  double refine_seconds = 0.0;     // RefineMesh
  double peak_rss_mb = 0.0;        // the larger of the two processes' peak resident sets
  std::filesystem::path mesh;      // <work>/refined.ply when ok
  std::string refine_command;      // RefineMesh's command line, as run (for the report)
};

// InterfaceCOLMAP on `work` (prepared by PrepareOpenMvsColmap) -> scene.mvs, then RefineMesh
// scene.mvs --mesh-file `mesh` (a PLY from WriteOpenMvsPly) -o refined.mvs with `extra_args`
// (e.g. --resolution-level 1), both in `work`, their output in work/openmvs.log. Never throws.
OpenMvsResult RunOpenMvs(const std::filesystem::path& bin_dir, const std::filesystem::path& work,
                         const std::filesystem::path& mesh,
                         const std::vector<std::string>& extra_args,
                         double timeout_seconds = 7200.0);

// The whole pipeline's settings. Image resolution is what its time follows: the KITTI raw
// sample's 78 frames took about 50 min of depth maps at full resolution and 8.4 min at half on 2
// cores, so the default is half, on the keyframes only.
struct OpenMvsPipelineOptions {
  int resolution_level = 1;   // DensifyPointCloud and RefineMesh: images halved this many times
  // Their --min-resolution: OpenMVS's 640 would keep a 1242 px KITTI image whole at level 1.
  int min_resolution = 320;
  // DensifyPointCloud --tower-mode 0: its default (4) may add a cylinder of points assuming the
  // scene is z-up, which a street seen by a car (y down) is not.
  bool no_tower = true;
  std::vector<std::string> densify_args, reconstruct_args, refine_args;  // appended as given
  double timeout_seconds = 7200.0;  // per step

  // "" when usable, else which field and why.
  std::string Check() const;
  // One line: the settings as they will be passed (for the bench's output).
  std::string Describe() const;
};

struct OpenMvsPipelineResult {
  struct Step {
    std::string name;          // InterfaceCOLMAP, DensifyPointCloud, ReconstructMesh, RefineMesh
    double seconds = 0.0;
    double peak_rss_mb = 0.0;  // the step's own process (wait4's rusage)
    std::string command;       // as run
  };
  bool ok = false;
  std::string error;               // why not, naming the step and the log to read
  std::vector<Step> steps;         // those that ran
  std::filesystem::path mesh;      // <work>/refined.ply when ok
  double Seconds() const;          // summed over the steps
  double PeakRssMb() const;        // the largest step's
};

// The four steps in `work` (prepared by PrepareOpenMvsColmap), each `nice -n 10`, their output in
// work/openmvs-pipeline.log: scene.mvs, dense.mvs (+ dense.ply), mesh.ply, then RefineMesh on
// dense.mvs with --mesh-file mesh.ply -> refined.ply. Stops at the first step that fails or
// writes nothing. Never throws.
OpenMvsPipelineResult RunOpenMvsPipeline(const std::filesystem::path& bin_dir,
                                         const std::filesystem::path& work,
                                         const OpenMvsPipelineOptions& options);

}  // namespace imr::bench
