// Edge flips that smooth the surface (edge_flips.h).
#include "host/engine/edge_flips.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <deque>
#include <unordered_map>
#include <unordered_set>
#include <utility>
#include <vector>

#include "host/engine/mesh_topology.h"

namespace imr::engine {

namespace {

using Vec3 = std::array<double, 3>;
constexpr double kDegrees = 180.0 / 3.14159265358979323846;

uint64_t UndirectedKey(uint32_t a, uint32_t b) {
  if (a > b) std::swap(a, b);
  return (uint64_t{a} << 32) | b;
}

class Flipper {
 public:
  // `seams`: no new edge between two vertices whose fans are open (a SurfacePart).
  Flipper(const std::vector<double>& xyz, std::vector<uint32_t>* faces, const EdgeFlipOptions& o,
          bool seams)
      : xyz_(xyz), faces_(*faces), o_(o), seams_(seams) {}

  EdgeFlipStats Run() {
    const std::size_t nf = faces_.size() / 3;
    if (nf == 0) return stats_;
    BuildTopology();
    stats_.degrees_sum_before = AngleSum(&stats_.edges);
    const double min_gain = o_.min_gain_degrees / kDegrees;
    const double min_angle = o_.min_angle_degrees / kDegrees;
    const int64_t max_flips = static_cast<int64_t>(nf) * o_.max_flips_per_face;

    std::deque<uint32_t> work;
    queued_.assign(faces_.size(), 0);
    for (uint32_t h = 0; h < faces_.size(); ++h)
      if (opp_[h] >= 0 && h < opp_[h]) work.push_back(h), queued_[h] = 1;
    while (!work.empty() && stats_.flips < max_flips) {
      const uint32_t h = work.front();
      work.pop_front();
      queued_[h] = 0;
      if (opp_[h] < 0 || !TryFlip(h, min_gain, min_angle)) continue;
      ++stats_.flips;
      const uint32_t f = h / 3, g = static_cast<uint32_t>(opp_[3 * f + 2]) / 3;
      for (const uint32_t e : {3 * f, 3 * f + 1, 3 * g, 3 * g + 1})
        if (opp_[e] >= 0 && !queued_[e]) work.push_back(e), queued_[e] = 1;
    }
    int64_t edges = 0;
    stats_.degrees_sum_after = AngleSum(&edges);
    return stats_;
  }

