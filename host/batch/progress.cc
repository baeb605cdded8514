#include "host/batch/progress.h"

#include <sys/ioctl.h>
#include <unistd.h>

#include <cstdio>

namespace imr::batch {
namespace {

double Since(std::chrono::steady_clock::time_point t, std::chrono::steady_clock::time_point now) {
  return std::chrono::duration<double>(now - t).count();
}

// Share of a running sequence done, when its length is known.
double Fraction(const pipeline::SequenceProgress& p) {
  if (p.total_keyframes <= 0) return 0.0;
  return std::min(1.0, static_cast<double>(p.keyframes) / p.total_keyframes);
}

int TerminalWidth() {
  winsize w{};
  if (::ioctl(STDERR_FILENO, TIOCGWINSZ, &w) == 0 && w.ws_col > 20) return w.ws_col;
  return 100;
}

}  // namespace

std::string FormatDuration(double seconds) {
  if (!(seconds >= 0) || seconds > 1e7) return "?";
  const long s = static_cast<long>(seconds + 0.5);
  char buf[32];
  if (s < 60)
    std::snprintf(buf, sizeof(buf), "%ld s", s);
  else if (s < 3600)
    std::snprintf(buf, sizeof(buf), "%ld:%02ld", s / 60, s % 60);
  else
    std::snprintf(buf, sizeof(buf), "%ld:%02ld:%02ld", s / 3600, (s / 60) % 60, s % 60);
  return buf;
}

ProgressDisplay::ProgressDisplay(ProgressMode mode, double interval)
    : mode_(mode), interval_(interval), start_(std::chrono::steady_clock::now()), last_(start_) {}

std::string ProgressDisplay::Describe(const BatchProgress& p, std::chrono::steady_clock::time_point now,
                                      std::chrono::steady_clock::time_point batch_start) {
  std::string s = std::to_string(p.done) + "/" + std::to_string(p.total) + " sequences done";
  if (p.failed > 0) s += ", " + std::to_string(p.failed) + " failed";
  if (p.skipped > 0) s += ", " + std::to_string(p.skipped) + " up to date";
  double work = 0.0;
  for (const RunningSequence& r : p.running) {
    s += " | " + r.name;
    const auto& q = r.progress;
    if (q.keyframes == 0) {
      s += " starting";
      continue;
    }
    s += " keyframe " + std::to_string(q.keyframes);
    if (q.total_keyframes > 0) s += "/" + std::to_string(q.total_keyframes);
    s += " (frame " + std::to_string(q.frame) + ")";
    const double f = Fraction(q);
    work += f;
    if (f > 0.0 && f < 1.0) s += " ETA " + FormatDuration(Since(r.started, now) * (1.0 - f) / f);
  }
  // Batch ETA from the pace so far: sequences run (not skipped) plus running fractions.
  const double run_done = (p.done - p.skipped) + work;
  const double left = (p.total - p.done) - work;
  if (run_done > 0.05 && left > 0.0)
    s += " | batch ETA " + FormatDuration(Since(batch_start, now) / run_done * left);
  return s;
}

void ProgressDisplay::Update(const BatchProgress& p, bool force) {
  if (mode_ == ProgressMode::kNone) return;
  const auto now = std::chrono::steady_clock::now();
  const double since_last = Since(last_, now);
  if (mode_ == ProgressMode::kLines) {
    if (!force && since_last < interval_) return;
    last_ = now;
    std::fprintf(stderr, "progress: %s\n", Describe(p, now, start_).c_str());
    std::fflush(stderr);
    return;
  }
  if (!force && drawn_ && since_last < 0.1) return;
  last_ = now;
  // [#####.....] then the text, cut to the terminal's width.
  const int width = TerminalWidth();
  const int bar = 20;
  double f = p.total > 0 ? static_cast<double>(p.done) / p.total : 1.0;
  for (const RunningSequence& r : p.running)
    f += p.total > 0 ? Fraction(r.progress) / p.total : 0.0;
  const int filled = static_cast<int>(std::min(1.0, f) * bar + 0.5);
  std::string line = "[" + std::string(filled, '#') + std::string(bar - filled, '.') + "] " +
                     Describe(p, now, start_);
  if (static_cast<int>(line.size()) > width - 1) line = line.substr(0, width - 1);
  std::fprintf(stderr, "\r\033[K%s", line.c_str());
  std::fflush(stderr);
  drawn_ = true;
}

void ProgressDisplay::Clear() {
  if (mode_ != ProgressMode::kBar || !drawn_) return;
  std::fprintf(stderr, "\r\033[K");
  std::fflush(stderr);
  drawn_ = false;
}

}  // namespace imr::batch
