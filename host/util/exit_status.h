// imr's exit statuses, one contract for every command. 1..63 count failures (of sequences, or
// 1 for a single-result command); 64 and up are sysexits.h's codes for what is not a failure
// of the work itself: bad usage, and the environment (a batch folder that cannot be created,
// another run holding it). A script or a Slurm array task's state can tell them apart.
#pragma once

#include <algorithm>

namespace imr {

inline constexpr int kExitOk = 0;
// A single-result command (evaluate, render, submit) failed.
inline constexpr int kExitFailed = 1;
// The most failed sequences an exit status can count: 63 means 63 or more.
inline constexpr int kExitMaxFailures = 63;
// Bad command line or invalid job (also a job file that cannot be read): nothing ran (EX_USAGE).
inline constexpr int kExitUsage = 64;
// The batch folder cannot be created or written (a read-only or full file system, permissions):
// nothing ran (EX_CANTCREAT).
inline constexpr int kExitCantCreate = 73;
// Another `imr run` holds the batch folder's lock: nothing ran; retry when it has ended
// (EX_TEMPFAIL).
inline constexpr int kExitTempFail = 75;

// `imr run` and `imr report`: 0 when every sequence is fine, else how many failed (did not
// run, were interrupted), up to kExitMaxFailures.
inline int ExitStatusForFailures(int failed) {
  return std::clamp(failed, 0, kExitMaxFailures);
}

}  // namespace imr
