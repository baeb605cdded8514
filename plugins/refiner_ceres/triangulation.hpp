// Two-view-and-more geometry of one 3D point with known cameras (paper section 2.1): linear DLT
// triangulation, then the reprojection error minimised with Ceres, the poses held fixed.
#pragma once

#include <Eigen/Core>
#include <optional>
#include <span>
#include <vector>

namespace imr::ceres_refiner {

// Pinhole camera, world -> camera: x_cam = R X + t, pixel = K x_cam (dehomogenised).
struct Camera {
  Eigen::Matrix3d K = Eigen::Matrix3d::Identity();
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t = Eigen::Vector3d::Zero();

  Camera() = default;
  Camera(const Eigen::Matrix3d& k, const Eigen::Matrix3d& r, const Eigen::Vector3d& tr);

  Eigen::Vector3d Center() const { return center_; }
  double Depth(const Eigen::Vector3d& X) const { return R.row(2).dot(X) + t.z(); }
  Eigen::Vector2d Project(const Eigen::Vector3d& X) const;
  // Unit direction, in the world, of the ray through `pixel`.
  Eigen::Vector3d Ray(const Eigen::Vector2d& pixel) const;
  // Normalised image coordinates (K^-1 pixel) of `pixel`.
  Eigen::Vector2d Normalized(const Eigen::Vector2d& pixel) const;

 private:
  Eigen::Matrix3d K_inv_ = Eigen::Matrix3d::Identity();
  Eigen::Vector3d center_ = Eigen::Vector3d::Zero();
};

// One observation of the point: a camera and the pixel where the point was seen.
struct View {
  const Camera* camera = nullptr;
  Eigen::Vector2d pixel = Eigen::Vector2d::Zero();
};

// Linear (DLT) triangulation from >= 2 views, in normalised coordinates, about the first camera's
// centre for conditioning. Empty when the solution is at infinity (rays parallel).
std::optional<Eigen::Vector3d> TriangulateDlt(std::span<const View> views);

// Largest angle, degrees, between the ray of the first view and the ray of any other view.
double ParallaxDeg(std::span<const View> views);

struct RefineOptions {
  double huber_px = 1.0;     // Huber loss scale, pixels (0: plain least squares).
  int max_iterations = 10;   // Levenberg-Marquardt iterations, at most.
};

// Minimises the reprojection error of X over all views (cameras fixed). False when Ceres reports
// no usable solution (X is then unchanged).
bool RefinePoint(std::span<const View> views, const RefineOptions& options, Eigen::Vector3d* X);

// Reprojection error, pixels, of X in each view (infinity for a view where X is behind).
std::vector<double> ReprojectionErrors(std::span<const View> views, const Eigen::Vector3d& X);

}  // namespace imr::ceres_refiner
