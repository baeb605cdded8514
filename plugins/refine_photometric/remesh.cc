// Edge splits and dihedral-lowering edge flips on a 2-manifold with boundary (remesh.hpp).
#include "remesh.hpp"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <queue>
#include <tuple>
#include <unordered_map>

namespace imr::photometric {
namespace {

using Vec3 = Eigen::Vector3d;
using Face = std::array<uint32_t, 3>;

constexpr double kPi = 3.14159265358979323846;
constexpr double kDeg = kPi / 180.0;

uint64_t Key(uint32_t a, uint32_t b) { return static_cast<uint64_t>(a) << 32 | b; }

Vec3 UnitNormal(const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 n = (b - a).cross(c - a);
  const double len = n.norm();
  return len > 0.0 ? Vec3(n / len) : Vec3::Zero();
}

// Radians between two unit normals (a zero normal, a degenerate face: a right angle).
double Angle(const Vec3& m, const Vec3& n) { return std::acos(std::clamp(m.dot(n), -1.0, 1.0)); }

// 4 sqrt(3) area / sum of squared edges: 1 for an equilateral triangle, 0 for a degenerate one.
double Quality(const Vec3& a, const Vec3& b, const Vec3& c) {
  const double s = (b - a).squaredNorm() + (c - b).squaredNorm() + (a - c).squaredNorm();
  return s > 0.0 ? 2.0 * std::sqrt(3.0) * (b - a).cross(c - a).norm() / s : 0.0;
}

// The mesh as faces plus a map from each directed edge to its face: enough to walk across an
// edge, and cheap to keep current through a flip or a split.
class Remesher {
 public:
  Remesher(const RemeshOptions& o, const std::vector<Viewpoint>& viewpoints, std::vector<Vec3>* p,
           std::vector<Face>* faces, std::vector<std::array<uint32_t, 2>>* parents)
      : o_(o), viewpoints_(viewpoints), p_(*p), f_(*faces), parents_(parents), cos_turn_(std::cos(o.max_turn_deg * kDeg)),
        corner_(o.corner_deg * kDeg), fold_(o.fold_deg * kDeg), gain_(o.min_gain_deg * kDeg) {
    he_.reserve(3 * f_.size());
  }

  // Builds the edge map; a face that is degenerate or repeats a directed edge locks its corners.
  void Build(std::vector<uint8_t> locked) {
    locked_ = std::move(locked);
    locked_.resize(p_.size(), 0);
    around_.assign(p_.size(), Vec3::Zero());
    for (uint32_t f = 0; f < f_.size(); ++f) {
      const Face& F = f_[f];
      if (F[0] == F[1] || F[1] == F[2] || F[2] == F[0]) {
        for (uint32_t v : F) locked_[v] = 1;
        continue;
      }
      const Vec3 n = UnitNormal(p_[F[0]], p_[F[1]], p_[F[2]]);
      for (uint32_t v : F) around_[v] += n;
      for (int k = 0; k < 3; ++k)
        if (!he_.emplace(Key(F[k], F[(k + 1) % 3]), f).second) {
          for (uint32_t v : F) locked_[v] = 1;
          const Face& G = f_[he_[Key(F[k], F[(k + 1) % 3])]];
          for (uint32_t v : G) locked_[v] = 1;
        }
    }
  }

