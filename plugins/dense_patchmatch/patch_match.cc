#include "patch_match.hpp"

#include <opencv2/imgproc.hpp>

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <thread>

namespace imr::dense {

bool PatchMatchOptions::Check(std::string* error) const {
  auto fail = [&](const char* what) {
    if (error) *error = what;
    return false;
  };
  if (!(min_depth > 0.0) || !(max_depth > min_depth) || !std::isfinite(max_depth))
    return fail("depth range: expected 0 < min_depth < max_depth, finite");
  if (iterations < 1 || iterations > 64) return fail("iterations: expected 1..64");
  if (window_radius < 1 || window_radius > 16) return fail("window_radius: expected 1..16");
  if (window_step < 1 || window_step > window_radius) return fail("window_step: expected 1..window_radius");
  if (!(max_normal_angle_deg > 0.0 && max_normal_angle_deg < 90.0))
    return fail("max_normal_angle_deg: expected in (0, 90)");
  if (!(min_zncc >= -1.0 && min_zncc <= 1.0)) return fail("min_zncc: expected -1..1");
  if (min_views < 1) return fail("min_views: expected >= 1");
  if (!(min_texture >= 0.0)) return fail("min_texture: expected >= 0");
  if (threads < 1 || threads > 256) return fail("threads: expected 1..256");
  return true;
}

View Downscaled(const View& full, double s) {
  View v = full;
  if (s >= 1.0) return v;
  const int w = std::max(1, static_cast<int>(std::lround(full.gray.cols * s)));
  const int h = std::max(1, static_cast<int>(std::lround(full.gray.rows * s)));
  cv::resize(full.gray, v.gray, cv::Size(w, h), 0, 0, cv::INTER_AREA);
  const double sx = static_cast<double>(w) / full.gray.cols, sy = static_cast<double>(h) / full.gray.rows;
  // Pixel centres at integer coordinates: u' = s (u + 0.5) - 0.5.
  v.K(0, 0) = full.K(0, 0) * sx;
  v.K(0, 1) = full.K(0, 1) * sx;
  v.K(0, 2) = (full.K(0, 2) + 0.5) * sx - 0.5;
  v.K(1, 1) = full.K(1, 1) * sy;
  v.K(1, 2) = (full.K(1, 2) + 0.5) * sy - 0.5;
  return v;
}

namespace {

// Deterministic per-pixel randomness (the same map whatever the threads): splitmix64.
uint64_t Mix(uint64_t x) {
  x += 0x9e3779b97f4a7c15ULL;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}
struct Random {
  uint64_t state;
  double Uniform() { return (Mix(state++) >> 11) * (1.0 / 9007199254740992.0); }  // [0, 1)
  double Signed() { return 2.0 * Uniform() - 1.0; }
};

// A neighbour view seen from the reference camera (Y_n = Rr Y_ref + tr): the homography of the
// plane n . Y_ref = offset is K (Rr + tr n^T / offset) Kref^-1 = A + b m^T with m =
// Kref^-T n / offset, so A and b once per neighbour and a rank-one term per plane.
struct Neighbour {
  const View* view;
  int w, h;
  Eigen::Matrix3d A;  // K Rr Kref^-1
  Eigen::Vector3d b;  // K tr
};

struct Plane {
  float depth = 0.0f;  // along the camera's z axis
  Eigen::Vector3f n = Eigen::Vector3f(0, 0, -1);
};

// Normals along the camera's axes, facing it: frontal, a wall on either side, the ground (y down).
const Eigen::Vector3f kAxes[4] = {{0, 0, -1}, {1, 0, 0}, {-1, 0, 0}, {0, -1, 0}};

class Solver {
 public:
  Solver(const View& ref, const std::vector<View>& nbs, const PatchMatchOptions& o)
      : ref_(ref), o_(o), w_(ref.gray.cols), h_(ref.gray.rows) {
    Kinv_ = ref.K.inverse();
    for (const View& v : nbs) {
      const Eigen::Matrix3d Rr = v.R * ref.R.transpose();
      const Eigen::Vector3d tr = v.t - Rr * ref.t;
      nb_.push_back(Neighbour{&v, v.gray.cols, v.gray.rows, v.K * Rr * Kinv_, v.K * tr});
    }
    best_ = std::max<int>(1, (static_cast<int>(nb_.size()) + 1) / 2);
    planes_.assign(static_cast<std::size_t>(w_) * h_, Plane{});
    cost_.assign(planes_.size(), 2.0f);
    cos_max_ = static_cast<float>(std::cos(o_.max_normal_angle_deg * M_PI / 180.0));
    // The reference patch's samples and their spread, once per pixel.
    const int r = o_.window_radius, s = o_.window_step;
    for (int dy = -r; dy <= r; dy += s)
      for (int dx = -r; dx <= r; dx += s) offsets_.emplace_back(dx, dy);
    // Texture in every direction (the smaller eigenvalue of the structure tensor over the
    // window): a sky's smooth gradient matches itself along the gradient's normal at any depth.
    cv::Mat gx, gy, gxx, gyy, gxy;
    cv::Sobel(ref.gray, gx, CV_32F, 1, 0, 3, 0.125);
    cv::Sobel(ref.gray, gy, CV_32F, 0, 1, 3, 0.125);
    const cv::Size box(2 * r + 1, 2 * r + 1);
    cv::boxFilter(gx.mul(gx), gxx, CV_32F, box);
    cv::boxFilter(gy.mul(gy), gyy, CV_32F, box);
    cv::boxFilter(gx.mul(gy), gxy, CV_32F, box);
    texture_.assign(planes_.size(), 0.0f);
    for (int y = 0; y < h_; ++y)
      for (int x = 0; x < w_; ++x) {
        const double a = gxx.at<float>(y, x), b = gxy.at<float>(y, x), c = gyy.at<float>(y, x);
        const double lmin = 0.5 * (a + c) - std::sqrt(0.25 * (a - c) * (a - c) + b * b);
        texture_[Index(x, y)] = static_cast<float>(std::sqrt(std::max(0.0, lmin)));
      }
    ref_std_.assign(planes_.size(), 0.0f);
    for (int y = 0; y < h_; ++y)
      for (int x = 0; x < w_; ++x) {
        double sum = 0, sum2 = 0;
        int n = 0;
        for (auto [dx, dy] : offsets_) {
          const int xx = std::clamp(x + dx, 0, w_ - 1), yy = std::clamp(y + dy, 0, h_ - 1);
          const double v = ref_.gray.at<float>(yy, xx);
          sum += v;
          sum2 += v * v;
          ++n;
        }
        const double m = sum / n;
        ref_std_[Index(x, y)] = static_cast<float>(std::sqrt(std::max(0.0, sum2 / n - m * m)));
      }
  }

