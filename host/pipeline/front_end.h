// The image front end (docs/user-guide.md, Image sequences): an image sequence with known poses, driven frame by frame
// through a features plugin (2D tracks) and a refiner plugin (3D points), becomes the engine's
// keyframe updates. It is a KeyframeSource like the SfM readers, so the pipeline downstream does
// not know whether points came from images or from a file.
//
// Frame k is a keyframe when k % keyframe_every == 0, and the last frame is one too, so every
// frame's camera reaches the engine. Both plugins see the same is_keyframe; camera ids are the
// frame indices (strictly increasing). Plugin output views are used before the plugin's next call.
#pragma once

#include "host/eval/synthetic_truth.h"
#include "host/io/image_io.h"
#include "host/io/image_sequence.h"
#include "host/io/keyframe_source.h"
#include "host/pipeline/point_error_summary.h"
#include "host/pipeline/prefetch.h"
#include "host/pipeline/stage_watch.h"

#include <imr/sdk/host.hpp>
#include <nlohmann/json.hpp>

#include <future>
#include <memory>
#include <optional>
#include <string>
#include <unordered_map>
#include <vector>

namespace imr::synthetic {
struct MeshAccuracy;
}

namespace imr::pipeline {

// Keyframes `frames` frames make at `keyframe_every` (every k-th from frame 0, and the last).
int KeyframeCount(int frames, int keyframe_every);
// The fewest keyframes a job that did not choose keyframe_every gets: a short image set (a
// Middlebury ring of 16) at the default would give the engine too few views to mesh.
constexpr int kMinKeyframes = 12;
// keyframe_every, lowered while it gives fewer than kMinKeyframes keyframes (never below 1).
int ShortSequenceKeyframeEvery(int frames, int keyframe_every);

struct FrontEndOptions {
  int keyframe_every = 5;  // a keyframe every this many frames (paper: 5)
  // Ground-truth evaluation of synthetic sequences: true surface samples are taken by casting
  // rays from every keyframe's camera on a grid of this many pixels, up to truth_range metres.
  int truth_pixel_step = 16;
  double truth_range = 30.0;
  double tau = 0.2;  // metres: a mesh or true point within tau counts as precise / complete
  // Three threads instead of one (run.cc sets it with the overlap, on 2 cores or more): frame
  // k + 2's image is decoded and frame k + 1 is tracked by the features plugin while the refiner
  // plugin takes frame k. What each plugin gets, and in which order, is the same.
  bool track_ahead = false;

  // Empty when usable, else which field and why.
  std::string Check() const;
};

// Per-stage time and counts over a sequence.
struct FrontEndStats {
  int frames = 0;
  int keyframes = 0;
  double read_seconds = 0.0;      // image decoding
  double features_seconds = 0.0;  // the features plugin
  double refiner_seconds = 0.0;   // the refiner plugin
  int64_t observations = 0;       // track observations over all frames
  int64_t new_points = 0;
  int64_t moved_points = 0;
  int64_t removed_points = 0;
  // Tracks seen in a keyframe that are still seen keyframe_every frames later (the next
  // keyframe), summed over keyframe intervals; their ratio is the track survival.
  // The dense stage (when the job has one): its time and points.
  double dense_seconds = 0.0;
  int64_t dense_new_points = 0;
  int64_t dense_removed_points = 0;
  int64_t tracks_at_keyframes = 0;
  int64_t tracks_surviving_interval = 0;
};

// A synthetic sequence's ground truth (imr-synth's ground_truth/scene.json; host/eval).
using eval::ReadSyntheticTruth;
using eval::SyntheticTruth;

// A camera as plugins see it (imr_camera): K from the intrinsics (all zero when unknown or not
// a pinhole the host can project), R and t, the image size given.
imr_camera ToPluginCamera(const io::CameraGeometry& g, int width, int height);

class ImageFrontEndSource : public io::KeyframeSource {
 public:
  // The instances must outlive the source.
  ImageFrontEndSource(io::ImageSequence sequence, const imr::sdk::Instance& features,
                      const imr::sdk::Instance& refiner, const FrontEndOptions& options);
  ~ImageFrontEndSource() override;

  bool Next(engine::KeyframeUpdate* update, io::KeyframeInfo* info) override;
  int KeyframeCount() const override;
  nlohmann::json Evaluate(const engine::Mesh& mesh) const override;
  bool CanEvaluate() const override { return truth_ != nullptr; }
  // Evaluate's figures from a mesh read in blocks (a forgetting run's spool), bit for bit: holds
  // the true surface samples and a distance each, never the mesh.
  std::unique_ptr<io::BlockEvaluation> EvaluateInBlocks() const override;
  const io::CameraGeometry* Camera(uint64_t camera_id) const override;
  nlohmann::json Summary() const override;

