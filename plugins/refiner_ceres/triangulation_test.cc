// The refiner's geometry on hand-computed cases: DLT, parallax, Ceres refinement, errors.
#include "triangulation.hpp"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <limits>
#include <random>

namespace imr::ceres_refiner {
namespace {

// KITTI's left gray camera.
Eigen::Matrix3d KittiK() {
  Eigen::Matrix3d K;
  K << 718.856, 0, 607.1928, 0, 718.856, 185.2157, 0, 0, 1;
  return K;
}

Camera At(const Eigen::Vector3d& centre, const Eigen::Matrix3d& R = Eigen::Matrix3d::Identity()) {
  return Camera(KittiK(), R, -R * centre);
}

TEST(Triangulation, DltRecoversANoiseFreePointFromHandComputedPixels) {
  // Cameras looking down +z at x = 0 and x = 1: X = (2, -1, 15) projects by hand to
  // u = fx * (X - Cx) / Z + cx, v = fy * Y / Z + cy.
  const Camera c0 = At({0, 0, 0}), c1 = At({1, 0, 0});
  const double fx = 718.856, cx = 607.1928, cy = 185.2157;
  const View views[] = {{&c0, {fx * 2.0 / 15.0 + cx, fx * -1.0 / 15.0 + cy}},
                        {&c1, {fx * 1.0 / 15.0 + cx, fx * -1.0 / 15.0 + cy}}};
  const auto X = TriangulateDlt(views);
  ASSERT_TRUE(X.has_value());
  EXPECT_LT((*X - Eigen::Vector3d(2, -1, 15)).norm(), 1e-6) << X->transpose();
}

TEST(Triangulation, DltRecoversANoiseFreePointFromRotatedCamerasFarFromTheOrigin) {
  const Eigen::Vector3d truth(1000.5, 20.25, -3000.0);
  std::vector<Camera> cams;
  for (int i = 0; i < 6; ++i) {
    const Eigen::Matrix3d R =
        Eigen::AngleAxisd(0.05 * i, Eigen::Vector3d(0.2, 1.0, 0.1).normalized()).toRotationMatrix();
    cams.push_back(At(Eigen::Vector3d(1000.0 + 0.8 * i, 20.0, -3030.0 + 0.3 * i), R));
  }
  std::vector<View> views;
  for (const Camera& c : cams) {
    const Eigen::Vector3d p = c.K * (c.R * truth + c.t);  // pixel = K (R X + t), dehomogenised
    ASSERT_GT(p.z(), 0.0);
    views.push_back({&c, p.head<2>() / p.z()});
  }
  const auto X = TriangulateDlt(views);
  ASSERT_TRUE(X.has_value());
  EXPECT_LT((*X - truth).norm(), 1e-6) << X->transpose();
}

TEST(Triangulation, ParallelRaysHaveNoDltSolution) {
  const Camera c0 = At({0, 0, 0}), c1 = At({1, 0, 0});
  const View views[] = {{&c0, {700, 200}}, {&c1, {700, 200}}};  // a point at infinity
  EXPECT_FALSE(TriangulateDlt(views).has_value());
  EXPECT_NEAR(ParallaxDeg(views), 0.0, 1e-6);
}

TEST(Triangulation, ParallaxIsTheAngleBetweenRays) {
  // X = (0, 0, 10) seen from (0, 0, 0) straight ahead and from (10, 0, 0) at 45 degrees.
  const Camera c0 = At({0, 0, 0}), c1 = At({10, 0, 0});
  const Eigen::Vector3d X(0, 0, 10);
  const View views[] = {{&c0, c0.Project(X)}, {&c1, c1.Project(X)}};
  EXPECT_NEAR(ParallaxDeg(views), 45.0, 1e-9);
}

TEST(Triangulation, ReprojectionErrorsAreInPixelsAndInfiniteBehind) {
  const Camera c0 = At({0, 0, 0});
  const Eigen::Vector3d X(1, 2, 10);
  const View views[] = {{&c0, c0.Project(X) + Eigen::Vector2d(3, 4)}};
  EXPECT_NEAR(ReprojectionErrors(views, X)[0], 5.0, 1e-9);
  EXPECT_TRUE(std::isinf(ReprojectionErrors(views, Eigen::Vector3d(1, 2, -10))[0]));
}

struct Sequence {
  std::vector<Camera> cams;
  std::vector<View> views;
};

// 20 frames moving forward 1 m each, observing `truth` with Gaussian pixel noise.
Sequence Forward(const Eigen::Vector3d& truth, double sigma_px, uint32_t seed) {
  Sequence s;
  s.cams.reserve(20);
  std::mt19937 rng(seed);
  std::normal_distribution<double> noise(0.0, sigma_px);
  for (int i = 0; i < 20; ++i) {
    s.cams.push_back(At({0, 0, static_cast<double>(i)}));
    s.views.push_back({&s.cams.back(), s.cams.back().Project(truth) +
                                           Eigen::Vector2d(noise(rng), noise(rng))});
  }
  return s;
}

TEST(Refinement, ConvergesToTheNoiseFreePointFromAPerturbedStart) {
  const Eigen::Vector3d truth(-6, 1.2, 40);
  const Sequence s = Forward(truth, 0.0, 1);
  Eigen::Vector3d X = truth + Eigen::Vector3d(0.5, -0.3, 4.0);
  ASSERT_TRUE(RefinePoint(s.views, {1.0, 50}, &X));
  EXPECT_LT((X - truth).norm(), 1e-6) << X.transpose();
}

TEST(Refinement, LowersTheReprojectionErrorOfTheDltEstimateUnderNoise) {
  const Eigen::Vector3d truth(-6, 1.2, 40);
  const Sequence s = Forward(truth, 0.5, 2);
  const auto dlt = TriangulateDlt(s.views);
  ASSERT_TRUE(dlt.has_value());
  Eigen::Vector3d X = *dlt;
  ASSERT_TRUE(RefinePoint(s.views, {0.0, 20}, &X));  // plain least squares: minimises the RMS
  auto rms = [&](const Eigen::Vector3d& p) {
    double sum = 0;
    for (double e : ReprojectionErrors(s.views, p)) sum += e * e;
    return std::sqrt(sum / static_cast<double>(s.views.size()));
  };
  EXPECT_LT(rms(X), rms(*dlt));
  EXPECT_LT(rms(X), 1.0);
  EXPECT_LT((X - truth).norm(), 1.0);  // depth 40 m with 19 m of baseline, 0.5 px noise
}

TEST(Refinement, HuberLossResistsOneGrossOutlier) {
  const Eigen::Vector3d truth(-6, 1.2, 40);
  Sequence s = Forward(truth, 0.3, 3);
  s.views[10].pixel += Eigen::Vector2d(60, -40);
  Eigen::Vector3d huber = truth + Eigen::Vector3d(0.2, 0.2, 2), plain = huber;
  ASSERT_TRUE(RefinePoint(s.views, {1.0, 50}, &huber));
  ASSERT_TRUE(RefinePoint(s.views, {0.0, 50}, &plain));
  EXPECT_LT((huber - truth).norm(), 0.5 * (plain - truth).norm())
      << "huber " << (huber - truth).norm() << " m, plain " << (plain - truth).norm() << " m";
}

}  // namespace
}  // namespace imr::ceres_refiner
