#include "host/pipeline/prefetch.h"

#include <stdexcept>
#include <utility>

namespace imr::pipeline {

PrefetchingSource::PrefetchingSource(io::KeyframeSource* inner, int depth)
    : inner_(inner), depth_(static_cast<std::size_t>(depth)) {
  if (inner_ == nullptr || depth < 1)
    throw std::invalid_argument("PrefetchingSource: needs a source and a depth >= 1");
}

PrefetchingSource::~PrefetchingSource() { Stop(); }

void PrefetchingSource::Stop() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  changed_.notify_all();
  if (thread_.joinable()) thread_.join();
}

bool PrefetchingSource::Next(engine::KeyframeUpdate* update, io::KeyframeInfo* info) {
  if (!thread_.joinable() && !ended_) thread_ = std::thread([this] { Produce(); });
  std::unique_lock<std::mutex> lock(mutex_);
  changed_.wait(lock, [&] { return !ready_.empty() || ended_; });
  if (!ready_.empty()) {
    *update = std::move(ready_.front().update);
    *info = ready_.front().info;
    ready_.pop_front();
    lock.unlock();
    changed_.notify_all();
    return true;
  }
  // The inner is done: join its thread, so that what it wrote (its stats for Summary, its
  // ground truth for Evaluate) is seen by this thread.
  lock.unlock();
  if (thread_.joinable()) thread_.join();
  if (error_) std::rethrow_exception(std::exchange(error_, nullptr));
  return false;
}

void PrefetchingSource::Produce() {
  for (;;) {
    {
      std::unique_lock<std::mutex> lock(mutex_);
      changed_.wait(lock, [&] { return stop_ || ready_.size() < depth_; });
      if (stop_) return;
    }
    Item item;
    bool more = false;
    std::exception_ptr error;
    try {
      more = inner_->Next(&item.update, &item.info);
    } catch (...) {
      error = std::current_exception();
    }
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (more) {
        ready_.push_back(std::move(item));
      } else {
        ended_ = true;
        error_ = error;
      }
    }
    changed_.notify_all();
    if (!more) return;
  }
}

}  // namespace imr::pipeline
