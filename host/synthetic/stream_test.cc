#include "host/synthetic/stream.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <map>
#include <set>
#include <stdexcept>

namespace imr::synthetic {
namespace {

StreamOptions Small(SceneKind scene, uint64_t seed) {
  StreamOptions o;
  o.scene = scene;
  o.seed = seed;
  o.frames = 60;
  o.points_per_keyframe = 80;
  return o;
}

TEST(StreamTest, KittiLikeCamerasAndKeyframes) {
  SyntheticStream s(Small(SceneKind::kStreet, 1));
  EXPECT_EQ(s.keyframe_count(), 12);
  StreamKeyframe kf;
  int n = 0;
  std::set<uint64_t> cams;
  while (s.Next(&kf)) {
    EXPECT_EQ(kf.index, n);
    EXPECT_EQ(kf.cameras.size(), 5u);
    for (const auto& c : kf.cameras) EXPECT_TRUE(cams.insert(c.id).second);
    ++n;
  }
  EXPECT_EQ(n, 12);
  // About 1 m per frame.
  const Vec3 a = s.CameraCenter(10), b = s.CameraCenter(11);
  EXPECT_NEAR(Norm(Sub(b, a)), 1.0, 0.05);
}

TEST(StreamTest, PointsLieNearSurfacesAndConvergeWhileMoving) {
  for (SceneKind scene : {SceneKind::kStreet, SceneKind::kRoom, SceneKind::kPlane}) {
    SyntheticStream s(Small(scene, 5));
    StreamKeyframe kf;
    std::set<uint64_t> known;
    int moves = 0;
    double first_error = 0, last_error = 0;
    int first_n = 0, last_n = 0;
    while (s.Next(&kf)) {
      if (kf.index > 0) {
        EXPECT_FALSE(kf.moved_points.empty()) << ToString(scene);
      }
      for (const auto& p : kf.new_points) {
        EXPECT_TRUE(known.insert(p.id).second);
        EXPECT_GE(p.camera_ids.size(), 2u);
        EXPECT_LT(s.scene().Distance(s.TruePosition(p.id)), 1e-6);
        first_error += Norm(Sub(p.position, s.TruePosition(p.id)));
        ++first_n;
      }
      for (const auto& p : kf.moved_points) {
        EXPECT_TRUE(known.count(p.id));
        ++moves;
        last_error += Norm(Sub(p.position, s.TruePosition(p.id)));
        ++last_n;
      }
    }
    EXPECT_GT(first_n, 500) << ToString(scene);
    EXPECT_GT(moves, 300) << ToString(scene);
    EXPECT_LT(last_error / last_n, 0.6 * first_error / first_n) << ToString(scene);
  }
}

TEST(StreamTest, DeterministicBySeedAndFrozenVariant) {
  auto collect = [](StreamOptions o) {
    SyntheticStream s(o);
    StreamKeyframe kf;
    std::vector<double> v;
    size_t moves = 0;
    while (s.Next(&kf)) {
      for (const auto& p : kf.new_points) v.insert(v.end(), p.position.begin(), p.position.end());
      moves += kf.moved_points.size();
    }
    return std::make_pair(v, moves);
  };
  StreamOptions o = Small(SceneKind::kStreet, 9);
  EXPECT_EQ(collect(o), collect(o));
  StreamOptions other = o;
  other.seed = 10;
  EXPECT_NE(collect(o).first, collect(other).first);
  StreamOptions frozen = o;
  frozen.frozen = true;
  const auto f = collect(frozen);
  EXPECT_EQ(f.second, 0u);                // No moves.
  EXPECT_EQ(f.first, collect(o).first);  // Same new points at the same first estimates.
}


// ---- The tracked model (track_frames > 0) ----

// The dense street of configs/dense-street.json: a keyframe per frame, tracks of up to 17
// observations, the street stream's range and noise.
StreamOptions DenseStreet(int frames, int keyframe_every, uint64_t seed = 1) {
  StreamOptions o;
  o.seed = seed;
  o.frames = frames;
  o.keyframe_every = keyframe_every;
  o.track_frames = 17;
  o.max_range = 40.0;
  o.noise_at_10m = 0.2;
  return o;
}

// What a consumer (the engine) checks of a stream, and the figures the tests look at.
struct TrackedRun {
  int64_t frames = 0;
  int64_t observations = 0;  // camera ids handed out
  int64_t new_points = 0, moves = 0;
  std::map<uint64_t, int> observed;           // point -> observations handed out
  std::map<uint64_t, double> first_error;     // point -> error of its first report
  std::map<uint64_t, double> last_error;      // point -> error of its latest report
  std::map<uint64_t, size_t> first_cameras;   // point -> cameras of its first report
  std::vector<double> checksum;               // positions, in order (determinism)
};

TrackedRun RunTracked(const StreamOptions& o, bool check_sees) {
  SyntheticStream s(o);
  StreamKeyframe kf;
  TrackedRun r;
  std::set<uint64_t> cameras;
  uint64_t last_camera = 0;
  while (s.Next(&kf)) {
    EXPECT_EQ(kf.cameras.size(), static_cast<size_t>(o.keyframe_every));
    for (const auto& c : kf.cameras) {
      EXPECT_TRUE(cameras.empty() || c.id == last_camera + 1);
      cameras.insert(c.id);
      last_camera = c.id;
    }
    EXPECT_EQ(kf.cameras.back().id, static_cast<uint64_t>(kf.frame));
    std::set<uint64_t> named;  // a point at most once per keyframe
    for (const auto& p : kf.new_points) {
      EXPECT_TRUE(named.insert(p.id).second);
      EXPECT_EQ(r.observed.count(p.id), 0u) << "point " << p.id << " new twice";
      // Reported from its 2nd observation: at least two cameras, the first report has them all.
      EXPECT_GE(p.camera_ids.size(), 2u);
      EXPECT_TRUE(std::is_sorted(p.camera_ids.begin(), p.camera_ids.end()));
      const Vec3 truth = s.TruePosition(p.id);
      EXPECT_LT(s.scene().Distance(truth), 1e-6);
      for (uint64_t c : p.camera_ids) {
        EXPECT_TRUE(cameras.count(c)) << "camera " << c << " not in the stream so far";
        if (check_sees) {
          EXPECT_TRUE(s.Sees(static_cast<int>(c), truth)) << "camera " << c << ", point " << p.id;
        }
      }
      r.observed[p.id] = static_cast<int>(p.camera_ids.size());
      r.first_cameras[p.id] = p.camera_ids.size();
      r.first_error[p.id] = r.last_error[p.id] = Norm(Sub(p.position, truth));
      r.observations += static_cast<int64_t>(p.camera_ids.size());
      r.checksum.insert(r.checksum.end(), p.position.begin(), p.position.end());
      ++r.new_points;
    }
    for (const auto& p : kf.moved_points) {
      EXPECT_TRUE(named.insert(p.id).second);
      EXPECT_EQ(r.observed.count(p.id), 1u) << "moved point " << p.id << " never new";
      EXPECT_FALSE(p.camera_ids.empty());  // a move brings the frames that observed it
      const Vec3 truth = s.TruePosition(p.id);
      for (uint64_t c : p.camera_ids) {
        EXPECT_TRUE(cameras.count(c));
        EXPECT_GT(c, static_cast<uint64_t>(kf.frame - o.keyframe_every));  // this block's frames
        if (check_sees) {
          EXPECT_TRUE(s.Sees(static_cast<int>(c), truth));
        }
      }
      r.observed[p.id] += static_cast<int>(p.camera_ids.size());
      r.last_error[p.id] = Norm(Sub(p.position, truth));
      r.observations += static_cast<int64_t>(p.camera_ids.size());
      r.checksum.insert(r.checksum.end(), p.position.begin(), p.position.end());
      ++r.moves;
    }
  }
  r.frames = s.stats().frames;
  // The stream's own figures agree with what it handed out.
  EXPECT_EQ(s.stats().observations, r.observations);
  EXPECT_EQ(s.stats().new_points, r.new_points);
  EXPECT_EQ(s.stats().moved_points, r.moves);
  for (const auto& [id, n] : r.observed) EXPECT_LE(n, o.track_frames) << "point " << id;
  return r;
}

TEST(TrackedStreamTest, DenseStreetStatistics) {
  const StreamOptions o = DenseStreet(300, 1);
  const TrackedRun r = RunTracked(o, true);
  EXPECT_EQ(r.frames, 300);
  // Observations per frame near the street stream's (~1,226; the issue's ~1,270). Measured
  // 1,309 over these 300 frames (the start-up adds: every surface in view starts a track at
  // frame 0), 1,268 over 2,000.
  const double per_frame = static_cast<double>(r.observations) / r.frames;
  EXPECT_GT(per_frame, 1000.0);
  EXPECT_LT(per_frame, 1450.0);
  // Tracks: most run to track_frames, the rest are lost (out of view or occluded) on the way.
  int64_t full = 0, total = 0;
  for (const auto& [id, n] : r.observed) {
    total += n;
    full += n == o.track_frames;
  }
  const double mean = static_cast<double>(total) / r.observed.size();
  EXPECT_GT(mean, 12.0);
  EXPECT_LE(mean, 17.0);
  EXPECT_GT(full, static_cast<int64_t>(r.observed.size() / 2));
  // Every point moves while tracked: a keyframe per frame, so each further observation is a move.
  EXPECT_GT(static_cast<double>(r.moves) / r.frames, 800.0);
  // Moved points converge: after all their observations they are much nearer the truth than
  // when first reported (the mean of k draws: sigma / sqrt(k), and later draws are nearer).
  double first = 0.0, last = 0.0;
  int n = 0;
  for (const auto& [id, k] : r.observed) {
    if (k < o.track_frames) continue;
    first += r.first_error.at(id);
    last += r.last_error.at(id);
    ++n;
  }
  ASSERT_GT(n, 1000);
  EXPECT_LT(last / n, 0.5 * first / n);
}

TEST(TrackedStreamTest, KeyframeEveryFiveCarriesTheBlocksFramesAndLatestEstimates) {
  // The frames are the same whatever the keyframes: the same tracks, handed out in fewer updates.
  const TrackedRun one = RunTracked(DenseStreet(120, 1, 4), false);
  const TrackedRun five = RunTracked(DenseStreet(120, 5, 4), true);
  EXPECT_EQ(five.observations, one.observations);
  EXPECT_EQ(five.observed.size(), one.observed.size());
  EXPECT_LT(five.moves, one.moves / 3);  // one move per point per keyframe, not per frame
  // The last report of a point is its latest estimate, the same in both.
  for (const auto& [id, e] : five.last_error) EXPECT_DOUBLE_EQ(e, one.last_error.at(id));
  // A new point of a 5-frame keyframe may have more than two cameras, from the earlier block too.
  size_t more = 0;
  for (const auto& [id, c] : five.first_cameras) more += c > 2;
  EXPECT_GT(more, five.first_cameras.size() / 2);
}

TEST(TrackedStreamTest, DeterministicBySeed) {
  const StreamOptions o = DenseStreet(60, 1, 9);
  EXPECT_EQ(RunTracked(o, false).checksum, RunTracked(o, false).checksum);
  StreamOptions other = o;
  other.seed = 10;
  EXPECT_NE(RunTracked(o, false).checksum, RunTracked(other, false).checksum);
}

TEST(TrackedStreamTest, FrozenKeepsTheFirstEstimate) {
  StreamOptions o = DenseStreet(40, 1, 2);
  o.frozen = true;
  SyntheticStream s(o);
  StreamKeyframe kf;
  std::map<uint64_t, Vec3> first;
  size_t moves = 0;
  while (s.Next(&kf)) {
    for (const auto& p : kf.new_points) first[p.id] = p.position;
    for (const auto& p : kf.moved_points) {
      EXPECT_EQ(p.position, first.at(p.id));
      EXPECT_FALSE(p.camera_ids.empty());
      ++moves;
    }
  }
  EXPECT_GT(moves, 1000u);  // still there: they bring the new cameras
}

TEST(TrackedStreamTest, OtherScenesAndEveryOptionRefusedWhenUnusable) {
  for (SceneKind scene : {SceneKind::kRoom, SceneKind::kPlane}) {
    StreamOptions o = DenseStreet(60, 1, 3);
    o.scene = scene;
    const TrackedRun r = RunTracked(o, true);
    std::printf("%s: %lld new points, %lld moves\n", ToString(scene).c_str(),
                static_cast<long long>(r.new_points), static_cast<long long>(r.moves));
    EXPECT_GT(r.new_points, 100) << ToString(scene);
    EXPECT_GT(r.moves, 5 * r.new_points) << ToString(scene);
  }
  StreamOptions bad = DenseStreet(10, 1);
  bad.track_frames = 1;  // never reaches min_observations 2
  EXPECT_NE(bad.Check().find("track_frames"), std::string::npos);
  EXPECT_THROW(SyntheticStream{bad}, std::invalid_argument);
  bad = DenseStreet(10, 1);
  bad.frames = 300000;  // 300 km of street
  EXPECT_NE(bad.Check().find("frames x speed"), std::string::npos);
  bad = DenseStreet(10, 1);
  bad.track_density = -1.0;
  EXPECT_NE(bad.Check().find("track_density"), std::string::npos);
  EXPECT_EQ(DenseStreet(10, 1).Check(), "");
  EXPECT_EQ(StreamOptions{}.Check(), "");
}

// The generator's memory does not grow with the drive: the live tracks stay bounded, and
// without keep_truth it holds no point once its track has ended.
TEST(TrackedStreamTest, BoundedGeneratorMemory) {
  StreamOptions o = DenseStreet(3000, 1);
  o.keep_truth = false;
  o.track_density = 0.7;  // a third of the dense street's tracks: a third of the time
  SyntheticStream s(o);
  StreamKeyframe kf;
  size_t most_late = 0, most_early = 0;
  while (s.Next(&kf)) {
    size_t& most = kf.frame < 1500 ? most_early : most_late;
    most = std::max(most, s.stats().active_tracks);
    EXPECT_EQ(s.stats().kept_truths, 0u);
  }
  // ~400 tracks live at a time (~26 start per frame, each lives <= 17 frames; the dense street has
  // three times as many); no more in the second half than in the first, however long the drive.
  std::printf("live tracks at most: %zu (first half), %zu (second half); %lld points\n", most_early,
              most_late, static_cast<long long>(s.stats().new_points));
  EXPECT_GT(most_late, 250u);
  EXPECT_LT(most_late, 900u);
  EXPECT_LE(most_late, most_early + 100);
  EXPECT_GT(s.stats().new_points, 60000);
  // An ended track is gone: its truth is no longer held.
  EXPECT_EQ(s.TruePosition(1), (Vec3{0.0, 0.0, 0.0}));
  EXPECT_LT(s.TruePoints().size(), 900u);

  // With keep_truth the block model too keeps every point; without, only those it refines.
  StreamOptions block = Small(SceneKind::kStreet, 1);
  block.frames = 300;
  block.keep_truth = false;
  SyntheticStream b(block);
  while (b.Next(&kf)) EXPECT_LE(b.stats().kept_truths, 80u * 3);
}

// keep_truth changes nothing of what the stream hands out (block model: the original bytes).
TEST(TrackedStreamTest, KeepTruthChangesNoOutput) {
  auto collect = [](StreamOptions o) {
    SyntheticStream s(o);
    StreamKeyframe kf;
    std::vector<double> v;
    while (s.Next(&kf)) {
      for (const auto* list : {&kf.new_points, &kf.moved_points})
        for (const auto& p : *list) {
          v.insert(v.end(), p.position.begin(), p.position.end());
          for (uint64_t c : p.camera_ids) v.push_back(static_cast<double>(c));
        }
    }
    return v;
  };
  for (StreamOptions o : {Small(SceneKind::kStreet, 2), DenseStreet(50, 1, 2)}) {
    StreamOptions off = o;
    off.keep_truth = false;
    EXPECT_EQ(collect(o), collect(off));
  }
}

}  // namespace
}  // namespace imr::synthetic
