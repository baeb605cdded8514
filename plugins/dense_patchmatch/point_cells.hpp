// The cells of the dense points' 3D grid that hold a point (one point per cell), kept while a
// depth map can still put a point there: a cell farther than a map's reach from the newest
// reference camera is forgotten (Forget). A set of every cell ever filled grew with the drive
// (issue 46: a record per dense point); a surface the cameras come back to after leaving it is
// sampled again.
#pragma once

#include <Eigen/Core>

#include <cmath>
#include <cstdint>
#include <unordered_set>

namespace imr::dense {

class PointCells {
 public:
  // Cells of side `spacing` (> 0) from the first Insert on; SetSpacing before.
  void SetSpacing(double spacing) { spacing_ = spacing; }
  double spacing() const { return spacing_; }

  // False when X's cell holds a point already; else it holds X's from now on.
  bool Insert(const Eigen::Vector3d& X) { return cells_.insert(Key(X)).second; }

  // Drops every cell whose centre is farther than `reach` from `centre`.
  void Forget(const Eigen::Vector3d& centre, double reach) {
    const double r2 = reach * reach;
    for (auto it = cells_.begin(); it != cells_.end();)
      it = (Centre(*it) - centre).squaredNorm() > r2 ? cells_.erase(it) : std::next(it);
  }

  std::size_t size() const { return cells_.size(); }

 private:
  // 21 bits an axis, two's complement: +-2^20 cells from the origin.
  static constexpr uint64_t kMask = 0x1fffff;
  uint64_t Key(const Eigen::Vector3d& X) const {
    const auto q = [&](double a) {
      return static_cast<uint64_t>(static_cast<int64_t>(std::floor(a / spacing_))) & kMask;
    };
    return q(X.x()) | (q(X.y()) << 21) | (q(X.z()) << 42);
  }
  Eigen::Vector3d Centre(uint64_t key) const {
    const auto axis = [&](int shift) {
      int64_t v = static_cast<int64_t>((key >> shift) & kMask);
      if (v & 0x100000) v -= 0x200000;  // sign
      return (static_cast<double>(v) + 0.5) * spacing_;
    };
    return {axis(0), axis(21), axis(42)};
  }

  double spacing_ = 0.0;
  std::unordered_set<uint64_t> cells_;
};

}  // namespace imr::dense