  // Every call into the two plugins becomes a watched call of its stage (the stages must
  // outlive the source); without this, calls are not watched.
  void Watch(StageWatch* watch, const WatchedStage* features, const WatchedStage* refiner) {
    watch_ = watch;
    watch_features_ = features;
    watch_refiner_ = refiner;
  }

  // A dense stage (optional; must outlive the source): called per frame after the refiner,
  // with the frame's image; its points join the refiner's in the same update, their ids moved
  // to [kDenseIdBase, 2 kDenseIdBase) so that the two plugins' ids never meet (2^23: both fit the
  // 24-bit point-id channel of glTF exports).
  void SetDense(const imr::sdk::Instance* dense, const WatchedStage* stage) {
    dense_ = dense;
    watch_dense_ = stage;
  }
  static constexpr uint64_t kDenseIdBase = uint64_t{1} << 23;

  // With track_ahead, the features plugin's calls run on `lane` (where its instance was made and
  // is destroyed: one thread per instance, as the SDK promises); must outlive the source.
  void TrackOn(Lane* lane) { track_lane_ = lane; }

  const FrontEndStats& stats() const { return stats_; }
  const io::ImageSequence& sequence() const { return sequence_; }

 private:
  // A frame through the reader and the features plugin, for the refiner.
  struct TrackedFrame {
    std::size_t index = 0;
    bool keyframe = false;
    imr_camera camera{};
    std::vector<imr_track_observation> tracks;  // a copy of the plugin's view
    io::Image image;  // kept for the dense stage, when there is one
    double read_seconds = 0.0, features_seconds = 0.0;
  };
  bool IsKeyframe(int frame) const;
  // The next frame not yet tracked; false after the last. Runs on the tracking thread with
  // track_ahead, which alone touches tracked_frames_, width_, height_ and ahead_ until it ends.
  bool TrackFrame(TrackedFrame* out);
  // Frame `index`'s image and the seconds its decoding took (the read-ahead's when it has it).
  std::pair<io::Image, double> ReadFrame(std::size_t index);
  std::optional<StageWatch::Call> Watched(const WatchedStage* stage);
  void TrackPointError(uint64_t id, const io::Vec3& position, bool is_new);
  // The frame to the dense stage; on a keyframe its points into `update`.
  void AddDensePoints(const TrackedFrame& tracked, engine::KeyframeUpdate* update);
  // Synthetic truth only: the true surface samples the keyframes so far saw (scene frame), and
  // the report's accuracy object from the figures over them.
  std::vector<io::Vec3> TruthSamples() const;
  nlohmann::json AccuracyJson(const synthetic::MeshAccuracy& a, std::size_t samples) const;

  io::ImageSequence sequence_;
  const imr::sdk::Instance& features_;
  const imr::sdk::Instance& refiner_;
  FrontEndOptions options_;
  StageWatch* watch_ = nullptr;
  const WatchedStage* watch_features_ = nullptr;
  const WatchedStage* watch_refiner_ = nullptr;
  const imr::sdk::Instance* dense_ = nullptr;
  const WatchedStage* watch_dense_ = nullptr;
  Lane* track_lane_ = nullptr;
  FrontEndStats stats_;
  std::size_t next_frame_ = 0;     // frames through the refiner
  std::size_t tracked_frames_ = 0;  // frames through the features plugin
  int next_keyframe_ = 0;
  int width_ = 0, height_ = 0;
  std::future<std::pair<io::Image, double>> ahead_;  // frame ahead_frame_'s, being read
  std::size_t ahead_frame_ = 0;
  std::vector<uint64_t> keyframe_tracks_;  // sorted track ids seen at the last keyframe
  std::unique_ptr<SyntheticTruth> truth_;
  // Synthetic truth only: distance to the true surface of each point's first and latest
  // estimate, held while the refiner moves the point (point_error_summary.h).
  PointErrorSummary point_errors_;
  DistanceSample dense_errors_;  // synthetic truth only: the dense points' distances to it
  // track_ahead: TrackFrame on a thread of its own; declared last, so that its thread is joined
  // before anything it uses goes.
  std::unique_ptr<Prefetcher<TrackedFrame>> tracker_;
};

}  // namespace imr::pipeline
