#include "tools/synth/raycaster.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace imr::synth {

using synthetic::Add;
using synthetic::Cross;
using synthetic::Dot;
using synthetic::Rect;
using synthetic::Scale;
using synthetic::Sub;

namespace {
constexpr double kInf = std::numeric_limits<double>::infinity();

void Extent(const Rect& r, int axis, double* lo, double* hi) {
  const double e = std::abs(r.u[axis]) * r.half_u + std::abs(r.v[axis]) * r.half_v;
  *lo = r.center[axis] - e;
  *hi = r.center[axis] + e;
}
}  // namespace

RayCaster::RayCaster(const synthetic::Scene& scene, double cell, double large) : cell_(cell) {
  const std::vector<Rect>& rects = scene.rects();
  gx0_ = gy0_ = gz0_ = kInf;
  gx1_ = gy1_ = gz1_ = -kInf;
  for (int i = 0; i < static_cast<int>(rects.size()); ++i) {
    const Rect& r = rects[static_cast<size_t>(i)];
    const Plane p{r.center, r.u, r.v, Cross(r.u, r.v), r.half_u, r.half_v, i};
    double x0, x1, y0, y1, z0, z1;
    Extent(r, 0, &x0, &x1);
    Extent(r, 1, &y0, &y1);
    Extent(r, 2, &z0, &z1);
    if (std::max(x1 - x0, y1 - y0) > large) {
      large_.push_back(p);
      continue;
    }
    small_.push_back(p);
    gx0_ = std::min(gx0_, x0);
    gx1_ = std::max(gx1_, x1);
    gy0_ = std::min(gy0_, y0);
    gy1_ = std::max(gy1_, y1);
    gz0_ = std::min(gz0_, z0);
    gz1_ = std::max(gz1_, z1);
  }
  if (small_.empty()) return;
  // Pad so that rects on the border are strictly inside.
  const double pad = 1e-6;
  gx0_ -= pad, gy0_ -= pad, gz0_ -= pad, gx1_ += pad, gy1_ += pad, gz1_ += pad;
  nx_ = std::max(1, static_cast<int>(std::ceil((gx1_ - gx0_) / cell_)));
  ny_ = std::max(1, static_cast<int>(std::ceil((gy1_ - gy0_) / cell_)));
  gx1_ = gx0_ + nx_ * cell_;
  gy1_ = gy0_ + ny_ * cell_;
  std::vector<std::vector<uint32_t>> cells(static_cast<size_t>(nx_) * ny_);
  for (uint32_t k = 0; k < small_.size(); ++k) {
    const Rect& r = rects[static_cast<size_t>(small_[k].index)];
    double x0, x1, y0, y1;
    Extent(r, 0, &x0, &x1);
    Extent(r, 1, &y0, &y1);
    const int i0 = std::clamp(static_cast<int>(std::floor((x0 - pad - gx0_) / cell_)), 0, nx_ - 1);
    const int i1 = std::clamp(static_cast<int>(std::floor((x1 + pad - gx0_) / cell_)), 0, nx_ - 1);
    const int j0 = std::clamp(static_cast<int>(std::floor((y0 - pad - gy0_) / cell_)), 0, ny_ - 1);
    const int j1 = std::clamp(static_cast<int>(std::floor((y1 + pad - gy0_) / cell_)), 0, ny_ - 1);
    for (int j = j0; j <= j1; ++j)
      for (int i = i0; i <= i1; ++i) cells[static_cast<size_t>(j) * nx_ + i].push_back(k);
  }
  cell_begin_.reserve(cells.size() + 1);
  cell_begin_.push_back(0);
  for (const auto& c : cells) {
    cell_items_.insert(cell_items_.end(), c.begin(), c.end());
    cell_begin_.push_back(static_cast<uint32_t>(cell_items_.size()));
  }
}

inline void RayCaster::Test(const Plane& p, const Vec3& o, const Vec3& d, double* best,
                            int* best_rect) {
  const double denom = Dot(d, p.n);
  if (std::abs(denom) < 1e-14) return;
  const double t = Dot(Sub(p.c, o), p.n) / denom;
  if (!(t > 1e-9 && t < *best)) return;
  const Vec3 q = Sub(Add(o, Scale(d, t)), p.c);
  if (std::abs(Dot(q, p.u)) > p.hu || std::abs(Dot(q, p.v)) > p.hv) return;
  *best = t;
  *best_rect = p.index;
}

