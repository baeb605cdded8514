#include "host/synthetic/evaluation.h"

#include "host/util/parallel_for.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <unordered_map>
#include <utility>

namespace imr::synthetic {
namespace {

// Calls fn(i) for every i in [0, n) on the cores of the process's affinity mask.
template <typename Fn>
void ForEachIndex(size_t n, Fn&& fn) {
  util::ParallelFor(n, 0, [&](size_t begin, size_t end) {
    for (size_t i = begin; i < end; ++i) fn(i);
  }, 512);
}

// Truth -> mesh in EvaluateMesh: the grid's cells at least as large as the cap (so two rings at
// most), a triangle over 64 cells along an axis left out.
double TruthCell(double cap) { return std::max(cap, 1.0); }
constexpr int64_t kMaxSpan = 64;

// Truth -> mesh figures from each true point's distance to the mesh, summed in point order.
void AddTruthFigures(const std::vector<double>& distances, double tau, MeshAccuracy* r) {
  double tsum = 0.0;
  size_t near = 0;
  for (const double best : distances) {
    tsum += best;
    if (best <= tau) ++near;
  }
  r->mean_truth_to_mesh = tsum / static_cast<double>(distances.size());
  r->completeness = static_cast<double>(near) / static_cast<double>(distances.size());
}

}  // namespace

// Closest point on a triangle (Ericson, Real-Time Collision Detection, 5.1.5).
double PointTriangleDistance(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 ab = Sub(b, a), ac = Sub(c, a), ap = Sub(p, a);
  const double d1 = Dot(ab, ap), d2 = Dot(ac, ap);
  if (d1 <= 0 && d2 <= 0) return Norm(ap);
  const Vec3 bp = Sub(p, b);
  const double d3 = Dot(ab, bp), d4 = Dot(ac, bp);
  if (d3 >= 0 && d4 <= d3) return Norm(bp);
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return Norm(Sub(p, Add(a, Scale(ab, d1 / (d1 - d3)))));
  const Vec3 cp = Sub(p, c);
  const double d5 = Dot(ab, cp), d6 = Dot(ac, cp);
  if (d6 >= 0 && d5 <= d6) return Norm(cp);
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return Norm(Sub(p, Add(a, Scale(ac, d2 / (d2 - d6)))));
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    return Norm(Sub(p, Add(b, Scale(Sub(c, b), w))));
  }
  const double denom = 1.0 / (va + vb + vc);
  const double v = vb * denom, w = vc * denom;
  return Norm(Sub(p, Add(a, Add(Scale(ab, v), Scale(ac, w)))));
}

std::vector<Vec3> SampleRoadSurface(const Scene& scene, double density, uint64_t seed) {
  std::vector<Vec3> out;
  if (!(density > 0.0)) return out;
  // Footprints (x, y bounds) of the box tops: a box stands on the ground below its top.
  struct Footprint {
    double x0, y0, x1, y1;
  };
  std::vector<Footprint> boxes;
  for (const Rect& r : scene.rects()) {
    if (r.material != Material::kBoxTop) continue;
    const double ex = std::abs(r.u[0]) * r.half_u + std::abs(r.v[0]) * r.half_v;
    const double ey = std::abs(r.u[1]) * r.half_u + std::abs(r.v[1]) * r.half_v;
    boxes.push_back({r.center[0] - ex, r.center[1] - ey, r.center[0] + ex, r.center[1] + ey});
  }
  std::sort(boxes.begin(), boxes.end(),
            [](const Footprint& a, const Footprint& b) { return a.y0 < b.y0; });
  double longest = 0.0;  // boxes overlapping y start at most this far before it
  for (const Footprint& b : boxes) longest = std::max(longest, b.y1 - b.y0);
  const auto under_a_box = [&](const Vec3& p) {
    auto it = std::lower_bound(boxes.begin(), boxes.end(), p[1] - longest,
                               [](const Footprint& b, double y) { return b.y0 < y; });
    for (; it != boxes.end() && it->y0 <= p[1]; ++it)
      if (p[0] >= it->x0 && p[0] <= it->x1 && p[1] <= it->y1) return true;
    return false;
  };
  std::mt19937_64 g(seed);
  // Uniform in [0, 1) from the top 53 bits: fully specified, unlike the library distributions.
  const auto uniform = [&g] { return static_cast<double>(g() >> 11) * 0x1.0p-53; };
  const double step = 1.0 / std::sqrt(density);
  for (const Rect& r : scene.rects()) {
    if (r.material != Material::kGround) continue;
    const auto nu = static_cast<int64_t>(std::ceil(2.0 * r.half_u / step));
    const auto nv = static_cast<int64_t>(std::ceil(2.0 * r.half_v / step));
    for (int64_t j = 0; j < nv; ++j) {
      for (int64_t i = 0; i < nu; ++i) {
        const double s = -r.half_u + (static_cast<double>(i) + uniform()) * step;
        const double t = -r.half_v + (static_cast<double>(j) + uniform()) * step;
        if (s > r.half_u || t > r.half_v) continue;  // the last square sticks out
        const Vec3 p = Add(r.center, Add(Scale(r.u, s), Scale(r.v, t)));
        if (!under_a_box(p)) out.push_back(p);
      }
    }
  }
  return out;
}

