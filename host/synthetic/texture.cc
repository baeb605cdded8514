#include "host/synthetic/texture.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace imr::synthetic {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// --- Deterministic hashing (splitmix64), independent of the standard library's distributions.

inline uint64_t Mix(uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}
inline uint64_t Hash(uint64_t a, uint64_t b) { return Mix(a ^ Mix(b)); }
inline uint64_t Hash(uint64_t a, int64_t i, int64_t j) {
  return Mix(a ^
             Mix(static_cast<uint64_t>(i) * 0xD1B54A32D192ED03ull ^ Mix(static_cast<uint64_t>(j))));
}
inline double U01(uint64_t h) { return static_cast<double>(h >> 11) * 0x1.0p-53; }

struct Rng {
  uint64_t state;
  uint64_t Next() { return Mix(state++); }
  double Uniform(double lo, double hi) { return lo + (hi - lo) * U01(Next()); }
};

// --- Colours.

Rgb Make(double r, double g, double b) {
  return {static_cast<float>(r), static_cast<float>(g), static_cast<float>(b)};
}
Rgb Gray(double v) { return Make(v, v, v); }
Rgb operator*(const Rgb& c, double k) { return Make(c.r * k, c.g * k, c.b * k); }
Rgb operator+(const Rgb& a, const Rgb& b) { return {a.r + b.r, a.g + b.g, a.b + b.b}; }
Rgb Lerp(const Rgb& a, const Rgb& b, double t) { return a * (1.0 - t) + b * t; }
Rgb Clamp01(const Rgb& c) {
  return {std::clamp(c.r, 0.0f, 1.0f), std::clamp(c.g, 0.0f, 1.0f), std::clamp(c.b, 0.0f, 1.0f)};
}

// --- Box-filtered patterns. x is the sample position, w the footprint width (the filter is the
// box [x - w/2, x + w/2]); w = 0 samples the pattern at x.

double SmoothStep(double e0, double e1, double x) {
  const double t = std::clamp((x - e0) / (e1 - e0), 0.0, 1.0);
  return t * t * (3.0 - 2.0 * t);
}

// Share of the footprint inside [lo, hi).
double Box(double x, double w, double lo, double hi) {
  if (w <= 1e-12) return x >= lo && x < hi ? 1.0 : 0.0;
  const double a = std::max(x - 0.5 * w, lo), b = std::min(x + 0.5 * w, hi);
  return b > a ? (b - a) / w : 0.0;
}

// Integral over (-inf, x] of the pulse train with pulses [k * period, k * period + width).
double PulseIntegral(double x, double period, double width) {
  const double k = std::floor(x / period);
  return k * width + std::min(x - k * period, width);
}

// Share of the footprint covered by the pulses [offset + k * period, offset + k * period + width)
// that lie in [lo, hi] (both ends on pulse boundaries or between pulses).
double Pulses(double x, double w, double period, double width, double offset, double lo = -kInf,
              double hi = kInf) {
  if (w <= 1e-12) {
    if (x < lo || x >= hi) return 0.0;
    const double u = x - offset;
    return u - std::floor(u / period) * period < width ? 1.0 : 0.0;
  }
  const double a = std::max(x - 0.5 * w, lo), b = std::min(x + 0.5 * w, hi);
  if (b <= a) return 0.0;
  return (PulseIntegral(b - offset, period, width) - PulseIntegral(a - offset, period, width)) / w;
}

// Share of a footprint of size w inside the disc of radius r at distance d from its centre (a
// smooth edge as wide as the footprint).
double Disc(double d, double r, double w) {
  if (w <= 1e-12) return d < r ? 1.0 : 0.0;
  return std::clamp((r - d) / w + 0.5, 0.0, 1.0);
}

// Weight of a random per-element variation (bricks, windows) given the footprint relative to
// the element size: 1 while elements are resolved, fading to 0 (their mean) once several share
// a pixel.
double ElementWeight(double footprint_over_size) {
  return 1.0 - SmoothStep(0.3, 0.8, footprint_over_size);
}

