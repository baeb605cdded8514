// Progress of a batch. On a terminal: one status line redrawn in place (sequences done of all,
// failures, each running sequence's keyframes, frame and ETA, the batch's ETA). Elsewhere (a
// Slurm log, a pipe): one plain line every few seconds. Off with --quiet.
#pragma once

#include "host/pipeline/run.h"

#include <chrono>
#include <string>
#include <vector>

namespace imr::batch {

enum class ProgressMode { kNone, kBar, kLines };

struct RunningSequence {
  std::string name;
  pipeline::SequenceProgress progress;
  std::chrono::steady_clock::time_point started;
};

struct BatchProgress {
  int total = 0;    // sequences this run handles (skipped ones included)
  int done = 0;     // finished, failed or skipped
  int failed = 0;
  int skipped = 0;
  std::vector<RunningSequence> running;
};

class ProgressDisplay {
 public:
  // `interval`: seconds between lines in kLines mode.
  ProgressDisplay(ProgressMode mode, double interval = 5.0);
  ~ProgressDisplay() { Clear(); }
  // Redraws the bar (at most 10 times a second) or writes a line when the interval has passed.
  void Update(const BatchProgress& p, bool force = false);
  // Removes the bar before something else is printed on the terminal (the next Update redraws).
  void Clear();
  ProgressMode mode() const { return mode_; }

  // The text of one update (without the bar's terminal controls); for tests.
  static std::string Describe(const BatchProgress& p, std::chrono::steady_clock::time_point now,
                              std::chrono::steady_clock::time_point batch_start);

 private:
  ProgressMode mode_;
  double interval_;
  std::chrono::steady_clock::time_point start_, last_;
  bool drawn_ = false;
};

// "1:05", "12 s".
std::string FormatDuration(double seconds);

}  // namespace imr::batch
