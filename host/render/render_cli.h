// `imr render`: a mesh drawn into one frame's camera over its image (shaded, wireframe or both),
// or seen from above with the camera path — for looking at a result without a 3D viewer.
//
//   imr render MESH --sequence DIR --format kitti_odometry|kitti_raw|middlebury [--camera K]
//              [--frames FIRST[:COUNT[:STEP]]] --frame N [--mode shaded|wireframe|both]
//              [--opacity A] [--no-image] --out out.png
//   imr render MESH --top-down [--sequence DIR --format F ...] [--keyframe-every N]
//              [--size PX] [--up X,Y,Z] [--mode ...] --out top.png
//
// MESH: any format host/eval/mesh_io.h reads (.obj, .ply, .gltf, .glb). The sequence is read
// with host/io's readers (image_sequence.h), so pixels and poses follow the convention there.
#pragma once

namespace imr::render {

// The command's entry point, as main() would be: argv[0] is the command's name (e.g. "render")
// and is ignored; the options follow. Prints what it wrote to stdout and problems to stderr.
// Returns 0 written, 1 failed (a missing or bad file: the message names it), 2 bad usage
// (also prints the usage). --help prints the usage and returns 0. Never throws.
int RenderMain(int argc, char** argv);

}  // namespace imr::render