bool RayCaster::CastWith(const Vec3& o, const Vec3& d, double t_max, const uint32_t* small,
                         size_t n, Hit* hit) const {
  double best = std::nextafter(t_max, kInf);
  int rect = -1;
  for (const Plane& p : large_) Test(p, o, d, &best, &rect);
  for (size_t k = 0; k < n; ++k) Test(small_[small[k]], o, d, &best, &rect);
  if (rect < 0) return false;
  hit->rect = rect;
  hit->t = best;
  return true;
}

void RayCaster::SmallCorners(size_t k, Vec3 corners[4]) const {
  const Plane& p = small_[k];
  const double su[4] = {-1, 1, 1, -1}, sv[4] = {-1, -1, 1, 1};
  for (int i = 0; i < 4; ++i)
    corners[i] = Add(p.c, Add(Scale(p.u, su[i] * p.hu), Scale(p.v, sv[i] * p.hv)));
}

bool RayCaster::Cast(const Vec3& o, const Vec3& d, double t_max, Hit* hit) const {
  // Strictly beyond t_max means a miss; `best` starts just above it so that t == t_max counts.
  double best = std::nextafter(t_max, kInf);
  int rect = -1;
  for (const Plane& p : large_) Test(p, o, d, &best, &rect);

  if (!small_.empty()) {
    // Clip the ray to the grid box (xy) and the z range of the small rects.
    double t0 = 0.0, t1 = best;
    const double lo[3] = {gx0_, gy0_, gz0_}, hi[3] = {gx1_, gy1_, gz1_};
    bool inside = true;
    for (int a = 0; a < 3 && inside; ++a) {
      if (d[a] == 0.0) {
        if (o[a] < lo[a] || o[a] > hi[a]) inside = false;
        continue;
      }
      double ta = (lo[a] - o[a]) / d[a], tb = (hi[a] - o[a]) / d[a];
      if (ta > tb) std::swap(ta, tb);
      t0 = std::max(t0, ta);
      t1 = std::min(t1, tb);
      if (t0 > t1) inside = false;
    }
    if (inside) {
      const double px = o[0] + t0 * d[0], py = o[1] + t0 * d[1];
      int ix = std::clamp(static_cast<int>(std::floor((px - gx0_) / cell_)), 0, nx_ - 1);
      int iy = std::clamp(static_cast<int>(std::floor((py - gy0_) / cell_)), 0, ny_ - 1);
      const int sx = d[0] > 0 ? 1 : -1, sy = d[1] > 0 ? 1 : -1;
      const double dtx = d[0] != 0.0 ? cell_ / std::abs(d[0]) : kInf;
      const double dty = d[1] != 0.0 ? cell_ / std::abs(d[1]) : kInf;
      double tx = d[0] != 0.0 ? (gx0_ + (ix + (sx > 0 ? 1 : 0)) * cell_ - o[0]) / d[0] : kInf;
      double ty = d[1] != 0.0 ? (gy0_ + (iy + (sy > 0 ? 1 : 0)) * cell_ - o[1]) / d[1] : kInf;
      for (;;) {
        const size_t c = static_cast<size_t>(iy) * nx_ + ix;
        for (uint32_t k = cell_begin_[c]; k < cell_begin_[c + 1]; ++k)
          Test(small_[cell_items_[k]], o, d, &best, &rect);
        // Every rect hit before the exit of this cell was in a cell visited so far.
        const double exit = std::min(tx, ty);
        if (exit >= best || exit >= t1) break;
        if (tx < ty) {
          ix += sx;
          tx += dtx;
          if (ix < 0 || ix >= nx_) break;
        } else {
          iy += sy;
          ty += dty;
          if (iy < 0 || iy >= ny_) break;
        }
      }
    }
  }
  if (rect < 0) return false;
  hit->rect = rect;
  hit->t = best;
  return true;
}

}  // namespace imr::synth
