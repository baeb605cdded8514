// The image front end's "point_error" figures (synthetic truth only: report.json front_end): each
// refiner point's distance to the true surface at its first estimate and at its latest, and the
// medians over the run. A record per point for the whole drive grew with it (issue 46: ~60 bytes
// a point, ~10 kB a frame on imr-synth's street); here a point's record lives while the refiner
// still moves it, and one not updated for kSettleKeyframes keyframes is folded into fixed
// histograms, so that what is held is the points being refined, not the drive.
#pragma once

#include <array>
#include <cstdint>
#include <unordered_map>
#include <vector>

namespace imr::pipeline {

// Distances kept exactly up to kExact of them, then in PointErrorSummary's bins: the dense
// points' errors (front end, synthetic truth only) held a double per dense point for the drive.
class DistanceSample {
 public:
  // below() counts the distances under `limit`.
  explicit DistanceSample(double limit = 0.0) : limit_(limit) {}
  void Add(double d);
  int64_t size() const { return n_; }
  // The element at rank floor(q (n - 1)): exact up to kExact values, within a bin after.
  double Quantile(double q) const;
  // How many were under the limit (exact: counted as they came).
  int64_t below() const { return below_; }
  int64_t HeldBytes() const;

  static constexpr std::size_t kExact = std::size_t{1} << 16;

 private:
  double limit_;
  int64_t n_ = 0, below_ = 0;
  std::vector<double> exact_;
  std::vector<uint32_t> bins_;  // empty until exact_ is full
};

class PointErrorSummary {
 public:
  // A new point, its distance at keyframe `keyframe` (keyframes count up from 0).
  void Add(uint64_t id, double distance, int64_t keyframe);
  // A later estimate of a point (ignored when it was removed or folded already).
  void Move(uint64_t id, double distance, int64_t keyframe);
  // A removed point leaves the figures.
  void Remove(uint64_t id) { live_.erase(id); }
  // After keyframe `keyframe`: points last updated kSettleKeyframes before it are folded (every
  // kFoldEvery keyframes).
  void EndKeyframe(int64_t keyframe);

  struct Figures {
    int64_t points = 0, moved = 0;  // every point kept; of them, moved at least once
    double median_first = 0.0, moved_median_first = 0.0, moved_median_latest = 0.0;
  };
  // Exact medians (the element at rank n / 2) while nothing was folded; after, from the
  // histograms: within kFineBin below kFineLimit, kCoarseBin above.
  Figures Result() const;

  // What it holds: the live records and the histograms.
  int64_t HeldBytes() const;
  int64_t live() const { return static_cast<int64_t>(live_.size()); }

  static constexpr int64_t kSettleKeyframes = 50;
  static constexpr int64_t kFoldEvery = 10;
  static constexpr double kFineBin = 1e-4, kFineLimit = 1.0;  // metres
  static constexpr double kCoarseBin = 1e-2, kCoarseLimit = 100.0;
  static constexpr int kBins = static_cast<int>(kFineLimit / kFineBin) +
                               static_cast<int>((kCoarseLimit - kFineLimit) / kCoarseBin) + 1;

 private:
  struct Live {
    double first = 0.0, latest = 0.0;
    int moves = 0;
    int64_t keyframe = 0;  // of its last update
  };
  using Histogram = std::vector<uint32_t>;  // kBins counts, empty until the first fold
  friend class DistanceSample;
  static int Bin(double d);
  static double BinValue(int bin);
  static double Median(const Histogram& h, std::vector<double> live);

  std::unordered_map<uint64_t, Live> live_;
  Histogram first_all_, first_moved_, latest_moved_;
  int64_t folded_ = 0, folded_moved_ = 0;
};

}  // namespace imr::pipeline