  void Split(RemeshStats* stats) {
    if (!(o_.max_edge > 0.0)) return;
    const int64_t cap = o_.max_new_vertices >= 0 ? o_.max_new_vertices : static_cast<int64_t>(f_.size());
    // Longest first, so a long edge is halved before its neighbours are cut around it; ties by
    // index, so the result does not depend on the hash map's order.
    using Item = std::tuple<double, uint32_t, uint32_t>;
    std::priority_queue<Item> queue;
    const double max2 = o_.max_edge * o_.max_edge;
    auto offer = [&](uint32_t a, uint32_t b) {
      if (a > b) std::swap(a, b);
      const double len2 = (p_[a] - p_[b]).squaredNorm();
      if (len2 > max2) queue.emplace(len2, a, b);
    };
    for (const Face& F : f_)
      for (int k = 0; k < 3; ++k)
        if (F[k] < F[(k + 1) % 3]) offer(F[k], F[(k + 1) % 3]);
    while (!queue.empty() && stats->edges_split < cap) {
      const auto [len2, a, b] = queue.top();
      queue.pop();
      const auto ab = he_.find(Key(a, b)), ba = he_.find(Key(b, a));
      if (ab == he_.end() || ba == he_.end()) continue;  // gone, or a boundary edge: kept
      if ((p_[a] - p_[b]).squaredNorm() != len2) continue;
      const uint32_t f1 = ab->second, f2 = ba->second;
      const uint32_t c = Third(f1, a, b), d = Third(f2, b, a);
      if (locked_[a] || locked_[b] || locked_[c] || locked_[d]) continue;
      const uint32_t m = static_cast<uint32_t>(p_.size());
      const Vec3 M = 0.5 * (p_[a] + p_[b]), around_m = around_[a] + around_[b];
      if (!Faithful(p_[a], M, p_[c], around_[a] + around_m + around_[c]) ||
          !Faithful(M, p_[b], p_[c], around_m + around_[b] + around_[c]) ||
          !Faithful(p_[b], M, p_[d], around_[b] + around_m + around_[d]) ||
          !Faithful(M, p_[a], p_[d], around_m + around_[a] + around_[d]))
        continue;
      p_.push_back(M);
      around_.push_back(around_m);
      locked_.push_back(0);
      if (parents_) parents_->push_back({a, b});
      // (a,b,c) -> (a,m,c) + (m,b,c); (b,a,d) -> (b,m,d) + (m,a,d).
      const uint32_t f3 = static_cast<uint32_t>(f_.size()), f4 = f3 + 1;
      f_[f1] = {a, m, c};
      f_[f2] = {b, m, d};
      f_.push_back({m, b, c});
      f_.push_back({m, a, d});
      he_.erase(Key(a, b));
      he_.erase(Key(b, a));
      he_[Key(a, m)] = f1, he_[Key(m, c)] = f1;
      he_[Key(m, b)] = f3, he_[Key(b, c)] = f3, he_[Key(c, m)] = f3;
      he_[Key(b, m)] = f2, he_[Key(m, d)] = f2;
      he_[Key(m, a)] = f4, he_[Key(a, d)] = f4, he_[Key(d, m)] = f4;
      ++stats->edges_split;
      offer(a, m), offer(m, b), offer(c, m), offer(d, m);
    }
  }

  void Flip(RemeshStats* stats) {
    std::vector<uint8_t> dirty(p_.size(), 1), next(p_.size(), 0);
    for (int pass = 0; pass < o_.flip_passes; ++pass) {
      int64_t flipped = 0;
      std::fill(next.begin(), next.end(), 0);
      for (uint32_t f = 0; f < f_.size(); ++f)
        for (int k = 0; k < 3; ++k) {
          const uint32_t a = f_[f][k], b = f_[f][(k + 1) % 3];
          if (a > b || !(dirty[a] || dirty[b])) continue;  // each edge once, near last pass's flips
          if (TryFlip(f, a, b, stats)) {
            ++flipped;
            for (uint32_t v : last_quad_) next[v] = 1;
            break;  // face f changed: its edges are not the ones this loop read
          }
        }
      if (flipped == 0) break;
      dirty.swap(next);
    }
  }

 private:
  uint32_t Third(uint32_t f, uint32_t a, uint32_t b) const {
    const Face& F = f_[f];
    for (uint32_t v : F)
      if (v != a && v != b) return v;
    return F[0];  // unreachable on a face with edge (a, b)
  }

  // Whether face (x, y, z) stays within max_turn_deg of the input surface around its corners
  // (`around`: the sum of the input faces' unit normals at them): flips one after another may
  // each turn a face a little, never far from what the input said.
  bool Faithful(const Vec3& x, const Vec3& y, const Vec3& z, const Vec3& around) const {
    const double len = around.norm();
    return len > 0.0 && UnitNormal(x, y, z).dot(around) >= cos_turn_ * len;
  }

  // Whether a viewpoint in range would see more of the new faces (a,d,c), (d,b,c) from behind
  // than of the old ones (a,b,c), (b,a,d).
  bool TurnsAway(const Vec3& A, const Vec3& B, const Vec3& C, const Vec3& D, const Vec3& n1,
                 const Vec3& n2, const Vec3& m1, const Vec3& m2) const {
    const Vec3 c1 = (A + B + C) / 3.0, c2 = (B + A + D) / 3.0, k1 = (A + D + C) / 3.0, k2 = (D + B + C) / 3.0;
    for (const Viewpoint& v : viewpoints_) {
      if ((v.centre - c1).squaredNorm() > v.range * v.range) continue;
      const int old_back = ((v.centre - c1).dot(n1) <= 0.0) + ((v.centre - c2).dot(n2) <= 0.0);
      const int new_back = ((v.centre - k1).dot(m1) <= 0.0) + ((v.centre - k2).dot(m2) <= 0.0);
      if (new_back > old_back) return true;
    }
    return false;
  }

