// Wall-clock durations for timings in reports, logs and benchmarks (the steady clock: never
// jumps with the system time).
#pragma once

#include <chrono>

namespace imr {

// Seconds elapsed since `start`.
inline double SecondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace imr
