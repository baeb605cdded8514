#include "host/pipeline/scale.h"

#include <gtest/gtest.h>

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
}

TEST(ScaleTest, EveryLengthTheJobDoesNotSetIsScaled) {
  ScaleEstimate e;
  e.factor = 0.1;
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
  EXPECT_NE(line.find("ratio 1, scale 0.1, steiner_margin 0.5, max_ray_length 4"), std::string::npos) << line;
}

}  // namespace
}  // namespace imr::pipeline
