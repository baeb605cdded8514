// Hand-computed cases for the three weight-transfer policies.
#include "weight_transfer.hpp"

#include <gtest/gtest.h>

#include <vector>

namespace imr::policies {
namespace {

// Two removed cells on the x axis, at x = 0 (weight 1) and x = 4 (weight 3).
const std::vector<double> kRemovedC = {0, 0, 0, 4, 0, 0};
const std::vector<double> kRemovedW = {1.0, 3.0};
const RemovedCells kRemoved{kRemovedC.data(), kRemovedW.data(), 2};

TEST(WeightTransfer, MeanGivesEveryNewCellTheMean) {
  const std::vector<double> added = {1, 0, 0, 10, 10, 10, -5, 0, 0};
  std::vector<double> out(3, -1.0);
  TransferMean(kRemoved, {added.data(), 3}, out.data());
  for (double w : out) EXPECT_DOUBLE_EQ(w, 2.0);
}

TEST(WeightTransfer, NearestTakesTheClosestCentroid) {
  const std::vector<double> added = {1, 0, 0, 3, 0, 0, 2, 0, 0, 100, 0, 0};
  std::vector<double> out(4, -1.0);
  TransferNearest(kRemoved, {added.data(), 4}, out.data());
  EXPECT_DOUBLE_EQ(out[0], 1.0);
  EXPECT_DOUBLE_EQ(out[1], 3.0);
  EXPECT_DOUBLE_EQ(out[2], 1.0);  // tie at x = 2: the lowest index wins, deterministically
  EXPECT_DOUBLE_EQ(out[3], 3.0);
}

TEST(WeightTransfer, WeightedMeanIsInverseDistance) {
  // At x = 1: distances 1 and 3 -> (1/1 * 1 + 1/3 * 3) / (1/1 + 1/3) = 2 / (4/3) = 1.5.
  // At x = 2: equal distances -> plain mean 2. At x = 4: coincident -> exactly 3.
  const std::vector<double> added = {1, 0, 0, 2, 0, 0, 4, 0, 0};
  std::vector<double> out(3, -1.0);
  TransferWeightedMean(kRemoved, {added.data(), 3}, out.data());
  EXPECT_DOUBLE_EQ(out[0], 1.5);
  EXPECT_DOUBLE_EQ(out[1], 2.0);
  EXPECT_DOUBLE_EQ(out[2], 3.0);
}

TEST(WeightTransfer, NoRemovedCellsGivesZero) {
  const std::vector<double> added = {1, 2, 3};
  const RemovedCells none{nullptr, nullptr, 0};
  for (auto fn : {&TransferMean, &TransferWeightedMean, &TransferNearest}) {
    double out = -1.0;
    fn(none, {added.data(), 1}, &out);
    EXPECT_EQ(out, 0.0);
  }
}

TEST(WeightTransfer, NearestKeepsTheDiscontinuity) {
  // The paper's argument for "minimum distance": a sharp free/matter edge stays sharp.
  // Free cells (weight 5) left of x = 0, matter (0) right of it.
  const std::vector<double> rc = {-1, 0, 0, -2, 0, 0, 1, 0, 0, 2, 0, 0};
  const std::vector<double> rw = {5, 5, 0, 0};
  const RemovedCells removed{rc.data(), rw.data(), 4};
  const std::vector<double> added = {-0.5, 0, 0, 0.5, 0, 0};
  std::vector<double> nearest(2), mean(2);
  TransferNearest(removed, {added.data(), 2}, nearest.data());
  TransferMean(removed, {added.data(), 2}, mean.data());
  EXPECT_EQ(nearest[0], 5.0);
  EXPECT_EQ(nearest[1], 0.0);
  EXPECT_EQ(mean[0], mean[1]);  // the mean blurs both sides to 2.5
}

}  // namespace
}  // namespace imr::policies
