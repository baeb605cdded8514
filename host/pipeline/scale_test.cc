#include "host/pipeline/scale.h"

#include <gtest/gtest.h>

#include <cmath>

namespace imr::pipeline {
namespace {

using nlohmann::json;

// One keyframe: a camera at (k, 0, 0) and `n` new points seen by it at distance `d` (and by an
// unknown camera, which is not measured).
engine::KeyframeUpdate Keyframe(uint64_t k, int n, double d) {
  engine::KeyframeUpdate u;
  engine::Camera c;
  c.id = k;
  c.center = {static_cast<double>(k), 0.0, 0.0};
  u.cameras.push_back(c);
  for (int i = 0; i < n; ++i) {
    engine::NewPoint p;
    p.id = k * 100000 + static_cast<uint64_t>(i);
    p.position = {static_cast<double>(k), d, 0.0};
    p.camera_ids = {k, 999999};
    u.new_points.push_back(p);
  }
  return u;
}

TEST(ScaleTest, ModeFromTheJobOrTheFormat) {
  EXPECT_EQ(ScaleModeOf(json::object(), "colmap"), ScaleMode::kAuto);
  EXPECT_EQ(ScaleModeOf(json::object(), "openmvg"), ScaleMode::kAuto);
  EXPECT_EQ(ScaleModeOf(json::object(), "slam_json"), ScaleMode::kAuto);
  EXPECT_EQ(ScaleModeOf(json::object(), "middlebury"), ScaleMode::kAuto);
  EXPECT_EQ(ScaleModeOf(json::object(), "kitti_odometry"), ScaleMode::kMetric);
  EXPECT_EQ(ScaleModeOf(json::object(), "synthetic"), ScaleMode::kMetric);
  EXPECT_EQ(ScaleModeOf({{"scale", "metric"}}, "colmap"), ScaleMode::kMetric);
  EXPECT_EQ(ScaleModeOf({{"scale", "auto"}}, "kitti_raw"), ScaleMode::kAuto);
}

TEST(ScaleTest, ProbeMeasuresTheFirstKeyframesRays) {
  ScaleProbe probe;
  EXPECT_EQ(probe.Estimate().rays, 0);
  EXPECT_EQ(probe.Estimate().factor, 1.0);  // nothing measured: metric
  // Four keyframes of 600 rays at 0.5: enough rays, not enough keyframes.
  for (uint64_t k = 0; k < 4; ++k) probe.Add(Keyframe(k, 600, 0.5));
  EXPECT_FALSE(probe.Enough());
  probe.Add(Keyframe(4, 200, 2.0));
  EXPECT_TRUE(probe.Enough());
  const ScaleEstimate e = probe.Estimate();
  EXPECT_EQ(e.keyframes, 5);
  EXPECT_EQ(e.rays, 2600);  // the unknown camera's rays are not measured
  EXPECT_DOUBLE_EQ(e.median_ray, 0.5);
  EXPECT_DOUBLE_EQ(e.p95_ray, 2.0);
  EXPECT_DOUBLE_EQ(e.ratio, 0.5 / kReferenceMedianRay);
  EXPECT_DOUBLE_EQ(e.factor, 0.02);  // 0.02 = 0.5 / 25 exactly
  // Few rays: not enough whatever the keyframes.
  ScaleProbe sparse;
  for (uint64_t k = 0; k < 49; ++k) sparse.Add(Keyframe(k, 10, 1.0));
  EXPECT_FALSE(sparse.Enough());
  sparse.Add(Keyframe(49, 10, 1.0));
  EXPECT_TRUE(sparse.Enough());  // 50 keyframes decide, however few their rays
  EXPECT_EQ(sparse.Estimate().rays, 500);
}

TEST(ScaleTest, FactorsAreRoundedToOneTwoFive) {
  EXPECT_DOUBLE_EQ(RoundTo125(0.99), 1.0);    // the street stream (24.7 / 25)
  EXPECT_DOUBLE_EQ(RoundTo125(1.4), 1.0);     // sqrt(2) is the boundary between 1 and 2
  EXPECT_DOUBLE_EQ(RoundTo125(1.5), 2.0);
  EXPECT_DOUBLE_EQ(RoundTo125(3.0), 2.0);     // sqrt(10) between 2 and 5
  EXPECT_DOUBLE_EQ(RoundTo125(3.3), 5.0);
  EXPECT_DOUBLE_EQ(RoundTo125(8.0), 10.0);
  EXPECT_DOUBLE_EQ(RoundTo125(0.026), 0.02);  // the dinoRing (0.65 / 25)
  EXPECT_NEAR(RoundTo125(0.0026), 0.002, 1e-15);
  EXPECT_DOUBLE_EQ(RoundTo125(0.0), 1.0);
  EXPECT_DOUBLE_EQ(RoundTo125(-3.0), 1.0);
  EXPECT_DOUBLE_EQ(RoundToR10(2.63), 2.5);
  EXPECT_DOUBLE_EQ(RoundToR10(2.9), 3.15);
  EXPECT_DOUBLE_EQ(RoundToR10(0.99), 1.0);
  EXPECT_NEAR(RoundToR10(0.0175), 0.016, 1e-15);
  EXPECT_DOUBLE_EQ(RoundToR10(95.0), 100.0);
  EXPECT_DOUBLE_EQ(RoundToR10(0.0), 1.0);
}

TEST(ScaleTest, EveryLengthTheJobDoesNotSetIsScaled) {
  ScaleEstimate e;
  e.factor = e.scene_factor = e.reach_factor = 0.1;
  engine::EngineOptions base;
  base.steiner_spacing = 7.0;  // as a job would set it
  base.window = 9;             // not a length
  const engine::EngineOptions o = ScaledOptions(base, e, {"steiner_spacing"});
  const engine::EngineOptions metric;
  EXPECT_DOUBLE_EQ(o.steiner_spacing, 7.0);
  EXPECT_DOUBLE_EQ(o.steiner_margin, 0.1 * metric.steiner_margin);
  EXPECT_DOUBLE_EQ(o.max_ray_length, 0.1 * metric.max_ray_length);
  EXPECT_DOUBLE_EQ(o.shrink_radius, 0.1 * metric.shrink_radius);
  EXPECT_DOUBLE_EQ(o.regrow_radius, 0.1 * metric.regrow_radius);
  EXPECT_DOUBLE_EQ(o.camera_path_radius, 0.1 * metric.camera_path_radius);
  EXPECT_DOUBLE_EQ(o.fill_holes_perimeter, 0.1 * metric.fill_holes_perimeter);
  EXPECT_EQ(o.window, 9);
  EXPECT_EQ(o.Check(), "");
  EXPECT_EQ(ScaledOptionNames().size(), 7u);

  const json j = ScaleJson(ScaleMode::kAuto, e, o, {"steiner_spacing"});
  EXPECT_EQ(j["mode"], "auto");
  EXPECT_DOUBLE_EQ(j["factor"].get<double>(), 0.1);
  EXPECT_FALSE(j["set"].contains("steiner_spacing"));
  EXPECT_DOUBLE_EQ(j["set"]["max_ray_length"].get<double>(), o.max_ray_length);
  EXPECT_EQ(j["given_by_the_job"], json::array({"steiner_spacing"}));
  EXPECT_EQ(ScaleJson(ScaleMode::kMetric, e, o, {}), json({{"mode", "metric"}}));
  const std::string line = ScaleLogLine(e, o, {"steiner_spacing"});
  EXPECT_NE(line.find("ratio 1, scale 0.1, the rays decided every length, steiner_margin 0.5, "
                      "max_ray_length 4"), std::string::npos) << line;
}

// Points on two walls 12 apart and the ground between them, x in [x0, x1].
std::vector<engine::Vec3> Corridor(double x0, double x1, int n) {
  std::vector<engine::Vec3> p;
  for (int i = 0; i < n; ++i) {
    const double x = x0 + (x1 - x0) * (i + 0.5) / n;
    const double t = (i * 7 % 13) / 13.0;
    if (i % 3 == 0) p.push_back({x, -6.0, 8.0 * t});
    else if (i % 3 == 1) p.push_back({x, 6.0, 8.0 * t});
    else p.push_back({x, -6.0 + 12.0 * t, 0.0});
  }
  return p;
}

// Issue 37 item 2: a camera moving forward down a street 12 wide and seeing it 70-100 ahead.
// Its rays (85 long) ask for 5 times the metric lengths: a Steiner grid of 25, wider than the
// street, closes it into a slab. What each camera sees spreads as a street does: the view
// extent decides every length but max_ray_length, and the log says so.
TEST(ScaleTest, AStreetSeenFarAheadIsScaledByWhatEachCameraSees) {
  ScaleProbe probe;
  uint64_t id = 0;
  for (uint64_t k = 0; k < 10; ++k) {
    engine::KeyframeUpdate u;
    const double cx = 2.0 * static_cast<double>(k);
    u.cameras.push_back({k, {cx, 0.0, 1.5}});
    for (const engine::Vec3& x : Corridor(cx + 70.0, cx + 100.0, 300))
      u.new_points.push_back({id++, x, {k}});
    probe.Add(u);
  }
  ASSERT_TRUE(probe.Enough());
  const ScaleEstimate e = probe.Estimate();
  EXPECT_GT(e.median_ray, 80.0);
  EXPECT_EQ(e.factor, 5.0);
  EXPECT_EQ(e.views, 10);
  EXPECT_GT(e.view_extent, 6.0);
  EXPECT_LT(e.view_extent, 12.0);
  EXPECT_FALSE(e.around_an_object);
  EXPECT_EQ(e.scene_factor, 1.0);
  EXPECT_EQ(e.decided_by, "view extent");
  const engine::EngineOptions o = ScaledOptions(engine::EngineOptions{}, e, {});
  EXPECT_EQ(o.steiner_spacing, 5.0);
  EXPECT_EQ(o.shrink_radius, 6.0);
  // The rays are still cast whole (the longest is 100.4): max_ray_length follows their 95th
  // percentile (99.4 / 37.5 = 2.65 -> 2.5), not 5 times 40: a grid of 5 around each camera
  // reaching 200 would cost 8 times the nodes.
  EXPECT_GT(e.p95_ray, 95.0);
  EXPECT_EQ(e.reach_factor, 2.5);
  EXPECT_EQ(o.max_ray_length, 100.0);
  const std::string line = ScaleLogLine(e, o, {});
  EXPECT_NE(line.find("scale 1 for every length but max_ray_length (the view extent decided)"),
            std::string::npos) << line;
  EXPECT_EQ(ScaleJson(ScaleMode::kAuto, e, o, {})["decided_by"], "view extent");
}

// Cameras on a ring around a small object see it across free space as wide as their rays are
// long: the rays decide, however small the object (the dinoRing: 0.033 per view, rays 0.65).
TEST(ScaleTest, CamerasAroundAnObjectAreScaledByTheirRays) {
  ScaleProbe probe;
  uint64_t id = 0;
  for (uint64_t k = 0; k < 12; ++k) {
    engine::KeyframeUpdate u;
    const double a = 0.5 * static_cast<double>(k);
    u.cameras.push_back({k, {0.65 * std::cos(a), 0.65 * std::sin(a), 0.1}});
    for (int i = 0; i < 200; ++i) {
      const double b = 0.1 * i, h = 0.001 * (i % 50);
      u.new_points.push_back({id++, {0.03 * std::cos(b), 0.03 * std::sin(b), h}, {k}});
    }
    probe.Add(u);
  }
  const ScaleEstimate e = probe.Estimate();
  EXPECT_EQ(e.factor, 0.02);
  EXPECT_LT(e.extent_ratio, 0.01);
  EXPECT_TRUE(e.around_an_object) << e.camera_spread << " " << e.point_spread;
  EXPECT_EQ(e.scene_factor, 0.02);
  EXPECT_EQ(e.reach_factor, 0.02);
  EXPECT_EQ(e.decided_by, "rays");
}

}  // namespace
}  // namespace imr::pipeline
