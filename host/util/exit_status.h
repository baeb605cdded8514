// imr's exit statuses, one contract for every command (sysexits.h's EX_USAGE for usage, so
// that 1..63 can count failures).
#pragma once

#include <algorithm>

namespace imr {

inline constexpr int kExitOk = 0;
// A single-result command (evaluate, render, submit) failed.
inline constexpr int kExitFailed = 1;
// The most failed sequences an exit status can count: 63 means 63 or more.
inline constexpr int kExitMaxFailures = 63;
// Bad command line or invalid job: nothing ran (EX_USAGE).
inline constexpr int kExitUsage = 64;

// `imr run` and `imr report`: 0 when every sequence is fine, else how many failed (did not
// run, were interrupted), up to kExitMaxFailures.
inline int ExitStatusForFailures(int failed) {
  return std::clamp(failed, 0, kExitMaxFailures);
}

}  // namespace imr
