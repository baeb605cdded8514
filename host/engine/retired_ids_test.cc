#include "host/engine/retired_ids.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <random>
#include <set>

namespace imr::engine::detail {
namespace {

// Adds `ids` to a RetiredIds and a std::set, then asks both about every id near them.
void ExpectSameAsASet(const std::vector<uint64_t>& ids, RetiredIds* retired) {
  std::set<uint64_t> truth;
  for (uint64_t id : ids) {
    retired->Add(id);
    truth.insert(id);
  }
  EXPECT_EQ(retired->size(), static_cast<int64_t>(truth.size()));
  for (uint64_t id : truth)
    for (uint64_t near : {id - 1, id, id + 1, id + 4096, id - 4096})
      ASSERT_EQ(retired->Contains(near), truth.count(near) > 0) << near;
}

TEST(RetiredIds, InOrderWithGapsCostsABitAnId) {
  // An image drive's shape: 2,000 frames of 1,000 track ids each; a point of every third track
  // is forgotten, some frames later and not in id order.
  std::mt19937_64 rng(7);
  std::vector<uint64_t> ids;
  for (uint64_t frame = 0; frame < 2000; ++frame) {
    std::vector<uint64_t> these;
    for (uint64_t k = 0; k < 1000; ++k)
      if (rng() % 3 == 0) these.push_back(frame * 1000 + k);
    std::shuffle(these.begin(), these.end(), rng);
    ids.insert(ids.end(), these.begin(), these.end());
  }
  RetiredIds retired;
  ExpectSameAsASet(ids, &retired);
  // 2,000,000 ids named: a bit each is 250 kB (runs of consecutive ids took 48 bytes a gap:
  // about 21 MB here).
  EXPECT_LT(retired.MemoryBytes(), 300 * 1000) << retired.MemoryBytes();
}

TEST(RetiredIds, ConsecutiveIdsCostNearlyNothing) {
  std::vector<uint64_t> ids;
  for (uint64_t id = 1000; id < 4'000'000; ++id) ids.push_back(id);
  RetiredIds retired;
  for (uint64_t id : ids) retired.Add(id);
  EXPECT_EQ(retired.size(), 4'000'000 - 1000);
  EXPECT_FALSE(retired.Contains(999));
  EXPECT_TRUE(retired.Contains(1000));
  EXPECT_TRUE(retired.Contains(3'999'999));
  EXPECT_FALSE(retired.Contains(4'000'000));
  // 977 full chunks of a map entry each.
  EXPECT_LT(retired.MemoryBytes(), 100 * 1000) << retired.MemoryBytes();
}

TEST(RetiredIds, ScatteredIdsAndTheEnds) {
  std::mt19937_64 rng(11);
  std::vector<uint64_t> ids = {0, 1, 4095, 4096, UINT64_MAX, UINT64_MAX - 1};
  for (int k = 0; k < 20000; ++k) ids.push_back(rng());
  for (int k = 0; k < 20000; ++k) ids.push_back(rng() % 50000);  // dense and repeated
  RetiredIds retired;
  ExpectSameAsASet(ids, &retired);
  // Scattered ids cost about a chunk's entry each, a few times a run's 48 bytes.
  EXPECT_LT(retired.MemoryBytes(), 20000 * 200) << retired.MemoryBytes();
}

TEST(RetiredIds, EmptyHoldsNothing) {
  RetiredIds retired;
  EXPECT_TRUE(retired.empty());
  EXPECT_FALSE(retired.Contains(0));
  EXPECT_FALSE(retired.Contains(UINT64_MAX));
  retired.Add(5);
  retired.Add(5);
  EXPECT_FALSE(retired.empty());
  EXPECT_EQ(retired.size(), 1);
}

}  // namespace
}  // namespace imr::engine::detail
