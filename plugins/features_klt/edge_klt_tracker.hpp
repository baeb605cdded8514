// Edge-point features tracked with pyramidal Lucas-Kanade (paper section 2.1, "Sparse point
// cloud"; docs/user-guide.md, Image sequences). Edge points are Canny edge pixels, one per grid cell (the
// strongest gradient of the cell), so they spread over the image; Shi-Tomasi corners are the
// alternative detector. Tracks are followed frame to frame and kept only when tracking the new
// position back lands near the old one (forward-backward check); new tracks start on the first
// frame and at keyframes, in cells no current track occupies.
#pragma once

#include <imr/sdk/plugin.h>

#include <cstdint>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

namespace imr::edge_klt {

enum class Detector { kEdge, kShiTomasi };

struct TrackerOptions {
  Detector detector = Detector::kEdge;  // "edge" (Canny edge points) or "shi_tomasi" (corners).
  int max_features = 1500;              // Tracks alive at once, at most.
  int grid_cell_size = 16;              // Pixels; at most one new feature per cell.
  double canny_low = 50.0;              // Canny hysteresis thresholds on the L2 Sobel gradient.
  double canny_high = 150.0;
  double min_distance = 8.0;            // Pixels between a new feature and any other feature.
  int border = 8;                       // Pixels at the image border where features are dropped.
  double shi_tomasi_quality = 0.01;     // Relative corner quality (goodFeaturesToTrack).
  int shi_tomasi_block_size = 3;        // Neighbourhood of the corner measure.
  // Edge detector: a free cell without an edge pixel (weak texture, e.g. asphalt) takes its
  // strongest corner instead, when its minimum eigenvalue (cv::cornerMinEigenVal over
  // corner_block_size pixels) reaches corner_min_eigen.
  bool corner_fallback = true;
  double corner_min_eigen = 3e-5;
  int corner_block_size = 5;
  int lk_window = 21;                   // Lucas-Kanade window side, pixels.
  int lk_levels = 3;                    // Pyramid levels above the image (0: no pyramid).
  int lk_max_iterations = 30;           // Per level.
  double lk_epsilon = 0.01;             // Stop when the update is below this (pixels).
  double lk_min_eigen = 1e-4;           // Drop a track whose window has too little texture.
  double fb_max_error = 1.0;            // Forward-backward: max distance back to the start, px.

  // Empty when usable, else which field and why.
  std::string Check() const;
};

class EdgeKltTracker {
 public:
  explicit EdgeKltTracker(const TrackerOptions& options);

  // Tracks into `gray` (8-bit, one channel) and, on the first frame and keyframes, starts new
  // tracks. Returns every track observed in this frame; valid until the next call.
  const std::vector<imr_track_observation>& Process(const cv::Mat& gray, bool is_keyframe);

 private:
  void Track(const std::vector<cv::Mat>& pyramid);
  void Detect(const cv::Mat& gray);
  void DetectEdgePoints(const cv::Mat& gray, const cv::Mat& free_mask,
                        std::vector<cv::Point2f>* out) const;
  void DetectCorners(const cv::Mat& gray, const cv::Mat& free_mask,
                     std::vector<cv::Point2f>* out) const;
  // Appends the strongest corner of each free cell that holds no point of `out` yet.
  void DetectFallbackCorners(const cv::Mat& gray, const cv::Mat& free_mask,
                             std::vector<cv::Point2f>* out) const;
  bool Inside(const cv::Point2f& p) const;

  TrackerOptions options_;
  cv::Size size_;
  std::vector<cv::Mat> prev_pyramid_;
  std::vector<cv::Point2f> points_;  // Current positions of the live tracks.
  std::vector<uint64_t> ids_;        // Their ids, parallel to points_.
  uint64_t next_id_ = 0;
  std::vector<imr_track_observation> out_;
};

}  // namespace imr::edge_klt