// Value noise in [-1, 1] on the unit lattice, quintic interpolation. The noise is the hot spot
// of texturing: a cheap 32-bit hash per lattice point (lattice coordinates wrap at 2^32).
inline double Lattice(int64_t i, int64_t j, uint32_t key) {
  uint32_t h =
      key ^ (static_cast<uint32_t>(i) * 0x8DA6B343u) ^ (static_cast<uint32_t>(j) * 0xD8163841u);
  h ^= h >> 16;
  h *= 0x7FEB352Du;
  h ^= h >> 15;
  h *= 0x846CA68Bu;
  h ^= h >> 16;
  return static_cast<double>(h) * (2.0 / 4294967296.0) - 1.0;
}

double ValueNoise(double x, double y, uint32_t key) {
  const double fx = std::floor(x), fy = std::floor(y);
  const auto ix = static_cast<int64_t>(fx), iy = static_cast<int64_t>(fy);
  const double tx = x - fx, ty = y - fy;
  const double ux = tx * tx * tx * (tx * (tx * 6.0 - 15.0) + 10.0);
  const double uy = ty * ty * ty * (ty * (ty * 6.0 - 15.0) + 10.0);
  const double a = Lattice(ix, iy, key), b = Lattice(ix + 1, iy, key);
  const double c = Lattice(ix, iy + 1, key), d = Lattice(ix + 1, iy + 1, key);
  const double ab = a + (b - a) * ux, cd = c + (d - c) * ux;
  return ab + (cd - ab) * uy;
}

// Fractal value noise: `octaves` octaves from f0 cycles per metre, each doubling the frequency
// and scaling the amplitude by gain. Octaves finer than the footprint w fade out (band limit).
double Fbm(double x, double y, double w, double f0, int octaves, double gain, uint64_t key) {
  double sum = 0.0, amp = 1.0, f = f0;
  for (int o = 0; o < octaves; ++o) {
    const double fade = 1.0 - SmoothStep(0.25, 0.7, f * w);
    if (fade <= 0.0) break;
    sum += amp * fade * ValueNoise(x * f, y * f, static_cast<uint32_t>(Mix(key + o)));
    amp *= gain;
    f *= 2.0;
  }
  return sum;
}

const Rgb kBrickColors[] = {Make(0.55, 0.27, 0.19), Make(0.62, 0.36, 0.24), Make(0.47, 0.22, 0.17),
                            Make(0.70, 0.58, 0.42)};
const Rgb kPlasterColors[] = {Make(0.82, 0.76, 0.64), Make(0.72, 0.72, 0.70),
                              Make(0.86, 0.84, 0.80), Make(0.76, 0.62, 0.50),
                              Make(0.62, 0.68, 0.70), Make(0.80, 0.70, 0.52)};
const Rgb kCarColors[] = {Make(0.85, 0.85, 0.83), Make(0.60, 0.62, 0.64), Make(0.08, 0.08, 0.09),
                          Make(0.62, 0.09, 0.07), Make(0.12, 0.22, 0.52), Make(0.12, 0.32, 0.16),
                          Make(0.82, 0.66, 0.12), Make(0.36, 0.37, 0.39)};
const Rgb kAccentColors[] = {Make(0.9, 0.45, 0.05), Make(0.1, 0.55, 0.75), Make(0.85, 0.85, 0.85),
                             Make(0.75, 0.1, 0.1), Make(0.1, 0.1, 0.1)};
template <typename T, size_t N>
const T& Pick(const T (&a)[N], uint64_t h) {
  return a[h % N];
}

}  // namespace