  // The normal of the face across directed edge (u, v) of a face, or none (a boundary edge).
  bool Across(uint32_t u, uint32_t v, Vec3* n) const {
    const auto it = he_.find(Key(v, u));
    if (it == he_.end()) return false;
    const Face& G = f_[it->second];
    *n = UnitNormal(p_[G[0]], p_[G[1]], p_[G[2]]);
    return true;
  }

  // Flips edge (a, b) of face f1 when every rule allows it and it lowers the total dihedral.
  bool TryFlip(uint32_t f1, uint32_t a, uint32_t b, RemeshStats* stats) {
    const auto ba = he_.find(Key(b, a));
    if (ba == he_.end()) return false;  // a boundary edge stays
    const uint32_t f2 = ba->second;
    const uint32_t c = Third(f1, a, b), d = Third(f2, b, a);
    if (locked_[a] || locked_[b] || locked_[c] || locked_[d]) return false;
    if (c == d || he_.count(Key(c, d)) || he_.count(Key(d, c))) return false;  // an edge twice
    const Vec3 &A = p_[a], &B = p_[b], &C = p_[c], &D = p_[d];
    const Vec3 n1 = UnitNormal(A, B, C), n2 = UnitNormal(B, A, D);
    const double before = Angle(n1, n2);
    // A fold: the two faces turn back on each other (the carving's sheet crumpled between
    // noisy points). Flipping it is right when the new faces lie flat on one of the old ones.
    const bool fold = before > fold_;
    if (before > corner_ && !fold) {
      ++stats->creases_kept;
      return false;
    }
    // After: (a, d, c) and (d, b, c).
    const Vec3 m1 = UnitNormal(A, D, C), m2 = UnitNormal(D, B, C);
    const double after = Angle(m1, m2);
    if (fold && after > corner_) return false;
    // The four edges around the quad: which old and which new face holds each.
    struct Outer {
      uint32_t u, v;
      const Vec3 *old_n, *new_n;
    };
    const Outer outer[4] = {{b, c, &n1, &m2}, {c, a, &n1, &m1}, {a, d, &n2, &m1}, {d, b, &n2, &m2}};
    double cost_before = before, cost_after = after;
    for (const Outer& e : outer) {
      Vec3 n;
      if (!Across(e.u, e.v, &n)) continue;
      const double old_angle = Angle(*e.old_n, n), new_angle = Angle(*e.new_n, n);
      // A crease beside it would be smoothed (a fold beside it is not a crease).
      if (old_angle > corner_ && old_angle <= fold_ && new_angle <= corner_) {
        ++stats->creases_kept;
        return false;
      }
      cost_before += old_angle;
      cost_after += new_angle;
    }
    if (!(cost_after < cost_before - gain_)) return false;
    // Each new face within max_turn of both old ones; out of a fold, of one of them (the other
    // is the sheet turned back).
    auto near = [this](const Vec3& m, const Vec3& n) { return m.dot(n) >= cos_turn_; };
    const bool turned = fold ? !((near(m1, n1) && near(m2, n1)) || (near(m1, n2) && near(m2, n2)))
                             : !(near(m1, n1) && near(m1, n2) && near(m2, n1) && near(m2, n2));
    const bool folds = turned ||
                       !Faithful(A, D, C, around_[a] + around_[d] + around_[c]) ||
                       !Faithful(D, B, C, around_[d] + around_[b] + around_[c]);
    const double q_new = std::min(Quality(A, D, C), Quality(D, B, C));
    const double q_old = std::min(Quality(A, B, C), Quality(B, A, D));
    if (folds || (q_new < o_.min_quality && q_new < q_old) || q_new <= 0.0) {
      ++stats->flips_refused;
      return false;
    }
    if (TurnsAway(A, B, C, D, n1, n2, m1, m2)) {
      ++stats->flips_facing_away;
      return false;
    }
    // (a,b,c) -> (a,d,c); (b,a,d) -> (d,b,c).
    f_[f1] = {a, d, c};
    f_[f2] = {d, b, c};
    he_.erase(Key(a, b));
    he_.erase(Key(b, a));
    he_[Key(a, d)] = f1, he_[Key(d, c)] = f1, he_[Key(c, a)] = f1;
    he_[Key(d, b)] = f2, he_[Key(b, c)] = f2, he_[Key(c, d)] = f2;
    last_quad_ = {a, b, c, d};
    ++stats->edges_flipped;
    stats->folds_flipped += fold ? 1 : 0;
    return true;
  }

