#include "host/eval/ground_truth.h"

#include "host/util/input_file.h"

#include "host/eval/parallel.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <fstream>
#include <random>
#include <stdexcept>
#include <string>
#include <unordered_map>

namespace imr::eval {
namespace {

namespace fs = std::filesystem;

// Uniform in [0, 1) from the top 53 bits: fully specified, unlike std::uniform_real_distribution.
double Uniform(std::mt19937_64& g) { return static_cast<double>(g() >> 11) * 0x1.0p-53; }

double TriangleArea(const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 u = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, v = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
  const Vec3 n = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]};
  return 0.5 * std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
}

struct CellKey {
  int64_t x, y, z;
  bool operator==(const CellKey&) const = default;
};
struct CellHash {
  std::size_t operator()(const CellKey& k) const {
    return static_cast<std::size_t>(k.x * 73856093) ^ static_cast<std::size_t>(k.y * 19349663) ^
           static_cast<std::size_t>(k.z * 83492791);
  }
};

}  // namespace

std::vector<Vec3> SampleSurface(const TriangleMesh& mesh, std::size_t count, uint64_t seed) {
  std::vector<double> cumulative(mesh.triangles.size());
  double total = 0.0;
  for (std::size_t i = 0; i < mesh.triangles.size(); ++i) {
    const auto& t = mesh.triangles[i];
    total += TriangleArea(mesh.vertices[t[0]], mesh.vertices[t[1]], mesh.vertices[t[2]]);
    cumulative[i] = total;
  }
  std::vector<Vec3> out;
  if (!(total > 0.0) || count == 0) return out;
  out.reserve(count);
  std::mt19937_64 g(seed);
  for (std::size_t s = 0; s < count; ++s) {
    const double pick = Uniform(g) * total;
    std::size_t i = std::upper_bound(cumulative.begin(), cumulative.end(), pick) - cumulative.begin();
    i = std::min(i, cumulative.size() - 1);
    const auto& t = mesh.triangles[i];
    const Vec3 &a = mesh.vertices[t[0]], &b = mesh.vertices[t[1]], &c = mesh.vertices[t[2]];
    // Uniform in the triangle: sqrt of the first variate (Osada et al. 2002).
    const double r1 = std::sqrt(Uniform(g)), r2 = Uniform(g);
    const double wa = 1.0 - r1, wb = r1 * (1.0 - r2), wc = r1 * r2;
    out.push_back({wa * a[0] + wb * b[0] + wc * c[0], wa * a[1] + wb * b[1] + wc * c[1],
                   wa * a[2] + wb * b[2] + wc * c[2]});
  }
  return out;
}

std::vector<Vec3> ReadVelodyneScan(const fs::path& path) {
  const std::string bytes =
      ReadInputFile(path, "a Velodyne scan (float32 x, y, z, reflectance)");  // the open rule
  if (bytes.size() % 16 != 0)
    throw std::runtime_error(path.string() + ": " + std::to_string(bytes.size()) +
                             " bytes, not a multiple of 16 (float32 x, y, z, reflectance)");
  std::vector<Vec3> out(bytes.size() / 16);
  for (std::size_t i = 0; i < out.size(); ++i) {
    float v[4];
    std::memcpy(v, bytes.data() + 16 * i, 16);  // little-endian, as this host
    out[i] = {v[0], v[1], v[2]};
  }
  return out;
}

Vec3 VelodyneToWorld(const io::Mat34& tr, const io::Mat3& r, const Vec3& t, const Vec3& x) {
  Vec3 c;  // Tr X_velo - t
  for (int i = 0; i < 3; ++i)
    c[i] = tr[i][0] * x[0] + tr[i][1] * x[1] + tr[i][2] * x[2] + tr[i][3] - t[i];
  return {r[0][0] * c[0] + r[1][0] * c[1] + r[2][0] * c[2],
          r[0][1] * c[0] + r[1][1] * c[1] + r[2][1] * c[2],
          r[0][2] * c[0] + r[1][2] * c[1] + r[2][2] * c[2]};
}

VelodyneTruth LoadVelodyneTruth(const io::ImageSequence& sequence, int scan_step) {
  if (!sequence.has_lidar)
    throw std::runtime_error(sequence.root + ": the sequence has no Velodyne scans");
  if (scan_step < 1) throw std::invalid_argument("scan step must be at least 1");
  if (sequence.lidar.scan_paths.size() != sequence.frames.size())
    throw std::runtime_error(sequence.root + ": " + std::to_string(sequence.lidar.scan_paths.size()) +
                             " scan paths for " + std::to_string(sequence.frames.size()) + " frames");
  VelodyneTruth out;
  for (std::size_t i = 0; i < sequence.frames.size(); i += static_cast<std::size_t>(scan_step)) {
    const std::string& scan = sequence.lidar.scan_paths[i];
    if (scan.empty()) {
      ++out.frames_without_scan;
      continue;
    }
    const io::CameraGeometry& cam = sequence.frames[i].camera;
    auto to_world = [&](const Vec3& x) {
      return VelodyneToWorld(sequence.lidar.velo_to_camera, cam.rotation, cam.translation, x);
    };
    const std::vector<Vec3> points = ReadVelodyneScan(scan);
    for (const Vec3& x : points) out.points.push_back(to_world(x));
    const Vec3 origin = to_world({0.0, 0.0, 0.0});
    const std::array<Vec3, 3> axes = {Sub(to_world({1.0, 0.0, 0.0}), origin),
                                      Sub(to_world({0.0, 1.0, 0.0}), origin),
                                      Sub(to_world({0.0, 0.0, 1.0}), origin)};
    out.views.push_back(ScannerViewOf(points, origin, axes));
    ++out.scans;
  }
  return out;
}

