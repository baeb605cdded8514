// Fast first-hit ray casting against a Scene's rects, for rendering many rays from few origins:
// the few large rects (street ground and facades) are tested for every ray; the many small ones
// (parked boxes) sit in a uniform xy grid walked along the ray (2-D DDA) only while it is inside
// their z range and closer than the best hit so far. Same answer as Scene::Intersect (first hit
// along the ray; synth_test compares them), much faster: no allocation, no sort, and a ray only
// visits the grid cells it crosses before its first hit.
#pragma once

#include <cstdint>
#include <vector>

#include "host/synthetic/scene.h"

namespace imr::synth {

using synthetic::Vec3;

class RayCaster {
 public:
  struct Hit {
    int rect = -1;   // Index into scene.rects(), -1 when nothing was hit.
    double t = 0.0;  // Hit point = origin + t * dir (t in units of |dir|).
  };

  // `cell`: grid cell size (metres); rects whose xy extent exceeds `large` are tested always.
  explicit RayCaster(const synthetic::Scene& scene, double cell = 2.0, double large = 20.0);

  // First hit of origin + t * dir with 1e-9 < t <= t_max; dir need not be unit length.
  bool Cast(const Vec3& origin, const Vec3& dir, double t_max, Hit* hit) const;

  // For callers that bin the small rects themselves (the renderer bins them per image tile):
  // the same first hit, testing the large rects and only the small rects small[0..n).
  bool CastWith(const Vec3& origin, const Vec3& dir, double t_max, const uint32_t* small, size_t n,
                Hit* hit) const;
  size_t small_count() const { return small_.size(); }
  // The corners of small rect k, in order around it.
  void SmallCorners(size_t k, Vec3 corners[4]) const;

 private:
  struct Plane {
    Vec3 c, u, v, n;
    double hu = 0.0, hv = 0.0;
    int index = -1;
  };
  static void Test(const Plane& p, const Vec3& o, const Vec3& d, double* best, int* best_rect);

  std::vector<Plane> large_;
  std::vector<Plane> small_;
  double cell_ = 2.0;
  double gx0_ = 0.0, gy0_ = 0.0, gx1_ = 0.0, gy1_ = 0.0, gz0_ = 0.0, gz1_ = 0.0;
  int nx_ = 0, ny_ = 0;
  std::vector<uint32_t> cell_begin_;  // nx * ny + 1 offsets into cell_items_.
  std::vector<uint32_t> cell_items_;  // Indices into small_.
};

}  // namespace imr::synth