  const RemeshOptions& o_;
  const std::vector<Viewpoint>& viewpoints_;
  std::vector<Vec3>& p_;
  std::vector<Face>& f_;
  std::vector<std::array<uint32_t, 2>>* parents_;
  const double cos_turn_, corner_, fold_, gain_;  // radians (cosine for the turn)
  std::vector<uint8_t> locked_;
  std::vector<Vec3> around_;  // per vertex, the input faces' unit normals summed (a midpoint: its ends')
  std::unordered_map<uint64_t, uint32_t> he_;  // directed edge (a << 32 | b) -> its face
  std::array<uint32_t, 4> last_quad_{};  // the last flip's corners: its edges are queued again
};

}  // namespace

bool RemeshOptions::Check(std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error) *error = m;
    return false;
  };
  if (!(max_edge >= 0.0) || !std::isfinite(max_edge)) return fail("max_edge must be finite and >= 0");
  if (max_new_vertices < -1) return fail("max_new_vertices must be >= -1 (-1: as many as the faces)");
  if (flip_passes < 0) return fail("flip_passes must be >= 0");
  if (!(corner_deg > 0.0 && corner_deg <= 180.0)) return fail("corner_deg must be in (0, 180]");
  if (!(fold_deg >= corner_deg && fold_deg <= 180.0)) return fail("fold_deg must be in [corner_deg, 180]");
  if (!(max_turn_deg > 0.0 && max_turn_deg < 90.0))
    return fail("max_turn_deg must be in (0, 90): a new face may not turn past a right angle");
  if (!(min_quality >= 0.0 && min_quality < 1.0)) return fail("min_quality must be in [0, 1)");
  if (!(min_gain_deg >= 0.0) || !std::isfinite(min_gain_deg)) return fail("min_gain_deg must be finite and >= 0");
  return true;
}

RemeshStats Remesh(const RemeshOptions& options, const std::vector<Viewpoint>& viewpoints,
                   std::vector<Eigen::Vector3d>* vertices,
                   std::vector<std::array<uint32_t, 3>>* faces, std::vector<uint8_t>* locked,
                   std::vector<std::array<uint32_t, 2>>* parents) {
  RemeshStats stats;
  const std::size_t n = vertices->size();
  for (const Face& F : *faces)
    for (uint32_t v : F)
      if (v >= n) return stats;  // not a mesh of these vertices: left as it is
  stats.total_dihedral_before = TotalDihedralDeg(*vertices, *faces, &stats.interior_edges_before);
  Remesher r(options, viewpoints, vertices, faces, parents);
  std::vector<uint8_t> lock = locked && !locked->empty() ? *locked : std::vector<uint8_t>(n, 0);
  r.Build(std::move(lock));
  r.Split(&stats);
  r.Flip(&stats);
  if (locked && !locked->empty()) locked->resize(vertices->size(), 0);
  stats.total_dihedral_after = TotalDihedralDeg(*vertices, *faces, &stats.interior_edges_after);
  return stats;
}

double TotalDihedralDeg(const std::vector<Eigen::Vector3d>& p, const std::vector<std::array<uint32_t, 3>>& faces,
                        int64_t* interior_edges) {
  std::unordered_map<uint64_t, uint32_t> he;
  he.reserve(3 * faces.size());
  for (uint32_t f = 0; f < faces.size(); ++f)
    for (int k = 0; k < 3; ++k) he.emplace(Key(faces[f][k], faces[f][(k + 1) % 3]), f);
  double sum = 0.0;
  int64_t count = 0;
  for (const Face& F : faces)  // in face order: the same sum on every run
    for (int k = 0; k < 3; ++k) {
      const uint32_t a = F[k], b = F[(k + 1) % 3];
      const auto it = he.find(Key(b, a));
      if (a > b || it == he.end()) continue;
      const Face& G = faces[it->second];
      sum += Angle(UnitNormal(p[F[0]], p[F[1]], p[F[2]]), UnitNormal(p[G[0]], p[G[1]], p[G[2]])) / kDeg;
      ++count;
    }
  if (interior_edges) *interior_edges = count;
  return sum;
}

}  // namespace imr::photometric
