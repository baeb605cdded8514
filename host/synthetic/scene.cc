#include "host/synthetic/scene.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>

namespace imr::synthetic {

std::string ToString(Material material) {
  switch (material) {
    case Material::kPlain: return "plain";
    case Material::kGround: return "ground";
    case Material::kFacade: return "facade";
    case Material::kBoxSide: return "box_side";
    case Material::kBoxEnd: return "box_end";
    case Material::kBoxTop: return "box_top";
  }
  return "plain";
}

Vec3 Normalized(const Vec3& a) {
  const double n = Norm(a);
  return n > 0.0 ? Scale(a, 1.0 / n) : a;
}

namespace {

double RectDistance(const Rect& r, const Vec3& p) {
  const Vec3 d = Sub(p, r.center);
  const double s = Dot(d, r.u), t = Dot(d, r.v);
  const Vec3 n = Cross(r.u, r.v);
  const double dn = Dot(d, n);
  const double ds = std::max(std::abs(s) - r.half_u, 0.0);
  const double dt = std::max(std::abs(t) - r.half_v, 0.0);
  return std::sqrt(dn * dn + ds * ds + dt * dt);
}

bool RectIntersect(const Rect& r, const Vec3& o, const Vec3& dir, double t_max, double* t_hit) {
  const Vec3 n = Cross(r.u, r.v);
  const double denom = Dot(dir, n);
  if (std::abs(denom) < 1e-12) return false;
  const double t = Dot(Sub(r.center, o), n) / denom;
  if (!(t > 1e-9 && t <= t_max)) return false;
  const Vec3 q = Sub(Add(o, Scale(dir, t)), r.center);
  if (std::abs(Dot(q, r.u)) > r.half_u || std::abs(Dot(q, r.v)) > r.half_v) return false;
  *t_hit = t;
  return true;
}

void RectBounds(const Rect& r, double* x0, double* y0, double* x1, double* y1) {
  const double ex = std::abs(r.u[0]) * r.half_u + std::abs(r.v[0]) * r.half_v;
  const double ey = std::abs(r.u[1]) * r.half_u + std::abs(r.v[1]) * r.half_v;
  *x0 = r.center[0] - ex;
  *x1 = r.center[0] + ex;
  *y0 = r.center[1] - ey;
  *y1 = r.center[1] + ey;
}

}  // namespace

Scene Scene::StreetCanyon(double length, uint64_t seed, double half_width, double facade_height) {
  Scene s;
  s.name_ = "street";
  const double y0 = -40.0, y1 = length + 40.0;
  const double cy = 0.5 * (y0 + y1), hy = 0.5 * (y1 - y0);
  // Ground, normal +z.
  s.AddRect({{0.0, cy, 0.0}, {1, 0, 0}, {0, 1, 0}, half_width, hy, Material::kGround});
  // Facades facing the street.
  s.AddRect({{-half_width, cy, 0.5 * facade_height}, {0, 1, 0}, {0, 0, 1}, hy, 0.5 * facade_height,
             Material::kFacade, 0});
  s.AddRect({{half_width, cy, 0.5 * facade_height}, {0, 0, 1}, {0, 1, 0}, 0.5 * facade_height, hy,
             Material::kFacade, 1});
  // Parked boxes along both kerbs.
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> gap(1.5, 9.0), len(3.8, 4.8), height(1.3, 1.7);
  int box = 0;
  for (int side = -1; side <= 1; side += 2) {
    double y = y0 + gap(rng);
    while (y < y1 - 5.0) {
      const double l = len(rng), h = height(rng);
      const double xin = side * (half_width - 3.2), xout = side * (half_width - 1.4);
      const size_t first = s.rects_.size();
      s.AddBox({std::min(xin, xout), y, 0.0}, {std::max(xin, xout), y + l, h}, false);
      // Boxes are long along y: faces with a +-x normal are the sides, +-y the ends.
      for (size_t i = first; i < s.rects_.size(); ++i) {
        Rect& r = s.rects_[i];
        const Vec3 n = Cross(r.u, r.v);
        r.material = std::abs(n[2]) > 0.5   ? Material::kBoxTop
                     : std::abs(n[0]) > 0.5 ? Material::kBoxSide
                                            : Material::kBoxEnd;
        r.group = box;
      }
      ++box;
      y += l + gap(rng);
    }
  }
  return s;
}

Scene Scene::ClosedRoom(const Vec3& min, const Vec3& max) {
  Scene s;
  s.name_ = "room";
  s.AddBox(min, max, true);
  return s;
}

Scene Scene::Plane(double half_size, double height) {
  Scene s;
  s.name_ = "plane";
  s.AddRect({{0.0, 0.0, height}, {1, 0, 0}, {0, 1, 0}, half_size, half_size});
  return s;
}

void Scene::AddRect(const Rect& r) {
  rects_.push_back(r);
  indexed_ = false;
}

void Scene::AddBox(const Vec3& mn, const Vec3& mx, bool with_bottom) {
  const Vec3 c = Scale(Add(mn, mx), 0.5);
  const Vec3 h = Scale(Sub(mx, mn), 0.5);
  // Normals point out of the box (u x v); for a room seen from inside that does not matter here.
  AddRect({{c[0], c[1], mx[2]}, {1, 0, 0}, {0, 1, 0}, h[0], h[1]});
  if (with_bottom) AddRect({{c[0], c[1], mn[2]}, {0, 1, 0}, {1, 0, 0}, h[1], h[0]});
  AddRect({{mx[0], c[1], c[2]}, {0, 1, 0}, {0, 0, 1}, h[1], h[2]});
  AddRect({{mn[0], c[1], c[2]}, {0, 0, 1}, {0, 1, 0}, h[2], h[1]});
  AddRect({{c[0], mx[1], c[2]}, {0, 0, 1}, {1, 0, 0}, h[2], h[0]});
  AddRect({{c[0], mn[1], c[2]}, {1, 0, 0}, {0, 0, 1}, h[0], h[2]});
}

namespace {
constexpr int kLargeBins = 8;
}  // namespace

void Scene::Index() const {
  if (indexed_) return;
  double x0 = std::numeric_limits<double>::infinity(), y0 = x0, x1 = -x0, y1 = -x0;
  for (const Rect& r : rects_) {
    double a, b, c, d;
    RectBounds(r, &a, &b, &c, &d);
    x0 = std::min(x0, a);
    y0 = std::min(y0, b);
    x1 = std::max(x1, c);
    y1 = std::max(y1, d);
  }
  if (rects_.empty()) x0 = y0 = x1 = y1 = 0.0;
  min_x_ = x0;
  min_y_ = y0;
  nx_ = std::max(1, static_cast<int>(std::ceil((x1 - x0) / bin_)) + 1);
  ny_ = std::max(1, static_cast<int>(std::ceil((y1 - y0) / bin_)) + 1);
  bins_.assign(static_cast<size_t>(nx_) * ny_, {});
  large_.clear();
  for (int i = 0; i < static_cast<int>(rects_.size()); ++i) {
    double a, b, c, d;
    RectBounds(rects_[i], &a, &b, &c, &d);
    const int i0 = std::clamp(static_cast<int>((a - min_x_) / bin_), 0, nx_ - 1);
    const int i1 = std::clamp(static_cast<int>((c - min_x_) / bin_), 0, nx_ - 1);
    const int j0 = std::clamp(static_cast<int>((b - min_y_) / bin_), 0, ny_ - 1);
    const int j1 = std::clamp(static_cast<int>((d - min_y_) / bin_), 0, ny_ - 1);
    if (static_cast<int64_t>(i1 - i0 + 1) * (j1 - j0 + 1) > kLargeBins) {
      large_.push_back(i);
      continue;
    }
    for (int ix = i0; ix <= i1; ++ix)
      for (int jy = j0; jy <= j1; ++jy) bins_[static_cast<size_t>(jy) * nx_ + ix].push_back(i);
  }
  indexed_ = true;
}

template <typename Visit>
void Scene::ForEachCandidate(double x0, double y0, double x1, double y1, Visit&& visit) const {
  Index();
  for (int i : large_) visit(i);
  const int i0 = std::clamp(static_cast<int>(std::floor((x0 - min_x_) / bin_)), 0, nx_ - 1);
  const int i1 = std::clamp(static_cast<int>(std::floor((x1 - min_x_) / bin_)), 0, nx_ - 1);
  const int j0 = std::clamp(static_cast<int>(std::floor((y0 - min_y_) / bin_)), 0, ny_ - 1);
  const int j1 = std::clamp(static_cast<int>(std::floor((y1 - min_y_) / bin_)), 0, ny_ - 1);
  for (int jy = j0; jy <= j1; ++jy)
    for (int ix = i0; ix <= i1; ++ix)
      for (int i : bins_[static_cast<size_t>(jy) * nx_ + ix]) visit(i);
}

std::vector<int> Scene::RectsNear(double x0, double y0, double x1, double y1) const {
  std::vector<int> out;
  ForEachCandidate(x0, y0, x1, y1, [&](int i) { out.push_back(i); });
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

// The minimum over a superset of the rects that can be hit or be near is the minimum over all
// rects: a rect whose bounding box misses the query box is farther than the ring (Distance) or
// cannot hold a point of the segment (Intersect), so results do not depend on the index.
double Scene::Distance(const Vec3& p) const {
  double best = std::numeric_limits<double>::infinity();
  Index();
  const double extent = bin_ * (nx_ + ny_ + 2);
  for (double r = bin_;; r *= 2.0) {
    ForEachCandidate(p[0] - r, p[1] - r, p[0] + r, p[1] + r,
                     [&](int i) { best = std::min(best, RectDistance(rects_[i], p)); });
    if (best <= r || r > extent) break;
  }
  return best;
}

bool Scene::Cast(const Vec3& o, const Vec3& dir, double t_max, bool any, double* t_hit) const {
  const Vec3 e = Add(o, Scale(dir, t_max));
  double best = std::numeric_limits<double>::infinity();
  // No early return from the walk: `any` only skips the remaining rect tests.
  ForEachCandidate(std::min(o[0], e[0]), std::min(o[1], e[1]), std::max(o[0], e[0]),
                   std::max(o[1], e[1]), [&](int i) {
                     if (any && best < std::numeric_limits<double>::infinity()) return;
                     double t;
                     if (RectIntersect(rects_[i], o, dir, t_max, &t) && t < best) best = t;
                   });
  if (best == std::numeric_limits<double>::infinity()) return false;
  *t_hit = best;
  return true;
}

bool Scene::Intersect(const Vec3& o, const Vec3& dir, double t_max, double* t_hit) const {
  return Cast(o, dir, t_max, false, t_hit);
}

bool Scene::Visible(const Vec3& from, const Vec3& to, double eps) const {
  const Vec3 d = Sub(to, from);
  const double len = Norm(d);
  if (len <= eps) return true;
  double t;
  return !Cast(from, Scale(d, 1.0 / len), len - eps, true, &t);
}

}  // namespace imr::synthetic