  DepthMap Run(const std::function<bool()>& cancelled) {
    ForRows([&](int y) {
      for (int x = 0; x < w_; ++x) {
        Random rnd{Mix(o_.seed ^ (static_cast<uint64_t>(y) << 32 ^ static_cast<uint64_t>(x)))};
        Plane p = RandomPlane(x, y, &rnd);
        planes_[Index(x, y)] = p;
        cost_[Index(x, y)] = Cost(x, y, p, nullptr);
        for (const Eigen::Vector3f& n : kAxes) Try(x, y, Plane{p.depth, n});
      }
    });
    for (int it = 0; it < o_.iterations; ++it) {
      if (cancelled && cancelled()) throw std::runtime_error("cancelled");
      for (int colour = 0; colour < 2; ++colour)
        ForRows([&](int y) {
          for (int x = (y + colour) & 1; x < w_; x += 2) Update(x, y, it);
        });
    }
    DepthMap m;
    m.depth = cv::Mat::zeros(h_, w_, CV_32FC1);
    m.normal = cv::Mat::zeros(h_, w_, CV_32FC3);
    m.score = cv::Mat::zeros(h_, w_, CV_32FC1);
    m.views = cv::Mat::zeros(h_, w_, CV_32SC1);
    std::vector<float> zncc;
    for (int y = 0; y < h_; ++y)
      for (int x = 0; x < w_; ++x) {
        const std::size_t i = Index(x, y);
        if (texture_[i] < o_.min_texture) continue;
        Cost(x, y, planes_[i], &zncc);
        int mask = 0, agree = 0;
        double sum = 0;
        for (std::size_t k = 0; k < zncc.size(); ++k)
          if (zncc[k] >= o_.min_zncc) {
            mask |= 1 << k;
            ++agree;
            sum += zncc[k];
          }
        if (agree < o_.min_views) continue;
        m.depth.at<float>(y, x) = planes_[i].depth;
        const Eigen::Vector3f& n = planes_[i].n;
        m.normal.at<cv::Vec3f>(y, x) = cv::Vec3f(n.x(), n.y(), n.z());
        m.score.at<float>(y, x) = static_cast<float>(sum / agree);
        m.views.at<int>(y, x) = mask;
        ++m.kept;
      }
    return m;
  }

