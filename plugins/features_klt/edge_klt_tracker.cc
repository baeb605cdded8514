#include "edge_klt_tracker.hpp"

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>

namespace imr::edge_klt {

std::string TrackerOptions::Check() const {
  if (max_features < 1) return "max_features: expected >= 1";
  if (grid_cell_size < 2) return "grid_cell_size: expected >= 2";
  if (!(canny_low >= 0.0) || !(canny_high >= canny_low))
    return "canny_low/canny_high: expected 0 <= canny_low <= canny_high";
  if (!(min_distance >= 0.0)) return "min_distance: expected >= 0";
  if (border < 0) return "border: expected >= 0";
  if (!(shi_tomasi_quality > 0.0 && shi_tomasi_quality <= 1.0))
    return "shi_tomasi_quality: expected in (0, 1]";
  if (shi_tomasi_block_size < 2) return "shi_tomasi_block_size: expected >= 2";
  if (!(corner_min_eigen >= 0.0)) return "corner_min_eigen: expected >= 0";
  if (corner_block_size < 2 || corner_block_size > 31)
    return "corner_block_size: expected in [2, 31]";
  if (lk_window < 3) return "lk_window: expected >= 3";
  if (lk_levels < 0 || lk_levels > 10) return "lk_levels: expected in [0, 10]";
  if (lk_max_iterations < 1) return "lk_max_iterations: expected >= 1";
  if (!(lk_epsilon >= 0.0)) return "lk_epsilon: expected >= 0";
  if (!(lk_min_eigen >= 0.0)) return "lk_min_eigen: expected >= 0";
  if (!(fb_max_error >= 0.0)) return "fb_max_error: expected >= 0";
  return {};
}

EdgeKltTracker::EdgeKltTracker(const TrackerOptions& options) : options_(options) {}

bool EdgeKltTracker::Inside(const cv::Point2f& p) const {
  const float b = static_cast<float>(options_.border);
  return p.x >= b && p.y >= b && p.x <= static_cast<float>(size_.width - 1) - b &&
         p.y <= static_cast<float>(size_.height - 1) - b;
}

const std::vector<imr_track_observation>& EdgeKltTracker::Process(const cv::Mat& gray,
                                                                  bool is_keyframe) {
  const bool first = prev_pyramid_.empty();
  const cv::Size win(options_.lk_window, options_.lk_window);
  std::vector<cv::Mat> pyramid;
  // No reuse of the input: the pyramid outlives this call and the host's pixels do not.
  cv::buildOpticalFlowPyramid(gray, pyramid, win, options_.lk_levels, /*withDerivatives=*/true,
                              cv::BORDER_REFLECT_101, cv::BORDER_CONSTANT,
                              /*tryReuseInputImage=*/false);
  size_ = gray.size();
  if (!first) Track(pyramid);
  prev_pyramid_ = std::move(pyramid);
  if (first || is_keyframe) Detect(gray);

  out_.clear();
  out_.reserve(points_.size());
  for (std::size_t i = 0; i < points_.size(); ++i)
    out_.push_back({ids_[i], static_cast<double>(points_[i].x), static_cast<double>(points_[i].y)});
  return out_;
}

void EdgeKltTracker::Track(const std::vector<cv::Mat>& pyramid) {
  if (points_.empty()) return;
  const cv::Size win(options_.lk_window, options_.lk_window);
  const cv::TermCriteria criteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS,
                                  options_.lk_max_iterations, options_.lk_epsilon);
  std::vector<cv::Point2f> forward, backward;
  std::vector<uchar> status_f, status_b;
  std::vector<float> err;
  cv::calcOpticalFlowPyrLK(prev_pyramid_, pyramid, points_, forward, status_f, err, win,
                           options_.lk_levels, criteria, 0, options_.lk_min_eigen);
  // Track back from where the forward pass landed: a consistent track returns to its start.
  cv::calcOpticalFlowPyrLK(pyramid, prev_pyramid_, forward, backward, status_b, err, win,
                           options_.lk_levels, criteria, 0, options_.lk_min_eigen);
  const double max_fb2 = options_.fb_max_error * options_.fb_max_error;
  std::size_t kept = 0;
  for (std::size_t i = 0; i < points_.size(); ++i) {
    if (!status_f[i] || !status_b[i] || !Inside(forward[i])) continue;
    const cv::Point2f d = backward[i] - points_[i];
    if (static_cast<double>(d.dot(d)) > max_fb2) continue;
    points_[kept] = forward[i];
    ids_[kept] = ids_[i];
    ++kept;
  }
  points_.resize(kept);
  ids_.resize(kept);
}

