// The PatchMatch core on scenes rendered in code: a textured plane with a step, and a textured
// box on a textured ground, seen by a few cameras (sideways and forward, as a street camera
// moves). The depths it keeps must be the true ones within a stated tolerance.
#include "patch_match.hpp"

#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <functional>
#include <vector>

namespace imr::dense {
namespace {

// Smooth value noise in 0..255 from 2D coordinates: texture that ZNCC can lock on at any scale
// from a few centimetres to a metre.
double Hash(int x, int y) {
  uint32_t h = static_cast<uint32_t>(x) * 374761393u + static_cast<uint32_t>(y) * 668265263u;
  h = (h ^ (h >> 13)) * 1274126177u;
  return ((h ^ (h >> 16)) & 0xffff) / 65535.0;
}
double Noise(double u, double v) {
  const int x = static_cast<int>(std::floor(u)), y = static_cast<int>(std::floor(v));
  const double fx = u - x, fy = v - y;
  const double sx = fx * fx * (3 - 2 * fx), sy = fy * fy * (3 - 2 * fy);
  const double a = Hash(x, y), b = Hash(x + 1, y), c = Hash(x, y + 1), d = Hash(x + 1, y + 1);
  return (a * (1 - sx) + b * sx) * (1 - sy) + (c * (1 - sx) + d * sx) * sy;
}
double Texture(double u, double v) {
  return 255.0 * (0.5 * Noise(u * 4, v * 4) + 0.3 * Noise(u * 9 + 7, v * 9 + 3) +
                  0.2 * Noise(u * 1.3 + 11, v * 1.3));
}

// A scene: the first hit along a ray (origin, unit direction) and the texture there; false for
// none.
using Scene = std::function<bool(const Eigen::Vector3d& o, const Eigen::Vector3d& d, double* t,
                                 double* grey)>;

View Camera(const Eigen::Vector3d& centre, const Eigen::Matrix3d& R, int w, int h, double f) {
  View v;
  v.K << f, 0, (w - 1) / 2.0, 0, f, (h - 1) / 2.0, 0, 0, 1;
  v.R = R;
  v.t = -R * centre;
  v.gray = cv::Mat(h, w, CV_32FC1, cv::Scalar(0));
  return v;
}

// Renders with 2x2 supersampling; returns each pixel's true depth (camera z; 0 for no hit).
cv::Mat Render(View* v, const Scene& scene) {
  const int w = v->gray.cols, h = v->gray.rows;
  cv::Mat depth(h, w, CV_32FC1, cv::Scalar(0));
  const Eigen::Matrix3d Kinv = v->K.inverse();
  const Eigen::Vector3d c = v->Center();
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      double sum = 0;
      for (int s = 0; s < 4; ++s) {
        const double px = x - 0.25 + 0.5 * (s & 1), py = y - 0.25 + 0.5 * (s >> 1);
        const Eigen::Vector3d d = (v->R.transpose() * (Kinv * Eigen::Vector3d(px, py, 1))).normalized();
        double t = 0, g = 0;
        if (scene(c, d, &t, &g)) sum += g;
      }
      v->gray.at<float>(y, x) = static_cast<float>(sum / 4);
      const Eigen::Vector3d d = (v->R.transpose() * (Kinv * Eigen::Vector3d(x, y, 1))).normalized();
      double t = 0, g = 0;
      if (scene(c, d, &t, &g)) depth.at<float>(y, x) = static_cast<float>((v->R * (d * t)).z());
    }
  return depth;
}

// A wall facing -z: z = 10 for x < 0, z = 8.5 for x >= 0 (a step of 1.5), textured in x, y.
bool StepWall(const Eigen::Vector3d& o, const Eigen::Vector3d& d, double* t, double* grey) {
  for (double z : {8.5, 10.0}) {
    if (std::abs(d.z()) < 1e-9) return false;
    const double s = (z - o.z()) / d.z();
    if (s <= 0) continue;
    const Eigen::Vector3d p = o + s * d;
    if ((z == 8.5) != (p.x() >= 0)) continue;
    *t = s;
    *grey = Texture(p.x(), p.y());
    return true;
  }
  return false;
}

// A 2 x 2 x 2 box standing on the ground plane y = 1 (y points down, as in camera frames),
// centred at x = 0, z = 9; the ground textured too.
bool BoxOnGround(const Eigen::Vector3d& o, const Eigen::Vector3d& d, double* t, double* grey) {
  double best = 1e30, g = 0;
  // The box: slab intersection.
  const Eigen::Vector3d lo(-1, -1, 8), hi(1, 1, 10);
  double t0 = 0, t1 = 1e30;
  int axis = -1;
  bool hit = true;
  for (int a = 0; a < 3 && hit; ++a) {
    if (std::abs(d[a]) < 1e-12) {
      if (o[a] < lo[a] || o[a] > hi[a]) hit = false;
      continue;
    }
    double ta = (lo[a] - o[a]) / d[a], tb = (hi[a] - o[a]) / d[a];
    if (ta > tb) std::swap(ta, tb);
    if (ta > t0) {
      t0 = ta;
      axis = a;
    }
    t1 = std::min(t1, tb);
    if (t0 > t1) hit = false;
  }
  if (hit && axis >= 0 && t0 > 0) {
    best = t0;
    const Eigen::Vector3d p = o + t0 * d;
    const int u = (axis + 1) % 3, v = (axis + 2) % 3;
    g = Texture(p[u] * 1.7 + axis * 5, p[v] * 1.7);
  }
  if (d.y() > 1e-9) {
    const double s = (1.0 - o.y()) / d.y();
    if (s > 0 && s < best) {
      best = s;
      const Eigen::Vector3d p = o + s * d;
      g = Texture(p.x(), p.z());
    }
  }
  if (best >= 1e29) return false;
  *t = best;
  *grey = g;
  return true;
}

struct Result {
  double kept = 0;          // share of the pixels with a true depth that kept a depth
  double within = 0;        // share of the kept whose depth is within tolerance
  double median_error = 0;  // relative
};

Result Score(const DepthMap& m, const cv::Mat& truth, double tolerance) {
  int with_truth = 0, kept = 0, within = 0;
  std::vector<double> errors;
  for (int y = 0; y < truth.rows; ++y)
    for (int x = 0; x < truth.cols; ++x) {
      const double t = truth.at<float>(y, x);
      if (t <= 0) continue;
      ++with_truth;
      const double z = m.depth.at<float>(y, x);
      if (z <= 0) continue;
      ++kept;
      const double e = std::abs(z - t) / t;
      errors.push_back(e);
      within += e <= tolerance;
    }
  Result r;
  r.kept = with_truth ? static_cast<double>(kept) / with_truth : 0;
  r.within = kept ? static_cast<double>(within) / kept : 0;
  if (!errors.empty()) {
    std::nth_element(errors.begin(), errors.begin() + errors.size() / 2, errors.end());
    r.median_error = errors[errors.size() / 2];
  }
  return r;
}

PatchMatchOptions Options() {
  PatchMatchOptions o;
  o.min_depth = 2.0;
  o.max_depth = 100.0;
  o.iterations = 5;
  o.threads = 2;
  return o;
}

TEST(PatchMatch, APlaneWithAStepSeenSidewaysGetsItsDepths) {
  const Eigen::Matrix3d I = Eigen::Matrix3d::Identity();
  View ref = Camera({0, 0, 0}, I, 160, 120, 150);
  View left = Camera({-0.6, 0, 0}, I, 160, 120, 150);
  View right = Camera({0.6, 0, 0}, I, 160, 120, 150);
  const cv::Mat truth = Render(&ref, StepWall);
  Render(&left, StepWall);
  Render(&right, StepWall);
  const DepthMap m = ComputeDepthMap(ref, {left, right}, Options());
  const Result r = Score(m, truth, 0.02);
  EXPECT_GT(r.kept, 0.7) << "share of the pixels kept";
  EXPECT_GT(r.within, 0.9) << "share within 2 % of the true depth";
  EXPECT_LT(r.median_error, 0.005);
  // The step stays a step: pixels six columns (a window and a half) either side of it keep their own depths.
  int step_column = -1;
  for (int x = 1; x < truth.cols && step_column < 0; ++x)
    if (std::abs(truth.at<float>(60, x) - truth.at<float>(60, x - 1)) > 1.0f) step_column = x;
  ASSERT_GT(step_column, 0);
  int sharp = 0, rows = 0;
  for (int y = 10; y < 110; ++y) {
    const float a = m.depth.at<float>(y, step_column - 6), b = m.depth.at<float>(y, step_column + 6);
    if (a <= 0 || b <= 0) continue;
    ++rows;
    sharp += std::abs(a - truth.at<float>(y, step_column - 6)) < 0.2f &&
             std::abs(b - truth.at<float>(y, step_column + 6)) < 0.2f;
  }
  ASSERT_GT(rows, 30);
  EXPECT_GT(static_cast<double>(sharp) / rows, 0.8) << "depths either side of the step";
}

TEST(PatchMatch, ABoxOnTheGroundSeenByACameraDrivingTowardIt) {
  // A street camera: forward motion (the epipole inside the image), views behind and ahead.
  const Eigen::Matrix3d I = Eigen::Matrix3d::Identity();
  View ref = Camera({0.3, 0, 0}, I, 200, 150, 170);
  View before = Camera({0.0, 0, -1.0}, I, 200, 150, 170);
  View after = Camera({0.6, 0, 1.0}, I, 200, 150, 170);
  const cv::Mat truth = Render(&ref, BoxOnGround);
  Render(&before, BoxOnGround);
  Render(&after, BoxOnGround);
  const DepthMap m = ComputeDepthMap(ref, {before, after}, Options());
  const Result r = Score(m, truth, 0.05);
  EXPECT_GT(r.kept, 0.5);
  EXPECT_GT(r.within, 0.85) << "share within 5 % of the true depth";
  EXPECT_LT(r.median_error, 0.01);
}

TEST(PatchMatch, TheSameInputGivesTheSameMapWhateverTheThreads) {
  const Eigen::Matrix3d I = Eigen::Matrix3d::Identity();
  View ref = Camera({0, 0, 0}, I, 80, 60, 75);
  View right = Camera({0.5, 0, 0}, I, 80, 60, 75);
  Render(&ref, StepWall);
  Render(&right, StepWall);
  PatchMatchOptions one = Options(), two = Options();
  one.threads = 1;
  two.threads = 3;
  const DepthMap a = ComputeDepthMap(ref, {right}, one), b = ComputeDepthMap(ref, {right}, two);
  EXPECT_EQ(cv::norm(a.depth, b.depth, cv::NORM_INF), 0.0);
}

TEST(PatchMatch, RefusesBadOptionsAndImages) {
  View v = Camera({0, 0, 0}, Eigen::Matrix3d::Identity(), 10, 10, 10);
  PatchMatchOptions o = Options();
  o.max_depth = o.min_depth;
  EXPECT_THROW(ComputeDepthMap(v, {v}, o), std::invalid_argument);
  EXPECT_THROW(ComputeDepthMap(v, {}, Options()), std::invalid_argument);
  View bad = v;
  bad.gray = cv::Mat(10, 10, CV_8UC1, cv::Scalar(0));
  EXPECT_THROW(ComputeDepthMap(bad, {v}, Options()), std::invalid_argument);
}

}  // namespace
}  // namespace imr::dense