 private:
  std::size_t Index(int x, int y) const { return static_cast<std::size_t>(y) * w_ + x; }
  Eigen::Vector3d Ray(int x, int y) const { return Kinv_ * Eigen::Vector3d(x, y, 1.0); }

  // Rows split between the threads; a pass's rows are independent (red-black).
  template <typename F>
  void ForRows(F&& f) {
    const int t = std::min(o_.threads, h_);
    if (t <= 1) {
      for (int y = 0; y < h_; ++y) f(y);
      return;
    }
    std::vector<std::thread> pool;
    for (int k = 0; k < t; ++k)
      pool.emplace_back([&, k] {
        for (int y = k; y < h_; y += t) f(y);
      });
    for (std::thread& th : pool) th.join();
  }

  // A unit normal facing the camera along `ray` within the allowed angle.
  bool Facing(const Eigen::Vector3f& n, const Eigen::Vector3d& ray) const {
    const Eigen::Vector3f d = ray.normalized().cast<float>();
    return -n.dot(d) >= cos_max_;
  }

  Plane RandomPlane(int x, int y, Random* rnd) const {
    const Eigen::Vector3d ray = Ray(x, y);
    Plane p;
    const double inv = 1.0 / o_.max_depth + rnd->Uniform() * (1.0 / o_.min_depth - 1.0 / o_.max_depth);
    p.depth = static_cast<float>(1.0 / inv);
    const Eigen::Vector3f d = ray.normalized().cast<float>();
    for (int tries = 0; tries < 16; ++tries) {
      Eigen::Vector3f n(rnd->Signed(), rnd->Signed(), rnd->Signed());
      if (n.squaredNorm() > 1.0f || n.squaredNorm() < 1e-6f) continue;
      n = (n.normalized() - d).normalized();  // around the ray, facing the camera
      if (Facing(n, ray)) {
        p.n = n;
        return p;
      }
    }
    p.n = -d;
    return p;
  }

  // The plane `p` (of pixel x, y) through pixel (px, py)'s ray: its depth there, 0 when the ray
  // runs parallel to it or meets it behind the camera.
  float DepthAt(const Plane& p, int x, int y, int px, int py) const {
    const Eigen::Vector3d a = Ray(x, y), b = Ray(px, py);
    const double offset = p.depth * p.n.cast<double>().dot(a);  // n . X
    const double denom = p.n.cast<double>().dot(b);
    if (std::abs(denom) < 1e-9) return 0.0f;
    const double z = offset / denom;
    return z > 0.0 ? static_cast<float>(z) : 0.0f;
  }

