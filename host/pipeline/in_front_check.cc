#include "host/pipeline/in_front_check.h"

#include <cstdio>
#include <stdexcept>

namespace imr::pipeline {

void InFrontCheck::Add(const engine::KeyframeUpdate& update, const io::KeyframeSource& source) {
  for (const engine::NewPoint& p : update.new_points)
    for (uint64_t id : p.camera_ids) {
      const io::CameraGeometry* g = source.Camera(id);
      if (g == nullptr) continue;
      const io::Mat3& r = g->rotation;
      const double depth = r[2][0] * (p.position[0] - g->center[0]) +
                           r[2][1] * (p.position[1] - g->center[1]) +
                           r[2][2] * (p.position[2] - g->center[2]);
      ++checked_;
      if (depth > 0.0) continue;
      if (++behind_ == 1) {
        char b[240];
        std::snprintf(b, sizeof(b),
                      "point %llu at (%g, %g, %g) is %g behind camera %llu at (%g, %g, %g)",
                      static_cast<unsigned long long>(p.id), p.position[0], p.position[1],
                      p.position[2], -depth, static_cast<unsigned long long>(id), g->center[0],
                      g->center[1], g->center[2]);
        first_behind_ = b;
      }
    }
  if (checked_ >= 100 && 2 * behind_ > checked_) throw std::runtime_error(Message());
}

std::string InFrontCheck::Message() const {
  char share[32];
  std::snprintf(share, sizeof(share), "%.1f %%", 100.0 * static_cast<double>(behind_) /
                                                    static_cast<double>(checked_));
  return std::to_string(behind_) + " of " + std::to_string(checked_) +
         " observations of new points (" + share + ") put the point behind the camera that sees "
         "it (first: " + first_behind_ + "): are the points mirrored, or the rotations camera -> "
         "world where world -> camera is expected?";
}

}  // namespace imr::pipeline