namespace {
// The range bin of a return or sample at `range` (>= ScannerView::kFirstBin).
std::size_t RangeBin(double range) {
  return static_cast<std::size_t>(std::log(range / ScannerView::kFirstBin) /
                                  std::log(ScannerView::kBinRatio));
}
}  // namespace

ScannerView ScannerViewOf(const std::vector<Vec3>& points, const Vec3& origin,
                          const std::array<Vec3, 3>& axes) {
  ScannerView v;
  v.origin = origin;
  v.axes = axes;
  const std::array<double, 2> empty = {10.0, -10.0};  // no elevation inside: a bin without returns
  for (const Vec3& x : points) {
    const double horizontal = std::hypot(x[0], x[1]), range = std::hypot(horizontal, x[2]);
    if (!std::isfinite(range) || range < ScannerView::kFirstBin) continue;
    v.max_range = std::max(v.max_range, range);
    const std::size_t bin = RangeBin(range);
    if (bin >= v.bands.size()) v.bands.resize(bin + 1, empty);
    const double elevation = std::atan2(x[2], horizontal);
    v.bands[bin] = {std::min(v.bands[bin][0], elevation), std::max(v.bands[bin][1], elevation)};
  }
  if (v.bands.empty()) return v;
  for (std::size_t k = v.bands.size() - 1; k-- > 0;)  // the last bin holds the farthest return
    if (v.bands[k][0] > v.bands[k][1]) v.bands[k] = v.bands[k + 1];
  return v;
}

bool InScannerView(const std::vector<ScannerView>& views, const Vec3& x) {
  for (const ScannerView& v : views) {
    const Vec3 d = Sub(x, v.origin);
    const Vec3 local = {Dot(d, v.axes[0]), Dot(d, v.axes[1]), Dot(d, v.axes[2])};
    const double horizontal = std::hypot(local[0], local[1]), range = std::hypot(horizontal, local[2]);
    if (!(range >= ScannerView::kFirstBin) || range > v.max_range) continue;
    const std::array<double, 2>& band = v.bands[std::min(RangeBin(range), v.bands.size() - 1)];
    const double elevation = std::atan2(local[2], horizontal);
    if (elevation >= band[0] && elevation <= band[1]) return true;
  }
  return false;
}

bool InFrustum(const io::CameraGeometry& g, const Vec3& x) {
  double u = 0.0, v = 0.0;
  if (!io::Project(g, x, &u, &v)) return false;
  return u >= -0.5 && u < g.intrinsics.width - 0.5 && v >= -0.5 && v < g.intrinsics.height - 0.5;
}

std::vector<uint8_t> CropToCameras(const std::vector<Vec3>& points,
                                   const std::vector<io::CameraGeometry>& cameras,
                                   double max_ray_length, int threads, CropCounts* counts) {
  for (const auto& c : cameras)
    if (!c.has_intrinsics || !c.intrinsics.projectable || c.intrinsics.width <= 0 ||
        c.intrinsics.height <= 0)
      throw std::invalid_argument("camera " + std::to_string(c.id) +
                                  (c.name.empty() ? "" : " (" + c.name + ")") +
                                  " has no projectable intrinsics with an image size: cannot crop");
  const bool limited = max_ray_length > 0.0;
  const double cell = limited ? max_ray_length : 1.0;
  const double range2 = max_ray_length * max_ray_length;
  auto key = [&](const Vec3& p) {
    return CellKey{static_cast<int64_t>(std::floor(p[0] / cell)), static_cast<int64_t>(std::floor(p[1] / cell)),
                   static_cast<int64_t>(std::floor(p[2] / cell))};
  };
  std::unordered_map<CellKey, std::vector<uint32_t>, CellHash> grid;
  if (limited)
    for (std::size_t i = 0; i < cameras.size(); ++i) grid[key(cameras[i].center)].push_back(static_cast<uint32_t>(i));

  std::vector<uint8_t> keep(points.size(), 0);
  std::atomic<std::size_t> beyond{0}, outside{0};
  ParallelFor(points.size(), threads, [&](std::size_t begin, std::size_t end) {
    std::size_t local_beyond = 0, local_outside = 0;
    for (std::size_t i = begin; i < end; ++i) {
      const Vec3& p = points[i];
      bool in_range = false, seen = false;
      auto test = [&](const io::CameraGeometry& c) {
        if (limited) {
          const double dx = p[0] - c.center[0], dy = p[1] - c.center[1], dz = p[2] - c.center[2];
          if (dx * dx + dy * dy + dz * dz > range2) return false;
        }
        in_range = true;
        return InFrustum(c, p);
      };
      if (limited) {
        const CellKey k = key(p);
        for (int64_t dx = -1; dx <= 1 && !seen; ++dx)
          for (int64_t dy = -1; dy <= 1 && !seen; ++dy)
            for (int64_t dz = -1; dz <= 1 && !seen; ++dz) {
              const auto it = grid.find({k.x + dx, k.y + dy, k.z + dz});
              if (it == grid.end()) continue;
              for (uint32_t c : it->second)
                if (test(cameras[c])) {
                  seen = true;
                  break;
                }
            }
      } else {
        for (const auto& c : cameras)
          if (test(c)) {
            seen = true;
            break;
          }
      }
      keep[i] = seen ? 1 : 0;
      if (!seen) ++(in_range ? local_outside : local_beyond);
    }
    beyond += local_beyond;
    outside += local_outside;
  });
  if (counts) {
    counts->input = points.size();
    counts->beyond_range = beyond;
    counts->outside_frustum = outside;
    counts->kept = points.size() - counts->beyond_range - counts->outside_frustum;
  }
  return keep;
}

}  // namespace imr::eval
