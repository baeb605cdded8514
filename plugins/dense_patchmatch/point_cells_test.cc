// The dense points' grid cells over a long drive (issue 46): what is held follows the stretch of
// the drive a depth map can reach, not the drive.
#include "point_cells.hpp"

#include <gtest/gtest.h>

#include <random>

namespace imr::dense {
namespace {

TEST(PointCells, OnePointPerCellWhileInReach) {
  PointCells cells;
  cells.SetSpacing(0.5);
  EXPECT_TRUE(cells.Insert({0.1, 0.1, 0.1}));
  EXPECT_FALSE(cells.Insert({0.4, 0.2, 0.3}));  // the same cell
  EXPECT_TRUE(cells.Insert({-0.1, 0.1, 0.1}));  // the next one, across 0
  EXPECT_TRUE(cells.Insert({-20.2, 3.0, -7.7}));
  cells.Forget({0, 0, 0}, 5.0);  // the cell 22 m away goes, the two near stay
  EXPECT_EQ(cells.size(), 2u);
  EXPECT_FALSE(cells.Insert({0.2, 0.2, 0.2}));
  EXPECT_FALSE(cells.Insert({-0.2, 0.2, 0.2}));
  EXPECT_TRUE(cells.Insert({-20.2, 3.0, -7.7}));  // forgotten: sampled again
}

// A drive along x, 1 m a keyframe: 300 points a keyframe on facades up to 30 m ahead, each map
// then forgets beyond 60 m. The cells held after `keyframes` keyframes.
std::size_t HeldAfter(int keyframes) {
  PointCells cells;
  cells.SetSpacing(0.2);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (int k = 0; k < keyframes; ++k) {
    const Eigen::Vector3d camera(k, 0.0, 1.5);
    for (int i = 0; i < 300; ++i)
      cells.Insert({k + 2.0 + 28.0 * u(rng), u(rng) < 0.5 ? -7.0 : 8.0, 12.0 * u(rng)});
    cells.Forget(camera, 60.0);
  }
  return cells.size();
}

TEST(PointCells, WhatItHoldsStaysFlatOverTheDrive) {
  // A cell kept per point (or per keyframe) adds thousands between the two drives.
  const std::size_t at_100 = HeldAfter(100), at_400 = HeldAfter(400);
  EXPECT_GT(at_100, 1000u);
  EXPECT_LE(static_cast<double>(at_400), 1.1 * static_cast<double>(at_100))
      << "cells held at 100 keyframes " << at_100 << ", at 400 keyframes " << at_400;
}

}  // namespace
}  // namespace imr::dense
