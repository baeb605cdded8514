// The allocator's figures move with what the program holds: the drive bench and the trace read
// them beside the RSS to tell a leak (allocated grows) from memory freeing kept (resident does).
#include "host/util/process_memory.h"

#include <gtest/gtest.h>

#include <cstring>
#include <memory>
#include <vector>

namespace imr {
namespace {

TEST(ProcessMemory, HeapFiguresFollowWhatIsHeld) {
  const HeapBytes before = CurrentHeapBytes();
#ifdef IMR_TEST_JEMALLOC
  ASSERT_EQ(before.allocator, "jemalloc");
#else
  ASSERT_EQ(before.allocator, "glibc");
#endif
  constexpr std::size_t kBlock = 1 << 16, kBlocks = 1024;  // 64 MB in small blocks
  std::vector<std::unique_ptr<char[]>> blocks;
  for (std::size_t i = 0; i < kBlocks; ++i) {
    blocks.emplace_back(new char[kBlock]);
    std::memset(blocks.back().get(), static_cast<int>(i), kBlock);
  }
  const HeapBytes held = CurrentHeapBytes();
  // jemalloc's counts lag its thread caches by up to a few hundred kB.
  EXPECT_GE(held.allocated, before.allocated + kBlock * kBlocks * 95 / 100);
  EXPECT_GE(held.resident, held.allocated);
  EXPECT_LE(held.allocated, before.allocated + 2 * kBlock * kBlocks);
  EXPECT_GE(ResidentBytes(), kBlock * kBlocks);
  blocks.clear();
  const HeapBytes after = CurrentHeapBytes();
  EXPECT_LT(after.allocated, held.allocated - kBlock * kBlocks / 2);
}

}  // namespace
}  // namespace imr
