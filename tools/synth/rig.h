// The KITTI odometry rig the synthetic sequences imitate (sequence 00 calibration), and how it
// sits in the street scene. Frames:
//   scene:    the analytic Scene's frame (host/synthetic), z up, the street along +y;
//   camera i: KITTI's rectified camera frame, x right, y down, z forward. All four cameras share
//             one orientation: x = scene +x, y = scene -z, z = scene +y (looking along the street);
//   velodyne: x forward, y left, z up, 0.27 m behind and 0.08 m above camera 0 (1.73 m above
//             the ground when camera 0 is at 1.65 m);
//   world:    the poses file's frame = camera 0 at frame 0 (KITTI odometry convention).
#pragma once

#include <array>
#include <string>

#include "host/synthetic/scene.h"

namespace imr::synth {

using synthetic::Vec3;
using Mat34 = std::array<std::array<double, 4>, 3>;  // Row-major [R | t].
using Mat44 = std::array<std::array<double, 4>, 4>;

// Pinhole intrinsics; pixel centres at integer coordinates, (0, 0) = centre of the top-left pixel.
struct Intrinsics {
  int width = 1242;
  int height = 375;
  double fx = 718.856, fy = 718.856, cx = 607.1928, cy = 185.2157;
};

struct Rig {
  Intrinsics camera;         // Shared by the four rectified cameras.
  std::array<Mat34, 4> P{};  // Projection matrices P0..P3 (camera i <- camera-0 coordinates).
  Mat34 velo_to_cam{};       // Tr: velodyne -> camera 0.

  // KITTI odometry sequence 00 at 1242 x 375, scaled to width x height (rows 0 and 1 of every P
  // scale with the image, so cameras keep their positions).
  static Rig Kitti(int width, int height);

  // Centre of camera i in camera-0 coordinates (-K^-1 times P_i's last column).
  Vec3 CameraOffset(int i) const;
};

// Directions and points between the camera and scene frames (rotation only).
inline Vec3 SceneFromCamera(const Vec3& c) { return {c[0], c[2], -c[1]}; }
inline Vec3 CameraFromScene(const Vec3& s) { return {s[0], -s[2], s[1]}; }

// Maps scene coordinates into the poses' world frame (camera 0 at frame 0 centred at c0).
Mat44 WorldFromScene(const Vec3& c0);
// Pose of camera 0 at a frame whose centre is c (scene), in the poses' world frame: camera ->
// world, as in a KITTI poses file.
Mat34 CameraPose(const Vec3& c, const Vec3& c0);
// Velodyne origin and axes in the scene for camera-0 centre c.
Vec3 VelodyneOrigin(const Rig& rig, const Vec3& c);
Vec3 SceneFromVelodyne(const Rig& rig, const Vec3& dir);  // Rotation only.

// KITTI text formats.
std::string CalibText(const Rig& rig);    // calib.txt: P0..P3, Tr ("%.12e").
std::string PoseLine(const Mat34& pose);  // One poses.txt line ("%e").
std::string TimeLine(double seconds);     // One times.txt line ("%e").

}  // namespace imr::synth