void EdgeKltTracker::Detect(const cv::Mat& gray) {
  if (static_cast<int>(points_.size()) >= options_.max_features) return;
  // Free where no current track is within min_distance and away from the border.
  cv::Mat free_mask(gray.size(), CV_8UC1, cv::Scalar(0));
  const int b = options_.border;
  if (gray.cols > 2 * b && gray.rows > 2 * b)
    free_mask(cv::Rect(b, b, gray.cols - 2 * b, gray.rows - 2 * b)).setTo(255);
  const int radius = static_cast<int>(std::ceil(options_.min_distance));
  for (const cv::Point2f& p : points_)
    cv::circle(free_mask, cv::Point(cvRound(p.x), cvRound(p.y)), radius, cv::Scalar(0), cv::FILLED);
  // A cell already holding a track gets no new one: the grid caps each cell's share.
  const int cs = options_.grid_cell_size;
  for (const cv::Point2f& p : points_) {
    const int cx = std::clamp(cvFloor(p.x) / cs, 0, (gray.cols - 1) / cs);
    const int cy = std::clamp(cvFloor(p.y) / cs, 0, (gray.rows - 1) / cs);
    const cv::Rect cell = cv::Rect(cx * cs, cy * cs, cs, cs) & cv::Rect(0, 0, gray.cols, gray.rows);
    free_mask(cell).setTo(0);
  }

  std::vector<cv::Point2f> candidates;  // strongest first
  if (options_.detector == Detector::kEdge) {
    DetectEdgePoints(gray, free_mask, &candidates);
    if (options_.corner_fallback) DetectFallbackCorners(gray, free_mask, &candidates);
  } else
    DetectCorners(gray, free_mask, &candidates);

  // Greedy, strongest first: keep a candidate only if nothing kept so far is too close (two
  // neighbouring cells may pick pixels on either side of their common border).
  const int budget = options_.max_features - static_cast<int>(points_.size());
  int added = 0;
  for (const cv::Point2f& p : candidates) {
    if (added >= budget) break;
    const cv::Point q(cvRound(p.x), cvRound(p.y));
    if (free_mask.at<uchar>(q) == 0) continue;
    cv::circle(free_mask, q, radius, cv::Scalar(0), cv::FILLED);
    points_.push_back(p);
    ids_.push_back(next_id_++);
    ++added;
  }
}

void EdgeKltTracker::DetectEdgePoints(const cv::Mat& gray, const cv::Mat& free_mask,
                                      std::vector<cv::Point2f>* out) const {
  cv::Mat dx, dy, edges;
  cv::Sobel(gray, dx, CV_16S, 1, 0, 3);
  cv::Sobel(gray, dy, CV_16S, 0, 1, 3);
  cv::Canny(dx, dy, edges, options_.canny_low, options_.canny_high, /*L2gradient=*/true);

  // Per cell, the free edge pixel with the largest gradient magnitude.
  const int cs = options_.grid_cell_size;
  const int ncols = (gray.cols + cs - 1) / cs, nrows = (gray.rows + cs - 1) / cs;
  std::vector<int> best_mag2(static_cast<std::size_t>(ncols) * nrows, -1);
  std::vector<cv::Point> best_pt(best_mag2.size());
  for (int y = 0; y < gray.rows; ++y) {
    const uchar* e = edges.ptr<uchar>(y);
    const uchar* f = free_mask.ptr<uchar>(y);
    const int16_t* gx = dx.ptr<int16_t>(y);
    const int16_t* gy = dy.ptr<int16_t>(y);
    const std::size_t row = static_cast<std::size_t>(y / cs) * ncols;
    for (int x = 0; x < gray.cols; ++x) {
      if (!e[x] || !f[x]) continue;
      const int m2 = gx[x] * gx[x] + gy[x] * gy[x];
      const std::size_t c = row + static_cast<std::size_t>(x / cs);
      if (m2 > best_mag2[c]) {
        best_mag2[c] = m2;
        best_pt[c] = {x, y};
      }
    }
  }
  std::vector<std::size_t> order;
  for (std::size_t c = 0; c < best_mag2.size(); ++c)
    if (best_mag2[c] >= 0) order.push_back(c);
  std::sort(order.begin(), order.end(),
            [&](std::size_t a, std::size_t b) { return best_mag2[a] > best_mag2[b]; });
  out->reserve(order.size());
  for (std::size_t c : order)
    out->emplace_back(static_cast<float>(best_pt[c].x), static_cast<float>(best_pt[c].y));
}

