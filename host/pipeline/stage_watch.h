// A watchdog for calls into plugins (issue 9). A plugin that hangs cannot be unwound from
// another thread, so when a watched call runs past its stage's timeout a watchdog thread builds
// the message (which stage, which plugin, where the sequence was) and hands it to a handler that
// reports the failure and ends the process; `imr run` runs each sequence in its own process, so
// the batch records that sequence as failed and goes on.
//
// The code that calls a plugin marks the call: `auto call = watch.Enter(stage);` ... the call
// ... (the Call's destructor marks the end). One call is watched at a time: the pipeline calls its
// plugins from one thread.
#pragma once

#include "host/engine/weight_transfer_policy.h"
#include "host/io/job.h"

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <map>
#include <mutex>
#include <string>
#include <thread>
#include <utility>

namespace imr::pipeline {

// Exit status of a sequence's process that a stage timeout ended (as timeout(1)'s).
inline constexpr int kStageTimeoutExitCode = 124;

// What a watched call belongs to, for the timeout and the message.
struct WatchedStage {
  std::string kind;          // "features", "refiner", "weight_policy", "exporter"
  std::string plugin;        // the plugin id
  std::string json_path;     // "pipeline[2]"
  double timeout_seconds = 0.0;  // 0: not watched
  std::string limit_source;  // where the limit came from: "pipeline[2].timeout_seconds" or "--stage-timeout"
};

// A job stage's watch: its own timeout_seconds, else `default_seconds` (imr run --stage-timeout;
// 0: none).
WatchedStage WatchedStageOf(const io::StageSpec& stage, double default_seconds);

// "" when `seconds` is a usable timeout (0 = none, or in (0, io::kMaxStageTimeoutSeconds]), else what
// is expected.
std::string CheckStageTimeout(double seconds);

class StageWatch {
 public:
  // Called on the watchdog thread with the message once a watched call is past its deadline.
  // In a sequence's process it reports the failure and ends the process; if it returns, the
  // call is not reported again.
  using TimeoutHandler = std::function<void(const std::string& message)>;

  // Without a handler, a timeout is logged as an error and the process exits with
  // kStageTimeoutExitCode.
  explicit StageWatch(TimeoutHandler on_timeout = {});
  ~StageWatch();
  StageWatch(const StageWatch&) = delete;
  StageWatch& operator=(const StageWatch&) = delete;

  // Marks a call in progress until destroyed. Inert when the stage has no timeout.
  class Call {
   public:
    Call(Call&& o) noexcept : watch_(std::exchange(o.watch_, nullptr)), id_(o.id_) {}
    Call& operator=(Call&&) = delete;
    Call(const Call&) = delete;
    ~Call() {
      if (watch_ != nullptr) watch_->Leave(id_);
    }

   private:
    friend class StageWatch;
    Call(StageWatch* watch, uint64_t id) : watch_(watch), id_(id) {}
    StageWatch* watch_;
    uint64_t id_;
  };
  // `stage` must outlive the call. Starts the watchdog thread on the first watched call.
  [[nodiscard]] Call Enter(const WatchedStage& stage);

  // Where the calling thread's part of the sequence is, for the message of its calls:
  // "keyframe 3, frame 15".
  void SetPosition(std::string position);

 private:
  // A watched call in progress.
  struct Active {
    const WatchedStage* stage;
    std::chrono::steady_clock::time_point deadline;
    std::thread::id thread;
    bool reported = false;  // its timeout was handed to the handler
  };
  void Leave(uint64_t id);
  void Run();

  TimeoutHandler on_timeout_;
  std::mutex mutex_;
  std::condition_variable wake_;
  std::thread thread_;
  bool stop_ = false;
  uint64_t next_id_ = 1;
  std::map<uint64_t, Active> calls_;
  std::map<std::thread::id, std::string> positions_;
};

// A weight policy whose every Transfer is a watched call of `stage` (the engine calls the
// policy from inside an update, so this is where the plugin's time can be told apart).
class WatchedPolicy : public engine::WeightTransferPolicy {
 public:
  WatchedPolicy(engine::WeightTransferPolicy* policy, StageWatch* watch, WatchedStage stage)
      : policy_(policy), watch_(watch), stage_(std::move(stage)) {}
  void Transfer(const engine::TransferInput& in, double* out_weights) override {
    const StageWatch::Call call = watch_->Enter(stage_);
    policy_->Transfer(in, out_weights);
  }
  std::string Name() const override { return policy_->Name(); }

 private:
  engine::WeightTransferPolicy* policy_;
  StageWatch* watch_;
  WatchedStage stage_;
};

}  // namespace imr::pipeline