SceneTexture::SceneTexture(const Scene& scene, uint64_t seed)
    : scene_(scene), seed_(Mix(seed ^ 0x7E57u)) {
  const std::vector<Rect>& rects = scene.rects();
  frames_.resize(rects.size());
  double facade_lo[2] = {kInf, kInf}, facade_hi[2] = {-kInf, -kInf};
  double ground_lo = kInf, ground_hi = -kInf;
  int boxes = 0;
  for (size_t i = 0; i < rects.size(); ++i) {
    const Rect& r = rects[i];
    Frame& f = frames_[i];
    const double ex = std::abs(r.u[0]) * r.half_u + std::abs(r.v[0]) * r.half_v;
    const double ey = std::abs(r.u[1]) * r.half_u + std::abs(r.v[1]) * r.half_v;
    const double ez = std::abs(r.u[2]) * r.half_u + std::abs(r.v[2]) * r.half_v;
    switch (r.material) {
      case Material::kGround:
        f.axis_s = {1, 0, 0};
        f.axis_t = {0, 1, 0};
        road_half_width_ = std::max(road_half_width_, ex);
        ground_lo = std::min(ground_lo, r.center[1] - ey);
        ground_hi = std::max(ground_hi, r.center[1] + ey);
        break;
      case Material::kFacade: {
        f.origin = {0, 0, r.center[2] - ez};
        f.axis_s = {0, 1, 0};
        f.axis_t = {0, 0, 1};
        f.height = 2.0 * ez;
        const int side = r.group == 1 ? 1 : 0;
        facade_lo[side] = std::min(facade_lo[side], r.center[1] - ey);
        facade_hi[side] = std::max(facade_hi[side], r.center[1] + ey);
        break;
      }
      case Material::kBoxSide:
      case Material::kBoxEnd: {
        const bool u_vertical = std::abs(r.u[2]) > 0.5;
        f.origin = {r.center[0], r.center[1], r.center[2] - ez};
        f.axis_s = u_vertical ? r.v : r.u;
        f.axis_t = {0, 0, 1};
        f.half_s = u_vertical ? r.half_v : r.half_u;
        f.height = 2.0 * ez;
        f.front = Cross(r.u, r.v)[1] > 0.0;
        boxes = std::max(boxes, r.group + 1);
        break;
      }
      case Material::kBoxTop:
        f.origin = r.center;
        f.axis_s = {1, 0, 0};
        f.axis_t = {0, 1, 0};
        f.half_s = ex;
        f.half_t = ey;
        boxes = std::max(boxes, r.group + 1);
        break;
      case Material::kPlain:
        f.origin = r.center;
        f.axis_s = r.u;
        f.axis_t = r.v;
        break;
    }
  }

  // Buildings along each facade: spans of 9-24 m, generated from the facade's start so that a
  // longer street keeps the same buildings where it overlaps a shorter one.
  for (int side = 0; side < 2; ++side) {
    if (!(facade_lo[side] < facade_hi[side])) continue;
    Rng rng{Hash(seed_, 0xFACADEull + static_cast<uint64_t>(side))};
    for (double s = facade_lo[side]; s < facade_hi[side];) {
      Building b;
      b.s0 = s;
      b.s1 = s + rng.Uniform(9.0, 24.0);
      b.key = rng.Next();
      b.brick = rng.Uniform(0, 1) < 0.4;
      const uint64_t h = rng.Next();
      b.wall = b.brick ? Pick(kBrickColors, h) : Pick(kPlasterColors, h);
      b.wall = b.wall * rng.Uniform(0.85, 1.1);
      b.trim = rng.Uniform(0, 1) < 0.5 ? Make(0.78, 0.76, 0.70) : b.wall * 0.7;
      b.frame = Gray(rng.Uniform(0.07, 0.18));
      b.glass = Make(0.30, 0.35, 0.42) * rng.Uniform(0.7, 1.3);  // Reflects the sky.
      b.shop = rng.Uniform(0, 1) < 0.5;
      b.ground_floor = rng.Uniform(3.2, 4.2);
      b.storey = rng.Uniform(2.8, 3.4);
      b.bay = rng.Uniform(2.4, 3.6);
      b.win_w = rng.Uniform(0.9, std::min(1.6, b.bay - 0.9));
      b.win_h = rng.Uniform(1.3, std::min(1.9, b.storey - 1.0));
      b.sill = rng.Uniform(0.6, b.storey - b.win_h - 0.25);
      b.frame_w = rng.Uniform(0.07, 0.12);
      const double len = b.s1 - b.s0, margin = 1.0;
      const int bays = std::max(0, static_cast<int>(std::floor((len - 2.0 * margin) / b.bay)));
      b.bays_lo = b.s0 + 0.5 * (len - bays * b.bay);
      b.bays_hi = b.bays_lo + bays * b.bay;
      b.bay_offset = b.bays_lo + 0.5 * (b.bay - b.win_w);
      buildings_[side].push_back(b);
      s = b.s1;
    }
  }

  // Cars: a body colour, sometimes a stripe in an accent colour.
  Rng car_rng{Hash(seed_, 0xCA55ull)};
  cars_.resize(static_cast<size_t>(boxes));
  for (Car& c : cars_) {
    c.body = Pick(kCarColors, car_rng.Next()) * car_rng.Uniform(0.9, 1.08);
    c.accent = Pick(kAccentColors, car_rng.Next());
    c.glass = Make(0.07, 0.09, 0.12) * car_rng.Uniform(0.8, 1.6);
    c.stripe = car_rng.Uniform(0, 1) < 0.35;
  }

  // Zebra crossings every 45-110 m along the street (sorted by y).
  if (ground_lo < ground_hi) {
    Rng zebra{Hash(seed_, 0x2EB4Aull)};
    for (double y = ground_lo + zebra.Uniform(10.0, 50.0); y < ground_hi;
         y += zebra.Uniform(45.0, 110.0))
      crossings_.push_back(y);
  }
}