  // 1 - ZNCC of the reference patch at (x, y) against each neighbour through the homography of
  // plane p; the mean of the best views' costs (2 when a view sees nothing). With `zncc`, each
  // neighbour's ZNCC (-1 when out of its image) instead of only the aggregate.
  float Cost(int x, int y, const Plane& p, std::vector<float>* zncc) const {
    const std::size_t i = Index(x, y);
    const Eigen::Vector3d ray = Ray(x, y);
    const Eigen::Vector3d n = p.n.cast<double>();
    const double offset = p.depth * n.dot(ray);  // plane: n . Y = offset
    float costs[16];
    const int nn = static_cast<int>(std::min<std::size_t>(nb_.size(), 16));
    if (zncc) zncc->assign(nn, -1.0f);
    if (std::abs(offset) < 1e-12 || ref_std_[i] < 1e-3f) {
      return 2.0f;
    }
    const Eigen::Vector3d m = Kinv_.transpose() * n / offset;
    for (int k = 0; k < nn; ++k) {
      const Neighbour& nb = nb_[k];
      const Eigen::Matrix3d H = nb.A + nb.b * m.transpose();
      double sr = 0, sn = 0, snn = 0, srn = 0;
      int count = 0;
      bool inside = true;
      // H (xx, yy, 1) = H (x, y, 1) + dx H.col(0) + dy H.col(1).
      const Eigen::Vector3d centre = H * Eigen::Vector3d(x, y, 1.0);
      const Eigen::Vector3d cx = H.col(0), cy = H.col(1);
      for (auto [dx, dy] : offsets_) {
        const int xx = x + dx, yy = y + dy;
        if (xx < 0 || yy < 0 || xx >= w_ || yy >= h_) continue;
        const Eigen::Vector3d q = centre + dx * cx + dy * cy;
        if (q.z() <= 1e-9) {
          inside = false;
          break;
        }
        const double iz = 1.0 / q.z();
        const double u = q.x() * iz, v = q.y() * iz;
        if (!(u >= 0.0 && v >= 0.0 && u <= nb.w - 1.001 && v <= nb.h - 1.001)) {
          inside = false;
          break;
        }
        const int u0 = static_cast<int>(u), v0 = static_cast<int>(v);
        const double fu = u - u0, fv = v - v0;
        const float* r0 = nb.view->gray.ptr<float>(v0);
        const float* r1 = nb.view->gray.ptr<float>(v0 + 1);
        const double val = (1 - fv) * ((1 - fu) * r0[u0] + fu * r0[u0 + 1]) +
                           fv * ((1 - fu) * r1[u0] + fu * r1[u0 + 1]);
        const double rv = ref_.gray.at<float>(yy, xx);
        sr += rv;
        sn += val;
        snn += val * val;
        srn += rv * val;
        ++count;
      }
      float c = 2.0f;
      if (inside && count >= 4) {
        const double mr = sr / count, mn = sn / count;
        const double var_n = snn / count - mn * mn;
        const double cov = srn / count - mr * mn;
        // The reference's spread from its own samples here (border pixels use fewer samples).
        const double var_r = static_cast<double>(ref_std_[i]) * ref_std_[i];
        if (var_n > 1e-6 && var_r > 1e-6) {
          const double z = std::clamp(cov / std::sqrt(var_r * var_n), -1.0, 1.0);
          c = static_cast<float>(1.0 - z);
          if (zncc) (*zncc)[k] = static_cast<float>(z);
        }
      }
      costs[k] = c;
    }
    std::sort(costs, costs + nn);
    float sum = 0;
    for (int k = 0; k < best_; ++k) sum += costs[k];
    return sum / best_;
  }

