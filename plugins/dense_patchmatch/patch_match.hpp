// Multi-view PatchMatch stereo on calibrated keyframes: the core of org.imr.dense.patchmatch,
// with no SDK types (the plugin converts), so it is tested alone.
//
// Per pixel of a reference view, a plane (depth along the pixel's ray and a normal): random at
// first, then each pixel tries its neighbours' planes and small random changes of its own, kept
// when they make the reference patch look more alike in the neighbouring views (ZNCC through
// the homography the plane induces, so slanted surfaces - a façade seen along the street, the
// road - match as well as frontal ones). Red-black order, so both halves of an iteration run in
// parallel (Galliani et al. 2015). What the field does: Bleyer et al. 2011 (PatchMatch stereo),
// Schoenberger et al. 2016 (COLMAP), Shen 2013 (OpenMVS's DensifyPointCloud); written from the
// papers.
#pragma once

#include <opencv2/core.hpp>

#include <Eigen/Core>

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace imr::dense {

// A view at the working resolution: pinhole, world -> camera x_cam = R * X + t, pixel = K * x_cam
// (pixel centres at integer coordinates), its image as 32-bit float gray (CV_32FC1).
struct View {
  Eigen::Matrix3d K = Eigen::Matrix3d::Identity();
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  cv::Mat gray;
  Eigen::Vector3d Center() const { return -R.transpose() * t; }
};

struct PatchMatchOptions {
  double min_depth = 1.0;          // depth range of the random start (scene units, > 0)
  double max_depth = 100.0;
  int iterations = 4;              // red-black iterations (each: propagation + refinement)
  int window_radius = 4;           // patch half-size in pixels (window 2r+1)
  int window_step = 2;             // patch sample spacing in pixels (the patch is sparse)
  double max_normal_angle_deg = 80;  // a plane's normal stays within this of facing the camera
  double min_zncc = 0.6;           // a view agrees when the ZNCC at the final plane reaches this
  int min_views = 1;               // ... and a pixel is kept when this many views agree
  double min_texture = 2.0;        // grey-level gradient (0-255 per pixel) a patch needs in its
                                   // weaker direction (structure tensor): no depth on a blank sky
  int threads = 1;                 // threads inside a call (joined before it returns)
  uint64_t seed = 1;               // random start and perturbations: the same input gives the same map
  bool Check(std::string* error) const;  // false and a message naming the field when invalid
};

// The depth map of the reference view: per pixel the depth along the camera's z axis (0: none
// kept), the normal (camera frame), the mean ZNCC over the agreeing views, and a bit per
// neighbour view that agreed.
struct DepthMap {
  cv::Mat depth;    // CV_32FC1
  cv::Mat normal;   // CV_32FC3
  cv::Mat score;    // CV_32FC1
  cv::Mat views;    // CV_32SC1 bit mask over the neighbours (bit i: neighbours[i])
  int64_t kept = 0;
};

// The depth map of `reference` against `neighbours` (at least one, at the same resolution or
// not). `cancelled` (may be empty) is polled between iterations; when it says so, throws
// std::runtime_error("cancelled").
DepthMap ComputeDepthMap(const View& reference, const std::vector<View>& neighbours,
                         const PatchMatchOptions& options,
                         const std::function<bool()>& cancelled = {});

// A view scaled by `s` (0 < s <= 1) from a full-resolution one: the image resized (area
// averaging) and K adjusted for the pixel-centre convention.
View Downscaled(const View& full, double s);

}  // namespace imr::dense
