// Test and benchmark support: a synthetic keyframe as an engine update.
#pragma once

#include "host/engine/engine.h"
#include "host/synthetic/stream.h"

namespace imr::engine::testing {

inline KeyframeUpdate ToUpdate(const synthetic::StreamKeyframe& kf) {
  KeyframeUpdate u;
  for (const auto& c : kf.cameras) u.cameras.push_back({c.id, c.center});
  for (const auto& p : kf.new_points) u.new_points.push_back({p.id, p.position, p.camera_ids});
  for (const auto& p : kf.moved_points) u.moved_points.push_back({p.id, p.position, p.camera_ids});
  u.removed_points = kf.removed_points;
  return u;
}

}  // namespace imr::engine::testing
