// Incremental sparse point cloud from 2D tracks and known cameras (paper section 2.1; docs/user-guide.md,
// Image sequences). Every frame's observations are stored per track; at each keyframe, tracks with new
// observations are triangulated (DLT, once they are seen in enough keyframes with enough
// parallax) and refined (Ceres, reprojection error, poses fixed), outliers are dropped, and the
// changes since the previous keyframe are reported: new, moved and removed points.
#pragma once

#include <imr/sdk/plugin.hpp>

#include <Eigen/Core>
#include <cstdint>
#include <map>
#include <span>
#include <string>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include "triangulation.hpp"

namespace imr::ceres_refiner {

struct RefinerOptions {
  int min_keyframes = 2;                // Keyframes that must see a track before it is triangulated.
  int min_views = 2;                    // Observations (frames) of it, at least.
  double min_parallax_deg = 1.0;        // Largest angle between its rays, degrees, at least.
  double huber_px = 1.0;                // Huber loss scale of the refinement, pixels (0: none).
  int max_iterations = 10;              // Ceres iterations per point and keyframe, at most.
  double max_reprojection_error = 2.0;  // Pixels; observations beyond are outliers.
  double min_inlier_ratio = 0.5;        // A point keeps at least this share of its observations.
  double min_depth = 0.1;               // Cheirality: depth in every observing camera, at least.
  double max_distance = 100.0;          // Too far: distance to the nearest observing camera.
  double min_move = 0.01;               // A refinement moving less is not reported as a move.

  // Empty when usable, else which field and why.
  std::string Check() const;
};

// Ids of tracks that ended, as runs of consecutive ids: a tracker numbers its tracks in order
// (edge_klt does) and most of them end within a few frames of their neighbours, so the runs merge
// and what is held follows the live tracks, not the drive (a set of every id grew by a record per
// ended track: ~5 MB over 1,500 imr-synth frames).
class IdRuns {
 public:
  void Add(uint64_t id);
  bool Contains(uint64_t id) const;
  bool empty() const { return runs_.empty(); }
  std::size_t runs() const { return runs_.size(); }

 private:
  std::map<uint64_t, uint64_t> runs_;  // first id -> last id of each run
};

// What one keyframe changed (the SDK's type, handed to the host as it is).
using RefinerUpdate = imr::sdk::RefinerUpdate;

class PointRefiner {
 public:
  explicit PointRefiner(const RefinerOptions& options) : options_(options) {}

  // Stores the frame's camera and observations; on keyframes fills `update` (cleared first).
  // Throws imr::sdk::InvalidArgument on bad cameras or observations.
  void AddFrame(const imr_camera& camera, std::span<const imr_track_observation> observations,
                bool is_keyframe, RefinerUpdate* update);

  std::size_t live_track_count() const { return tracks_.size(); }
  // What it holds between frames, in records: live tracks, cameras, runs of ended ids.
  std::size_t held_records() const { return tracks_.size() + cameras_.size() + ended_.runs(); }

 private:
  struct Observation {
    uint64_t camera = 0;
    Eigen::Vector2d pixel = Eigen::Vector2d::Zero();
    bool keyframe = false;
    bool inlier = true;
  };
  struct Track {
    std::vector<Observation> observations;
    Eigen::Vector3d position = Eigen::Vector3d::Zero();  // current estimate (when reported)
    Eigen::Vector3d reported = Eigen::Vector3d::Zero();  // as last reported to the host
    std::size_t reported_observations = 0;  // observations covered by the last report
    uint64_t last_camera = 0;
    bool dirty = false;     // new observations since the last keyframe
    bool is_reported = false;
    bool rejected = false;  // an outlier for good: its later observations are ignored
  };

  void ValidateCamera(const imr_camera& camera) const;
  void ProcessKeyframe(uint64_t keyframe_id, RefinerUpdate* update);
  // Triangulates/refines one track and records what changed in `update`.
  void ProcessTrack(uint64_t id, Track* track, RefinerUpdate* update);
  void Report(uint64_t id, const Track& track, std::size_t from_observation,
              std::vector<imr_point_estimate>* list, RefinerUpdate* update) const;

  RefinerOptions options_;
  std::unordered_map<uint64_t, Camera> cameras_;
  std::map<uint64_t, Track> tracks_;  // ordered: reports come in track id order
  IdRuns ended_;  // ids of tracks that ended; ignored should they reappear
  bool has_frame_ = false;
  uint64_t last_camera_id_ = 0;
};

}  // namespace imr::ceres_refiner
