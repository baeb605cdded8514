// A fixed set of worker threads for data-parallel loops inside one process (the engine's ray
// casting). Workers are started once and reused: a keyframe runs several short parallel phases,
// and starting threads for each would cost more than some of them.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstddef>
#include <exception>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace imr::util {

// The cores this process may run on: its CPU affinity mask (what `taskset` and Slurm's
// --cpus-per-task give it), not the machine's core count. At least 1.
int AvailableCores();

// `requested` threads, or AvailableCores() when requested <= 0.
int ResolveThreads(int requested);

class ThreadPool {
 public:
  // threads <= 1: no worker is started and Run calls fn on the caller's thread.
  explicit ThreadPool(int threads);
  ~ThreadPool();
  ThreadPool(const ThreadPool&) = delete;
  ThreadPool& operator=(const ThreadPool&) = delete;

  int size() const { return threads_; }

  // Calls fn(task, worker) for every task in [0, tasks), each exactly once, spread over the
  // threads (the caller is worker 0); returns when all are done. Which worker runs which task is
  // not fixed: fn must not depend on it except to pick per-worker scratch. The first exception
  // thrown by fn is rethrown here after every task has stopped.
  void Run(std::size_t tasks, const std::function<void(std::size_t task, int worker)>& fn);

 private:
  void Work(int worker);
  void Drain(int worker);

  int threads_ = 1;
  std::vector<std::thread> workers_;
  std::mutex mutex_;
  std::condition_variable wake_, done_;
  const std::function<void(std::size_t, int)>* fn_ = nullptr;
  std::size_t tasks_ = 0;
  std::size_t next_ = 0;      // next task to hand out (under mutex_)
  int busy_ = 0;              // workers inside the current round
  // Written under mutex_; a worker waits for the next round spinning on them for a while first
  // (a keyframe's parallel phases come every few hundred microseconds while points move, and
  // waking a sleeping thread takes about as long as one of them).
  std::atomic<unsigned long> round_{0};
  std::atomic<bool> stop_{false};
  std::exception_ptr error_;
};

}  // namespace imr::util
