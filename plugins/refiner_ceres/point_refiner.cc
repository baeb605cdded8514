#include "point_refiner.hpp"

#include <imr/sdk/plugin.hpp>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>

namespace imr::ceres_refiner {

using imr::sdk::InvalidArgument;

std::string RefinerOptions::Check() const {
  if (min_keyframes < 1) return "min_keyframes: expected >= 1";
  if (min_views < 2) return "min_views: expected >= 2";
  if (!(min_parallax_deg >= 0.0 && min_parallax_deg < 180.0))
    return "min_parallax_deg: expected in [0, 180)";
  if (!(huber_px >= 0.0)) return "huber_px: expected >= 0";
  if (max_iterations < 1) return "max_iterations: expected >= 1";
  if (!(max_reprojection_error > 0.0)) return "max_reprojection_error: expected > 0";
  if (!(min_inlier_ratio >= 0.0 && min_inlier_ratio <= 1.0))
    return "min_inlier_ratio: expected in [0, 1]";
  if (!(min_depth >= 0.0)) return "min_depth: expected >= 0";
  if (!(max_distance > 0.0)) return "max_distance: expected > 0";
  if (!(min_move >= 0.0)) return "min_move: expected >= 0";
  return {};
}

void IdRuns::Add(uint64_t id) {
  auto next = runs_.upper_bound(id);  // the first run starting after id
  if (next != runs_.begin()) {
    auto prev = std::prev(next);
    if (id <= prev->second) return;  // already in
    if (id == prev->second + 1) {    // extends the run before it, maybe up to the next one
      prev->second = id;
      if (next != runs_.end() && next->first == id + 1) {
        prev->second = next->second;
        runs_.erase(next);
      }
      return;
    }
  }
  if (next != runs_.end() && next->first == id + 1) {  // extends the run after it
    const uint64_t last = next->second;
    runs_.erase(next);
    runs_.emplace(id, last);
    return;
  }
  runs_.emplace(id, id);
}

bool IdRuns::Contains(uint64_t id) const {
  auto next = runs_.upper_bound(id);
  return next != runs_.begin() && id <= std::prev(next)->second;
}

void PointRefiner::ValidateCamera(const imr_camera& c) const {
  const std::string where = "camera " + std::to_string(c.id);
  if (has_frame_ && c.id <= last_camera_id_)
    throw InvalidArgument(where + ": camera.id must increase from frame to frame (previous " +
                          std::to_string(last_camera_id_) + ")");
  for (double v : c.K)
    if (!std::isfinite(v)) throw InvalidArgument(where + ": camera.K is not finite");
  for (double v : c.R)
    if (!std::isfinite(v)) throw InvalidArgument(where + ": camera.R is not finite");
  for (double v : c.t)
    if (!std::isfinite(v)) throw InvalidArgument(where + ": camera.t is not finite");
  if (!(c.K[0] > 0.0 && c.K[4] > 0.0) || c.K[3] != 0.0 || c.K[6] != 0.0 || c.K[7] != 0.0 ||
      c.K[8] != 1.0)
    throw InvalidArgument(where + ": camera.K must be [fx s cx; 0 fy cy; 0 0 1] with fx, fy > 0");
  const Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>> R(c.R);
  if (!((R * R.transpose() - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() < 1e-6) ||
      !(R.determinant() > 0.0))
    throw InvalidArgument(where + ": camera.R is not a rotation (orthonormal, det +1)");
}

void PointRefiner::AddFrame(const imr_camera& camera,
                            std::span<const imr_track_observation> observations, bool is_keyframe,
                            RefinerUpdate* update) {
  update->Clear();
  ValidateCamera(camera);
  std::unordered_set<uint64_t> seen;
  seen.reserve(observations.size());
  for (std::size_t i = 0; i < observations.size(); ++i) {
    const imr_track_observation& o = observations[i];
    if (!std::isfinite(o.x) || !std::isfinite(o.y))
      throw InvalidArgument("observations[" + std::to_string(i) + "] (track " +
                            std::to_string(o.track_id) + "): x/y not finite");
    if (!seen.insert(o.track_id).second)
      throw InvalidArgument("observations[" + std::to_string(i) + "]: track_id " +
                            std::to_string(o.track_id) + " appears twice in one frame");
  }

  using RowMajor = Eigen::Matrix<double, 3, 3, Eigen::RowMajor>;
  cameras_.emplace(camera.id, Camera(Eigen::Map<const RowMajor>(camera.K),
                                     Eigen::Map<const RowMajor>(camera.R),
                                     Eigen::Vector3d(camera.t[0], camera.t[1], camera.t[2])));
  has_frame_ = true;
  last_camera_id_ = camera.id;

  for (const imr_track_observation& o : observations) {
    // An id is one track: a tracker that reuses an ended id gets no second point for it.
    if (!ended_.empty() && ended_.Contains(o.track_id)) continue;
    Track& track = tracks_[o.track_id];
    track.last_camera = camera.id;
    if (track.rejected) continue;
    track.observations.push_back({camera.id, {o.x, o.y}, is_keyframe, true});
    track.dirty = true;
  }
  if (is_keyframe) ProcessKeyframe(camera.id, update);
}

void PointRefiner::ProcessKeyframe(uint64_t keyframe_id, RefinerUpdate* update) {
  uint64_t oldest_camera = keyframe_id;
  for (auto it = tracks_.begin(); it != tracks_.end();) {
    Track& track = it->second;
    if (track.dirty) ProcessTrack(it->first, &track, update);
    track.dirty = false;
    // A track not seen in this keyframe has ended (ids are never reused): its estimate is final.
    if (track.last_camera != keyframe_id) {
      ended_.Add(it->first);
      it = tracks_.erase(it);
      continue;
    }
    if (!track.observations.empty())
      oldest_camera = std::min(oldest_camera, track.observations.front().camera);
    ++it;
  }
  // Cameras no live track refers to are no longer needed.
  std::erase_if(cameras_, [&](const auto& kv) { return kv.first < oldest_camera; });
}

void PointRefiner::ProcessTrack(uint64_t id, Track* track, RefinerUpdate* update) {
  std::vector<View> views;
  std::vector<std::size_t> index;  // views[k] is track->observations[index[k]]
  auto collect = [&](const std::vector<char>& inlier) {
    views.clear();
    index.clear();
    int keyframes = 0;
    for (std::size_t i = 0; i < track->observations.size(); ++i) {
      if (!inlier[i]) continue;
      const Observation& o = track->observations[i];
      views.push_back({&cameras_.at(o.camera), o.pixel});
      index.push_back(i);
      keyframes += o.keyframe ? 1 : 0;
    }
    return keyframes;
  };
  std::vector<char> inlier(track->observations.size());
  for (std::size_t i = 0; i < inlier.size(); ++i) inlier[i] = track->observations[i].inlier;
  int keyframes = collect(inlier);

  Eigen::Vector3d X = track->position;
  if (!track->is_reported) {
    if (keyframes < options_.min_keyframes) return;
    if (static_cast<int>(views.size()) < options_.min_views) return;
    if (ParallaxDeg(views) < options_.min_parallax_deg) return;
    const auto dlt = TriangulateDlt(views);
    if (!dlt) return;
    X = *dlt;
    // A first estimate behind a camera cannot be refined; wait for more observations.
    for (const View& v : views)
      if (v.camera->Depth(X) <= options_.min_depth) return;
  }

  const RefineOptions refine{options_.huber_px, options_.max_iterations};
  bool ok = RefinePoint(views, refine, &X);
  if (ok) {
    // Observations the refined point does not explain are outliers; refine again without them.
    const std::vector<double> errors = ReprojectionErrors(views, X);
    bool dropped = false;
    for (std::size_t k = 0; k < views.size(); ++k) {
      if (errors[k] > options_.max_reprojection_error) {
        inlier[index[k]] = 0;
        dropped = true;
      }
    }
    if (dropped) {
      keyframes = collect(inlier);
      ok = views.size() >= 2 && RefinePoint(views, refine, &X);
    }
  }

  // Acceptance: consistent, in front of every observing camera, not too far.
  bool accept = ok && keyframes >= options_.min_keyframes &&
                static_cast<int>(views.size()) >= options_.min_views &&
                static_cast<double>(views.size()) >=
                    options_.min_inlier_ratio * static_cast<double>(track->observations.size());
  bool inconsistent = !accept;  // reprojection-type failure: the track is an outlier
  if (accept) {
    const std::vector<double> errors = ReprojectionErrors(views, X);
    double nearest = std::numeric_limits<double>::infinity();
    for (std::size_t k = 0; k < views.size() && accept; ++k) {
      if (errors[k] > options_.max_reprojection_error) {
        accept = false;
        inconsistent = true;
      }
      if (views[k].camera->Depth(X) <= options_.min_depth) accept = false;
      nearest = std::min(nearest, (X - views[k].camera->Center()).norm());
    }
    if (nearest > options_.max_distance) accept = false;
  }

  if (!accept) {
    if (track->is_reported) {
      update->removed_ids.push_back(id);
      track->rejected = true;
    } else if (inconsistent) {
      track->rejected = true;  // never reported: just never created
    }
    if (track->rejected) {
      track->observations.clear();
      track->observations.shrink_to_fit();
    }
    return;  // otherwise (behind / too far before its first report): retry at a later keyframe
  }

  for (std::size_t i = 0; i < inlier.size(); ++i) track->observations[i].inlier = inlier[i] != 0;
  track->position = X;
  if (!track->is_reported) {
    track->is_reported = true;
    Report(id, *track, 0, &update->new_points, update);
  } else if ((X - track->reported).norm() > options_.min_move) {
    Report(id, *track, track->reported_observations, &update->moved_points, update);
  } else {
    return;
  }
  track->reported = X;
  track->reported_observations = track->observations.size();
}

void PointRefiner::Report(uint64_t id, const Track& track, std::size_t from_observation,
                          std::vector<imr_point_estimate>* list, RefinerUpdate* update) const {
  imr_point_estimate e{};
  e.id = id;
  e.position[0] = track.position.x();
  e.position[1] = track.position.y();
  e.position[2] = track.position.z();
  e.first_camera = update->camera_ids.size();
  for (std::size_t i = from_observation; i < track.observations.size(); ++i)
    if (track.observations[i].inlier) update->camera_ids.push_back(track.observations[i].camera);
  e.camera_count = update->camera_ids.size() - e.first_camera;
  list->push_back(e);
}

}  // namespace imr::ceres_refiner
