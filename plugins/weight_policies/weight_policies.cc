// The paper's three weight-transfer policies as plugins (the paper's section 3; host/engine/weight_transfer_policy.h). The arithmetic
// lives in weight_transfer.hpp, shared with the engine's tests and benchmark.
#include <imr/sdk/plugin.hpp>

#include "weight_transfer.hpp"

namespace {

using TransferFn = void (*)(const imr::policies::RemovedCells&, const imr::policies::AddedCells&,
                            double*);

// The three policies differ only in identity and in the function they apply.
template <typename Traits>
class Policy : public imr::sdk::WeightPolicy {
 public:
  static constexpr const char* kId = Traits::kId;
  static constexpr const char* kVersion = "1.0.0";
  static constexpr const char* kDescription = Traits::kDescription;
  static constexpr const char* kParamsSchema = "{}";

  Policy(const imr::sdk::Params&, const imr::sdk::Host&) {}

  void Transfer(const imr::sdk::TransferRequest& r) override {
    Traits::kFn({r.removed_centroids.data(), r.removed_weights.data(), r.removed_count()},
                {r.added_centroids.data(), r.added_count()}, r.added_weights.data());
  }
};

struct Mean {
  static constexpr const char* kId = "org.imr.policy.mean";
  static constexpr const char* kDescription = "Mean weight of the removed cells (paper: mean value)";
  static constexpr TransferFn kFn = &imr::policies::TransferMean;
};
struct WeightedMean {
  static constexpr const char* kId = "org.imr.policy.weighted_mean";
  static constexpr const char* kDescription =
      "Inverse-distance weighted mean of removed cells' weights by centroid distance";
  static constexpr TransferFn kFn = &imr::policies::TransferWeightedMean;
};
struct Nearest {
  static constexpr const char* kId = "org.imr.policy.nearest";
  static constexpr const char* kDescription =
      "Weight of the removed cell with the nearest centroid (paper: minimum distance; recommended)";
  static constexpr TransferFn kFn = &imr::policies::TransferNearest;
};

}  // namespace

IMR_PLUGIN_EXPORT(Policy<Mean>, Policy<WeightedMean>, Policy<Nearest>)
