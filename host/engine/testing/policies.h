// Test and benchmark support: WeightTransferPolicy adapters over the pure C++ policies of
// plugins/weight_policies/weight_transfer.hpp (the plugins wrap the same functions). Include with
// ${CMAKE_SOURCE_DIR}/plugins on the include path.
#pragma once

#include <memory>
#include <string>

#include "host/engine/weight_transfer_policy.h"
#include "weight_policies/weight_transfer.hpp"

namespace imr::engine::testing {

enum class PolicyKind { kNearest, kMean, kWeightedMean };

class ArrayPolicy : public WeightTransferPolicy {
 public:
  explicit ArrayPolicy(PolicyKind kind) : kind_(kind) {}
  void Transfer(const TransferInput& in, double* out) override {
    const policies::RemovedCells r{in.removed_centroids, in.removed_weights, in.removed_count};
    const policies::AddedCells a{in.new_centroids, in.new_count};
    switch (kind_) {
      case PolicyKind::kNearest: policies::TransferNearest(r, a, out); break;
      case PolicyKind::kMean: policies::TransferMean(r, a, out); break;
      case PolicyKind::kWeightedMean: policies::TransferWeightedMean(r, a, out); break;
    }
  }
  std::string Name() const override {
    switch (kind_) {
      case PolicyKind::kNearest: return "nearest";
      case PolicyKind::kMean: return "mean";
      case PolicyKind::kWeightedMean: return "weighted_mean";
    }
    return "nearest";
  }

 private:
  PolicyKind kind_;
};

inline std::unique_ptr<WeightTransferPolicy> MakePolicy(const std::string& name) {
  if (name == "nearest") return std::make_unique<ArrayPolicy>(PolicyKind::kNearest);
  if (name == "mean") return std::make_unique<ArrayPolicy>(PolicyKind::kMean);
  if (name == "weighted_mean") return std::make_unique<ArrayPolicy>(PolicyKind::kWeightedMean);
  return nullptr;
}

}  // namespace imr::engine::testing
