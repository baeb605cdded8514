// The front end and the engine overlapped (issue 18): work made ahead on a thread of its own, up
// to `depth` items ahead of the one taking it, so that while the engine applies keyframe k the
// image front end already makes k + 1 (PrefetchingSource), and inside the front end the features
// plugin tracks frame k + 1 while the refiner plugin takes frame k (front_end.cc).
//
// What the taker gets is exactly what the maker gives, in the same order: the items before a
// failure, then the maker's exception itself (same type, same message). The maker runs on one
// thread only (the prefetcher's, or a Lane), one call at a time.
#pragma once

#include "host/io/keyframe_source.h"

#include <condition_variable>
#include <deque>
#include <exception>
#include <functional>
#include <mutex>
#include <stdexcept>
#include <thread>
#include <utility>

namespace imr::pipeline {

// A thread of its own that runs the functions given to it, one at a time, in order. The SDK
// promises a plugin that create, every call and destroy of an instance come from one thread
// (imr/sdk/plugin.h): with the overlap, the features and refiner instances each live on a lane,
// made, called and destroyed there.
class Lane {
 public:
  Lane() : thread_([this] { Work(); }) {}
  // Runs what was posted, then joins.
  ~Lane() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      stop_ = true;
    }
    changed_.notify_all();
    thread_.join();
  }
  Lane(const Lane&) = delete;
  Lane& operator=(const Lane&) = delete;

  // Runs `f` on the lane after what was posted before and waits for it; rethrows what it throws.
  void Run(const std::function<void()>& f) {
    std::exception_ptr error;
    bool done = false;
    Post([&] {
      try {
        f();
      } catch (...) {
        error = std::current_exception();
      }
      std::lock_guard<std::mutex> lock(mutex_);
      done = true;
      changed_.notify_all();
    });
    std::unique_lock<std::mutex> lock(mutex_);
    changed_.wait(lock, [&] { return done; });
    lock.unlock();
    if (error) std::rethrow_exception(error);
  }
  // Runs `f` on the lane after what was posted before, and returns at once. `f` must not throw.
  void Post(std::function<void()> f) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      tasks_.push_back(std::move(f));
    }
    changed_.notify_all();
  }

 private:
  void Work() {
    std::unique_lock<std::mutex> lock(mutex_);
    for (;;) {
      changed_.wait(lock, [&] { return stop_ || !tasks_.empty(); });
      if (tasks_.empty()) return;  // stop_, and nothing left
      std::function<void()> f = std::move(tasks_.front());
      tasks_.pop_front();
      lock.unlock();
      f();
      lock.lock();
    }
  }

  std::mutex mutex_;
  std::condition_variable changed_;
  std::deque<std::function<void()>> tasks_;
  bool stop_ = false;
  std::thread thread_;  // last: started once the rest is made
};

template <class Item>
class Prefetcher {
 public:
  // Makes the next item; false when there is none; may throw.
  using Make = std::function<bool(Item*)>;
  // depth >= 1: items made ahead and not yet taken. `lane`: where the maker runs (it must
  // outlive this); null: on a thread of this prefetcher's own.
  Prefetcher(Make make, int depth, Lane* lane = nullptr)
      : make_(std::move(make)), depth_(static_cast<std::size_t>(depth)), lane_(lane) {
    if (!make_ || depth < 1) throw std::invalid_argument("Prefetcher: needs a maker and a depth >= 1");
  }
  // Stops making and waits for the maker to be done: a call in progress returns first (it is not
  // interrupted; a hung plugin is the stage watchdog's), no further call is made.
  ~Prefetcher() {
    std::unique_lock<std::mutex> lock(mutex_);
    stop_ = true;
    changed_.notify_all();
    changed_.wait(lock, [&] { return !producing_; });
    lock.unlock();
    if (thread_.joinable()) thread_.join();
  }
  Prefetcher(const Prefetcher&) = delete;
  Prefetcher& operator=(const Prefetcher&) = delete;

