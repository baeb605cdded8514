// A synthetic observation stream over a known Scene: cameras driving through it (KITTI-like: about
// 1 m per frame, a keyframe every 5 frames), 3D points sampled on the surfaces the cameras see, and
// point estimates that start noisy and converge as observations accumulate, so points move at
// keyframes. Deterministic by seed. It needs no images and knows nothing of the engine: its
// keyframes are plain structs that a caller maps to the engine's update.
//
// Two observation models (StreamOptions::track_frames):
// - block (0, the original): each keyframe samples new points in its camera's view, observed by
//   the frames of that keyframe's block only, refined for refine_keyframes keyframes.
// - tracked (> 0): a SLAM front end's stream, shaped like ../shared/data/street-stream. A point of
//   the surface starts a track in the frame that first sees it (features at track_density per m^2
//   of visible surface); every frame observes its tracks that it still sees (range, field of view,
//   not occluded) until a track has track_frames observations or is lost. A track is reported from
//   its min_observations-th observation as a new point (its observing frames), then at each
//   keyframe as a moved point (the frames that observed it since). Its estimate after k
//   observations is the truth plus the mean of k error draws, one per observation, each along
//   that observation's viewing ray (sigma noise_at_10m * (depth / 10 m)^2) plus angular_noise
//   across it: points move while tracked and converge. Only the active tracks are kept (and,
//   with keep_truth, every reported point's true position), so memory does not grow with the
//   drive.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "host/synthetic/scene.h"

namespace imr::synthetic {

enum class SceneKind { kStreet, kRoom, kPlane };
std::string ToString(SceneKind kind);
bool FromString(const std::string& s, SceneKind* kind);

// The street camera path (SceneKind::kStreet), shared with the image renderer (tools/synth) so
// that rendered sequences and observation streams drive through the same scene: the camera centre
// of frame `frame` sways 0.6 m sideways around the street axis, advances `speed` metres per frame
// along +y and stays 1.65 m above the ground (KITTI's camera height); it looks along +y.
Vec3 StreetCameraCenter(int frame, double speed);
// Length of the street canyon built for `frames` frames at `speed` (the path plus 10 m; the scene
// itself reaches 40 m further at both ends, see Scene::StreetCanyon).
double StreetLength(int frames, double speed);

struct StreamOptions {
  SceneKind scene = SceneKind::kStreet;  // Which known scene to drive through.
  uint64_t seed = 1;                     // Everything random derives from this.
  int frames = 1000;                     // Frames in the sequence.
  int keyframe_every = 5;                // A keyframe every this many frames (paper: 5).
  double speed = 1.0;                    // Camera motion per frame, metres (street; room scales it).
  int points_per_keyframe = 150;         // New points sampled on visible surfaces per keyframe.
  double max_range = 30.0;               // Points farther than this from a camera are not seen.
  double hfov_deg = 90.0;                // Horizontal field of view.
  double vfov_deg = 40.0;                // Vertical field of view.
  double noise_at_10m = 0.30;            // Depth error of a first estimate at 10 m (grows with d^2).
  double convergence = 0.5;              // Each refinement multiplies the error by this factor.
  int refine_keyframes = 3;              // Keyframes after insertion during which a point moves.
  double min_move = 1e-3;                // A refinement smaller than this is not reported as a move.
  bool frozen = false;                   // Points stay at their first estimate (gives T_nonmov).
  int min_observations = 2;              // A new point needs this many observing frames.

  // The tracked model (see the top of this file); 0 keeps the block model above, unchanged.
  int track_frames = 0;  // > 0: a track ends after this many observations (or when lost).
  // New tracks per m^2 of surface that comes into view. 2.1 gives ~1,270 observations per frame
  // on the street at 1 m per frame with track_frames 17 and max_range 40 (1,268 over 2,000
  // frames; configs/dense-street.json; ../shared/data/street-stream has ~1,226).
  double track_density = 2.1;
  // Error of one observation across its viewing ray, radians (per axis): 0.002 is 1 px of the
  // 1000-px-wide pinhole the synthetic input exports at hfov 90 degrees.
  double angular_noise = 0.002;
  // Keep the true position of every point reported (TruePoints, TruePosition; the synthetic input's
  // completeness). Off: only the active tracks' (block model: the points still refined), so the
  // generator's memory stays flat on any length of drive.
  bool keep_truth = true;

  // Empty when every field is usable; otherwise which field and why.
  std::string Check() const;
};

// What the stream has generated so far (both models; the track figures in the tracked model).
struct StreamStats {
  int64_t frames = 0;        // Frames generated.
  int64_t keyframes = 0;     // Keyframes handed out.
  int64_t observations = 0;  // Camera ids handed out: new points' cameras + moves' new cameras.
  int64_t new_points = 0;
  int64_t moved_points = 0;  // Moves handed out (a point moves at most once per keyframe).
  int64_t tracks_started = 0;
  int64_t tracks_ended = 0;    // Capped or lost (reported or not).
  int64_t tracks_lost = 0;     // Ended before track_frames observations.
  // lengths[n]: ended tracks that had n observations (index 0 unused).
  std::vector<int64_t> track_lengths;
  size_t active_tracks = 0;      // Tracks now alive (observed in the last frame, or to report).
  size_t max_active_tracks = 0;  // The most at any keyframe.
  size_t kept_truths = 0;        // True positions held (keep_truth, or points still refined).
  double seconds = 0.0;          // Wall time spent in Next.
};

struct StreamCamera {
  uint64_t id = 0;
  Vec3 center{};
  Vec3 forward{};
};

struct StreamPoint {
  uint64_t id = 0;
  Vec3 position{};                  // The current estimate.
  std::vector<uint64_t> camera_ids;  // New point: its observing cameras. Moved: new observations.
};

struct StreamKeyframe {
  int index = 0;  // Keyframe number, from 0.
  int frame = 0;  // Frame number of this keyframe.
  std::vector<StreamCamera> cameras;  // Frames since the previous keyframe (this one included).
  std::vector<StreamPoint> new_points;
  std::vector<StreamPoint> moved_points;
  std::vector<uint64_t> removed_points;
};

class SyntheticStream {
 public:
  // Throws std::invalid_argument with options.Check()'s message when an option is unusable.
  explicit SyntheticStream(const StreamOptions& options);
  ~SyntheticStream();

  // Fills the next keyframe; false at the end of the sequence.
  bool Next(StreamKeyframe* keyframe);

  const Scene& scene() const;
  const StreamOptions& options() const;
  int keyframe_count() const;
  const StreamStats& stats() const;
  // The true position of a point emitted so far: any with keep_truth, else only a point still
  // refined (block model) or tracked (tracked model; a scan of the active tracks). The origin
  // for a point it does not hold.
  Vec3 TruePosition(uint64_t point_id) const;
  // Camera centre of a frame (any frame of the sequence).
  Vec3 CameraCenter(int frame) const;
  // Viewing direction of a frame's camera (unit).
  Vec3 CameraForward(int frame) const;
  // True when the camera of `frame` sees x: within max_range, inside its field of view and not
  // hidden by the scene. Benchmarks sample ground truth with it (what the cameras saw).
  bool Sees(int frame, const Vec3& x) const;
  // True positions of every point emitted so far (for completeness measures); with keep_truth
  // false only those it still holds (see TruePosition).
  std::vector<Vec3> TruePoints() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace imr::synthetic
