// The prefetching source on made-up sources: the caller gets the inner's keyframes in order and
// then its exception (type and message); it never runs more than `depth` keyframes ahead; and it
// stops and joins its thread when dropped mid-sequence, whether the thread waits for room or is
// inside the inner's Next. The whole pipeline with it (same mesh bytes and report, errors, the
// watchdog, signals) is tested end to end in tests/front_end_test and tests/bad_input_test.
#include "host/pipeline/prefetch.h"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <stdexcept>
#include <thread>
#include <vector>

namespace imr::pipeline {
namespace {

using namespace std::chrono_literals;

// Keyframe k has camera k and one new point k; throws at keyframe `throw_at` (-1: never).
class CountingSource : public io::KeyframeSource {
 public:
  CountingSource(int count, int throw_at = -1) : count_(count), throw_at_(throw_at) {}
  bool Next(engine::KeyframeUpdate* u, io::KeyframeInfo* info) override {
    std::this_thread::sleep_for(delay_);
    const int k = made_;
    if (k == throw_at_) throw std::runtime_error("frames/" + std::to_string(k) + ".png: cannot be read");
    if (k >= count_) return false;
    *u = engine::KeyframeUpdate{};
    engine::Camera c;
    c.id = static_cast<uint64_t>(k);
    u->cameras.push_back(c);
    engine::NewPoint p;
    p.id = static_cast<uint64_t>(k);
    p.position = {1.0 * k, 2.0, 3.0};
    p.camera_ids = {c.id};
    u->new_points.push_back(p);
    *info = {k, 5 * k};
    ++made_;
    return true;
  }
  int KeyframeCount() const override { return count_; }
  nlohmann::json Summary() const override { return {{"made", made_.load()}}; }

  std::atomic<int> made_{0};
  std::chrono::milliseconds delay_{0};