  // The next item; false at the end, then always. The first call starts the maker. Once it has
  // returned false (or thrown) the maker is done, and what it wrote is visible to the caller.
  bool Take(Item* item) {
    std::unique_lock<std::mutex> lock(mutex_);
    if (!started_) {
      started_ = producing_ = true;
      if (lane_ != nullptr)
        lane_->Post([this] { Produce(); });
      else
        thread_ = std::thread([this] { Produce(); });
    }
    changed_.wait(lock, [&] { return !ready_.empty() || !producing_; });
    if (!ready_.empty()) {
      *item = std::move(ready_.front());
      ready_.pop_front();
      changed_.notify_all();
      return true;
    }
    if (error_) {
      std::exception_ptr error = std::exchange(error_, nullptr);
      lock.unlock();
      std::rethrow_exception(error);
    }
    return false;
  }

 private:
  void Produce() {
    std::unique_lock<std::mutex> lock(mutex_);
    for (;;) {
      changed_.wait(lock, [&] { return stop_ || ready_.size() < depth_; });
      if (stop_) break;
      lock.unlock();
      Item item;
      bool more = false;
      std::exception_ptr error;
      try {
        more = make_(&item);
      } catch (...) {
        error = std::current_exception();
      }
      lock.lock();
      if (!more) {
        error_ = error;
        break;
      }
      ready_.push_back(std::move(item));
      changed_.notify_all();
    }
    producing_ = false;  // the mutex hands what the maker wrote to the taker
    changed_.notify_all();
  }

  Make make_;
  const std::size_t depth_;
  Lane* lane_;
  std::thread thread_;  // without a lane
  std::mutex mutex_;
  std::condition_variable changed_;  // an item was made or taken, the maker is done, or stop
  std::deque<Item> ready_;
  bool started_ = false;
  bool producing_ = false;    // the maker may still be called
  std::exception_ptr error_;  // what the maker threw, handed over after the items before it
  bool stop_ = false;
};

// A KeyframeSource whose Next comes from another's, made ahead. The front end never reads the
// engine's state, so making keyframes earlier changes no keyframe. The inner's other methods are
// forwarded: Camera and PointColor may be called while its Next runs (the inner must allow it:
// the image front end's cameras are fixed when it opens), KeyframeCount at any time, Summary and
// Evaluate only once Next has returned false.
class PrefetchingSource : public io::KeyframeSource {
 public:
  // `inner` must outlive this source; its Next runs on `lane` (null: a thread of its own).
  PrefetchingSource(io::KeyframeSource* inner, int depth, Lane* lane = nullptr)
      : inner_(inner),
        ahead_([inner](Item* i) { return inner->Next(&i->update, &i->info); }, depth, lane) {}

  bool Next(engine::KeyframeUpdate* update, io::KeyframeInfo* info) override {
    Item item;
    if (!ahead_.Take(&item)) return false;
    *update = std::move(item.update);
    *info = item.info;
    return true;
  }
  int KeyframeCount() const override { return inner_->KeyframeCount(); }
  nlohmann::json Evaluate(const engine::Mesh& mesh) const override { return inner_->Evaluate(mesh); }
  bool CanEvaluate() const override { return inner_->CanEvaluate(); }
  std::unique_ptr<io::BlockEvaluation> EvaluateInBlocks() const override {
    return inner_->EvaluateInBlocks();
  }
  const io::CameraGeometry* Camera(uint64_t camera_id) const override {
    return inner_->Camera(camera_id);
  }
  bool PointColor(uint64_t point_id, std::array<uint8_t, 3>* rgb) const override {
    return inner_->PointColor(point_id, rgb);
  }
  bool Keypoint(uint64_t camera_id, uint64_t point_id, std::array<double, 2>* xy) const override {
    return inner_->Keypoint(camera_id, point_id, xy);
  }
  nlohmann::json Summary() const override { return inner_->Summary(); }

 private:
  struct Item {
    engine::KeyframeUpdate update;
    io::KeyframeInfo info;
  };
  io::KeyframeSource* inner_;
  Prefetcher<Item> ahead_;
};

}  // namespace imr::pipeline
