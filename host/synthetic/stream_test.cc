#include "host/synthetic/stream.h"

#include <gtest/gtest.h>

#include <set>

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

}  // namespace
}  // namespace imr::synthetic
