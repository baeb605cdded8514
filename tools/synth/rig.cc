#include "tools/synth/rig.h"

#include <cstdio>

namespace imr::synth {
namespace {

// KITTI odometry sequence 00 (calib.txt), 1242 x 376 images (375 after rectification crop).
constexpr double kFx = 718.856, kCx = 607.1928, kCy = 185.2157;
constexpr std::array<std::array<double, 3>, 4> kPt = {{
    {0.0, 0.0, 0.0},
    {-386.1448, 0.0, 0.0},
    {45.38225, -0.1130887, 0.003779761},
    {-337.2877, 2.369057, 0.004915215},
}};

// Velodyne -> camera 0: axes (x fwd, y left, z up) -> (x right, y down, z fwd), origin 0.27 m
// behind and 0.08 m above camera 0.
constexpr Mat34 kVeloToCam = {{
    {0.0, -1.0, 0.0, 0.0},
    {0.0, 0.0, -1.0, -0.08},
    {1.0, 0.0, 0.0, -0.27},
}};

double Clean(double v) { return v + 0.0; }  // No "-0" in text files.

void AppendNumbers(std::string* out, const Mat34& m, const char* fmt) {
  char buf[64];
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 4; ++c) {
      std::snprintf(buf, sizeof buf, fmt, Clean(m[r][c]));
      if (r + c > 0) out->push_back(' ');
      out->append(buf);
    }
}

}  // namespace

Rig Rig::Kitti(int width, int height) {
  Rig rig;
  const double sx = width / 1242.0, sy = height / 375.0;
  rig.camera.width = width;
  rig.camera.height = height;
  rig.camera.fx = kFx * sx;
  rig.camera.fy = kFx * sy;
  rig.camera.cx = kCx * sx;
  rig.camera.cy = kCy * sy;
  for (int i = 0; i < 4; ++i) {
    Mat34& P = rig.P[static_cast<size_t>(i)];
    P = {{{rig.camera.fx, 0.0, rig.camera.cx, kPt[static_cast<size_t>(i)][0] * sx},
          {0.0, rig.camera.fy, rig.camera.cy, kPt[static_cast<size_t>(i)][1] * sy},
          {0.0, 0.0, 1.0, kPt[static_cast<size_t>(i)][2]}}};
  }
  rig.velo_to_cam = kVeloToCam;
  return rig;
}

Vec3 Rig::CameraOffset(int i) const {
  const Mat34& m = P[static_cast<size_t>(i)];
  const double tz = m[2][3];
  const double ty = (m[1][3] - camera.cy * tz) / camera.fy;
  const double tx = (m[0][3] - camera.cx * tz) / camera.fx;
  return {-tx, -ty, -tz};
}

Mat44 WorldFromScene(const Vec3& c0) {
  const Vec3 t = CameraFromScene(c0);
  return {{{1.0, 0.0, 0.0, Clean(-t[0])},
           {0.0, 0.0, -1.0, Clean(-t[1])},
           {0.0, 1.0, 0.0, Clean(-t[2])},
           {0.0, 0.0, 0.0, 1.0}}};
}

Mat34 CameraPose(const Vec3& c, const Vec3& c0) {
  // Every camera has the same orientation, so the pose is a pure translation.
  const Vec3 t = CameraFromScene(synthetic::Sub(c, c0));
  return {{{1.0, 0.0, 0.0, t[0]}, {0.0, 1.0, 0.0, t[1]}, {0.0, 0.0, 1.0, t[2]}}};
}

Vec3 VelodyneOrigin(const Rig& rig, const Vec3& c) {
  const Mat34& T = rig.velo_to_cam;
  return synthetic::Add(c, SceneFromCamera({T[0][3], T[1][3], T[2][3]}));
}

Vec3 SceneFromVelodyne(const Rig& rig, const Vec3& d) {
  const Mat34& T = rig.velo_to_cam;
  Vec3 cam{};
  for (int r = 0; r < 3; ++r) cam[r] = T[r][0] * d[0] + T[r][1] * d[1] + T[r][2] * d[2];
  return SceneFromCamera(cam);
}

std::string CalibText(const Rig& rig) {
  std::string out;
  for (int i = 0; i < 4; ++i) {
    out += "P" + std::to_string(i) + ": ";
    AppendNumbers(&out, rig.P[static_cast<size_t>(i)], "%.12e");
    out += "\n";
  }
  out += "Tr: ";
  AppendNumbers(&out, rig.velo_to_cam, "%.12e");
  out += "\n";
  return out;
}

std::string PoseLine(const Mat34& pose) {
  std::string out;
  AppendNumbers(&out, pose, "%e");
  out += "\n";
  return out;
}

std::string TimeLine(double seconds) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%e\n", Clean(seconds));
  return buf;
}

}  // namespace imr::synth
