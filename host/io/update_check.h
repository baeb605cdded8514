// What every reader checks of the cameras and points it hands the engine, as one check for
// updates that no reader built (the Python module's keyframes, host/python): the same words as
// the readers (camera_model.h's RotationProblem and CoordinateProblem, the SLAM JSON reader's
// ids), so a bad update says the same thing whichever way it came in.
#pragma once

#include "host/engine/engine.h"
#include "host/io/camera_model.h"

#include <cstdint>
#include <string>
#include <unordered_map>
#include <unordered_set>

namespace imr::io {

// The SLAM JSON reader's words for a point named where it is not in the stream (removed twice,
// never entered) and for one named again after its removal.
std::string PointNotInStream(uint64_t id, int64_t keyframe);
std::string ObservedAfterRemoval(uint64_t id);

// Empty when `c` is a camera a reader could have given: a centre within kMaxCoordinate, a
// rotation (re-orthonormalised, as the readers do, within kRotationTolerance) and intrinsics
// all 0 (unknown) or IntrinsicsProblem's; else "camera 3: the rotation is not a rotation: ...".
std::string CameraProblem(engine::Camera* c);

// The readers' checks over a stream of updates: each camera (CameraProblem), each position
// within kMaxCoordinate, and the ids as the caller named them: a new point's id not known or
// removed before, a moved or removed point known and not removed (each removed once).
class UpdateCheck {
 public:
  // Empty when `update` (keyframe `keyframe` of the stream) passes, and then records its ids;
  // else the first problem, e.g. "removed_points: point 5 is not in the stream at keyframe 3",
  // and nothing is recorded. Cameras are re-orthonormalised in place.
  std::string Check(engine::KeyframeUpdate* update, int64_t keyframe);

 private:
  std::unordered_set<uint64_t> live_;              // entered, not removed
  std::unordered_map<uint64_t, int64_t> removed_;  // id -> the keyframe that removed it
};

}  // namespace imr::io