const SceneTexture::Car& SceneTexture::CarOf(int group) const {
  static const Car kDefault{Gray(0.5), Gray(0.8), Gray(0.1), false};
  if (group < 0 || group >= static_cast<int>(cars_.size())) return kDefault;
  return cars_[static_cast<size_t>(group)];
}

Rgb SceneTexture::Albedo(int rect, const Vec3& p, const Vec3& dpdx, const Vec3& dpdy) const {
  const Rect& r = scene_.rects()[static_cast<size_t>(rect)];
  const Frame& f = frames_[static_cast<size_t>(rect)];
  const Vec3 d = Sub(p, f.origin);
  const double s = Dot(d, f.axis_s), t = Dot(d, f.axis_t);
  const double ws = std::abs(Dot(dpdx, f.axis_s)) + std::abs(Dot(dpdy, f.axis_s));
  const double wt = std::abs(Dot(dpdx, f.axis_t)) + std::abs(Dot(dpdy, f.axis_t));
  Rgb c;
  switch (r.material) {
    case Material::kGround:
      c = Ground(s, t, ws, wt);
      break;
    case Material::kFacade:
      c = Facade(r.group == 1 ? 1 : 0, s, t, ws, wt, f.height);
      break;
    case Material::kBoxSide:
      c = CarSide(CarOf(r.group), s, t, ws, wt, f.half_s, f.height);
      break;
    case Material::kBoxEnd:
      c = CarEnd(CarOf(r.group), s, t, ws, wt, f.half_s, f.height, f.front);
      break;
    case Material::kBoxTop:
      c = CarTop(CarOf(r.group), s, t, ws, wt, f.half_s, f.half_t);
      break;
    case Material::kPlain:
      c = Plain(s, t, ws, wt);
      break;
  }
  return Clamp01(c);
}