namespace {

// For each point i of `which` (every point when null): nearest[i] = min(nearest[i], its distance
// to the nearest triangle), nearest[i] <= cap on entry. The hash grid and ring search of
// TruthToMeshDistances; starting from nearest[i] only stops the search sooner (a triangle left
// out is farther than what the point has), so the minimum is the same.
void NearerTriangles(const std::vector<double>& vertices, const std::vector<uint32_t>& faces,
                     const std::vector<Vec3>& truth, const std::vector<size_t>* which, double cap,
                     double cell, int64_t max_span, std::vector<double>* nearest) {
  const size_t triangles = faces.size() / 3;
  auto vert = [&](uint32_t i) -> Vec3 {
    return {vertices[3 * i], vertices[3 * i + 1], vertices[3 * i + 2]};
  };
  const double g = cell;
  auto key = [](int64_t x, int64_t y, int64_t z) {
    return (static_cast<uint64_t>(x & 0x1FFFFF) << 42) |
           (static_cast<uint64_t>(y & 0x1FFFFF) << 21) | static_cast<uint64_t>(z & 0x1FFFFF);
  };
  auto cell_of = [&](double v) { return static_cast<int64_t>(std::floor(v / g)); };
  std::unordered_map<uint64_t, std::vector<uint32_t>> grid;
  for (size_t t = 0; t < triangles; ++t) {
    int64_t lo[3] = {std::numeric_limits<int64_t>::max(), std::numeric_limits<int64_t>::max(),
                     std::numeric_limits<int64_t>::max()};
    int64_t hi[3] = {std::numeric_limits<int64_t>::min(), std::numeric_limits<int64_t>::min(),
                     std::numeric_limits<int64_t>::min()};
    for (int k = 0; k < 3; ++k) {
      const Vec3 v = vert(faces[3 * t + k]);
      for (int d = 0; d < 3; ++d) {
        lo[d] = std::min(lo[d], cell_of(v[d]));
        hi[d] = std::max(hi[d], cell_of(v[d]));
      }
    }
    if (hi[0] - lo[0] > max_span || hi[1] - lo[1] > max_span || hi[2] - lo[2] > max_span)
      continue;
    for (int64_t x = lo[0]; x <= hi[0]; ++x)
      for (int64_t y = lo[1]; y <= hi[1]; ++y)
        for (int64_t z = lo[2]; z <= hi[2]; ++z)
          grid[key(x, y, z)].push_back(static_cast<uint32_t>(t));
  }
  const int max_ring = static_cast<int>(std::ceil(cap / g)) + 1;
  const auto& cells = grid;  // read only from here on, by several threads
  auto nearer = [&](const Vec3& p, double best) {
    const int64_t cx = cell_of(p[0]), cy = cell_of(p[1]), cz = cell_of(p[2]);
    for (int ring = 0; ring <= max_ring; ++ring) {
      for (int64_t x = cx - ring; x <= cx + ring; ++x)
        for (int64_t y = cy - ring; y <= cy + ring; ++y)
          for (int64_t z = cz - ring; z <= cz + ring; ++z) {
            if (std::max({std::abs(x - cx), std::abs(y - cy), std::abs(z - cz)}) != ring) continue;
            auto it = cells.find(key(x, y, z));
            if (it == cells.end()) continue;
            for (uint32_t t : it->second)
              best = std::min(best, PointTriangleDistance(p, vert(faces[3 * t]),
                                                          vert(faces[3 * t + 1]),
                                                          vert(faces[3 * t + 2])));
          }
      // Every triangle within ring * g of p has been seen.
      if (best <= ring * g) break;
    }
    return best;
  };
  // Each point's distance on its own: the result does not depend on the threads.
  std::vector<double>& d = *nearest;
  if (which == nullptr)
    ForEachIndex(truth.size(), [&](size_t i) { d[i] = nearer(truth[i], d[i]); });
  else
    ForEachIndex(which->size(), [&](size_t k) { d[(*which)[k]] = nearer(truth[(*which)[k]], d[(*which)[k]]); });
}

}  // namespace

std::vector<double> TruthToMeshDistances(const std::vector<double>& vertices,
                                         const std::vector<uint32_t>& faces,
                                         const std::vector<Vec3>& truth, double cap, double cell,
                                         int64_t max_span) {
  std::vector<double> dist(truth.size(), cap);
  NearerTriangles(vertices, faces, truth, nullptr, cap, cell, max_span, &dist);
  return dist;
}

