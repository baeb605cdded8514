// The front end and the engine overlapped (issue 18): a KeyframeSource that calls another's Next
// on a thread of its own, up to `depth` keyframes ahead of its caller, so that while the engine
// applies keyframe k the image front end (read, features, refiner) already makes k + 1.
//
// What the caller gets is exactly what the inner source gives, in the same order: the keyframes
// before a failure, then the inner's exception itself (same type, same message). The inner's
// Next runs on the prefetching thread only, one call at a time; the front end never reads the
// engine's state, so making keyframes earlier changes no keyframe. The inner's other methods are
// forwarded: Camera and PointColor may be called while Next runs (the inner must allow it: the
// image front end's cameras are fixed when it opens), KeyframeCount at any time, Summary and
// Evaluate only once Next has returned false (the prefetching thread has ended by then).
#pragma once

#include "host/io/keyframe_source.h"

#include <condition_variable>
#include <deque>
#include <exception>
#include <mutex>
#include <thread>

namespace imr::pipeline {

class PrefetchingSource : public io::KeyframeSource {
 public:
  // `inner` must outlive this source. depth >= 1: keyframes made ahead and not yet taken.
  PrefetchingSource(io::KeyframeSource* inner, int depth);
  // Stops the prefetching thread and joins it: waits for a Next of the inner in progress to
  // return (it is not interrupted; a hung plugin is the stage watchdog's), makes no further call.
  ~PrefetchingSource() override;
  PrefetchingSource(const PrefetchingSource&) = delete;
  PrefetchingSource& operator=(const PrefetchingSource&) = delete;

  // The first call starts the thread.
  bool Next(engine::KeyframeUpdate* update, io::KeyframeInfo* info) override;
  int KeyframeCount() const override { return inner_->KeyframeCount(); }
  nlohmann::json Evaluate(const engine::Mesh& mesh) const override { return inner_->Evaluate(mesh); }
  const io::CameraGeometry* Camera(uint64_t camera_id) const override {
    return inner_->Camera(camera_id);
  }
  bool PointColor(uint64_t point_id, std::array<uint8_t, 3>* rgb) const override {
    return inner_->PointColor(point_id, rgb);
  }
  nlohmann::json Summary() const override { return inner_->Summary(); }

 private:
  struct Item {
    engine::KeyframeUpdate update;
    io::KeyframeInfo info;
  };
  void Produce();
  void Stop();

  io::KeyframeSource* inner_;
  const std::size_t depth_;
  std::thread thread_;
  std::mutex mutex_;
  std::condition_variable changed_;  // an item was made or taken, the inner ended, or stop
  std::deque<Item> ready_;
  bool ended_ = false;             // the inner returned false or threw; its thread is ending
  std::exception_ptr error_;       // what the inner threw, handed over after the items before it
  bool stop_ = false;
};

}  // namespace imr::pipeline