 private:
  Vec3 P(uint32_t v) const { return {xyz_[3 * size_t{v}], xyz_[3 * size_t{v} + 1], xyz_[3 * size_t{v} + 2]}; }
  static Vec3 Sub(const Vec3& a, const Vec3& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
  static double Dot(const Vec3& a, const Vec3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
  static Vec3 Cross(const Vec3& a, const Vec3& b) {
    return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
  }
  // The unit normal of the triangle (a, b, c), counter-clockwise; zero when degenerate.
  Vec3 Normal(uint32_t a, uint32_t b, uint32_t c) const {
    const Vec3 pa = P(a);
    Vec3 n = Cross(Sub(P(b), pa), Sub(P(c), pa));
    const double len = std::sqrt(Dot(n, n));
    if (!(len > 0.0)) return {0.0, 0.0, 0.0};
    for (double& x : n) x /= len;
    return n;
  }
  Vec3 FaceNormal(uint32_t f) const { return Normal(faces_[3 * f], faces_[3 * f + 1], faces_[3 * f + 2]); }
  // The angle between two unit normals; a right angle against a degenerate face.
  static double Angle(const Vec3& m, const Vec3& n) {
    if (Dot(m, m) == 0.0 || Dot(n, n) == 0.0) return 0.5 * 3.14159265358979323846;
    return std::acos(std::clamp(Dot(m, n), -1.0, 1.0));
  }
  // The smallest angle of the triangle (a, b, c) (0 when degenerate).
  double MinAngle(uint32_t a, uint32_t b, uint32_t c) const {
    const Vec3 p[3] = {P(a), P(b), P(c)};
    double smallest = 3.14159265358979323846;
    for (int k = 0; k < 3; ++k) {
      const Vec3 e1 = Sub(p[(k + 1) % 3], p[k]), e2 = Sub(p[(k + 2) % 3], p[k]);
      const double l = std::sqrt(Dot(e1, e1) * Dot(e2, e2));
      if (!(l > 0.0)) return 0.0;
      smallest = std::min(smallest, std::acos(std::clamp(Dot(e1, e2) / l, -1.0, 1.0)));
    }
    return smallest;
  }

  // opp_[3f + k]: the half-edge across edge k (vertices k, k + 1) of face f, -1 at the boundary
  // or at an edge that is not between exactly two consistently oriented faces (never flipped).
  void BuildTopology() {
    const std::size_t nh = faces_.size();
    std::unordered_map<uint64_t, int64_t> directed;  // (from, to) -> half-edge, -1: repeated
    directed.reserve(nh);
    for (uint32_t h = 0; h < nh; ++h) {
      const uint64_t key = (uint64_t{From(h)} << 32) | To(h);
      const auto [it, fresh] = directed.emplace(key, h);
      if (!fresh) it->second = -1;
    }
    opp_.assign(nh, -1);
    edges_.reserve(nh);
    for (uint32_t h = 0; h < nh; ++h) {
      edges_.insert(UndirectedKey(From(h), To(h)));
      const auto mine = directed.find((uint64_t{From(h)} << 32) | To(h));
      const auto it = directed.find((uint64_t{To(h)} << 32) | From(h));
      if (mine->second >= 0 && it != directed.end() && it->second >= 0) opp_[h] = it->second;
    }
    if (!seams_) return;
    // Seam vertices: those whose fan is not one closed cycle (plane_retriangulation's rule).
    const std::size_t nv = xyz_.size() / 3;
    std::vector<std::vector<std::pair<uint32_t, uint32_t>>> links(nv);
    for (uint32_t h = 0; h < nh; ++h) links[From(h)].emplace_back(To(h), Apex(h));
    closed_.assign(nv, 0);
    std::vector<std::pair<uint32_t, uint32_t>> by_first;
    std::vector<uint32_t> seconds;
    for (std::size_t v = 0; v < nv; ++v)
      closed_[v] = !links[v].empty() && CheckLink(links[v].data(), links[v].size(), &by_first, &seconds) ==
                                            LinkShape::kCycle;
  }
  uint32_t From(uint32_t h) const { return faces_[h]; }
  uint32_t To(uint32_t h) const { return faces_[h - h % 3 + (h % 3 + 1) % 3]; }
  uint32_t Apex(uint32_t h) const { return faces_[h - h % 3 + (h % 3 + 2) % 3]; }

  // The sum of the angles between neighbouring faces' normals over the interior edges (degrees).
  double AngleSum(int64_t* edges) const {
    double sum = 0.0;
    for (uint32_t h = 0; h < faces_.size(); ++h) {
      if (opp_[h] < 0 || h > opp_[h]) continue;
      sum += Angle(FaceNormal(h / 3), FaceNormal(static_cast<uint32_t>(opp_[h]) / 3)) * kDegrees;
      ++*edges;
    }
    return sum;
  }

  // Flips the edge of half-edge h when the rules of edge_flips.h allow it and the angles gain.
  bool TryFlip(uint32_t h, double min_gain, double min_angle) {
    const uint32_t h2 = static_cast<uint32_t>(opp_[h]);
    const uint32_t f = h / 3, g = h2 / 3;
    const uint32_t u = From(h), v = To(h), a = Apex(h), b = Apex(h2);
    if (f == g || a == b || edges_.count(UndirectedKey(a, b))) return false;
    if (seams_ && !closed_[a] && !closed_[b]) return false;
    // The half-edges around the quad (u, b, v, a) and the faces across them (-1: none).
    const uint32_t h_va = f * 3 + (h % 3 + 1) % 3, h_au = f * 3 + (h % 3 + 2) % 3;
    const uint32_t h_ub = g * 3 + (h2 % 3 + 1) % 3, h_bv = g * 3 + (h2 % 3 + 2) % 3;
    const Vec3 nf = FaceNormal(f), ng = FaceNormal(g);
    const Vec3 nF = Normal(a, u, b), nG = Normal(b, v, a);
    const Vec3 sum = {nf[0] + ng[0], nf[1] + ng[1], nf[2] + ng[2]};
    if (!(Dot(nF, sum) > 0.0) || !(Dot(nG, sum) > 0.0)) return false;
    const double old_min = std::min(MinAngle(u, v, a), MinAngle(v, u, b));
    const double new_min = std::min(MinAngle(a, u, b), MinAngle(b, v, a));
    if (new_min < std::min(old_min, min_angle)) return false;
    // The angles over the five edges, before and after; `around` sums the normals of the pair
    // and of the faces across the quad's edges.
    const uint32_t outer[4] = {h_va, h_au, h_ub, h_bv};
    const Vec3* was[4] = {&nf, &nf, &ng, &ng};  // the old face beside each outer edge
    const Vec3* now[4] = {&nG, &nF, &nF, &nG};  // the new one
    double before = Angle(nf, ng), after = Angle(nF, nG);
    Vec3 around = sum;
    for (int i = 0; i < 4; ++i) {
      if (opp_[outer[i]] < 0) continue;
      const Vec3 n = FaceNormal(static_cast<uint32_t>(opp_[outer[i]]) / 3);
      before += Angle(*was[i], n);
      after += Angle(*now[i], n);
      for (int k = 0; k < 3; ++k) around[k] += n[k];
    }
    if (!(before - after >= min_gain)) return false;
    // The new faces face the way the surface around does: each within 90 degrees of `around`.
    // A fold flipped open toward the wrong side would be a face seen from behind (imr-synth's
    // default mesh: the share seen from behind 0.35 % -> 0.91 % without this, 0.70 % with it).
    if (!(Dot(nF, around) > 0.0) || !(Dot(nG, around) > 0.0)) return false;

    // f = (a, u, b): edges (a, u), (u, b), (b, a); g = (b, v, a): edges (b, v), (v, a), (a, b).
    const int64_t o_va = opp_[h_va], o_au = opp_[h_au], o_ub = opp_[h_ub], o_bv = opp_[h_bv];
    edges_.erase(UndirectedKey(u, v));
    edges_.insert(UndirectedKey(a, b));
    faces_[3 * f] = a, faces_[3 * f + 1] = u, faces_[3 * f + 2] = b;
    faces_[3 * g] = b, faces_[3 * g + 1] = v, faces_[3 * g + 2] = a;
    const int64_t links[6][2] = {{3 * f, o_au}, {3 * f + 1, o_ub}, {3 * f + 2, 3 * g + 2},
                                 {3 * g, o_bv}, {3 * g + 1, o_va}, {3 * g + 2, 3 * f + 2}};
    for (const auto& [e, o] : links) {
      opp_[static_cast<std::size_t>(e)] = o;
      if (o >= 0) opp_[static_cast<std::size_t>(o)] = e;
    }
    return true;
  }

  const std::vector<double>& xyz_;
  std::vector<uint32_t>& faces_;
  const EdgeFlipOptions& o_;
  const bool seams_;
  std::vector<int64_t> opp_;
  std::unordered_set<uint64_t> edges_;
  std::vector<uint8_t> closed_;
  std::vector<uint8_t> queued_;
  EdgeFlipStats stats_;
};

}  // namespace

EdgeFlipOptions EdgeFlipOptions::FromEngine(const EngineOptions& options) {
  EdgeFlipOptions o;
  o.enabled = options.flip_edges;
  return o;
}

std::string EdgeFlipOptions::Check() const {
  if (!(min_gain_degrees > 0.0)) return "min_gain_degrees: expected > 0";
  if (!(min_angle_degrees >= 0.0 && min_angle_degrees < 60.0)) return "min_angle_degrees: expected 0 .. 60";
  if (max_flips_per_face < 0) return "max_flips_per_face: expected >= 0";
  return {};
}

EdgeFlipStats& EdgeFlipStats::operator+=(const EdgeFlipStats& o) {
  flips += o.flips;
  edges += o.edges;
  degrees_sum_before += o.degrees_sum_before;
  degrees_sum_after += o.degrees_sum_after;
  return *this;
}

EdgeFlipStats FlipEdges(Mesh* mesh, const EdgeFlipOptions& options) {
  if (!options.enabled) return {};
  return Flipper(mesh->vertices, &mesh->faces, options, /*seams=*/false).Run();
}

EdgeFlipStats FlipEdges(SurfacePart* part, const EdgeFlipOptions& options) {
  if (!options.enabled) return {};
  return Flipper(part->vertices, &part->faces, options, /*seams=*/true).Run();
}

}  // namespace imr::engine
