// Where the engine's per-keyframe updates come from. Each input format opens a KeyframeSource
// for one sequence: the synthetic stream, SfM/SLAM exports (OpenMVG, COLMAP, SLAM JSON) and
// the image front end (host/pipeline/front_end.h, over the features and refiner plugins).
// The pipeline only pulls updates from it, so a new format needs no pipeline change.
#pragma once

#include "host/engine/engine.h"
#include "host/io/camera_model.h"

#include <nlohmann/json.hpp>

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace imr::io {

struct KeyframeInfo {
  int index = 0;  // keyframe number, from 0
  int frame = 0;  // frame (or view) number of this keyframe in the sequence
};

// KeyframeSource::Evaluate over a mesh given in blocks of triangles (a long drive's single mesh,
// read back from disk in blocks): the same JSON as Evaluate with the whole mesh.
class BlockEvaluation {
 public:
  virtual ~BlockEvaluation() = default;
  // The next triangles in the mesh's order: packed xyz, and 3 indices into them per triangle.
  virtual void AddTriangles(const std::vector<double>& vertices, const std::vector<uint32_t>& faces) = 0;
  virtual nlohmann::json Finish() const = 0;
};

class KeyframeSource {
 public:
  virtual ~KeyframeSource() = default;
  // Fills the next update; false at the end of the sequence. Bad input throws
  // std::runtime_error whose message names the file and the field, id or line.
  virtual bool Next(engine::KeyframeUpdate* update, KeyframeInfo* info) = 0;
  // Keyframes in the sequence, or -1 when not known in advance.
  virtual int KeyframeCount() const { return -1; }
  // Accuracy of a mesh against what the source knows to be true (a known scene), as a JSON
  // object for the report; null when the source has no ground truth.
  virtual nlohmann::json Evaluate(const engine::Mesh& mesh) const {
    (void)mesh;
    return nullptr;
  }
  // Whether Evaluate gives anything (it needs the mesh whole: a run that keeps its mesh on disk
  // reads it back for it).
  virtual bool CanEvaluate() const { return false; }
  // Evaluate in blocks, or null when this source needs the mesh whole (or has no ground truth).
  virtual std::unique_ptr<BlockEvaluation> EvaluateInBlocks() const { return nullptr; }
  // What the source knows of a camera beyond its centre (rotation, intrinsics, image name), for
  // the stream and COLMAP exports; null when it knows only the centre.
  virtual const CameraGeometry* Camera(uint64_t camera_id) const {
    (void)camera_id;
    return nullptr;
  }
  // The colour (red, green, blue) the input gives 3D point `point_id`, for exporters of
  // engine-only inputs (COLMAP points3D); false when it gives none.
  virtual bool PointColor(uint64_t point_id, std::array<uint8_t, 3>* rgb) const {
    (void)point_id, (void)rgb;
    return false;
  }
  // Where the input measured point `point_id` in camera `camera_id`'s image (a keypoint: COLMAP
  // points2D, OpenMVG observations' x), in the pixel convention of the camera's intrinsics, for
  // the reprojection errors of the COLMAP export; false when the input gives none.
  virtual bool Keypoint(uint64_t camera_id, uint64_t point_id, std::array<double, 2>* xy) const {
    (void)camera_id, (void)point_id, (void)xy;
    return false;
  }
  // Bytes the source holds for the keyframes it has not handed out yet (input read ahead,
  // per-point state), so that a drive's memory beyond the engine can be told apart; -1 when it
  // does not count them.
  virtual int64_t PendingBytes() const { return -1; }
  // Figures about the input for the report (views, points, observations, what was skipped and
  // why), as a JSON object; null when there is nothing to say.
  virtual nlohmann::json Summary() const { return nullptr; }
};

// A source whose updates are all built up front (SfM exports): subclasses fill
// updates_ and frames_ (one frame number per update); Next hands them out in order, the last
// marked as such (engine::KeyframeUpdate::last: no ray lists are kept for it).
class PrecomputedKeyframeSource : public KeyframeSource {
 public:
  bool Next(engine::KeyframeUpdate* u, KeyframeInfo* info) override {
    if (next_ >= updates_.size()) return false;
    *u = std::move(updates_[next_]);
    *info = {static_cast<int>(next_), frames_[next_]};
    ++next_;
    u->last = next_ == updates_.size();
    return true;
  }
  int KeyframeCount() const override { return static_cast<int>(updates_.size()); }

 protected:
  std::vector<engine::KeyframeUpdate> updates_;
  std::vector<int> frames_;

 private:
  std::size_t next_ = 0;
};

}  // namespace imr::io
