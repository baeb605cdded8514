#include "host/util/thread_pool.h"

#include <sched.h>

#include <algorithm>
#include <chrono>

namespace imr::util {

int AvailableCores() {
  cpu_set_t set;
  CPU_ZERO(&set);
  if (sched_getaffinity(0, sizeof(set), &set) == 0) {
    const int n = CPU_COUNT(&set);
    if (n > 0) return n;
  }
  return std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
}

int ResolveThreads(int requested) { return requested > 0 ? requested : AvailableCores(); }

ThreadPool::ThreadPool(int threads) : threads_(std::max(1, threads)) {
  for (int w = 1; w < threads_; ++w) workers_.emplace_back([this, w] { Work(w); });
}

ThreadPool::~ThreadPool() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  wake_.notify_all();
  for (std::thread& t : workers_) t.join();
}

// Takes tasks one at a time until none is left (tasks are coarse: a batch of rays each).
void ThreadPool::Drain(int worker) {
  for (;;) {
    std::size_t task;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (next_ >= tasks_) return;
      task = next_++;
    }
    try {
      (*fn_)(task, worker);
    } catch (...) {
      std::lock_guard<std::mutex> lock(mutex_);
      if (!error_) error_ = std::current_exception();
      next_ = tasks_;  // the others stop after their current task
    }
  }
}

void ThreadPool::Work(int worker) {
  unsigned long seen = 0;
  for (;;) {
    // Spin up to 200 us for the next round before sleeping until it is announced.
    const auto spin_end = std::chrono::steady_clock::now() + std::chrono::microseconds(200);
    for (int i = 0; round_.load(std::memory_order_acquire) == seen &&
                    !stop_.load(std::memory_order_acquire);
         ++i) {
      if ((i & 63) == 63 && std::chrono::steady_clock::now() > spin_end) break;
#if defined(__x86_64__) || defined(__i386__)
      __builtin_ia32_pause();
#endif
    }
    {
      std::unique_lock<std::mutex> lock(mutex_);
      wake_.wait(lock, [&] { return stop_ || round_ != seen; });
      if (stop_) return;
      seen = round_;
      ++busy_;
    }
    Drain(worker);
    {
      std::lock_guard<std::mutex> lock(mutex_);
      --busy_;
    }
    done_.notify_all();
  }
}

void ThreadPool::Run(std::size_t tasks, const std::function<void(std::size_t, int)>& fn) {
  if (tasks == 0) return;
  if (workers_.empty() || tasks == 1) {
    for (std::size_t t = 0; t < tasks; ++t) fn(t, 0);
    return;
  }
  {
    std::lock_guard<std::mutex> lock(mutex_);
    fn_ = &fn;
    tasks_ = tasks;
    next_ = 0;
    error_ = nullptr;
    ++round_;
  }
  wake_.notify_all();
  Drain(0);
  std::exception_ptr error;
  {
    // Every task has been handed out; wait for the workers still inside this round.
    std::unique_lock<std::mutex> lock(mutex_);
    done_.wait(lock, [&] { return busy_ == 0; });
    fn_ = nullptr;
    tasks_ = 0;
    error = error_;
  }
  if (error) std::rethrow_exception(error);
}

}  // namespace imr::util
