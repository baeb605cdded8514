// A synthetic observation stream over a known Scene: cameras driving through it (KITTI-like: about
// 1 m per frame, a keyframe every 5 frames), 3D points sampled on the surfaces the cameras see, and
// point estimates that start noisy and converge as observations accumulate, so points move at
// keyframes. Deterministic by seed. It needs no images and knows nothing of the engine: its
// keyframes are plain structs that a caller maps to the engine's update.
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
  explicit SyntheticStream(const StreamOptions& options);
  ~SyntheticStream();

  // Fills the next keyframe; false at the end of the sequence.
  bool Next(StreamKeyframe* keyframe);

  const Scene& scene() const;
  const StreamOptions& options() const;
  int keyframe_count() const;
  // The true position of a point emitted so far.
  Vec3 TruePosition(uint64_t point_id) const;
  // Camera centre of a frame (any frame of the sequence).
  Vec3 CameraCenter(int frame) const;
  // Viewing direction of a frame's camera (unit).
  Vec3 CameraForward(int frame) const;
  // True when the camera of `frame` sees x: within max_range, inside its field of view and not
  // hidden by the scene. Benchmarks sample ground truth with it (what the cameras saw).
  bool Sees(int frame, const Vec3& x) const;
  // True positions of every point emitted so far (for completeness measures).
  std::vector<Vec3> TruePoints() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace imr::synthetic
