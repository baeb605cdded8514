#include "host/plugin/policy_adapter.h"

#include <cmath>

namespace imr::plugin {

void PluginWeightPolicy::Transfer(const engine::TransferInput& in, double* out) {
  imr_transfer_request req{};
  req.removed_centroids = in.removed_centroids;
  req.removed_weights = in.removed_weights;
  req.removed_count = in.removed_count;
  req.added_centroids = in.new_centroids;
  req.added_count = in.new_count;
  req.added_weights = out;
  try {
    instance_.instance.Transfer(&req);
    for (std::size_t i = 0; i < in.new_count; ++i) {
      if (!std::isfinite(out[i])) {
        if (error_.empty())
          error_ = name_ + ": transfer returned a non-finite weight (" + std::to_string(out[i]) + ")";
        out[i] = 0.0;
      }
    }
  } catch (const std::exception& e) {
    if (error_.empty()) error_ = e.what();
    for (std::size_t i = 0; i < in.new_count; ++i) out[i] = 0.0;
  }
}

}  // namespace imr::plugin
