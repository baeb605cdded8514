// imr-soak's trace parsing and memory analysis on hand-made traces (the soak itself is a tool run).
#include "tools/soak/trace.h"

#include <cmath>
#include <string>

#include <gtest/gtest.h>

namespace imr::soak {
namespace {

// A run of `keyframes` keyframes, 150 points each, RSS = base + per_point * points +
// per_keyframe * k (+ leak after `leak_from`), a check every 10 keyframes.
std::string Trace(int keyframes, int points_per_keyframe, double per_point, double per_keyframe,
                  int leak_from = -1, double leak_per_keyframe = 0.0) {
  std::string s;
  for (int k = 0; k < keyframes; ++k) {
    const long points = static_cast<long>(points_per_keyframe) * (k + 1);
    const long steiner = 40L * (k + 1);
    double rss = 20e6 + per_point * points + per_keyframe * k;
    if (leak_from >= 0 && k > leak_from)
      rss += leak_per_keyframe * (k - leak_from) * (k - leak_from);
    s += "{\"keyframe\":" + std::to_string(k) + ",\"frame\":" + std::to_string(5 * k + 4) +
         ",\"points\":" + std::to_string(points) + ",\"vertices\":" +
         std::to_string(points + steiner) + ",\"cells\":" + std::to_string(7 * (points + steiner)) +
         ",\"cells_in_o\":" + std::to_string(3 * points) + ",\"rss_bytes\":" +
         std::to_string(static_cast<long>(rss)) + ",\"engine_seconds\":0.05";
    if (k % 10 == 9) s += ",\"check_seconds\":0.25";
    s += "}\n";
  }
  return s;
}

TEST(SoakTrace, ParsesRecordsAndOptionalCheck) {
  std::vector<TraceRecord> r;
  std::string note, error;
  ASSERT_TRUE(ParseTrace(Trace(20, 150, 1000, 0), &r, &note, &error)) << error;
  ASSERT_EQ(r.size(), 20u);
  EXPECT_EQ(r[3].points, 600);
  EXPECT_EQ(r[3].frame, 19);
  EXPECT_FALSE(r[3].check_seconds.has_value());
  ASSERT_TRUE(r[9].check_seconds.has_value());
  EXPECT_DOUBLE_EQ(*r[9].check_seconds, 0.25);
  EXPECT_TRUE(note.empty());
}

TEST(SoakTrace, CutLastLineIsSkippedOtherBadLinesAreErrors) {
  std::vector<TraceRecord> r;
  std::string note, error;
  const std::string whole = Trace(6, 150, 1000, 0);
  ASSERT_TRUE(ParseTrace(whole.substr(0, whole.size() - 20), &r, &note, &error)) << error;
  EXPECT_EQ(r.size(), 5u);
  EXPECT_NE(note.find("line 6"), std::string::npos) << note;

  EXPECT_FALSE(ParseTrace("{\"keyframe\":0}\n" + whole, &r, &note, &error));
  EXPECT_NE(error.find("line 1"), std::string::npos) << error;
  EXPECT_NE(error.find("\"frame\""), std::string::npos) << error;

  EXPECT_FALSE(ParseTrace(whole + whole, &r, &note, &error));  // keyframes go back to 0
  EXPECT_NE(error.find("line 7"), std::string::npos) << error;
}

TEST(SoakTrace, LinearMemoryFollowsThePoints) {
  std::vector<TraceRecord> r;
  std::string note, error;
  ASSERT_TRUE(ParseTrace(Trace(200, 150, 1200, 0), &r, &note, &error)) << error;
  SoakFigures f;
  ASSERT_TRUE(Analyse(r, &f, &error)) << error;
  EXPECT_EQ(f.keyframes, 200);
  EXPECT_EQ(f.frames, 5 * 199 + 5);
  EXPECT_EQ(f.checks, 20);
  EXPECT_NEAR(f.check_total_s, 5.0, 1e-9);
  EXPECT_NEAR(f.engine_total_s, 10.0, 1e-9);
  EXPECT_NEAR(f.fit_points.b, 1200.0, 1e-6);
  EXPECT_NEAR(f.fit_points.a, 20e6, 1.0);
  EXPECT_LT(f.fit_points.max_abs, 2.0);
  EXPECT_EQ(f.rss_peak_keyframe, 199);
  EXPECT_LT(std::fabs(f.holdout_max_dev_pct), 1e-6);
  EXPECT_TRUE(f.follows_points);
}

TEST(SoakTrace, LateAcceleratingGrowthFailsTheHoldout) {
  std::vector<TraceRecord> r;
  std::string note, error;
  // From keyframe 100 on, memory grows quadratically: 200 kB * j^2 after j keyframes.
  ASSERT_TRUE(ParseTrace(Trace(200, 150, 1200, 0, 100, 2e5), &r, &note, &error)) << error;
  SoakFigures f;
  ASSERT_TRUE(Analyse(r, &f, &error)) << error;
  EXPECT_FALSE(f.follows_points);
  EXPECT_GT(f.holdout_max_dev, 0.0);
  EXPECT_EQ(f.holdout_worst_keyframe, 199);
}

// A run of 100 keyframes: ppk points and spk Steiner points per keyframe; RSS = 10 MB + 1200 bytes
// per point + 700 per Steiner point + `leak` bytes per keyframe.
std::vector<TraceRecord> Synthetic(int ppk, int spk, double leak) {
  std::string s;
  for (int k = 1; k <= 100; ++k) {
    const long points = static_cast<long>(ppk) * k, steiner = 1000L + spk * k;
    s += "{\"keyframe\":" + std::to_string(k) + ",\"frame\":" + std::to_string(5 * k) +
         ",\"points\":" + std::to_string(points) + ",\"vertices\":" +
         std::to_string(points + steiner) + ",\"cells\":" + std::to_string(7 * (points + steiner)) +
         ",\"cells_in_o\":0,\"rss_bytes\":" +
         std::to_string(static_cast<long>(1e7 + 1200.0 * points + 700.0 * steiner + leak * k)) +
         ",\"engine_seconds\":0.01}\n";
  }
  std::vector<TraceRecord> r;
  std::string note, error;
  EXPECT_TRUE(ParseTrace(s, &r, &note, &error)) << error;
  return r;
}

TEST(SoakTrace, DecompositionSeparatesPointsSteinerAndKeyframes) {
  {
    const auto dense = Synthetic(150, 250, 5e4), sparse = Synthetic(75, 250, 5e4),
               coarse = Synthetic(150, 32, 5e4);
    const Decomposition d = Decompose({&dense, &sparse, &coarse});
    ASSERT_TRUE(d.ok);
    EXPECT_NEAR(d.per_point, 1200.0, 1e-2);
    EXPECT_NEAR(d.per_steiner, 700.0, 1e-2);
    EXPECT_NEAR(d.per_keyframe, 5e4, 1.0);
    EXPECT_NEAR(d.growth_keyframes, 5e4 * 99, 1e3);
    EXPECT_NEAR(d.growth_points + d.growth_steiner + d.growth_keyframes, d.growth, 1e3);
    EXPECT_GT(d.growth_keyframes / d.growth, kKeyframeGrowthTolerance);
  }
  {
    const auto dense = Synthetic(150, 250, 0), sparse = Synthetic(75, 250, 0),
               coarse = Synthetic(150, 32, 0);
    const Decomposition d = Decompose({&dense, &sparse, &coarse});
    ASSERT_TRUE(d.ok);
    EXPECT_NEAR(d.per_keyframe, 0.0, 1.0);
    EXPECT_LT(std::fabs(d.growth_keyframes / d.growth), kKeyframeGrowthTolerance);
    EXPECT_LT(d.max_abs, 2.0);
    // Without the coarse run, Steiner points and keyframes grow together: nothing to separate.
    EXPECT_FALSE(Decompose({&dense, &sparse, &sparse}).ok);
    EXPECT_FALSE(Decompose({&dense, &sparse}).ok);
  }
}

TEST(SoakTrace, TooShortIsAnError) {
  std::vector<TraceRecord> r;
  std::string note, error;
  ASSERT_TRUE(ParseTrace(Trace(3, 150, 1000, 0), &r, &note, &error));
  SoakFigures f;
  EXPECT_FALSE(Analyse(r, &f, &error));
  EXPECT_NE(error.find("needs 4"), std::string::npos) << error;
}

}  // namespace
}  // namespace imr::soak