Rgb SceneTexture::Ground(double x, double y, double wx, double wy) const {
  const double w = std::max(wx, wy);
  // Asphalt: faint 10 m blotches and a strong grain from 60 cm down to 2 cm (the grain is what
  // KLT tracks on the road near the camera; farther away it averages out to the mean grey).
  Rgb c = Make(0.30, 0.30, 0.315) * (1.0 + 0.10 * Fbm(x, y, w, 0.1, 3, 0.5, seed_ ^ 0xA5u) +
                                     0.30 * Fbm(x, y, w, 1.6, 6, 0.8, seed_ ^ 0xA6u));

  // Repaired patches: darker rectangles, at most one per 15 m of street.
  const double cell = 15.0;
  const auto k0 = static_cast<int64_t>(std::floor((y - 0.5 * wy) / cell));
  const auto k1 = static_cast<int64_t>(std::floor((y + 0.5 * wy) / cell));
  for (int64_t k = k0; k <= std::min(k1, k0 + 5); ++k) {
    const uint64_t h = Hash(seed_ ^ 0xBA7Cu, k, 0);
    if (U01(h) < 0.45) continue;
    Rng rng{h};
    const double x0 = rng.Uniform(-4.0, 2.0), xw = rng.Uniform(0.8, 2.5);
    const double y0 = k * cell + rng.Uniform(0.0, 9.0), yw = rng.Uniform(1.0, 5.0);
    const double cover = Box(x, wx, x0, x0 + xw) * Box(y, wy, y0, y0 + yw);
    if (cover > 0.0) c = Lerp(c, c * rng.Uniform(0.7, 0.85), cover);
  }

  const double hw = road_half_width_;
  if (hw < 5.5) return c;  // Too narrow for a street layout: plain asphalt.
  const double kerb = hw - 1.2, lane = hw - 3.5;

  // White markings: dashed centre line, solid lines along the parking lanes, zebra crossings.
  double m = Box(x, wx, -0.06, 0.06) * Pulses(y, wy, 9.0, 3.0, 0.0);
  m += Box(x, wx, lane - 0.06, lane + 0.06) + Box(x, wx, -lane - 0.06, -lane + 0.06);
  const auto first = std::lower_bound(crossings_.begin(), crossings_.end(), y - 0.5 * wy - 6.0);
  for (auto it = first; it != crossings_.end() && *it < y + 0.5 * wy + 2.0; ++it) {
    const double yc = *it;
    m += Pulses(x, wx, 1.0, 0.5, 0.25, -lane + 0.25, lane - 0.25) * Box(y, wy, yc, yc + 3.5);
    m += Box(x, wx, -lane, 0.0) * Box(y, wy, yc + 4.5, yc + 4.8);
    m += Box(x, wx, 0.0, lane) * Box(y, wy, yc - 1.3, yc - 1.0);
  }
  if (m > 0.0) {
    const Rgb paint = Gray(0.80) * (1.0 + 0.08 * Fbm(x, y, w, 1.0, 3, 0.6, seed_ ^ 0x9A1Au));
    c = Lerp(c, paint, std::min(m, 1.0));
  }

  // Gutter, kerb stones, then paved pavements up to the facades.
  const double gutter = Box(x, wx, kerb - 0.2, kerb) + Box(x, wx, -kerb, -kerb + 0.2);
  if (gutter > 0.0) c = Lerp(c, c * 0.6, gutter);
  const double kerb_cover = Box(x, wx, kerb, kerb + 0.15) + Box(x, wx, -kerb - 0.15, -kerb);
  if (kerb_cover > 0.0) {
    const Rgb stone = Make(0.70, 0.69, 0.66) * (1.0 + 0.06 * Fbm(x, y, w, 2.0, 3, 0.6, 0x4Bu));
    c = Lerp(c, stone, kerb_cover);
  }
  const double pave = Box(x, wx, kerb + 0.15, kInf) + Box(x, wx, -kInf, -kerb - 0.15);
  if (pave > 0.0) {
    const double tile = 0.6;
    const double jx = Pulses(x, wx, tile, 0.02, kerb + 0.15), jy = Pulses(y, wy, tile, 0.02, 0.0);
    const double joint = jx + jy - jx * jy;
    const double var =
        2.0 * U01(Hash(seed_ ^ 0x711Eu, static_cast<int64_t>(std::floor((x - kerb - 0.15) / tile)),
                       static_cast<int64_t>(std::floor(y / tile)))) -
        1.0;
    const double fade = ElementWeight(std::max(wx, wy) / tile);
    Rgb slab = Make(0.56, 0.54, 0.51) *
               (1.0 + 0.08 * var * fade + 0.07 * Fbm(x, y, w, 0.5, 4, 0.6, seed_ ^ 0x9A7Eu));
    slab = Lerp(slab, Gray(0.30), 0.8 * joint);
    c = Lerp(c, slab, pave);
  }
  return c;
}

