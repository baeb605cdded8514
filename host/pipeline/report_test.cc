// The run's warnings that report.cc words (issue 47: the Steiner grid's size).
#include "host/pipeline/report.h"

#include <gtest/gtest.h>

namespace imr::pipeline {
namespace {

engine::EngineStats Stats(int64_t points, int64_t steiner) {
  engine::EngineStats s;
  s.points_inserted = points;
  s.steiner_points = steiner;
  return s;
}

TEST(SteinerGridWarningTest, NamesTheSizeAndTheOptionsWhenTheGridOutgrowsThePoints) {
  engine::EngineOptions o;
  o.steiner_spacing = 0.25;
  // The forward COLMAP model of issue 47 under the camera cubes: 670,824 for 4,217 points.
  const std::string w = SteinerGridWarning(Stats(4217, 670824), o);
  ASSERT_FALSE(w.empty());
  EXPECT_NE(w.find("670824 points for 4217 data points (159 a point"), std::string::npos) << w;
  EXPECT_NE(w.find("steiner_spacing 0.25"), std::string::npos) << w;
  EXPECT_NE(w.find("a larger engine.steiner_spacing"), std::string::npos) << w;
  // Points refused at first and entered later count as data points.
  engine::EngineStats reentered = Stats(4217, 670824);
  reentered.points_reentered = 40000;
  EXPECT_EQ(SteinerGridWarning(reentered, o), "");
}

TEST(SteinerGridWarningTest, SilentAtOrBelowTheBoundOrForASmallGrid) {
  const engine::EngineOptions o;
  EXPECT_EQ(SteinerGridWarning(Stats(10000, 200000), o), "");  // 20 a point: the bound
  EXPECT_NE(SteinerGridWarning(Stats(10000, 200001), o), "");
  EXPECT_EQ(SteinerGridWarning(Stats(100, 99999), o), "");  // under the floor
  EXPECT_NE(SteinerGridWarning(Stats(100, 100000), o), "");
  EXPECT_NE(SteinerGridWarning(Stats(0, 100000), o), "");   // no point at all
}

}  // namespace
}  // namespace imr::pipeline
