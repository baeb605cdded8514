// imr-soak's analysis of an `imr run --trace` file (JSON lines, one object per keyframe; format in
// tools/soak/README.md): totals, RSS figures, and whether the resident memory follows the points
// kept. Pure functions over parsed records, so tools/soak/trace_test checks them on hand-made
// traces.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace imr::soak {

struct TraceRecord {
  int64_t keyframe = 0;
  int64_t frame = 0;
  int64_t points = 0;    // points kept (in the triangulation)
  int64_t vertices = 0;  // points kept + Steiner points
  int64_t cells = 0;
  int64_t cells_in_o = 0;
  double rss_bytes = 0.0;
  double engine_seconds = 0.0;
  std::optional<double> check_seconds;  // only where the invariant check ran
};

// Parses a trace. A last line cut short (a killed run) is skipped and noted in *note; any other
// bad line is an error naming the line. Returns false with *error set on error.
bool ParseTrace(const std::string& text, std::vector<TraceRecord>* records, std::string* note,
                std::string* error);
bool ReadTrace(const std::string& path, std::vector<TraceRecord>* records, std::string* note,
               std::string* error);

// y = a + b x by least squares, with the residuals' RMS and largest absolute value.
struct LinearFit {
  double a = 0.0, b = 0.0;
  double rms = 0.0, max_abs = 0.0;
  int n = 0;
};
LinearFit FitLine(const std::vector<double>& x, const std::vector<double>& y);

// y = c[0] + sum_j c[j+1] x[j] by least squares over the columns x; false when the columns are
// (nearly) collinear, e.g. one run only, where points, Steiner points and keyframes all grow
// together.
bool FitLeastSquares(const std::vector<std::vector<double>>& x, const std::vector<double>& y,
                     std::vector<double>* c);

// The keyframes whose RSS samples are comparable: those where the invariant check ran, when there
// are at least 4. The check's working memory (edge maps over the whole of dO) stays with malloc
// after it returns and the engine grows into it, so between checks the RSS stays flat and at the
// next check it steps up: samples right after a check are all taken at the same point of that
// cycle. Without checks, every keyframe.
std::vector<TraceRecord> SamePhase(const std::vector<TraceRecord>& records);

// The pass/fail rule (printed with the verdict): fit rss = a + b*points on the first half of the
// same-phase samples, predict the second half; memory follows the points kept when no second-half
// sample is off by more than kHoldoutTolerance of its measured RSS.
inline constexpr double kHoldoutTolerance = 0.05;

struct SoakFigures {
  int keyframes = 0;
  int64_t frames = 0;  // last keyframe's frame + 1
  TraceRecord first, last;
  int checks = 0;
  double check_total_s = 0.0, check_max_s = 0.0;
  double engine_total_s = 0.0;
  double rss_start = 0.0, rss_end = 0.0, rss_peak = 0.0;
  int64_t rss_peak_keyframe = 0;
  LinearFit fit_points;     // rss against points kept, whole run
  LinearFit fit_vertices;   // rss against vertices, whole run (context)
  LinearFit fit_cells;      // rss against cells, whole run (context)
  double growth_at_checks = 0.0;  // RSS growth on check keyframes, share of the whole run's
  bool holdout_at_checks = false;  // the holdout used the check keyframes (SamePhase)
  LinearFit fit_first_half;  // rss against points kept, first half of the same-phase samples
  double holdout_max_dev = 0.0;      // bytes, signed: measured - predicted, largest in magnitude
  double holdout_max_dev_pct = 0.0;  // of the measured RSS at that keyframe
  int64_t holdout_worst_keyframe = 0;
  bool follows_points = false;
};

// Needs at least 4 records.
bool Analyse(const std::vector<TraceRecord>& records, SoakFigures* f, std::string* error);

// Runs over the same frames that differ in points per keyframe (same cameras, so the same Steiner
// grid) and in Steiner spacing (same points) separate what the resident memory grows with:
// rss = a + p*points + s*steiner + c*keyframe over all runs, steiner = vertices - points (the grid
// covers the region the cameras reach, so it grows with the distance driven). c is memory that
// grows with keyframes alone (cameras, per-keyframe bookkeeping, a leak).
struct Decomposition {
  bool ok = false;  // false: fewer than 3 runs, or they do not vary independently
  double a = 0.0, per_point = 0.0, per_steiner = 0.0, per_keyframe = 0.0;
  // The main run's (runs[0]) RSS growth, first to last keyframe, and each term's share of it.
  double growth = 0.0, growth_points = 0.0, growth_steiner = 0.0, growth_keyframes = 0.0;
  double rms = 0.0, max_abs = 0.0;  // residuals over all runs
};
Decomposition Decompose(const std::vector<const std::vector<TraceRecord>*>& runs);
// |growth_keyframes| may be at most this share of the main run's growth.
inline constexpr double kKeyframeGrowthTolerance = 0.05;

// Bytes as MiB with one decimal ("123.4"), the unit of every printed memory figure.
std::string Mib(double bytes);

}  // namespace imr::soak