 private:
  int count_, throw_at_;
};

TEST(PrefetchingSource, GivesTheInnersKeyframesInOrderThenEnds) {
  CountingSource inner(50);
  PrefetchingSource source(&inner, 2);
  EXPECT_EQ(source.KeyframeCount(), 50);
  engine::KeyframeUpdate u;
  io::KeyframeInfo info;
  for (int k = 0; k < 50; ++k) {
    ASSERT_TRUE(source.Next(&u, &info)) << k;
    EXPECT_EQ(info.index, k);
    EXPECT_EQ(info.frame, 5 * k);
    ASSERT_EQ(u.cameras.size(), 1u);
    EXPECT_EQ(u.cameras[0].id, static_cast<uint64_t>(k));
    ASSERT_EQ(u.new_points.size(), 1u);
    EXPECT_EQ(u.new_points[0].position[0], 1.0 * k);
  }
  EXPECT_FALSE(source.Next(&u, &info));
  EXPECT_FALSE(source.Next(&u, &info));  // and stays ended
  EXPECT_EQ(source.Summary()["made"], 50);
}

TEST(PrefetchingSource, NeverRunsMoreThanDepthAhead) {
  CountingSource inner(20);
  PrefetchingSource source(&inner, 2);
  engine::KeyframeUpdate u;
  io::KeyframeInfo info;
  // Waits (up to 5 s, a loaded machine) for the inner to have made `n`, then a little longer:
  // it must not make more.
  auto made_after_a_while = [&](int n) {
    for (int i = 0; i < 500 && inner.made_.load() < n; ++i) std::this_thread::sleep_for(10ms);
    std::this_thread::sleep_for(200ms);
    return inner.made_.load();
  };
  ASSERT_TRUE(source.Next(&u, &info));
  // Taken 1, 2 waiting: the inner made 3 and is not called again until one is taken.
  EXPECT_EQ(made_after_a_while(3), 3);
  ASSERT_TRUE(source.Next(&u, &info));
  EXPECT_EQ(made_after_a_while(4), 4);
}

TEST(PrefetchingSource, TheInnersErrorComesAfterTheKeyframesBeforeIt) {
  CountingSource inner(50, /*throw_at=*/7);
  PrefetchingSource source(&inner, 2);
  engine::KeyframeUpdate u;
  io::KeyframeInfo info;
  for (int k = 0; k < 7; ++k) ASSERT_TRUE(source.Next(&u, &info)) << k;
  try {
    source.Next(&u, &info);
    FAIL() << "no exception";
  } catch (const std::runtime_error& e) {
    EXPECT_STREQ(e.what(), "frames/7.png: cannot be read");
  }
  EXPECT_FALSE(source.Next(&u, &info));
}

TEST(PrefetchingSource, DroppedMidSequenceItStopsAndJoins) {
  // Its thread waiting for room (the caller stopped taking, as when the engine fails).
  {
    CountingSource inner(1000);
    PrefetchingSource source(&inner, 1);
    engine::KeyframeUpdate u;
    io::KeyframeInfo info;
    ASSERT_TRUE(source.Next(&u, &info));
    std::this_thread::sleep_for(50ms);
  }
  // Its thread inside a slow Next: the call ends, no further one is made.
  CountingSource inner(1000);
  inner.delay_ = 300ms;
  const auto start = std::chrono::steady_clock::now();
  {
    PrefetchingSource source(&inner, 2);
    engine::KeyframeUpdate u;
    io::KeyframeInfo info;
    ASSERT_TRUE(source.Next(&u, &info));
    std::this_thread::sleep_for(100ms);  // the thread is now inside the second Next
  }
  // The call in progress (usually the second) had returned when the source was gone: nothing
  // changes after, and no call was made beyond it.
  const int made = inner.made_.load();
  std::this_thread::sleep_for(400ms);
  EXPECT_EQ(inner.made_.load(), made);
  EXPECT_LE(made, 2);
  EXPECT_LT(std::chrono::steady_clock::now() - start, 3s);
  // Never asked for a keyframe: no thread was started.
  CountingSource unused(5);
  { PrefetchingSource source(&unused, 2); }
  EXPECT_EQ(unused.made_.load(), 0);
}

// The SDK's promise (one thread per plugin instance): what runs on a lane, made there, called
// there by a prefetcher and released there, all on the lane's one thread, in the order given.
TEST(Lane, RunsWhatItIsGivenInOrderOnOneThreadAndRethrows) {
  Lane lane;
  std::thread::id made, released;
  std::vector<std::thread::id> called;
  lane.Run([&] { made = std::this_thread::get_id(); });
  EXPECT_NE(made, std::this_thread::get_id());
  {
    int n = 0;
    Prefetcher<int> ahead(
        [&](int* item) {
          called.push_back(std::this_thread::get_id());
          *item = n;
          return n++ < 5;
        },
        2, &lane);
    int item = -1;
    for (int k = 0; k < 5; ++k) {
      ASSERT_TRUE(ahead.Take(&item));
      EXPECT_EQ(item, k);
    }
    EXPECT_FALSE(ahead.Take(&item));
  }
  lane.Run([&] { released = std::this_thread::get_id(); });
  EXPECT_EQ(released, made);
  ASSERT_EQ(called.size(), 6u);
  for (const std::thread::id& id : called) EXPECT_EQ(id, made);
  try {
    lane.Run([] { throw std::runtime_error("pipeline[0] (features): create failed"); });
    FAIL() << "no exception";
  } catch (const std::runtime_error& e) {
    EXPECT_STREQ(e.what(), "pipeline[0] (features): create failed");
  }
  // A prefetcher dropped while its maker waits for room on the lane: the lane is free again.
  {
    Prefetcher<int> ahead([](int* item) { *item = 1; return true; }, 1, &lane);
    int item = 0;
    ASSERT_TRUE(ahead.Take(&item));
  }
  bool ran = false;
  lane.Run([&] { ran = true; });
  EXPECT_TRUE(ran);
}

}  // namespace
}  // namespace imr::pipeline