void EdgeKltTracker::DetectFallbackCorners(const cv::Mat& gray, const cv::Mat& free_mask,
                                           std::vector<cv::Point2f>* out) const {
  const int cs = options_.grid_cell_size;
  const int ncols = (gray.cols + cs - 1) / cs, nrows = (gray.rows + cs - 1) / cs;
  const auto cell_of = [&](int x, int y) {
    return static_cast<std::size_t>(y / cs) * ncols + static_cast<std::size_t>(x / cs);
  };
  std::vector<uchar> taken(static_cast<std::size_t>(ncols) * nrows, 0);
  for (const cv::Point2f& p : *out) taken[cell_of(cvFloor(p.x), cvFloor(p.y))] = 1;
  cv::Mat eig;
  cv::cornerMinEigenVal(gray, eig, options_.corner_block_size, 3);
  const float threshold = static_cast<float>(options_.corner_min_eigen);
  std::vector<float> best(taken.size(), -1.0f);
  std::vector<cv::Point> best_pt(taken.size());
  for (int y = 0; y < gray.rows; ++y) {
    const float* e = eig.ptr<float>(y);
    const uchar* f = free_mask.ptr<uchar>(y);
    for (int x = 0; x < gray.cols; ++x) {
      if (!f[x] || e[x] < threshold) continue;
      const std::size_t c = cell_of(x, y);
      if (!taken[c] && e[x] > best[c]) {
        best[c] = e[x];
        best_pt[c] = {x, y};
      }
    }
  }
  std::vector<std::size_t> order;
  for (std::size_t c = 0; c < best.size(); ++c)
    if (best[c] >= 0.0f) order.push_back(c);
  // After the edge points (they keep priority), strongest corner first.
  std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return best[a] > best[b]; });
  for (std::size_t c : order)
    out->emplace_back(static_cast<float>(best_pt[c].x), static_cast<float>(best_pt[c].y));
}

void EdgeKltTracker::DetectCorners(const cv::Mat& gray, const cv::Mat& free_mask,
                                   std::vector<cv::Point2f>* out) const {
  std::vector<cv::Point2f> corners;  // sorted by decreasing quality
  cv::goodFeaturesToTrack(gray, corners, 0, options_.shi_tomasi_quality, options_.min_distance,
                          free_mask, options_.shi_tomasi_block_size);
  // At most one per cell: the strongest corner of each cell.
  const int cs = options_.grid_cell_size;
  const int ncols = (gray.cols + cs - 1) / cs, nrows = (gray.rows + cs - 1) / cs;
  std::vector<uchar> taken(static_cast<std::size_t>(ncols) * nrows, 0);
  for (const cv::Point2f& p : corners) {
    const std::size_t c = static_cast<std::size_t>(cvFloor(p.y) / cs) * ncols +
                          static_cast<std::size_t>(cvFloor(p.x) / cs);
    if (taken[c]) continue;
    taken[c] = 1;
    out->push_back(p);
  }
}

}  // namespace imr::edge_klt