  // Tries plane p at pixel (x, y): kept when it costs less. A plane equal to the pixel's own or
  // to one `tried` already in this update (a converged neighbourhood hands the same plane back
  // from several sides) has a known cost and is not measured again: the same map, faster.
  void Try(int x, int y, const Plane& p, std::vector<Plane>* tried = nullptr) {
    if (!(p.depth > 0.0f)) return;
    const std::size_t i = Index(x, y);
    auto same = [&p](const Plane& q) { return p.depth == q.depth && p.n == q.n; };
    if (same(planes_[i])) return;
    if (tried != nullptr) {
      if (std::any_of(tried->begin(), tried->end(), same)) return;
      tried->push_back(p);
    }
    if (!Facing(p.n, Ray(x, y))) return;
    const float c = Cost(x, y, p, nullptr);
    if (c < cost_[i]) {
      cost_[i] = c;
      planes_[i] = p;
    }
  }

  void Update(int x, int y, int iteration) {
    // Propagation: the planes of pixels of the other colour, near and a little further.
    static const int kOffsets[8][2] = {{-1, 0}, {1, 0}, {0, -1}, {0, 1}, {-5, 0}, {5, 0}, {0, -5}, {0, 5}};
    thread_local std::vector<Plane> tried;
    tried.clear();
    for (const auto& d : kOffsets) {
      const int px = x + d[0], py = y + d[1];
      if (px < 0 || py < 0 || px >= w_ || py >= h_) continue;
      Plane q = planes_[Index(px, py)];
      q.depth = DepthAt(q, px, py, x, y);
      Try(x, y, q, &tried);
    }
    // Refinement: the plane's depth and normal changed at random, less each iteration.
    Random rnd{Mix(o_.seed * 7919 + (static_cast<uint64_t>(iteration) << 48) +
                   (static_cast<uint64_t>(y) << 24) + static_cast<uint64_t>(x))};
    const double scale = std::pow(0.5, iteration + 1);
    // The camera's axes as normals (a façade beside a street camera, the road below it, a
    // frontal wall): the slants a random search finds last.
    Try(x, y, Plane{planes_[Index(x, y)].depth, kAxes[(x + y + iteration) % 4]});
    for (int k = 0; k < 2; ++k) {
      Plane q = planes_[Index(x, y)];
      const double inv = 1.0 / q.depth;
      const double span = (1.0 / o_.min_depth - 1.0 / o_.max_depth) * scale * (k == 0 ? 1.0 : 0.1);
      const double ninv = std::clamp(inv + rnd.Signed() * span, 1.0 / o_.max_depth, 1.0 / o_.min_depth);
      q.depth = static_cast<float>(1.0 / ninv);
      const float a = static_cast<float>(scale * (k == 0 ? 1.0 : 0.3));
      q.n = (q.n + a * Eigen::Vector3f(rnd.Signed(), rnd.Signed(), rnd.Signed())).normalized();
      Try(x, y, q);
    }
  }

  const View& ref_;
  const PatchMatchOptions& o_;
  const int w_, h_;
  Eigen::Matrix3d Kinv_;
  std::vector<Neighbour> nb_;
  int best_ = 1;
  float cos_max_ = 0.0f;
  std::vector<std::pair<int, int>> offsets_;
  std::vector<float> ref_std_, texture_;
  std::vector<Plane> planes_;
  std::vector<float> cost_;
};

}  // namespace

DepthMap ComputeDepthMap(const View& reference, const std::vector<View>& neighbours,
                         const PatchMatchOptions& options, const std::function<bool()>& cancelled) {
  std::string error;
  if (!options.Check(&error)) throw std::invalid_argument("patch match options: " + error);
  if (neighbours.empty()) throw std::invalid_argument("patch match: no neighbouring view");
  if (reference.gray.type() != CV_32FC1 || reference.gray.empty())
    throw std::invalid_argument("patch match: the reference image is not 32-bit float gray");
  for (const View& v : neighbours)
    if (v.gray.type() != CV_32FC1 || v.gray.empty())
      throw std::invalid_argument("patch match: a neighbour's image is not 32-bit float gray");
  Solver solver(reference, neighbours, options);
  return solver.Run(cancelled);
}

}  // namespace imr::dense
