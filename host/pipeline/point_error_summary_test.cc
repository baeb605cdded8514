// The front end's point-error figures in memory bounded by the points still being refined.
#include "host/pipeline/point_error_summary.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

namespace imr::pipeline {
namespace {

// A drive of `keyframes` keyframes: 40 new points at each, each moved at the 3 keyframes after
// (its distance shrinking), every 7th removed at the next.
struct Drive {
  PointErrorSummary summary;
  int64_t points = 0;  // added and not removed
};
void RunDrive(int keyframes, Drive* d) {
  uint64_t next = 0;
  for (int k = 0; k < keyframes; ++k) {
    for (int j = 0; j < 40; ++j) {
      const uint64_t id = next++;
      d->summary.Add(id, 0.01 + 0.37 * std::fmod(id * 0.618034, 1.0), k);
      ++d->points;
    }
    for (uint64_t id = next >= 160 ? next - 160 : 0; id + 40 < next; ++id)
      d->summary.Move(id, (0.01 + 0.37 * std::fmod(id * 0.618034, 1.0)) * 0.5, k);
    if (k > 0)
      for (uint64_t id = next - 80; id < next - 40; id += 7) {
        d->summary.Remove(id);
        --d->points;
      }
    d->summary.EndKeyframe(k);
  }
}

double MedianOf(std::vector<double> v) {
  const auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}

// A record kept per keyframe handed out would put 300 x its size between a drive of 300
// keyframes and one of 600: what is held stays the points being refined.
TEST(PointErrorSummary, HoldsThePointsBeingRefinedNotTheDrive) {
  Drive a, b;
  RunDrive(300, &a);
  RunDrive(600, &b);
  EXPECT_LE(a.summary.live(), 40 * (PointErrorSummary::kSettleKeyframes + PointErrorSummary::kFoldEvery));
  EXPECT_EQ(a.summary.live(), b.summary.live());
  EXPECT_LE(std::abs(b.summary.HeldBytes() - a.summary.HeldBytes()), 8 * 300 - 1)
      << a.summary.HeldBytes() << " bytes after 300 keyframes, " << b.summary.HeldBytes()
      << " after 600";
  // Every point kept is counted, folded or not.
  EXPECT_EQ(a.summary.Result().points, a.points);
  EXPECT_EQ(b.summary.Result().points, b.points);
}

// The medians: exact while nothing is folded, within a fine bin after.
TEST(PointErrorSummary, MediansMatchTheExactOnes) {
  for (int keyframes : {20, 400}) {
    SCOPED_TRACE(keyframes);
    PointErrorSummary s;
    std::vector<double> first_all, first_moved, latest_moved;
    std::vector<double> first(40 * keyframes), latest(40 * keyframes);
    std::vector<int> moves(40 * keyframes, 0);
    for (int k = 0; k < keyframes; ++k) {
      for (int j = 0; j < 40; ++j) {
        const int id = 40 * k + j;
        first[id] = latest[id] = 0.003 * ((id * 37) % 101) + 0.0001 * j;
        s.Add(id, first[id], k);
      }
      if (k > 0)
        for (int id = 40 * (k - 1); id < 40 * k; id += 3) {
          latest[id] = first[id] * 0.7;
          ++moves[id];
          s.Move(id, latest[id], k);
        }
      s.EndKeyframe(k);
    }
    for (int id = 0; id < 40 * keyframes; ++id) {
      first_all.push_back(first[id]);
      if (moves[id] == 0) continue;
      first_moved.push_back(first[id]);
      latest_moved.push_back(latest[id]);
    }
    const PointErrorSummary::Figures f = s.Result();
    EXPECT_EQ(f.points, static_cast<int64_t>(first_all.size()));
    EXPECT_EQ(f.moved, static_cast<int64_t>(first_moved.size()));
    const double tolerance = keyframes <= PointErrorSummary::kSettleKeyframes ? 0.0 : PointErrorSummary::kFineBin;
    EXPECT_NEAR(f.median_first, MedianOf(first_all), tolerance);
    EXPECT_NEAR(f.moved_median_first, MedianOf(first_moved), tolerance);
    EXPECT_NEAR(f.moved_median_latest, MedianOf(latest_moved), tolerance);
  }
}

// The dense points' distances: exact quantiles while few, within a fine bin once folded, and what
// is held stops growing (a double per distance grew with the drive).
TEST(DistanceSample, ExactWhileFewWithinABinAfterAndBounded) {
  DistanceSample small(0.2), large(0.2);
  std::vector<double> all;
  const std::size_t n = 4 * DistanceSample::kExact;
  for (std::size_t i = 0; i < n; ++i) {
    const double d = 0.5 * std::fmod(i * 0.618034, 1.0) * std::fmod(i * 0.414214, 1.0);
    if (i < 1000) small.Add(d);
    large.Add(d);
    all.push_back(d);
  }
  std::vector<double> first(all.begin(), all.begin() + 1000);
  std::sort(first.begin(), first.end());
  std::sort(all.begin(), all.end());
  EXPECT_EQ(small.Quantile(0.5), first[499]);
  EXPECT_EQ(small.Quantile(0.9), first[static_cast<std::size_t>(0.9 * 999)]);
  EXPECT_EQ(small.below(), std::lower_bound(first.begin(), first.end(), 0.2) - first.begin());
  EXPECT_NEAR(large.Quantile(0.5), all[(n - 1) / 2], PointErrorSummary::kFineBin);
  EXPECT_NEAR(large.Quantile(0.9), all[static_cast<std::size_t>(0.9 * (n - 1))], PointErrorSummary::kFineBin);
  EXPECT_EQ(large.below(), std::lower_bound(all.begin(), all.end(), 0.2) - all.begin());
  EXPECT_EQ(large.size(), static_cast<int64_t>(n));
  const int64_t held = large.HeldBytes();
  for (std::size_t i = 0; i < n; ++i) large.Add(0.01);
  EXPECT_EQ(large.HeldBytes(), held);
  EXPECT_LT(held, static_cast<int64_t>(DistanceSample::kExact * sizeof(double)));
}

}  // namespace
}  // namespace imr::pipeline
