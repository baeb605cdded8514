#include "host/pipeline/stage_watch.h"

#include "host/util/log.h"

#include <cmath>
#include <cstdio>
#include <cstdlib>

namespace imr::pipeline {
namespace {

using Clock = std::chrono::steady_clock;

// How often the watchdog looks when nothing is due sooner: a timeout fires at most this late.
constexpr auto kPoll = std::chrono::milliseconds(100);

std::string Seconds(double s) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%g s", s);
  return buf;
}

}  // namespace

WatchedStage WatchedStageOf(const io::StageSpec& stage, double default_seconds) {
  WatchedStage w{stage.kind, stage.plugin, stage.json_path, 0.0, ""};
  if (stage.timeout_seconds > 0.0) {
    w.timeout_seconds = stage.timeout_seconds;
    w.limit_source = stage.json_path + ".timeout_seconds";
  } else if (default_seconds > 0.0) {
    w.timeout_seconds = default_seconds;
    w.limit_source = "--stage-timeout";
  }
  return w;
}

std::string CheckStageTimeout(double seconds) {
  if (std::isfinite(seconds) && seconds >= 0.0 && seconds <= io::kMaxStageTimeoutSeconds) return {};
  return "expected a number of seconds >= 0 (0: no limit) and at most " +
         std::to_string(static_cast<long>(io::kMaxStageTimeoutSeconds)) + " (a year)";
}

StageWatch::StageWatch(TimeoutHandler on_timeout) : on_timeout_(std::move(on_timeout)) {
  if (!on_timeout_)
    on_timeout_ = [](const std::string& message) {
      LogError(message);
      std::_Exit(kStageTimeoutExitCode);
    };
}

StageWatch::~StageWatch() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  wake_.notify_all();
  if (thread_.joinable()) thread_.join();
}

StageWatch::Call StageWatch::Enter(const WatchedStage& stage) {
  if (!(stage.timeout_seconds > 0.0)) return Call(nullptr, 0);
  std::lock_guard<std::mutex> lock(mutex_);
  const uint64_t id = next_id_++;
  calls_.emplace(id, Active{&stage,
                            Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                               std::chrono::duration<double>(stage.timeout_seconds)),
                            std::this_thread::get_id()});
  if (!thread_.joinable()) thread_ = std::thread([this] { Run(); });
  return Call(this, id);
}

void StageWatch::Leave(uint64_t id) {
  std::lock_guard<std::mutex> lock(mutex_);
  calls_.erase(id);
}

void StageWatch::SetPosition(std::string position) {
  std::lock_guard<std::mutex> lock(mutex_);
  positions_[std::this_thread::get_id()] = std::move(position);
}

void StageWatch::Run() {
  std::unique_lock<std::mutex> lock(mutex_);
  while (!stop_) {
    const auto now = Clock::now();
    auto wait = Clock::duration(kPoll);
    Active* due = nullptr;
    for (auto& [id, call] : calls_) {
      if (call.reported) continue;
      if (now >= call.deadline) {
        due = &call;
        break;
      }
      wait = std::min(wait, call.deadline - now);
    }
    if (due != nullptr) {
      const WatchedStage& s = *due->stage;
      const auto at = positions_.find(due->thread);
      const std::string position = at == positions_.end() ? std::string() : at->second;
      const std::string message =
          "stage \"" + s.kind + "\" (" + s.json_path +
          (s.plugin.empty() ? std::string() : ", plugin " + s.plugin) + ") did not return within " +
          Seconds(s.timeout_seconds) +
          (position.empty() ? std::string() : " (" + position + ")") + "; the limit is " +
          s.limit_source;
      due->reported = true;
      // The handler ends the process; unlocked, so that a handler that returns (tests) does not
      // block the watched threads.
      lock.unlock();
      on_timeout_(message);
      lock.lock();
      continue;
    }
    wake_.wait_for(lock, wait);
  }
}

}  // namespace imr::pipeline
