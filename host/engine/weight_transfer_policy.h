// The weight-transfer policy of Romanoni & Matteucci, section 3.2: when the Delaunay triangulation
// replaces removed tetrahedra R by new ones A (a vertex removed or a point inserted), the policy
// gives the new tetrahedra weights from the removed ones, without re-casting rays. The host binds
// a loaded policy plugin to this interface; the engine only sees this class.
#pragma once

#include <cstddef>
#include <string>

namespace imr::engine {

struct TransferInput {
  const double* removed_centroids = nullptr;  // Packed xyz, 3 * removed_count doubles.
  const double* removed_weights = nullptr;    // removed_count weights (in weight units, e.g. 1.0).
  std::size_t removed_count = 0;
  const double* new_centroids = nullptr;      // Packed xyz, 3 * new_count doubles.
  std::size_t new_count = 0;
};

class WeightTransferPolicy {
 public:
  virtual ~WeightTransferPolicy() = default;
  // Writes in.new_count weights to out_weights. Must not throw; a NaN output is treated as 0.
  virtual void Transfer(const TransferInput& in, double* out_weights) = 0;
  // Short name for logs and reports ("nearest", "mean", ...).
  virtual std::string Name() const = 0;
};

}  // namespace imr::engine
