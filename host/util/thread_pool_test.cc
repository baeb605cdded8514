#include "host/util/thread_pool.h"

#include <gtest/gtest.h>

#include <sched.h>

#include <atomic>
#include <stdexcept>

namespace imr::util {
namespace {

TEST(ThreadPool, RunsEveryTaskOnceOverManyRounds) {
  for (int threads : {1, 2, 4}) {
    ThreadPool pool(threads);
    EXPECT_EQ(pool.size(), threads);
    for (int round = 0; round < 200; ++round) {
      const std::size_t n = static_cast<std::size_t>(round % 7);
      std::vector<std::atomic<int>> hits(n);
      std::atomic<int> bad_worker{0};
      pool.Run(n, [&](std::size_t t, int w) {
        hits[t].fetch_add(1);
        if (w < 0 || w >= threads) bad_worker = 1;
      });
      for (std::size_t t = 0; t < n; ++t) ASSERT_EQ(hits[t].load(), 1) << "round " << round;
      EXPECT_EQ(bad_worker.load(), 0);
    }
  }
}

TEST(ThreadPool, RethrowsTheFirstErrorAndStaysUsable) {
  ThreadPool pool(2);
  EXPECT_THROW(pool.Run(16, [](std::size_t t, int) {
    if (t == 3) throw std::runtime_error("task 3");
  }), std::runtime_error);
  std::atomic<int> n{0};
  pool.Run(8, [&](std::size_t, int) { ++n; });
  EXPECT_EQ(n.load(), 8);
}

TEST(ThreadPool, AvailableCoresFollowsTheAffinityMask) {
  cpu_set_t saved;
  ASSERT_EQ(sched_getaffinity(0, sizeof(saved), &saved), 0);
  EXPECT_EQ(AvailableCores(), CPU_COUNT(&saved));
  // Restricted to one core (as `taskset -c N` would), the process sees one.
  int first = 0;
  while (!CPU_ISSET(first, &saved)) ++first;
  cpu_set_t one;
  CPU_ZERO(&one);
  CPU_SET(first, &one);
  ASSERT_EQ(sched_setaffinity(0, sizeof(one), &one), 0);
  EXPECT_EQ(AvailableCores(), 1);
  EXPECT_EQ(ResolveThreads(0), 1);
  EXPECT_EQ(ResolveThreads(3), 3);
  ASSERT_EQ(sched_setaffinity(0, sizeof(saved), &saved), 0);
}

}  // namespace
}  // namespace imr::util
