// `imr render`'s work, as a library call: a mesh file drawn into one frame's camera over its
// image (shaded, wireframe or both), or seen from above with the camera path, written as a PNG —
// for looking at a result without a 3D viewer. The command line lives in host/cli.
//
// The mesh: any format host/eval/mesh_io.h reads (.obj, .ply, .gltf, .glb). The sequence is read
// with host/io's readers (image_sequence.h), so pixels and poses follow the convention there.
#pragma once

#include "host/io/image_sequence.h"
#include "host/render/rasterizer.h"

#include <filesystem>
#include <stdexcept>
#include <string>

namespace imr::render {

struct RenderFilesRequest {
  std::string mesh;                      // the mesh file
  std::string sequence;                  // the sequence (folder or file); empty: none
  std::string format;                    // kitti_odometry, kitti_raw, middlebury or slam_json
  io::ImageSequenceOptions sequence_options;  // frames and camera of the sequence
  bool top_down = false;                 // from above with the camera path, else into `frame`
  int frame = 0;                         // the frame to draw into (after the frame selection)
  bool no_image = false;                 // draw on black (implied by slam_json)
  RenderOptions render;                  // into a frame
  TopDownOptions top_down_options;       // from above
  int keyframe_every = 5;                // top-down: mark every n-th frame (0: none)
  std::filesystem::path out;             // the PNG, written whole or not at all
};

// The formats RenderFiles reads a sequence in.
inline const char* const kRenderSequenceFormats[] = {"kitti_odometry", "kitti_raw", "middlebury",
                                                     "slam_json", "colmap", "openmvg"};

// Thrown when the request's frame is not in the sequence: the caller's mistake, not a file's.
struct FrameOutOfRange : std::invalid_argument {
  using std::invalid_argument::invalid_argument;
};

// Reads, draws and writes; returns one line saying what was written. Throws FrameOutOfRange, or
// std::runtime_error naming the file that is missing or bad.
std::string RenderFiles(const RenderFilesRequest& request);

}  // namespace imr::render