MeshAccuracy EvaluateMesh(const Scene& scene, const std::vector<double>& vertices,
                          const std::vector<uint32_t>& faces, const std::vector<Vec3>& truth,
                          double tau, double cap) {
  MeshToScene mesh_to_scene(scene, tau);
  mesh_to_scene.AddTriangles(vertices, faces);
  MeshAccuracy r = mesh_to_scene.Result();
  // Truth -> mesh: the grid's cells at least as large as the cap (so two rings at most).
  if (truth.empty()) return r;
  AddTruthFigures(TruthToMeshDistances(vertices, faces, truth, cap, TruthCell(cap), kMaxSpan), tau, &r);
  return r;
}

void MeshToScene::AddTriangles(const std::vector<double>& vertices, const std::vector<uint32_t>& faces) {
  const Scene& scene = scene_;
  const size_t triangles = faces.size() / 3;
  triangles_ += triangles;
  auto vert = [&](uint32_t i) -> Vec3 {
    return {vertices[3 * i], vertices[3 * i + 1], vertices[3 * i + 2]};
  };
  // Mesh -> scene: four samples per triangle (centroid and three inner points), area-weighted.
  // The samples' distances on several threads, then summed in triangle order (the same sums as
  // one thread makes).
  struct Samples {
    double area = 0.0;
    double d[4] = {0.0, 0.0, 0.0, 0.0};
  };
  std::vector<Samples> samples(triangles);
  scene.Distance({0.0, 0.0, 0.0});  // builds the scene's lazy index before the threads read it
  ForEachIndex(triangles, [&](size_t t) {
    const Vec3 a = vert(faces[3 * t]), b = vert(faces[3 * t + 1]), c = vert(faces[3 * t + 2]);
    const double area = 0.5 * Norm(Cross(Sub(b, a), Sub(c, a)));
    if (area <= 0.0) return;
    const Vec3 g = Scale(Add(a, Add(b, c)), 1.0 / 3.0);
    const Vec3 q[4] = {g, Scale(Add(Scale(a, 4), Add(b, c)), 1.0 / 6.0),
                       Scale(Add(Scale(b, 4), Add(a, c)), 1.0 / 6.0),
                       Scale(Add(Scale(c, 4), Add(a, b)), 1.0 / 6.0)};
    samples[t].area = area;
    for (int k = 0; k < 4; ++k) samples[t].d[k] = scene.Distance(q[k]);
  });
  for (const Samples& x : samples) {
    if (x.area <= 0.0) continue;
    for (const double d : x.d) {
      sum_ += 0.25 * x.area * d;
      if (d <= tau_) within_ += 0.25 * x.area;
    }
    area_ += x.area;
  }
}

MeshAccuracy MeshToScene::Result() const {
  MeshAccuracy r;
  r.tau = tau_;
  r.triangles = triangles_;
  r.area = area_;
  if (r.area > 0.0) {
    r.mean_mesh_to_scene = sum_ / r.area;
    r.precision = within_ / r.area;
  }
  return r;
}

MeshAccuracyInBlocks::MeshAccuracyInBlocks(const Scene& scene, std::vector<Vec3> truth, double tau,
                                           double cap)
    : mesh_to_scene_(scene, tau), truth_(std::move(truth)), nearest_(truth_.size(), cap), tau_(tau),
      cap_(cap) {}

void MeshAccuracyInBlocks::AddTriangles(const std::vector<double>& vertices,
                                        const std::vector<uint32_t>& faces) {
  mesh_to_scene_.AddTriangles(vertices, faces);
  if (truth_.empty() || faces.empty()) return;
  // Only the points within the cap of the block's box can come nearer (a margin over the cap for
  // the distance's rounding); a long drive's block covers a short stretch of it.
  double lo[3] = {std::numeric_limits<double>::max(), std::numeric_limits<double>::max(),
                  std::numeric_limits<double>::max()};
  double hi[3] = {std::numeric_limits<double>::lowest(), std::numeric_limits<double>::lowest(),
                  std::numeric_limits<double>::lowest()};
  for (const uint32_t v : faces)
    for (int d = 0; d < 3; ++d) {
      lo[d] = std::min(lo[d], vertices[3 * v + d]);
      hi[d] = std::max(hi[d], vertices[3 * v + d]);
    }
  const double reach = cap_ * (1.0 + 1e-9) + 1e-9;
  std::vector<size_t> near;
  for (size_t i = 0; i < truth_.size(); ++i) {
    const Vec3& p = truth_[i];
    if (p[0] >= lo[0] - reach && p[0] <= hi[0] + reach && p[1] >= lo[1] - reach &&
        p[1] <= hi[1] + reach && p[2] >= lo[2] - reach && p[2] <= hi[2] + reach)
      near.push_back(i);
  }
  if (!near.empty()) NearerTriangles(vertices, faces, truth_, &near, cap_, TruthCell(cap_), kMaxSpan, &nearest_);
}

MeshAccuracy MeshAccuracyInBlocks::Result() const {
  MeshAccuracy r = mesh_to_scene_.Result();
  if (truth_.empty()) return r;
  AddTruthFigures(nearest_, tau_, &r);  // EvaluateMesh's sums
  return r;
}

}  // namespace imr::synthetic
