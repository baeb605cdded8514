#include "tools/synth/renderer.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

namespace imr::synth {

using synthetic::Add;
using synthetic::Cross;
using synthetic::Dot;
using synthetic::Normalized;
using synthetic::Rect;
using synthetic::Rgb;
using synthetic::Scale;
using synthetic::SceneTexture;
using synthetic::Sub;

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kPi = 3.14159265358979323846;

// Lighting: a sun from above-left-behind plus ambient sky light; haze with distance.
const Vec3 kSun = Normalized({0.3, -0.4, 0.85});
constexpr double kAmbient = 0.45, kDiffuse = 0.6, kHazeDistance = 800.0;  // Half haze there.
const Rgb kHaze{0.80f, 0.83f, 0.87f};

inline uint64_t Mix(uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

// Acklam's rational approximation of the standard normal quantile (relative error < 1.2e-9).
double InverseNormalCdf(double p) {
  static const double a[] = {-3.969683028665376e+01, 2.209460984245205e+02,  -2.759285104469687e+02,
                             1.383577518672690e+02,  -3.066479806614716e+01, 2.506628277459239e+00};
  static const double b[] = {-5.447609879822406e+01, 1.615858368580409e+02, -1.556989798598866e+02,
                             6.680131188771972e+01, -1.328068155288572e+01};
  static const double c[] = {-7.784894002430293e-03, -3.223964580411365e-01, -2.400758277161838e+00,
                             -2.549732539343734e+00, 4.374664141464968e+00,  2.938163982698783e+00};
  static const double d[] = {7.784695709041462e-03, 3.224671290700398e-01, 2.445134137142996e+00,
                             3.754408661907416e+00};
  auto tail = [&](double q) {
    return (((((c[0] * q + c[1]) * q + c[2]) * q + c[3]) * q + c[4]) * q + c[5]) /
           ((((d[0] * q + d[1]) * q + d[2]) * q + d[3]) * q + 1.0);
  };
  if (p < 0.02425) return tail(std::sqrt(-2.0 * std::log(p)));
  if (p > 1.0 - 0.02425) return -tail(std::sqrt(-2.0 * std::log(1.0 - p)));
  const double q = p - 0.5, r = q * q;
  return (((((a[0] * r + a[1]) * r + a[2]) * r + a[3]) * r + a[4]) * r + a[5]) * q /
         (((((b[0] * r + b[1]) * r + b[2]) * r + b[3]) * r + b[4]) * r + 1.0);
}

Rgb Sky(const Vec3& dir) {
  const double el = dir[2] / std::sqrt(Dot(dir, dir));
  const double k = std::clamp(el / 0.6, 0.0, 1.0);
  const double s = k * k * (3.0 - 2.0 * k);
  return {static_cast<float>(0.86 - 0.38 * s), static_cast<float>(0.88 - 0.26 * s),
          static_cast<float>(0.91 - 0.06 * s)};
}

// Derivative of the hit point on a plane with normal n when the ray direction changes by dd.
Vec3 HitDerivative(const Vec3& dir, const Vec3& n, double t, const Vec3& dd) {
  return Scale(Sub(dd, Scale(dir, Dot(n, dd) / Dot(n, dir))), t);
}

inline uint8_t Quantize(double v) {
  return static_cast<uint8_t>(std::clamp(std::floor(v + 0.5), 0.0, 255.0));
}

}  // namespace

Renderer::Renderer(const synthetic::Scene& scene, const SceneTexture& texture,
                   const RayCaster& caster, const Intrinsics& camera, const RenderOptions& options)
    : scene_(scene), texture_(texture), caster_(caster), camera_(camera), options_(options) {
  gauss_.resize(1 << 16);
  for (size_t k = 0; k < gauss_.size(); ++k)
    gauss_[k] = static_cast<float>(InverseNormalCdf((k + 0.5) / static_cast<double>(1 << 16)));
  all_small_.resize(caster_.small_count());
  std::iota(all_small_.begin(), all_small_.end(), 0u);
}

Rgb Renderer::ColorToward(const Vec3& center, const Vec3& p, int rect, int* hit) const {
  // Render's ray through a pixel centre has camera z = 1: scale p - center to that.
  const Vec3 d = Sub(p, center);
  const double z = CameraFromScene(d)[2];
  if (!(z > 0.0)) {
    *hit = -1;
    return {};
  }
  const Vec3 ddx = SceneFromCamera({1.0 / camera_.fx, 0.0, 0.0});
  const Vec3 ddy = SceneFromCamera({0.0, 1.0 / camera_.fy, 0.0});
  if (rect >= 0) {
    *hit = rect;
    return ShadeHit(center, Scale(d, 1.0 / z), ddx, ddy, rect, z);
  }
  return Shade(center, Scale(d, 1.0 / z), ddx, ddy, all_small_.data(), all_small_.size(), hit);
}

Renderer::TileBins Renderer::Bin(const Vec3& center) const {
  const int w = camera_.width, h = camera_.height;
  TileBins bins;
  bins.tiles_x = (w + kTile - 1) / kTile;
  const int tiles_y = (h + kTile - 1) / kTile;
  std::vector<std::vector<uint32_t>> lists(static_cast<size_t>(bins.tiles_x) * tiles_y);
  constexpr double kNear = 1e-3;
  for (size_t k = 0; k < caster_.small_count(); ++k) {
    Vec3 corner[4];
    caster_.SmallCorners(k, corner);
    Vec3 q[4];
    for (int i = 0; i < 4; ++i) q[i] = CameraFromScene(Sub(corner[i], center));
    // Clip the quad to z >= kNear (Sutherland-Hodgman, one plane), then bound its projection.
    double u0 = kInf, u1 = -kInf, v0 = kInf, v1 = -kInf;
    auto add = [&](const Vec3& p) {
      const double u = camera_.fx * p[0] / p[2] + camera_.cx;
      const double v = camera_.fy * p[1] / p[2] + camera_.cy;
      u0 = std::min(u0, u), u1 = std::max(u1, u), v0 = std::min(v0, v), v1 = std::max(v1, v);
    };
    for (int i = 0; i < 4; ++i) {
      const Vec3& a = q[i];
      const Vec3& b = q[(i + 1) % 4];
      if (a[2] >= kNear) add(a);
      if ((a[2] >= kNear) != (b[2] >= kNear))
        add(Add(a, Scale(Sub(b, a), (kNear - a[2]) / (b[2] - a[2]))));
    }
    if (!(u0 <= u1)) continue;  // Entirely behind the camera.
    // One pixel of margin: supersampling rays spread over the whole pixel.
    u0 = std::floor(u0 - 1.0), u1 = std::ceil(u1 + 1.0);
    v0 = std::floor(v0 - 1.0), v1 = std::ceil(v1 + 1.0);
    if (u1 < 0.0 || v1 < 0.0 || u0 > w - 1 || v0 > h - 1) continue;
    const int i0 = static_cast<int>(std::max(u0, 0.0)) / kTile;
    const int i1 = static_cast<int>(std::min(u1, w - 1.0)) / kTile;
    const int j0 = static_cast<int>(std::max(v0, 0.0)) / kTile;
    const int j1 = static_cast<int>(std::min(v1, h - 1.0)) / kTile;
    for (int j = j0; j <= j1; ++j)
      for (int i = i0; i <= i1; ++i)
        lists[static_cast<size_t>(j) * bins.tiles_x + i].push_back(static_cast<uint32_t>(k));
  }
  bins.begin.reserve(lists.size() + 1);
  bins.begin.push_back(0);
  for (const auto& l : lists) {
    bins.items.insert(bins.items.end(), l.begin(), l.end());
    bins.begin.push_back(static_cast<uint32_t>(bins.items.size()));
  }
  return bins;
}

Rgb Renderer::Shade(const Vec3& o, const Vec3& dir, const Vec3& ddx, const Vec3& ddy,
                    const uint32_t* small, size_t small_count, int* rect) const {
  RayCaster::Hit hit;
  if (!caster_.CastWith(o, dir, kInf, small, small_count, &hit)) {
    *rect = -1;
    return Sky(dir);
  }
  *rect = hit.rect;
  return ShadeHit(o, dir, ddx, ddy, hit.rect, hit.t);
}

Rgb Renderer::ShadeHit(const Vec3& o, const Vec3& dir, const Vec3& ddx, const Vec3& ddy, int rect,
                       double t) const {
  const Rect& r = scene_.rects()[static_cast<size_t>(rect)];
  Vec3 n = Cross(r.u, r.v);
  const Vec3 p = Add(o, Scale(dir, t));
  const Rgb albedo = texture_.Albedo(rect, p, HitDerivative(dir, n, t, ddx),
                                     HitDerivative(dir, n, t, ddy));
  if (Dot(n, dir) > 0.0) n = Scale(n, -1.0);  // The side facing the camera.
  const double light = kAmbient + kDiffuse * std::max(0.0, Dot(n, kSun));
  const double distance = t * std::sqrt(Dot(dir, dir));
  const double haze = distance / (distance + kHazeDistance);
  auto mix = [&](float a, float h) {
    return static_cast<float>(a * light * (1.0 - haze) + h * haze);
  };
  return {mix(albedo.r, kHaze.r), mix(albedo.g, kHaze.g), mix(albedo.b, kHaze.b)};
}

cv::Mat Renderer::Render(const Vec3& center, int frame) const {
  const int w = camera_.width, h = camera_.height;
  const size_t count = static_cast<size_t>(w) * h;
  const double fx = camera_.fx, fy = camera_.fy, cx = camera_.cx, cy = camera_.cy;
  auto direction = [&](double u, double v) {
    return SceneFromCamera({(u - cx) / fx, (v - cy) / fy, 1.0});
  };
  const Vec3 ddx = SceneFromCamera({1.0 / fx, 0.0, 0.0});
  const Vec3 ddy = SceneFromCamera({0.0, 1.0 / fy, 0.0});
  cv::Mat image(h, w, options_.color ? CV_8UC3 : CV_8UC1);
  const TileBins bins = Bin(center);
  auto tile = [&](int i, int j) {
    const size_t t = static_cast<size_t>(j / kTile) * bins.tiles_x + i / kTile;
    return std::pair<const uint32_t*, size_t>(bins.items.data() + bins.begin[t],
                                              bins.begin[t + 1] - bins.begin[t]);
  };

  if (options_.id_colors) {
    for (int j = 0; j < h; ++j)
      for (int i = 0; i < w; ++i) {
        RayCaster::Hit hit;
        const auto [small, n] = tile(i, j);
        const uint32_t id = caster_.CastWith(center, direction(i, j), kInf, small, n, &hit)
                                ? static_cast<uint32_t>(hit.rect) + 1u
                                : 0u;
        if (options_.color)
          image.at<cv::Vec3b>(j, i) = {static_cast<uint8_t>(id & 255),
                                       static_cast<uint8_t>((id >> 8) & 255),
                                       static_cast<uint8_t>((id >> 16) & 255)};
        else
          image.at<uint8_t>(j, i) = static_cast<uint8_t>(id & 255);
      }
    return image;
  }

  // Pass 1: one ray through every pixel centre (textures are prefiltered over the footprint).
  std::vector<Rgb> color(count);
  std::vector<int> rect(count);
  for (int j = 0; j < h; ++j)
    for (int i = 0; i < w; ++i) {
      const size_t k = static_cast<size_t>(j) * w + i;
      const auto [small, n] = tile(i, j);
      color[k] = Shade(center, direction(i, j), ddx, ddy, small, n, &rect[k]);
    }
  // Pass 2: pixels on a geometric edge (a 4-neighbour sees another rect or the sky) average n
  // rays spread over the pixel in an n-rooks lattice (n distinct offsets along each axis, so a
  // nearly axis-aligned edge still gets n coverage levels), each with a footprint n^-1/2 smaller.
  const int n = std::max(1, options_.supersample);
  if (n > 1) {
    int step = std::max(1, static_cast<int>(std::lround(0.382 * n)));
    while (std::gcd(step, n) != 1) ++step;
    const double shrink = 1.0 / std::sqrt(static_cast<double>(n));
    const Vec3 sdx = Scale(ddx, shrink), sdy = Scale(ddy, shrink);
    std::vector<Rgb> fixed;
    std::vector<size_t> where;
    for (int j = 0; j < h; ++j)
      for (int i = 0; i < w; ++i) {
        const size_t k = static_cast<size_t>(j) * w + i;
        const int id = rect[k];
        const bool edge = (i > 0 && rect[k - 1] != id) || (i + 1 < w && rect[k + 1] != id) ||
                          (j > 0 && rect[k - w] != id) || (j + 1 < h && rect[k + w] != id);
        if (!edge) continue;
        const auto [small, small_count] = tile(i, j);
        double r = 0.0, g = 0.0, b = 0.0;
        for (int q = 0; q < n; ++q) {
          const double du = (q + 0.5) / n - 0.5, dv = ((q * step) % n + 0.5) / n - 0.5;
          int unused;
          const Rgb s =
              Shade(center, direction(i + du, j + dv), sdx, sdy, small, small_count, &unused);
          r += s.r, g += s.g, b += s.b;
        }
        fixed.push_back(
            {static_cast<float>(r / n), static_cast<float>(g / n), static_cast<float>(b / n)});
        where.push_back(k);
      }
    for (size_t q = 0; q < where.size(); ++q) color[where[q]] = fixed[q];
  }

  // Quantise with Gaussian noise: a counter-based hash of (seed, frame, pixel, channel) picks a
  // normal quantile, so the noise is the same whatever the thread schedule.
  const uint64_t key =
      Mix(options_.seed * 0x2545F4914F6CDD1Dull ^ Mix(static_cast<uint64_t>(frame)));
  const double sigma = options_.noise;
  auto noise = [&](uint64_t index) {
    return sigma > 0.0 ? sigma * gauss_[Mix(key ^ index) >> 48] : 0.0;
  };
  for (int j = 0; j < h; ++j) {
    for (int i = 0; i < w; ++i) {
      const size_t k = static_cast<size_t>(j) * w + i;
      const Rgb& c = color[k];
      if (options_.color) {
        image.at<cv::Vec3b>(j, i) = {Quantize(255.0 * c.b + noise(3 * k)),
                                     Quantize(255.0 * c.g + noise(3 * k + 1)),
                                     Quantize(255.0 * c.r + noise(3 * k + 2))};
      } else {
        image.at<uint8_t>(j, i) = Quantize(255.0 * SceneTexture::Luminance(c) + noise(k));
      }
    }
  }
  return image;
}

std::vector<float> ScanVelodyne(const RayCaster& caster, const SceneTexture& texture,
                                const Rig& rig, const Vec3& camera_center,
                                const LidarOptions& options) {
  const Vec3 origin = VelodyneOrigin(rig, camera_center);
  const int steps =
      std::max(1, static_cast<int>(std::floor(360.0 / options.horizontal_step_deg + 1e-9)));
  const int beams = std::max(1, options.beams);
  std::vector<double> ca(static_cast<size_t>(steps)), sa(static_cast<size_t>(steps));
  for (int a = 0; a < steps; ++a) {
    const double az = (180.0 - a * options.horizontal_step_deg) * kPi / 180.0;
    ca[static_cast<size_t>(a)] = std::cos(az);
    sa[static_cast<size_t>(a)] = std::sin(az);
  }
  // Reflectance: the albedo averaged over the beam's footprint (divergence about 3 mrad), and
  // over at least 10 cm (the finest texture detail costs time and is not what a lidar sees).
  constexpr double kDivergence = 0.003, kMinFootprint = 0.1;
  const Vec3 up = SceneFromVelodyne(rig, {0.0, 0.0, 1.0});
  std::vector<float> out;
  out.reserve(static_cast<size_t>(beams) * steps * 4 / 2);
  for (int b = 0; b < beams; ++b) {
    const double el =
        (beams == 1
             ? options.max_elevation_deg
             : options.max_elevation_deg -
                   b * (options.max_elevation_deg - options.min_elevation_deg) / (beams - 1)) *
        kPi / 180.0;
    const double ce = std::cos(el), se = std::sin(el);
    for (int a = 0; a < steps; ++a) {
      const Vec3 dv{ce * ca[static_cast<size_t>(a)], ce * sa[static_cast<size_t>(a)], se};
      const Vec3 dir = SceneFromVelodyne(rig, dv);
      RayCaster::Hit hit;
      if (!caster.Cast(origin, dir, options.max_range, &hit)) continue;
      const Rect& r = texture.scene().rects()[static_cast<size_t>(hit.rect)];
      const Vec3 n = Cross(r.u, r.v);
      const Vec3 side = Normalized(Cross(dir, up));
      const Vec3 over = Cross(side, dir);
      const double spread = std::max(kDivergence, kMinFootprint / hit.t);
      const Rgb albedo = texture.Albedo(hit.rect, Add(origin, Scale(dir, hit.t)),
                                        HitDerivative(dir, n, hit.t, Scale(side, spread)),
                                        HitDerivative(dir, n, hit.t, Scale(over, spread)));
      out.push_back(static_cast<float>(dv[0] * hit.t));
      out.push_back(static_cast<float>(dv[1] * hit.t));
      out.push_back(static_cast<float>(dv[2] * hit.t));
      out.push_back(SceneTexture::Luminance(albedo));
    }
  }
  return out;
}

}  // namespace imr::synth
