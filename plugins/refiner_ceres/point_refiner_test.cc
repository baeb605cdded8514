// The refiner's own state over a long drive (issue 46): what it holds follows the live tracks,
// not the frames driven. Linked from source: the C ABI does not show what an instance holds.
#include "point_refiner.hpp"
#include "test_cameras.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <deque>
#include <random>
#include <vector>

namespace imr::ceres_refiner {
namespace {

using testing::CameraAt;
using testing::kCx;
using testing::kCy;
using testing::kFx;
using testing::kHeight;
using testing::kWidth;

TEST(IdRuns, MergesNeighboursAndKnowsWhatItHolds) {
  IdRuns r;
  for (uint64_t id : {5, 7, 9}) r.Add(id);
  EXPECT_EQ(r.runs(), 3u);
  r.Add(6);  // joins 5 and 7
  r.Add(8);  // joins 5..7 and 9
  EXPECT_EQ(r.runs(), 1u);
  r.Add(4);
  r.Add(10);
  r.Add(7);  // already in
  EXPECT_EQ(r.runs(), 1u);
  for (uint64_t id = 4; id <= 10; ++id) EXPECT_TRUE(r.Contains(id)) << id;
  EXPECT_FALSE(r.Contains(3));
  EXPECT_FALSE(r.Contains(11));
  r.Add(20);
  EXPECT_EQ(r.runs(), 2u);
  EXPECT_FALSE(r.Contains(15));
}

// A tracker numbering its tracks in order, 12 new ones a frame on the facades ahead, each
// followed for 3 to 40 frames (so tracks end out of order), keyframes every 5 frames. The
// refiner's records after `keyframes` keyframes.
std::size_t HeldAfter(int keyframes) {
  PointRefiner refiner(RefinerOptions{});
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  struct Live {
    uint64_t id;
    double x, y, z;
    uint64_t end;
  };
  std::deque<Live> live;
  uint64_t next_id = 0;
  RefinerUpdate update;
  const uint64_t frames = static_cast<uint64_t>(5 * keyframes);
  for (uint64_t f = 0; f < frames; ++f) {
    for (int k = 0; k < 12; ++k) {
      const double z = static_cast<double>(f) + 10.0 + 40.0 * u(rng);
      live.push_back({next_id++, u(rng) < 0.5 ? -7.0 : 8.0, -3.0 + 4.6 * u(rng), z,
                      f + 3 + static_cast<uint64_t>(37.0 * u(rng))});
    }
    std::vector<imr_track_observation> obs;
    std::deque<Live> still;
    for (const Live& t : live) {
      const double depth = t.z - static_cast<double>(f);
      const double px = kFx * t.x / depth + kCx, py = kFx * t.y / depth + kCy;
      if (f >= t.end || depth < 2.0 || px < 0 || py < 0 || px > kWidth - 1 || py > kHeight - 1)
        continue;  // the track ends: never seen again
      obs.push_back({t.id, px, py});
      still.push_back(t);
    }
    live.swap(still);
    refiner.AddFrame(CameraAt(f), obs, f % 5 == 0, &update);
  }
  return refiner.held_records();
}

TEST(PointRefiner, WhatItHoldsStaysFlatOverTheDrive) {
  // 12 tracks end a frame: a record kept per ended track (or per frame) adds 750+ records
  // between the two drives; the live tracks and their cameras are the same few hundred.
  const std::size_t at_50 = HeldAfter(50), at_200 = HeldAfter(200);
  EXPECT_GT(at_50, 100u);  // the live tracks are counted
  EXPECT_LE(static_cast<double>(at_200), 1.1 * static_cast<double>(at_50))
      << "held records at 50 keyframes " << at_50 << ", at 200 keyframes " << at_200;
}

}  // namespace
}  // namespace imr::ceres_refiner
