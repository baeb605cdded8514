#include "host/io/update_check.h"

#include "host/io/camera_model.h"

#include <sstream>

namespace imr::io {

std::string PointNotInStream(uint64_t id, int64_t keyframe) {
  return "point " + std::to_string(id) + " is not in the stream at keyframe " + std::to_string(keyframe);
}

std::string ObservedAfterRemoval(uint64_t id) {
  return "point " + std::to_string(id) + " is observed after it was removed";
}

namespace {

// "x" / "y" / "z": which coordinate of a position is out of bounds, or "".
std::string PositionProblem(const Vec3& x) {
  static const char* const kAxis[] = {"x", "y", "z"};
  for (int i = 0; i < 3; ++i)
    if (const std::string p = CoordinateProblem(x[i]); !p.empty()) return std::string(kAxis[i]) + ": " + p;
  return {};
}

}  // namespace

std::string CameraProblem(engine::Camera* c) {
  const std::string name = "camera " + std::to_string(c->id) + ": ";
  if (const std::string p = PositionProblem(c->center); !p.empty()) return name + "center " + p;
  Mat3 r;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) r[i][j] = c->rotation[3 * i + j];
  if (const std::string p = CheckRotation(&r); !p.empty()) return name + "the rotation " + p;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) c->rotation[3 * i + j] = r[i][j];
  const auto& k = c->intrinsics;
  const bool unknown = k[0] == 0.0 && k[1] == 0.0 && k[2] == 0.0 && k[3] == 0.0;
  if (!unknown)
    if (const std::string p = IntrinsicsProblem(k[0], k[1], k[2], k[3]); !p.empty())
      return name + "intrinsics: " + p;
  return {};
}

std::string UpdateCheck::Check(engine::KeyframeUpdate* u, int64_t keyframe) {
  for (engine::Camera& c : u->cameras)
    if (std::string p = CameraProblem(&c); !p.empty()) return p;
  std::unordered_set<uint64_t> added, gone;
  for (const engine::NewPoint& p : u->new_points) {
    const std::string what = "new_points: point " + std::to_string(p.id);
    if (const std::string x = PositionProblem(p.position); !x.empty()) return what + ": " + x;
    if (const auto it = removed_.find(p.id); it != removed_.end())
      return what + " uses the id of a point removed at keyframe " + std::to_string(it->second) +
             ": ids must not be reused";
    if (live_.count(p.id) || !added.insert(p.id).second) return what + " uses an id that is already known";
  }
  for (uint64_t id : u->removed_points) {
    if (!live_.count(id) || !gone.insert(id).second)
      return "removed_points: " + PointNotInStream(id, keyframe);
  }
  for (const engine::MovedPoint& p : u->moved_points) {
    const std::string what = "moved_points: point " + std::to_string(p.id);
    if (const std::string x = PositionProblem(p.position); !x.empty()) return what + ": " + x;
    if (removed_.count(p.id) || gone.count(p.id)) return "moved_points: " + ObservedAfterRemoval(p.id);
    if (!live_.count(p.id)) return "moved_points: " + PointNotInStream(p.id, keyframe);
  }
  for (uint64_t id : added) live_.insert(id);
  for (uint64_t id : gone) {
    live_.erase(id);
    removed_.emplace(id, keyframe);
  }
  return {};
}

}  // namespace imr::io