Rgb SceneTexture::Facade(int side, double s, double t, double ws, double wt, double height) const {
  const std::vector<Building>& bs = buildings_[side];
  if (bs.empty()) return Plain(s, t, ws, wt);
  // The building holding s; near a party wall, the footprint is split between the buildings it
  // covers (each part filtered on its own), so the change of building is anti-aliased too.
  auto it = std::upper_bound(bs.begin(), bs.end(), s,
                             [](double v, const Building& b) { return v < b.s0; });
  const size_t i = it == bs.begin() ? 0 : static_cast<size_t>(it - bs.begin()) - 1;
  const double a = s - 0.5 * ws, b = s + 0.5 * ws;
  if (ws <= 1e-12 || (a >= bs[i].s0 && b <= bs[i].s1) || (i == 0 && b <= bs[0].s1) ||
      (i + 1 == bs.size() && a >= bs[i].s0))
    return BuildingColor(bs[i], s, t, ws, wt, height);
  Rgb sum;
  double total = 0.0;
  size_t j = i;
  while (j > 0 && bs[j].s0 > a) --j;
  for (int n = 0; j < bs.size() && bs[j].s0 < b && n < 8; ++j, ++n) {
    const double lo = j == 0 ? a : std::max(a, bs[j].s0);
    const double hi = j + 1 == bs.size() ? b : std::min(b, bs[j].s1);
    if (hi <= lo) continue;
    sum = sum + BuildingColor(bs[j], 0.5 * (lo + hi), t, hi - lo, wt, height) * (hi - lo);
    total += hi - lo;
  }
  return total > 0.0 ? sum * (1.0 / total) : BuildingColor(bs[i], s, t, ws, wt, height);
}

