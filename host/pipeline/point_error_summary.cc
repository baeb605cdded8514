#include "host/pipeline/point_error_summary.h"

#include <algorithm>
#include <cmath>

namespace imr::pipeline {

void PointErrorSummary::Add(uint64_t id, double distance, int64_t keyframe) {
  live_[id] = {distance, distance, 0, keyframe};
}

void PointErrorSummary::Move(uint64_t id, double distance, int64_t keyframe) {
  auto it = live_.find(id);
  if (it == live_.end()) return;
  it->second.latest = distance;
  ++it->second.moves;
  it->second.keyframe = keyframe;
}

void PointErrorSummary::EndKeyframe(int64_t keyframe) {
  if (keyframe % kFoldEvery != 0) return;
  for (auto it = live_.begin(); it != live_.end();) {
    if (it->second.keyframe + kSettleKeyframes > keyframe) {
      ++it;
      continue;
    }
    if (first_all_.empty()) first_all_.assign(kBins, 0), first_moved_.assign(kBins, 0), latest_moved_.assign(kBins, 0);
    const Live& p = it->second;
    ++first_all_[Bin(p.first)];
    ++folded_;
    if (p.moves > 0) {
      ++first_moved_[Bin(p.first)];
      ++latest_moved_[Bin(p.latest)];
      ++folded_moved_;
    }
    it = live_.erase(it);
  }
}

int PointErrorSummary::Bin(double d) {
  if (!(d >= 0.0)) return 0;
  const int fine = static_cast<int>(kFineLimit / kFineBin);
  if (d < kFineLimit) return std::min(fine - 1, static_cast<int>(d / kFineBin));
  return std::min(kBins - 1, fine + static_cast<int>((d - kFineLimit) / kCoarseBin));
}

double PointErrorSummary::BinValue(int bin) {
  const int fine = static_cast<int>(kFineLimit / kFineBin);
  if (bin < fine) return (bin + 0.5) * kFineBin;
  return kFineLimit + (bin - fine + 0.5) * kCoarseBin;
}

// The element at rank n / 2 of the histogram's values and `live`'s together.
double PointErrorSummary::Median(const Histogram& h, std::vector<double> live) {
  int64_t n = static_cast<int64_t>(live.size());
  for (uint32_t c : h) n += c;
  if (n == 0) return 0.0;
  if (h.empty()) {
    const auto mid = live.begin() + static_cast<std::ptrdiff_t>(live.size() / 2);
    std::nth_element(live.begin(), mid, live.end());
    return *mid;
  }
  std::vector<int64_t> counts(h.begin(), h.end());
  for (double d : live) ++counts[Bin(d)];
  int64_t rank = n / 2;
  for (int b = 0; b < kBins; ++b) {
    if (rank < counts[b]) return BinValue(b);
    rank -= counts[b];
  }
  return BinValue(kBins - 1);
}

PointErrorSummary::Figures PointErrorSummary::Result() const {
  std::vector<double> first_all, first_moved, latest_moved;
  for (const auto& [id, p] : live_) {
    first_all.push_back(p.first);
    if (p.moves == 0) continue;
    first_moved.push_back(p.first);
    latest_moved.push_back(p.latest);
  }
  Figures f;
  f.points = folded_ + static_cast<int64_t>(first_all.size());
  f.moved = folded_moved_ + static_cast<int64_t>(first_moved.size());
  f.median_first = Median(first_all_, std::move(first_all));
  f.moved_median_first = Median(first_moved_, std::move(first_moved));
  f.moved_median_latest = Median(latest_moved_, std::move(latest_moved));
  return f;
}

void DistanceSample::Add(double d) {
  ++n_;
  if (d < limit_) ++below_;
  if (exact_.size() < kExact && bins_.empty()) {
    exact_.push_back(d);
    return;
  }
  if (bins_.empty()) {
    bins_.assign(PointErrorSummary::kBins, 0);
    for (double e : exact_) ++bins_[PointErrorSummary::Bin(e)];
    exact_.clear();
    exact_.shrink_to_fit();
  }
  ++bins_[PointErrorSummary::Bin(d)];
}

double DistanceSample::Quantile(double q) const {
  if (n_ == 0) return 0.0;
  const int64_t rank = static_cast<int64_t>(q * static_cast<double>(n_ - 1));
  if (bins_.empty()) {
    std::vector<double> e = exact_;
    std::nth_element(e.begin(), e.begin() + rank, e.end());
    return e[static_cast<std::size_t>(rank)];
  }
  int64_t left = rank;
  for (int b = 0; b < PointErrorSummary::kBins; ++b) {
    if (left < bins_[b]) return PointErrorSummary::BinValue(b);
    left -= bins_[b];
  }
  return PointErrorSummary::BinValue(PointErrorSummary::kBins - 1);
}

int64_t DistanceSample::HeldBytes() const {
  return static_cast<int64_t>(exact_.capacity() * sizeof(double) + bins_.capacity() * sizeof(uint32_t));
}

int64_t PointErrorSummary::HeldBytes() const {
  // A node per record (its key, value and the next pointer), a bucket pointer each.
  const int64_t node = static_cast<int64_t>(sizeof(uint64_t) + sizeof(Live) + sizeof(void*));
  return static_cast<int64_t>(live_.size()) * node +
         static_cast<int64_t>(live_.bucket_count() * sizeof(void*)) +
         static_cast<int64_t>((first_all_.capacity() + first_moved_.capacity() + latest_moved_.capacity()) *
                              sizeof(uint32_t));
}

}  // namespace imr::pipeline
