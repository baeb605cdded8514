// New points seen from behind the cameras that see them: a mirrored stream, or rotations the
// wrong way round, would mesh "ok" in the wrong place. The run of a sequence (run.cc) and the
// Python module's engine (host/python) count them the same way and fail with the same message.
#pragma once

#include "host/engine/engine.h"
#include "host/io/keyframe_source.h"

#include <cstdint>
#include <string>

namespace imr::pipeline {

class InFrontCheck {
 public:
  // Counts the observations of the update's new points that put the point behind its camera
  // (depth <= 0 in the camera's frame, for cameras whose rotation `source` knows). Once 100 are
  // counted, most of them behind throws std::runtime_error(Message()).
  void Add(const engine::KeyframeUpdate& update, const io::KeyframeSource& source);
  int64_t checked() const { return checked_; }
  int64_t behind() const { return behind_; }
  // How many of how many, the first one, and what is likely wrong.
  std::string Message() const;

 private:
  int64_t checked_ = 0, behind_ = 0;
  std::string first_behind_;
};

}  // namespace imr::pipeline