Rgb SceneTexture::BuildingColor(const Building& b, double s, double t, double ws, double wt,
                                double height) const {
  const double w = std::max(ws, wt);
  Rgb c = b.wall * (1.0 + 0.10 * Fbm(s, t, w, 0.15, 3, 0.5, b.key + 1));
  if (b.brick) {
    // Bricks 0.23 x 0.065 m in running bond, 1 cm mortar; per-brick shade while resolved.
    const double course = 0.075, len = 0.24, mortar = 0.011;
    const double h = Pulses(t, wt, course, mortar, 0.0);
    const double odd = Pulses(t, wt, 2.0 * course, course, course);  // Share in odd courses.
    const double v =
        (1.0 - odd) * Pulses(s, ws, len, mortar, 0.0) + odd * Pulses(s, ws, len, mortar, 0.5 * len);
    const auto row = static_cast<int64_t>(std::floor(t / course));
    const double shift = (row & 1) ? 0.5 * len : 0.0;
    const auto col = static_cast<int64_t>(std::floor((s - shift) / len));
    const double var = 2.0 * U01(Hash(b.key, col, row)) - 1.0;
    const double fade = ElementWeight(std::max(ws / len, wt / course));
    c = c * (1.0 + 0.18 * var * fade + 0.05 * Fbm(s, t, w, 4.0, 3, 0.6, b.key + 2));
    c = Lerp(c, Make(0.72, 0.70, 0.66), h + v - h * v);
  } else {
    c = c * (1.0 + 0.07 * Fbm(s, t, w, 1.0, 4, 0.6, b.key + 3));
    // Rusticated ground floor: horizontal grooves.
    const double groove = Pulses(t, wt, 0.45, 0.03, 0.5, 0.5, b.ground_floor - 0.4);
    c = Lerp(c, c * 0.65, groove);
  }
  // Plinth, string courses at every floor, cornice under the roof line.
  c = Lerp(c, b.trim * 0.8, Box(t, wt, -kInf, 0.45));
  const int rows =
      std::max(0, static_cast<int>(std::floor((height - 1.2 - b.ground_floor) / b.storey)));
  const double top = b.ground_floor + rows * b.storey;
  c = Lerp(c, b.trim,
           Pulses(t, wt, b.storey, 0.15, b.ground_floor - 0.15, b.ground_floor - 0.15, top));
  c = Lerp(c, b.trim, Box(t, wt, height - 0.9, height - 0.55));
  c = Lerp(c, b.trim * 0.55, Box(t, wt, height - 0.55, height - 0.45));
  // A downpipe at the party wall.
  c = Lerp(c, Gray(0.28), Box(s, ws, b.s0 + 0.12, b.s0 + 0.24));

  if (b.bays_hi <= b.bays_lo) return c;
  const double f = b.frame_w;
  // Upper windows: glass with a mullion and a transom, in a dark frame. Each coverage is a
  // product of two 1-D filtered pulse trains, which is the exact box filter of the rectangles.
  if (rows > 0) {
    const double lo = b.ground_floor, hi = top;
    const double y0 = b.ground_floor + b.sill;
    const double glass_t = Pulses(t, wt, b.storey, b.win_h, y0, lo, hi);
    const double outer_t = Pulses(t, wt, b.storey, b.win_h + 2 * f, y0 - f, lo, hi);
    const double transom_t = Pulses(t, wt, b.storey, 0.8 * f, y0 + 0.68 * b.win_h, lo, hi);
    const double glass_s = Pulses(s, ws, b.bay, b.win_w, b.bay_offset, b.bays_lo, b.bays_hi);
    const double outer_s =
        Pulses(s, ws, b.bay, b.win_w + 2 * f, b.bay_offset - f, b.bays_lo, b.bays_hi);
    const double mullion_s =
        Pulses(s, ws, b.bay, 0.8 * f, b.bay_offset + 0.5 * b.win_w - 0.4 * f, b.bays_lo, b.bays_hi);
    const double outer = outer_s * outer_t;
    if (outer > 0.0) {
      const double glass = glass_s * glass_t;
      const double bars = mullion_s * glass_t + glass_s * transom_t - mullion_s * transom_t;
      const auto col = static_cast<int64_t>(std::floor((s - b.bay_offset) / b.bay));
      const auto row = static_cast<int64_t>(std::floor((t - b.ground_floor) / b.storey));
      const double var = 2.0 * U01(Hash(b.key ^ 0x61A55u, col, row)) - 1.0;
      const double fade = ElementWeight(std::max(ws / b.bay, wt / b.storey));
      const double in = std::clamp((t - y0 - row * b.storey) / b.win_h, 0.0, 1.0);
      const Rgb pane = b.glass * ((1.0 + 0.5 * var * fade) * (0.75 + 0.5 * in));
      c = c * (1.0 - outer) + b.frame * (outer - glass + bars) + pane * (glass - bars);
    }
  }
  // Ground floor: shop windows under a coloured sign band, or small windows.
  if (b.shop) {
    const double sw = 0.72 * b.bay, off = b.bays_lo + 0.14 * b.bay;
    const double t0 = 0.55, t1 = b.ground_floor - 0.6;
    const double outer = Pulses(s, ws, b.bay, sw + 2 * f, off - f, b.bays_lo, b.bays_hi) *
                         Box(t, wt, t0 - f, t1 + f);
    if (outer > 0.0) {
      const double glass = Pulses(s, ws, b.bay, sw, off, b.bays_lo, b.bays_hi) * Box(t, wt, t0, t1);
      c = c * (1.0 - outer) + b.frame * (outer - glass) + b.glass * (0.75 * glass);
    }
    const Rgb sign = Pick(kAccentColors, b.key >> 7);
    c = Lerp(c, sign, Box(s, ws, b.bays_lo, b.bays_hi) * Box(t, wt, t1 + 0.15, t1 + 0.45));
  } else {
    const double win_h = std::min(b.win_h, b.ground_floor - 1.5), y0 = 1.0;
    const double outer =
        Pulses(s, ws, b.bay, b.win_w + 2 * f, b.bay_offset - f, b.bays_lo, b.bays_hi) *
        Box(t, wt, y0 - f, y0 + win_h + f);
    if (outer > 0.0) {
      const double glass = Pulses(s, ws, b.bay, b.win_w, b.bay_offset, b.bays_lo, b.bays_hi) *
                           Box(t, wt, y0, y0 + win_h);
      c = c * (1.0 - outer) + b.frame * (outer - glass) + b.glass * glass;
    }
  }
  return c;
}

