// Bilateral normal filtering (normal_filter.h).
#include "host/engine/normal_filter.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <unordered_map>
#include <utility>
#include <vector>

#include "host/engine/mesh_topology.h"

namespace imr::engine {

namespace {

using Vec3 = std::array<double, 3>;
constexpr double kPi = 3.14159265358979323846;
constexpr double kDegrees = 180.0 / kPi;

Vec3 Sub(const Vec3& a, const Vec3& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
double Dot(const Vec3& a, const Vec3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
Vec3 Cross(const Vec3& a, const Vec3& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}

class Filter {
 public:
  Filter(std::vector<double>* xyz, const std::vector<uint32_t>& faces, const NormalFilterOptions& o)
      : xyz_(*xyz), faces_(faces), o_(o) {}

  NormalFilterStats Run() {
    const std::size_t nf = faces_.size() / 3, nv = xyz_.size() / 3;
    if (nf == 0 || nv == 0) return stats_;
    BuildTopology(nv, nf);
    stats_.degrees_sum_before = AngleSum(&stats_.edges);
    const double edge = MedianEdgeLength();
    const std::vector<double> start = xyz_;
    if (edge > 0.0 && std::any_of(movable_.begin(), movable_.end(), [](uint8_t m) { return m != 0; })) {
      // Exponents: -d^2 / (2 sigma^2) as d^2 * factor.
      spatial_ = -0.5 / (o_.sigma_spatial * edge * o_.sigma_spatial * edge);
      range_ = -0.5 / (o_.sigma_range * o_.sigma_range);
      min_cos_ = std::cos(o_.max_turn_degrees / kDegrees);
      reference_.resize(nf);
      for (uint32_t f = 0; f < nf; ++f) reference_[f] = UnitNormal(f);
      for (int round = 0; round < o_.iterations; ++round) {
        FilterOnce();
        for (int step = 0; step < o_.vertex_steps; ++step) UpdateVertices();
        ++stats_.iterations;
      }
    }
    for (std::size_t v = 0; v < nv; ++v) {
      const Vec3 d = Sub(P(static_cast<uint32_t>(v)), {start[3 * v], start[3 * v + 1], start[3 * v + 2]});
      if (d[0] != 0.0 || d[1] != 0.0 || d[2] != 0.0) {
        ++stats_.vertices_moved;
        stats_.max_move = std::max(stats_.max_move, std::sqrt(Dot(d, d)));
      }
    }
    int64_t edges = 0;
    stats_.degrees_sum_after = AngleSum(&edges);
    return stats_;
  }

 private:
  Vec3 P(uint32_t v) const { return {xyz_[3 * size_t{v}], xyz_[3 * size_t{v} + 1], xyz_[3 * size_t{v} + 2]}; }
  const uint32_t* Face(uint32_t f) const { return &faces_[3 * size_t{f}]; }
  // The face's (b - a) x (c - a): twice its area times its unit normal.
  Vec3 AreaNormal(uint32_t f) const {
    const uint32_t* t = Face(f);
    const Vec3 a = P(t[0]);
    return Cross(Sub(P(t[1]), a), Sub(P(t[2]), a));
  }
  // Zero when degenerate.
  Vec3 UnitNormal(uint32_t f) const {
    Vec3 n = AreaNormal(f);
    const double len = std::sqrt(Dot(n, n));
    if (!(len > 0.0)) return {0.0, 0.0, 0.0};
    for (double& x : n) x /= len;
    return n;
  }
  Vec3 Centroid(uint32_t f) const {
    const uint32_t* t = Face(f);
    const Vec3 a = P(t[0]), b = P(t[1]), c = P(t[2]);
    return {(a[0] + b[0] + c[0]) / 3.0, (a[1] + b[1] + c[1]) / 3.0, (a[2] + b[2] + c[2]) / 3.0};
  }

  void BuildTopology(std::size_t nv, std::size_t nf) {
    VertexFans(faces_, nv, &fan_start_, &fan_);
    // A vertex may move when its fan is one closed cycle of consistently oriented faces (on a
    // whole mesh: not on the boundary; in a part: its whole fan is in the part).
    movable_ = ClosedFans(faces_, fan_start_, fan_);
    // Interior edges: the pairs of faces on either side (each edge once).
    std::unordered_map<uint64_t, int64_t> directed;  // (from, to) -> face, -1: repeated
    directed.reserve(faces_.size());
    for (uint32_t f = 0; f < nf; ++f)
      for (int k = 0; k < 3; ++k) {
        const uint64_t key = (uint64_t{Face(f)[k]} << 32) | Face(f)[(k + 1) % 3];
        const auto [it, fresh] = directed.emplace(key, f);
        if (!fresh) it->second = -1;
      }
    for (const auto& [key, f] : directed) {
      const uint32_t from = static_cast<uint32_t>(key >> 32), to = static_cast<uint32_t>(key);
      const auto reverse = directed.find((uint64_t{to} << 32) | from);
      if (from > to && reverse != directed.end()) continue;  // the edge is seen from (to, from)
      const Vec3 d = Sub(P(from), P(to));
      lengths_.push_back(std::sqrt(Dot(d, d)));
      if (f >= 0 && reverse != directed.end() && reverse->second >= 0)
        pairs_.emplace_back(static_cast<uint32_t>(f), static_cast<uint32_t>(reverse->second));
    }
    std::sort(pairs_.begin(), pairs_.end());
  }

  double MedianEdgeLength() {
    if (lengths_.empty()) return 0.0;
    std::nth_element(lengths_.begin(), lengths_.begin() + static_cast<std::ptrdiff_t>(lengths_.size() / 2),
                     lengths_.end());
    return lengths_[lengths_.size() / 2];
  }

  // The sum of the angles between neighbouring faces' normals over the interior edges (degrees).
  double AngleSum(int64_t* edges) const {
    double sum = 0.0;
    for (const auto& [f, g] : pairs_) {
      const Vec3 m = UnitNormal(f), n = UnitNormal(g);
      sum += (Dot(m, m) == 0.0 || Dot(n, n) == 0.0 ? 0.5 * kPi : std::acos(std::clamp(Dot(m, n), -1.0, 1.0))) *
             kDegrees;
      ++*edges;
    }
    return sum;
  }

  // Step 1: `normal_passes` bilateral passes over the faces' normals, from the current surface;
  // the neighbours of a face are the faces sharing a vertex with it (itself included).
  void FilterOnce() {
    const std::size_t nf = faces_.size() / 3;
    std::vector<Vec3> centroid(nf);
    std::vector<double> area(nf);
    normals_.resize(nf);
    for (uint32_t f = 0; f < nf; ++f) {
      const Vec3 n = AreaNormal(f);
      area[f] = 0.5 * std::sqrt(Dot(n, n));
      normals_[f] = UnitNormal(f);
      centroid[f] = Centroid(f);
    }
    std::vector<Vec3> next(nf);
    std::vector<uint32_t> seen(nf);
    for (int pass = 0; pass < o_.normal_passes; ++pass) {
      std::fill(seen.begin(), seen.end(), 0u);
      for (uint32_t f = 0; f < nf; ++f) {
        const Vec3& nf_ = normals_[f];
        Vec3 sum = {0.0, 0.0, 0.0};
        const uint32_t stamp = f + 1;
        for (int k = 0; k < 3; ++k) {
          const uint32_t v = Face(f)[k];
          for (uint32_t i = fan_start_[v]; i < fan_start_[v + 1]; ++i) {
            const uint32_t g = fan_[i];
            if (seen[g] == stamp) continue;
            seen[g] = stamp;
            const Vec3 dc = Sub(centroid[f], centroid[g]), dn = Sub(nf_, normals_[g]);
            const double w = area[g] * std::exp(Dot(dc, dc) * spatial_ + Dot(dn, dn) * range_);
            for (int j = 0; j < 3; ++j) sum[j] += w * normals_[g][j];
          }
        }
        const double len = std::sqrt(Dot(sum, sum));
        next[f] = len > 0.0 ? Vec3{sum[0] / len, sum[1] / len, sum[2] / len} : nf_;
      }
      normals_.swap(next);
    }
  }

  // Step 2: one update of every movable vertex toward the planes through its faces' centroids
  // with the filtered normals; then the guard: a face turned too far takes its vertices back.
  void UpdateVertices() {
    const std::size_t nv = xyz_.size() / 3, nf = faces_.size() / 3;
    std::vector<Vec3> centroid(nf);
    for (uint32_t f = 0; f < nf; ++f) centroid[f] = Centroid(f);
    const std::vector<double> before = xyz_;
    for (uint32_t v = 0; v < nv; ++v) {
      if (!movable_[v]) continue;
      const Vec3 x = {before[3 * size_t{v}], before[3 * size_t{v} + 1], before[3 * size_t{v} + 2]};
      Vec3 d = {0.0, 0.0, 0.0};
      for (uint32_t i = fan_start_[v]; i < fan_start_[v + 1]; ++i) {
        const uint32_t f = fan_[i];
        const Vec3& n = normals_[f];
        const double along = Dot(n, Sub(centroid[f], x));
        for (int k = 0; k < 3; ++k) d[k] += n[k] * along;
      }
      const double count = static_cast<double>(fan_start_[v + 1] - fan_start_[v]);
      for (int k = 0; k < 3; ++k) xyz_[3 * size_t{v} + k] = x[k] + d[k] / count;
    }
    // The guard, until no face turned: a vertex taken back stays back for this step, so it ends.
    std::vector<uint32_t> check;
    for (uint32_t f = 0; f < nf; ++f) check.push_back(f);
    std::vector<uint8_t> back(nv, 0);
    std::vector<uint32_t> next;
    while (!check.empty()) {
      next.clear();
      for (uint32_t f : check) {
        if (Turned(f)) {
          for (int k = 0; k < 3; ++k) {
            const uint32_t v = Face(f)[k];
            if (!movable_[v] || back[v]) continue;
            back[v] = 1;
            ++stats_.moves_reverted;
            for (int j = 0; j < 3; ++j) xyz_[3 * size_t{v} + j] = before[3 * size_t{v} + j];
            for (uint32_t i = fan_start_[v]; i < fan_start_[v + 1]; ++i) next.push_back(fan_[i]);
          }
        }
      }
      std::sort(next.begin(), next.end());
      next.erase(std::unique(next.begin(), next.end()), next.end());
      check.swap(next);
    }
  }

  // Whether face f turned more than max_turn_degrees from its normal before the pass, or became
  // degenerate (a face degenerate before is not held to it).
  bool Turned(uint32_t f) const {
    const Vec3& r = reference_[f];
    if (Dot(r, r) == 0.0) return false;
    const Vec3 n = UnitNormal(f);
    return Dot(n, n) == 0.0 || !(Dot(n, r) > min_cos_);
  }

  std::vector<double>& xyz_;
  const std::vector<uint32_t>& faces_;
  const NormalFilterOptions& o_;
  std::vector<uint32_t> fan_start_, fan_;  // faces at each vertex (CSR)
  std::vector<uint8_t> movable_;
  std::vector<std::pair<uint32_t, uint32_t>> pairs_;  // faces on either side of an interior edge
  std::vector<double> lengths_;                       // every edge's length
  std::vector<Vec3> reference_;  // each face's unit normal before the pass
  std::vector<Vec3> normals_;    // the filtered normals of this round
  double spatial_ = 0.0, range_ = 0.0, min_cos_ = 0.0;
  NormalFilterStats stats_;
};

}  // namespace

NormalFilterOptions NormalFilterOptions::FromEngine(const EngineOptions& options) {
  NormalFilterOptions o;
  o.iterations = options.filter_normals;
  o.sigma_spatial = options.filter_normals_spatial;
  o.sigma_range = options.filter_normals_range;
  return o;
}

std::string NormalFilterOptions::Check() const {
  if (iterations < 0) return "iterations: expected >= 0";
  if (!(sigma_spatial > 0.0 && std::isfinite(sigma_spatial))) return "sigma_spatial: expected > 0";
  if (!(sigma_range > 0.0 && std::isfinite(sigma_range))) return "sigma_range: expected > 0";
  if (normal_passes < 1) return "normal_passes: expected >= 1";
  if (vertex_steps < 1) return "vertex_steps: expected >= 1";
  if (!(max_turn_degrees > 0.0 && max_turn_degrees <= 180.0)) return "max_turn_degrees: expected 0 .. 180";
  return {};
}

NormalFilterStats& NormalFilterStats::operator+=(const NormalFilterStats& o) {
  iterations = std::max(iterations, o.iterations);
  vertices_moved += o.vertices_moved;
  moves_reverted += o.moves_reverted;
  max_move = std::max(max_move, o.max_move);
  edges += o.edges;
  degrees_sum_before += o.degrees_sum_before;
  degrees_sum_after += o.degrees_sum_after;
  return *this;
}

NormalFilterStats FilterNormals(Mesh* mesh, const NormalFilterOptions& options) {
  if (!options.enabled()) return {};
  return Filter(&mesh->vertices, mesh->faces, options).Run();
}

NormalFilterStats FilterNormals(SurfacePart* part, const NormalFilterOptions& options) {
  if (!options.enabled()) return {};
  return Filter(&part->vertices, part->faces, options).Run();
}

}  // namespace imr::engine
