// The refiner's tests' camera: KITTI-sized, looking down +z, one metre forward a frame.
#pragma once

#include <imr/sdk/plugin.h>

#include <algorithm>
#include <cstdint>

namespace imr::ceres_refiner::testing {

constexpr double kFx = 718.856, kCx = 607.1928, kCy = 185.2157;
constexpr int kWidth = 1242, kHeight = 375;

// Frame `frame`'s camera: identity rotation, centre (0, 0, frame).
inline imr_camera CameraAt(uint64_t frame) {
  imr_camera c{};
  c.id = frame;
  const double K[9] = {kFx, 0, kCx, 0, kFx, kCy, 0, 0, 1};
  const double R[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  std::copy(K, K + 9, c.K);
  std::copy(R, R + 9, c.R);
  c.t[2] = -static_cast<double>(frame);
  c.width = kWidth;
  c.height = kHeight;
  return c;
}

}  // namespace imr::ceres_refiner::testing