Rgb SceneTexture::CarSide(const Car& car, double s, double t, double ws, double wt, double half_len,
                          double height) const {
  const double w = std::max(ws, wt), hl = half_len, h = height;
  Rgb c = car.body * (0.92 + 0.12 * std::clamp(t / h, 0.0, 1.0));
  // Side windows with a B-pillar, door seams and handles, an optional stripe.
  const double band = Box(t, wt, 0.63 * h, 0.92 * h);
  const double glass = Box(s, ws, -hl + 0.75, hl - 0.5) * band;
  const double pillar = Box(s, ws, -0.08, 0.06) * band;
  c = Lerp(c, car.glass, glass - pillar);
  const double doors = Box(t, wt, 0.22, 0.6 * h);
  c = Lerp(c, car.body * 0.35, (Box(s, ws, 0.55, 0.575) + Box(s, ws, -0.65, -0.625)) * doors);
  c = Lerp(c, Gray(0.12),
           (Box(s, ws, 0.2, 0.36) + Box(s, ws, -0.45, -0.29)) * Box(t, wt, 0.5 * h, 0.54 * h));
  if (car.stripe)
    c = Lerp(c, car.accent, Box(s, ws, -hl + 0.15, hl - 0.15) * Box(t, wt, 0.42 * h, 0.47 * h));
  // Sill in shadow, then the wheels: arch, tyre, rim, hub.
  c = Lerp(c, Gray(0.05), Box(t, wt, -kInf, 0.18));
  for (double sc : {-(hl - 0.8), hl - 0.8}) {
    const double d = std::hypot(s - sc, t - 0.32);
    c = Lerp(c, Gray(0.10), Disc(d, 0.38, w) * Box(t, wt, 0.0, kInf));
    c = Lerp(c, Gray(0.05), Disc(d, 0.32, w));
    c = Lerp(c, Gray(0.55), Disc(d, 0.19, w));
    c = Lerp(c, Gray(0.22), Disc(d, 0.06, w));
  }
  return c;
}

Rgb SceneTexture::CarEnd(const Car& car, double s, double t, double ws, double wt,
                         double half_width, double height, bool front) const {
  const double hw = half_width, h = height;
  Rgb c = car.body;
  c = Lerp(c, car.glass, Box(s, ws, -hw + 0.2, hw - 0.2) * Box(t, wt, 0.62 * h, 0.9 * h));
  const Rgb light = front ? Make(0.92, 0.90, 0.78) : Make(0.68, 0.07, 0.05);
  c = Lerp(c, light,
           (Box(s, ws, -hw + 0.06, -hw + 0.38) + Box(s, ws, hw - 0.38, hw - 0.06)) *
               Box(t, wt, 0.46 * h, 0.57 * h));
  c = Lerp(c, Gray(0.16), Box(t, wt, 0.12, 0.3));  // Bumper.
  const double plate = Box(s, ws, -0.26, 0.26) * Box(t, wt, 0.32 * h, 0.42 * h);
  c = Lerp(c, Gray(0.88), plate);
  const double chars =
      Pulses(s, ws, 0.075, 0.045, -0.2, -0.2, 0.2) * Box(t, wt, 0.335 * h, 0.405 * h);
  c = Lerp(c, Gray(0.08), chars);
  c = Lerp(c, Gray(0.05), Box(t, wt, -kInf, 0.12));
  return c;
}

Rgb SceneTexture::CarTop(const Car& car, double s, double t, double ws, double wt, double half_s,
                         double half_t) const {
  Rgb c = car.body * 1.05;
  const double across = Box(s, ws, -half_s + 0.15, half_s - 0.15);
  c = Lerp(c, car.glass,
           across * (Box(t, wt, 0.25 * half_t, 0.55 * half_t) +
                     Box(t, wt, -0.62 * half_t, -0.42 * half_t)));
  c = Lerp(c, Gray(0.15),
           (Box(s, ws, -half_s + 0.1, -half_s + 0.16) + Box(s, ws, half_s - 0.16, half_s - 0.1)) *
               Box(t, wt, -0.4 * half_t, 0.25 * half_t));
  return c;
}

Rgb SceneTexture::Plain(double s, double t, double ws, double wt) const {
  const double w = std::max(ws, wt);
  Rgb c = Gray(0.55) * (1.0 + 0.25 * Fbm(s, t, w, 0.5, 6, 0.6, seed_ ^ 0x91A1u));
  const double gs = Pulses(s, ws, 1.0, 0.03, 0.0), gt = Pulses(t, wt, 1.0, 0.03, 0.0);
  return Lerp(c, Gray(0.2), gs + gt - gs * gt);
}

}  // namespace imr::synthetic
