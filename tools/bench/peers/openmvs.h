// OpenMVS's RefineMesh (Vu et al.'s photometric mesh refinement) as a peer of imr's own
// refinement (issue 34), for `imr-bench quality --openmvs BIN_DIR`: the same unrefined mesh and
// the same images, refined by OpenMVS, scored by the same code. OpenMVS is AGPL: it is built
// outside the repository by tools/bench/peers/build_openmvs.sh and only run as separate
// processes (InterfaceCOLMAP, RefineMesh); none of its code is here.
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

}  // namespace imr::bench
