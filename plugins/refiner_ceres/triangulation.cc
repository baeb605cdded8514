#include "triangulation.hpp"

#include <ceres/ceres.h>

#include <Eigen/Dense>
#include <Eigen/SVD>
#include <cmath>
#include <limits>

namespace imr::ceres_refiner {

Camera::Camera(const Eigen::Matrix3d& k, const Eigen::Matrix3d& r, const Eigen::Vector3d& tr)
    : K(k), R(r), t(tr), K_inv_(k.inverse()), center_(-r.transpose() * tr) {}

Eigen::Vector2d Camera::Project(const Eigen::Vector3d& X) const {
  const Eigen::Vector3d p = K * (R * X + t);
  return p.head<2>() / p.z();
}

Eigen::Vector2d Camera::Normalized(const Eigen::Vector2d& pixel) const {
  const Eigen::Vector3d n = K_inv_ * pixel.homogeneous();
  return n.head<2>() / n.z();
}

Eigen::Vector3d Camera::Ray(const Eigen::Vector2d& pixel) const {
  return (R.transpose() * (K_inv_ * pixel.homogeneous())).normalized();
}

std::optional<Eigen::Vector3d> TriangulateDlt(std::span<const View> views) {
  if (views.size() < 2) return std::nullopt;
  // x ~ [R | R o + t] [Y; 1] with X = o + Y: the first camera's centre as origin keeps the
  // homogeneous coordinates of similar size.
  const Eigen::Vector3d origin = views[0].camera->Center();
  Eigen::MatrixXd A(2 * views.size(), 4);
  for (std::size_t i = 0; i < views.size(); ++i) {
    const Camera& c = *views[i].camera;
    Eigen::Matrix<double, 3, 4> P;
    P.leftCols<3>() = c.R;
    P.col(3) = c.R * origin + c.t;
    const Eigen::Vector2d n = c.Normalized(views[i].pixel);
    A.row(static_cast<Eigen::Index>(2 * i)) = n.x() * P.row(2) - P.row(0);
    A.row(static_cast<Eigen::Index>(2 * i + 1)) = n.y() * P.row(2) - P.row(1);
  }
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(A, Eigen::ComputeFullV);
  const Eigen::Vector4d h = svd.matrixV().col(3);
  if (std::abs(h(3)) < 1e-12 * h.head<3>().norm() || h(3) == 0.0) return std::nullopt;
  const Eigen::Vector3d X = origin + h.head<3>() / h(3);
  if (!X.allFinite()) return std::nullopt;
  return X;
}

double ParallaxDeg(std::span<const View> views) {
  if (views.size() < 2) return 0.0;
  const Eigen::Vector3d r0 = views[0].camera->Ray(views[0].pixel);
  double min_cos = 1.0;
  for (std::size_t i = 1; i < views.size(); ++i)
    min_cos = std::min(min_cos, r0.dot(views[i].camera->Ray(views[i].pixel)));
  return std::acos(std::clamp(min_cos, -1.0, 1.0)) * 180.0 / M_PI;
}

namespace {

// Reprojection residual of one observation, pixels; the camera is data, the point the variable.
struct ReprojectionCost {
  ReprojectionCost(const Camera& camera, const Eigen::Vector2d& pixel)
      : K(camera.K), R(camera.R), t(camera.t), observed(pixel) {}

  template <typename T>
  bool operator()(const T* X, T* residual) const {
    T p[3];
    for (int i = 0; i < 3; ++i)
      p[i] = T(R(i, 0)) * X[0] + T(R(i, 1)) * X[1] + T(R(i, 2)) * X[2] + T(t(i));
    if (!(p[2] > T(0))) return false;  // behind the camera: not a usable step
    const T x = p[0] / p[2], y = p[1] / p[2];
    residual[0] = T(K(0, 0)) * x + T(K(0, 1)) * y + T(K(0, 2)) - T(observed.x());
    residual[1] = T(K(1, 1)) * y + T(K(1, 2)) - T(observed.y());
    return true;
  }

  Eigen::Matrix3d K, R;
  Eigen::Vector3d t;
  Eigen::Vector2d observed;
};

}  // namespace

bool RefinePoint(std::span<const View> views, const RefineOptions& options, Eigen::Vector3d* X) {
  double x[3] = {X->x(), X->y(), X->z()};
  ceres::Problem::Options problem_options;
  problem_options.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  ceres::Problem problem(problem_options);
  ceres::HuberLoss huber(options.huber_px > 0.0 ? options.huber_px : 1.0);
  ceres::LossFunction* loss = options.huber_px > 0.0 ? &huber : nullptr;
  for (const View& v : views) {
    problem.AddResidualBlock(
        new ceres::AutoDiffCostFunction<ReprojectionCost, 2, 3>(
            new ReprojectionCost(*v.camera, v.pixel)),
        loss, x);
  }
  ceres::Solver::Options solver;
  solver.linear_solver_type = ceres::DENSE_QR;
  solver.max_num_iterations = options.max_iterations;
  solver.logging_type = ceres::SILENT;
  solver.minimizer_progress_to_stdout = false;
  solver.num_threads = 1;
  ceres::Solver::Summary summary;
  ceres::Solve(solver, &problem, &summary);
  if (!summary.IsSolutionUsable()) return false;
  const Eigen::Vector3d refined(x[0], x[1], x[2]);
  if (!refined.allFinite()) return false;
  *X = refined;
  return true;
}

std::vector<double> ReprojectionErrors(std::span<const View> views, const Eigen::Vector3d& X) {
  std::vector<double> e;
  e.reserve(views.size());
  for (const View& v : views) {
    e.push_back(v.camera->Depth(X) > 0.0 ? (v.camera->Project(X) - v.pixel).norm()
                                          : std::numeric_limits<double>::infinity());
  }
  return e;
}

}  // namespace imr::ceres_refiner
