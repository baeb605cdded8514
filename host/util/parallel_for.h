// A minimal parallel loop (the evaluation's distances, synthetic::EvaluateMesh): std::thread
// workers take chunks of an index range from a shared counter (dynamic balance: distance queries
// vary a lot in cost). No pool: each call starts and joins its threads, which costs microseconds
// against seconds of queries.
#pragma once

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

#include "host/util/thread_pool.h"

namespace imr::util {

// Calls fn(begin, end) over [0, n) in chunks of `chunk`, on ResolveThreads(threads) threads. The
// first exception thrown by fn is rethrown here once every thread has stopped.
template <typename Fn>
void ParallelFor(std::size_t n, int threads, Fn&& fn, std::size_t chunk = 4096) {
  if (n == 0) return;
  const std::size_t chunks = (n + chunk - 1) / chunk;
  const int workers = static_cast<int>(std::min<std::size_t>(ResolveThreads(threads), chunks));
  std::atomic<std::size_t> next{0};
  std::exception_ptr error;
  std::mutex error_mutex;
  auto work = [&] {
    try {
      for (std::size_t c = next++; c < chunks; c = next++)
        fn(c * chunk, std::min(n, (c + 1) * chunk));
    } catch (...) {
      std::lock_guard<std::mutex> lock(error_mutex);
      if (!error) error = std::current_exception();
      next = chunks;  // the others stop at their next chunk
    }
  };
  if (workers <= 1) {
    work();
  } else {
    std::vector<std::thread> pool;
    pool.reserve(workers);
    for (int i = 0; i < workers; ++i) pool.emplace_back(work);
    for (auto& t : pool) t.join();
  }
  if (error) std::rethrow_exception(error);
}

}  // namespace imr::util
