// The stage watchdog on its own: a call past its deadline is reported once, with the stage, the
// plugin, where the limit came from and the position; calls that return in time, and stages
// without a timeout, are never reported. The process-ending handler of `imr run` is exercised
// end to end by tests/bad_input_test (a plugin that hangs).
#include "host/pipeline/stage_watch.h"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <limits>
#include <mutex>
#include <thread>
#include <vector>

namespace imr::pipeline {
namespace {

using namespace std::chrono_literals;

struct Reports {
  std::mutex mutex;
  std::vector<std::string> messages;
  std::vector<std::string> Get() {
    std::lock_guard<std::mutex> lock(mutex);
    return messages;
  }
};

StageWatch::TimeoutHandler Recorder(Reports* r) {
  return [r](const std::string& m) {
    std::lock_guard<std::mutex> lock(r->mutex);
    r->messages.push_back(m);
  };
}

WatchedStage Policy(double seconds) {
  io::StageSpec spec;
  spec.kind = "weight_policy";
  spec.plugin = "org.example.slow";
  spec.json_path = "pipeline[2]";
  spec.timeout_seconds = seconds;
  return WatchedStageOf(spec, 0.0);
}

TEST(StageWatch, ACallPastItsDeadlineIsReportedOnceWithStagePluginAndPosition) {
  Reports reports;
  StageWatch watch(Recorder(&reports));
  const WatchedStage stage = Policy(0.05);
  watch.SetPosition("keyframe 3, frame 15");
  const auto start = std::chrono::steady_clock::now();
  {
    const StageWatch::Call call = watch.Enter(stage);
    std::this_thread::sleep_for(400ms);  // "hangs" well past 0.05 s
  }
  const std::vector<std::string> got = reports.Get();
  ASSERT_EQ(got.size(), 1u);
  EXPECT_EQ(got[0],
            "stage \"weight_policy\" (pipeline[2], plugin org.example.slow) did not return within "
            "0.05 s (keyframe 3, frame 15); the limit is pipeline[2].timeout_seconds");
  EXPECT_LT(std::chrono::steady_clock::now() - start, 2s);
}

TEST(StageWatch, CallsThatReturnInTimeAndUnwatchedStagesAreNotReported) {
  Reports reports;
  StageWatch watch(Recorder(&reports));
  const WatchedStage quick = Policy(0.3);
  for (int i = 0; i < 2000; ++i) {  // many short calls, like a policy's Transfer
    const StageWatch::Call call = watch.Enter(quick);
  }
  {
    const StageWatch::Call call = watch.Enter(quick);
    std::this_thread::sleep_for(100ms);
  }
  const WatchedStage none = Policy(0.0);
  {
    const StageWatch::Call call = watch.Enter(none);
    std::this_thread::sleep_for(400ms);  // longer than `quick`'s limit, but not watched
  }
  EXPECT_EQ(reports.Get(), std::vector<std::string>{});
}

TEST(StageWatch, TheCommandLineDefaultAppliesWhenTheStageSetsNone) {
  io::StageSpec spec;
  spec.kind = "exporter";
  spec.plugin = "org.imr.exporter.assimp";
  spec.json_path = "pipeline[3]";
  WatchedStage w = WatchedStageOf(spec, 2.5);
  EXPECT_EQ(w.timeout_seconds, 2.5);
  EXPECT_EQ(w.limit_source, "--stage-timeout");
  spec.timeout_seconds = 7;  // the stage's own wins
  w = WatchedStageOf(spec, 2.5);
  EXPECT_EQ(w.timeout_seconds, 7.0);
  EXPECT_EQ(w.limit_source, "pipeline[3].timeout_seconds");
  EXPECT_EQ(WatchedStageOf(io::StageSpec{}, 0.0).timeout_seconds, 0.0);

  EXPECT_EQ(CheckStageTimeout(0.0), "");
  EXPECT_EQ(CheckStageTimeout(30.0), "");
  EXPECT_NE(CheckStageTimeout(-1.0), "");
  EXPECT_NE(CheckStageTimeout(1e308), "");
  EXPECT_NE(CheckStageTimeout(std::numeric_limits<double>::quiet_NaN()), "");
}

TEST(StageWatch, EachOverrunIsReportedAgainAndTheWatchStopsCleanly) {
  Reports reports;
  {
    StageWatch watch(Recorder(&reports));
    const WatchedStage stage = Policy(0.05);
    for (int k = 0; k < 2; ++k) {
      watch.SetPosition("frame " + std::to_string(k));
      const StageWatch::Call call = watch.Enter(stage);
      std::this_thread::sleep_for(300ms);
    }
  }  // joins the watchdog
  const std::vector<std::string> got = reports.Get();
  ASSERT_EQ(got.size(), 2u);
  EXPECT_NE(got[0].find("(frame 0)"), std::string::npos) << got[0];
  EXPECT_NE(got[1].find("(frame 1)"), std::string::npos) << got[1];
}

// The front end's plugins run on the prefetching thread while the engine calls the policy
// (prefetch.h): a call that overruns on one thread is reported with that thread's position,
// while the other thread's calls, returning in time, are not.
TEST(StageWatch, CallsOnTwoThreadsAreWatchedAtOnceEachWithItsThreadsPosition) {
  Reports reports;
  StageWatch watch(Recorder(&reports));
  const WatchedStage policy = Policy(0.3);
  io::StageSpec spec;
  spec.kind = "features";
  spec.plugin = "org.example.hangs";
  spec.json_path = "pipeline[0]";
  spec.timeout_seconds = 0.05;
  const WatchedStage features = WatchedStageOf(spec, 0.0);
  std::atomic<bool> done{false};
  std::thread engine([&] {
    watch.SetPosition("keyframe 3, frame 15");
    while (!done) {
      const StageWatch::Call call = watch.Enter(policy);
      std::this_thread::sleep_for(1ms);
    }
  });
  watch.SetPosition("frame 16");
  {
    const StageWatch::Call call = watch.Enter(features);
    std::this_thread::sleep_for(400ms);
  }
  done = true;
  engine.join();
  const std::vector<std::string> got = reports.Get();
  ASSERT_EQ(got.size(), 1u);
  EXPECT_EQ(got[0],
            "stage \"features\" (pipeline[0], plugin org.example.hangs) did not return within "
            "0.05 s (frame 16); the limit is pipeline[0].timeout_seconds");
}

}  // namespace
}  // namespace imr::pipeline
