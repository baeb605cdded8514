// The reconstruction engine (Romanoni & Matteucci, sections 2-3; DESIGN §3). The only CGAL
// translation unit of the engine.
//
// Notes on choices the paper leaves open:
// - Weights are int64 multiples of weight_unit, so a backward cast restores weights bit for bit;
//   policy outputs are rounded to the unit.
// - transfer_on_insert defaults to false: for a NEW point the cells of its conflict zone are
//   replaced by cells that start at weight 0 and are then weighted by the point's own rays. With
//   the policy (DESIGN §3 step 3) the big carved cells that straddle a surface before it is
//   sampled hand their free-space weight to the new cells behind the surface; on the synthetic
//   streams that carves the matter away (street: completeness of real-point triangles 0.08 with
//   nearest, 0.73 without, rays5 baseline 0.66). Moves always use the policy, as in the paper.
// - Two corrections of the efficient approach (measured with imr-bench paper; why: the mesh of
//   nearest had 3x the area of rays5's in triangles whose vertices lie on the true surfaces but
//   whose interior does not, mostly bulging into free space, and the cells behind them had
//   weights around -0.6):
//   * nonnegative_weights: a backward cast subtracts along today's triangulation, through cells
//     whose weight came from the policy or from 0 at an insertion, not from the ray cast
//     forward; without a floor at 0 they sink below 0 and no later ray frees them. The floor
//     keeps backward-after-forward exact (weights are >= 0 before the forward cast).
//   * transfer_camera_side: the policy carries the free space in front of a point's old position
//     to the new cells behind its new one (a refined point moves mostly along its viewing ray),
//     carving matter; new cells whose centroid lies behind the point, seen from its cameras,
//     start at 0. Each correction alone makes the mesh worse; together, on the 500-frame street,
//     ground truth -> mesh 0.48 -> 0.41 m (rays5: 0.58), mesh -> truth 0.22 -> 0.20 m (rays5:
//     0.11).
// - Steiner points sit off their grid nodes by a deterministic jitter (steiner_jitter, 1e-3 of
//   the spacing): on an exact grid many cells are cospherical and CGAL's predicates fall back to
//   exact arithmetic.
// - O never contains a cell adjacent to an infinite cell, so dO is always closed and finite.
// - Growing after the first keyframe is seeded with the cells whose state changed during the
//   keyframe (became free, were created, or were shrunk), not with all of dO, so the cost of a
//   keyframe does not grow with the size of the reconstruction.
#include "host/engine/engine.h"
#include "host/engine/engine_internal.h"

#include <CGAL/Delaunay_triangulation_3.h>
#include <CGAL/Delaunay_triangulation_cell_base_3.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Triangulation_cell_base_with_info_3.h>
#include <CGAL/Triangulation_vertex_base_with_info_3.h>
#include <CGAL/utility.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <functional>
#include <map>
#include <queue>
#include <sstream>
#include <unordered_map>
#include <unordered_set>

namespace imr::engine {
namespace {

using K = CGAL::Exact_predicates_inexact_constructions_kernel;

// One ray stored in a cell (kRays mode): camera, point, and the ring (0 = T, 1 = N1, 2 = N2).
struct RayEntry {
  uint32_t camera;
  uint32_t point;
  uint8_t level;
};

struct VertexInfo {
  int64_t id = -1;     // >= 0: internal point index; < 0: Steiner point number -(k + 1).
  int32_t o_cells = 0;  // Incident cells in O (kept by SetInO: cells of O are never destroyed,
                        // shrink takes them out of O before the triangulation changes).
};

struct CellInfo {
  int64_t weight = 0;     // In units of EngineOptions::weight_unit.
  uint64_t stamp = 0;     // Ray stamp: a cell joins T, N1 or N2 once per ray.
  bool in_o = false;      // Member of O (outside, the manifold part of free space).
  std::vector<RayEntry> rays;  // kRays: at most K rays that raised this cell's weight.
};

using Vb = CGAL::Triangulation_vertex_base_with_info_3<VertexInfo, K>;
using Cb = CGAL::Triangulation_cell_base_with_info_3<CellInfo, K,
                                                     CGAL::Delaunay_triangulation_cell_base_3<K>>;
using Tds = CGAL::Triangulation_data_structure_3<Vb, Cb>;
using Dt = CGAL::Delaunay_triangulation_3<K, Tds>;
using Point = Dt::Point;
using Cell_handle = Dt::Cell_handle;
using Vertex_handle = Dt::Vertex_handle;
using Facet = Dt::Facet;

using Clock = std::chrono::steady_clock;
double Seconds(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double>(b - a).count();
}

bool Finite(const Vec3& p) {
  return std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2]);
}

Point ToPoint(const Vec3& p) { return Point(p[0], p[1], p[2]); }

// Regularity of a vertex from the edges of its link on the surface: they must form exactly one
// closed cycle (or the vertex is not on the surface at all). Edges are given as id pairs.
template <class Id>
bool LinkIsOneCycle(const std::vector<std::pair<Id, Id>>& edges) {
  if (edges.empty()) return true;
  // Each link vertex must appear in exactly two edges.
  std::vector<std::pair<Id, std::array<Id, 2>>> adj;
  std::vector<int> deg;
  auto find = [&](Id v) -> int {
    for (size_t i = 0; i < adj.size(); ++i)
      if (adj[i].first == v) return static_cast<int>(i);
    adj.push_back({v, {v, v}});
    deg.push_back(0);
    return static_cast<int>(adj.size()) - 1;
  };
  for (const auto& e : edges) {
    if (e.first == e.second) return false;
    const int a = find(e.first), b = find(e.second);
    if (deg[a] >= 2 || deg[b] >= 2) return false;
    adj[a].second[deg[a]++] = e.second;
    adj[b].second[deg[b]++] = e.first;
  }
  for (int d : deg)
    if (d != 2) return false;
  // Walk the cycle from the first vertex; it must visit every vertex.
  Id start = adj[0].first, prev = start, cur = adj[0].second[0];
  size_t steps = 1;
  while (!(cur == start)) {
    const int i = find(cur);
    const Id next = (adj[i].second[0] == prev) ? adj[i].second[1] : adj[i].second[0];
    prev = cur;
    cur = next;
    if (++steps > adj.size()) return false;
  }
  return steps == adj.size() && adj.size() == edges.size();
}

// A deterministic number in [-1, 1] from a key and an axis (splitmix64).
double Jitter(uint64_t key, int axis) {
  uint64_t z = key * 3 + static_cast<uint64_t>(axis) + 0x9E3779B97F4A7C15ull;
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  z ^= z >> 31;
  return static_cast<double>(z >> 11) / static_cast<double>(1ull << 52) - 1.0;
}

// After dropping triangles from a closed 2-manifold, a vertex may keep several separate fans;
// give each extra fan its own copy of the vertex so the result is a 2-manifold with boundary.
void SplitPinchedVertices(Mesh* m) {
  const size_t nv = m->vertices.size() / 3;
  const size_t nt = m->faces.size() / 3;
  std::vector<std::vector<uint32_t>> around(nv);
  for (size_t t = 0; t < nt; ++t)
    for (int k = 0; k < 3; ++k) around[m->faces[3 * t + k]].push_back(static_cast<uint32_t>(t));
  for (size_t v = 0; v < nv; ++v) {
    const auto& tris = around[v];
    if (tris.size() < 2) continue;
    // Union-find over the triangles around v: two are joined when they share an edge at v.
    std::vector<int> parent(tris.size());
    for (size_t i = 0; i < tris.size(); ++i) parent[i] = static_cast<int>(i);
    auto root = [&](int i) {
      while (parent[i] != i) i = parent[i] = parent[parent[i]];
      return i;
    };
    auto others = [&](uint32_t t, uint32_t out[2]) {
      int n = 0;
      for (int k = 0; k < 3; ++k)
        if (m->faces[3 * t + k] != v) out[n++] = m->faces[3 * t + k];
    };
    for (size_t i = 0; i < tris.size(); ++i) {
      uint32_t a[2];
      others(tris[i], a);
      for (size_t j = i + 1; j < tris.size(); ++j) {
        uint32_t b[2];
        others(tris[j], b);
        if (a[0] == b[0] || a[0] == b[1] || a[1] == b[0] || a[1] == b[1])
          parent[root(static_cast<int>(i))] = root(static_cast<int>(j));
      }
    }
    std::map<int, uint32_t> copy;  // Component root -> vertex index.
    copy[root(0)] = static_cast<uint32_t>(v);
    for (size_t i = 0; i < tris.size(); ++i) {
      const int r = root(static_cast<int>(i));
      auto it = copy.find(r);
      if (it == copy.end()) {
        const uint32_t nvtx = static_cast<uint32_t>(m->vertices.size() / 3);
        m->vertices.insert(m->vertices.end(), {m->vertices[3 * v], m->vertices[3 * v + 1],
                                               m->vertices[3 * v + 2]});
        m->point_ids.push_back(m->point_ids[v]);
        it = copy.emplace(r, nvtx).first;
      }
      if (it->second == v) continue;
      for (int k = 0; k < 3; ++k)
        if (m->faces[3 * tris[i] + k] == v) m->faces[3 * tris[i] + k] = it->second;
    }
  }
}

}  // namespace

struct Engine::Impl {
  struct PointRecord {
    uint64_t id = 0;
    Vertex_handle vertex;        // Valid when in_triangulation.
    bool in_triangulation = false;
    Vec3 position{};             // Latest estimate received.
    std::vector<uint32_t> cameras;  // Observing cameras (internal indices), oldest first.
  };

  EngineOptions opt;
  WeightTransferPolicy* policy = nullptr;
  Status init;
  Dt dt;
  std::array<int64_t, 3> unit{};  // w1, w2, w3 in weight units.
  int64_t threshold = 0;

  std::vector<Point> cameras;
  std::vector<uint64_t> camera_ids;
  std::unordered_map<uint64_t, uint32_t> camera_index;
  std::vector<PointRecord> points;
  std::unordered_map<uint64_t, uint32_t> point_index;
  std::unordered_set<uint64_t> steiner_keys;
  int64_t steiner_count = 0;
  Vertex_handle last_vertex;  // Locate hint.

  uint64_t stamp = 0;
  // Cells whose state changed this keyframe (became free, created, shrunk): growing seeds.
  std::unordered_set<Cell_handle> dirty;
  int64_t cells_in_o = 0;
  // Sum of every cell's weight (finite and infinite), kept by each change of a weight and of the
  // cells: CheckInvariants compares it with the cells' own sum, so a weight changed or a cell made
  // or destroyed outside casting and transfer shows. Modulo 2^64 (unsigned wrap is exact).
  uint64_t weight_ledger = 0;
  EngineStats stats;

  // Benchmark hooks (engine_internal.h).
  bool cross_check_manifold_test = false;  // Run both forms of the manifold test, count differences.
  int64_t manifold_test_mismatches = 0;
  bool record_transfers = false;
  size_t record_limit = 0;
  std::vector<internal::RecordedTransfer> recorded;
  std::vector<Cell_handle> probe_cells;

  // Scratch buffers.
  std::vector<Cell_handle> ring[2];  // T and N1 of the ray being cast.
  std::vector<Cell_handle> incident_scratch;
  std::vector<Cell_handle> star_scratch;

  Impl(const EngineOptions& o, WeightTransferPolicy* p) : opt(o), policy(p) {
    std::string error;
    if (!opt.Check(&error)) {
      init = Status::Error("invalid engine options: " + error);
    } else if (opt.visibility_mode == VisibilityMode::kWeights && policy == nullptr) {
      init = Status::Error("visibility_mode 'weights' needs a weight-transfer policy");
    }
    unit = {ToUnits(opt.w1), ToUnits(opt.w2), ToUnits(opt.w3)};
    threshold = ToUnits(opt.free_threshold);
  }

  int64_t ToUnits(double w) const {
    if (!std::isfinite(w)) return 0;
    // A policy may return any finite double: saturate far below int64's range (llround of an
    // unrepresentable value is unspecified) while leaving room for rays added on top.
    constexpr double kMaxUnits = 4611686018427387904.0;  // 2^62
    const double u = std::clamp(w / opt.weight_unit, -kMaxUnits, kMaxUnits);
    return static_cast<int64_t>(std::llround(u));
  }
  void Ledger(int64_t before, int64_t after) {
    weight_ledger += static_cast<uint64_t>(after) - static_cast<uint64_t>(before);
  }
  double FromUnits(int64_t w) const { return static_cast<double>(w) * opt.weight_unit; }

  bool IsFree(Cell_handle c) const { return c->info().weight > threshold; }
  bool HullAdjacent(Cell_handle c) const {
    for (int i = 0; i < 4; ++i)
      if (dt.is_infinite(c->neighbor(i))) return true;
    return false;
  }
  bool TouchesO(Cell_handle c) const {
    for (int i = 0; i < 4; ++i)
      if (c->neighbor(i)->info().in_o) return true;
    return false;
  }

  Point Centroid(Cell_handle c) const {
    return CGAL::centroid(c->vertex(0)->point(), c->vertex(1)->point(), c->vertex(2)->point(),
                          c->vertex(3)->point());
  }

  void MarkDirty(Cell_handle c) {
    if (!dt.is_infinite(c) && !c->info().in_o) dirty.insert(c);
  }

  // ---------------------------------------------------------------------------------------------
  // Manifold test (DESIGN §3): toggling one cell in or out of O changes only the regularity of its
  // four vertices; each must stay regular (its surface triangles form one closed fan).
  bool VertexRegular(Vertex_handle v, Cell_handle toggled) {
    std::vector<Cell_handle>& cells = incident_scratch;
    cells.clear();
    dt.incident_cells(v, std::back_inserter(cells));
    auto in_o = [&](Cell_handle c) { return c == toggled ? !c->info().in_o : c->info().in_o; };
    std::vector<std::pair<Vertex_handle, Vertex_handle>> edges;
    for (Cell_handle c : cells) {
      if (!in_o(c)) continue;
      const int iv = c->index(v);
      for (int i = 0; i < 4; ++i) {
        if (i == iv || in_o(c->neighbor(i))) continue;
        Vertex_handle e[2];
        int n = 0;
        for (int j = 0; j < 4; ++j)
          if (j != iv && j != i) e[n++] = c->vertex(j);
        edges.push_back({e[0], e[1]});
      }
    }
    return LinkIsOneCycle(edges);
  }

  // The reference form of the test: the link of each of c's four vertices, rebuilt.
  bool ToggleKeepsManifoldByLinks(Cell_handle c) {
    for (int i = 0; i < 4; ++i)
      if (!VertexRegular(c->vertex(i), c)) return false;
    return true;
  }

  // The combinatorial form (Litvinov & Lhuillier 2013): toggling c keeps dO a 2-manifold iff
  // K = c ∩ closure(S) is a disk, the empty set or all of c's boundary, where S is the side c
  // joins (O when c enters O, the cells outside O when it leaves). With f facets of c on S:
  // f >= 3 always; f = 2 iff the edge opposite the two facets' common edge is not on S; f = 1
  // iff the vertex opposite the facet is not on S; f = 0 iff no vertex is on S. Equivalent to
  // the link test on the four vertices while dO is manifold (the engine's invariant); it only
  // looks at one edge's ring or one vertex, and a vertex on O is a counter, not a walk.
  bool ToggleKeepsManifold(Cell_handle c) {
    const bool adding = !c->info().in_o;
    int on_s[4], f = 0;
    for (int i = 0; i < 4; ++i)
      if (c->neighbor(i)->info().in_o == adding) on_s[f++] = i;
    bool keeps;
    if (f >= 3) {
      keeps = true;
    } else if (f == 2) {
      keeps = !EdgeTouchesSide(c, on_s[0], on_s[1], adding);
    } else if (f == 1) {
      keeps = !VertexTouchesSide(c, on_s[0], adding);
    } else {
      keeps = true;
      for (int i = 0; i < 4 && keeps; ++i) keeps = !VertexTouchesSide(c, i, adding);
    }
    if (cross_check_manifold_test && keeps != ToggleKeepsManifoldByLinks(c))
      ++manifold_test_mismatches;
    return keeps;
  }

  // Is vertex i of c on S through a cell other than c?
  bool VertexTouchesSide(Cell_handle c, int i, bool adding) {
    const Vertex_handle v = c->vertex(i);
    if (adding) return v->info().o_cells > 0;  // c itself is not in O.
    // Leaving O: is any other cell around v outside O? A walk over v's star that stops at the
    // first one (cells around a vertex inside O are all in O: the walk then sees them all).
    ++stamp;
    c->info().stamp = stamp;
    std::vector<Cell_handle>& todo = star_scratch;
    todo.clear();
    todo.push_back(c);
    while (!todo.empty()) {
      const Cell_handle x = todo.back();
      todo.pop_back();
      const int iv = x->index(v);
      for (int k = 0; k < 4; ++k) {
        if (k == iv) continue;
        const Cell_handle n = x->neighbor(k);
        if (n->info().stamp == stamp) continue;
        n->info().stamp = stamp;
        if (!n->info().in_o) return true;
        todo.push_back(n);
      }
    }
    return false;
  }

  // Is the edge (vertex i, vertex j) of c on S through a cell other than c?
  bool EdgeTouchesSide(Cell_handle c, int i, int j, bool adding) const {
    Dt::Cell_circulator it = dt.incident_cells(c, i, j), done = it;
    do {
      const Cell_handle x = it;
      if (x != c && x->info().in_o == adding) return true;
    } while (++it != done);
    return false;
  }

  void SetInO(Cell_handle c, bool in) {
    if (c->info().in_o == in) return;
    c->info().in_o = in;
    cells_in_o += in ? 1 : -1;
    for (int i = 0; i < 4; ++i) c->vertex(i)->info().o_cells += in ? 1 : -1;
  }

  // ---------------------------------------------------------------------------------------------
  // cast_rays: one viewing ray, camera centre -> point. T = traversed cells, N1 = their
  // neighbours, N2 = neighbours of N1; each cell once per ray (DESIGN §3, paper §2.1).
  void CastRay(uint32_t cam, uint32_t pt, int sign) {
    const PointRecord& rec = points[pt];
    if (!rec.in_triangulation) return;
    const Point& a = rec.vertex->point();
    const Point& b = cameras[cam];
    const double len2 = CGAL::squared_distance(a, b);
    if (len2 > opt.max_ray_length * opt.max_ray_length) {
      ++stats.rays_skipped_too_long;
      return;
    }
    if (len2 <= 0.0) return;  // A point at the camera centre carves nothing.
    if (dt.dimension() != 3) return;
    if (sign > 0) ++stats.rays_cast;
    else ++stats.rays_cast_backward;
    ++stamp;
    ring[0].clear();
    ring[1].clear();
    const bool rays_mode = opt.visibility_mode == VisibilityMode::kRays;
    // Each cell is weighted when it is first reached (T, then N1, then N2), while it is in cache;
    // only T and N1 are kept, to find the next ring.
    auto weigh = [&](Cell_handle c, int level) {
      CellInfo& info = c->info();
      const int64_t before = info.weight;
      const bool was_free = before > threshold;
      if (rays_mode) {
        // Lovi et al.: a cell remembers the rays that raised its weight (at most K, oldest
        // forgotten); a ray already stored is not counted twice when it is re-cast.
        for (const RayEntry& e : info.rays)
          if (e.camera == cam && e.point == pt) return;
        info.weight += unit[level];
        info.rays.push_back({cam, pt, static_cast<uint8_t>(level)});
        if (static_cast<int>(info.rays.size()) > opt.rays_per_cell)
          info.rays.erase(info.rays.begin());
      } else {
        info.weight += sign * unit[level];
        if (opt.nonnegative_weights && info.weight < 0) info.weight = 0;
      }
      Ledger(before, info.weight);
      if (!was_free && info.weight > threshold) MarkDirty(c);
    };
    // Traverse from the point's own vertex (DESIGN §9: located start, ~15x faster than a walk
    // from an arbitrary cell). The traversal stops at the cell holding the camera, at the hull,
    // or after max_cells_per_ray cells.
    int steps = 0;
    try {
      auto it = dt.segment_traverser_cells_begin(a, b, rec.vertex->cell());
      const auto end = dt.segment_traverser_cells_end();
      for (; it != end; ++it) {
        Cell_handle c = it;
        if (dt.is_infinite(c)) break;
        if (++steps > opt.max_cells_per_ray) {
          ++stats.rays_truncated;
          break;
        }
        if (c->info().stamp == stamp) continue;
        c->info().stamp = stamp;
        ring[0].push_back(c);
        weigh(c, 0);
      }
    } catch (...) {
      ++stats.rays_truncated;
    }
    stats.cells_traversed += static_cast<int64_t>(ring[0].size());
    int64_t weighted = static_cast<int64_t>(ring[0].size());
    for (int level = 1; level < 3; ++level)
      for (Cell_handle c : ring[level - 1])
        for (int i = 0; i < 4; ++i) {
          Cell_handle n = c->neighbor(i);
          if (n->info().stamp == stamp || dt.is_infinite(n)) continue;
          n->info().stamp = stamp;
          if (level == 1) ring[1].push_back(n);
          weigh(n, level);
          ++weighted;
        }
    stats.cells_weighted += weighted;
  }

  std::vector<uint32_t> Window(const PointRecord& rec) const {
    const size_t w = static_cast<size_t>(opt.window);
    const size_t n = rec.cameras.size();
    return std::vector<uint32_t>(rec.cameras.begin() + (n > w ? n - w : 0), rec.cameras.end());
  }

  // ---------------------------------------------------------------------------------------------
  // shrink: remove from O, lowest weight first and keeping dO manifold, the cells of an enclosing
  // set E of D (D plus the cells around D's vertices near the affected points). Returns whether
  // D no longer meets O.
  bool Shrink(const std::vector<Cell_handle>& d, const std::vector<Point>& centres) {
    auto meets_o = [&]() {
      for (Cell_handle c : d)
        if (c->info().in_o) return true;
      return false;
    };
    if (!meets_o()) return true;
    const auto t0 = Clock::now();
    // E: D, plus the cells around every vertex of D (all of them when the vertex lies within
    // shrink_radius of an affected point, else only the cells of D's facet neighbours).
    std::unordered_set<Cell_handle> e;
    for (Cell_handle c : d) {
      e.insert(c);
      for (int i = 0; i < 4; ++i) e.insert(c->neighbor(i));
    }
    const double r2 = opt.shrink_radius * opt.shrink_radius;
    std::unordered_set<Vertex_handle> vseen;
    std::vector<Cell_handle> inc;
    for (Cell_handle c : d)
      for (int i = 0; i < 4; ++i) {
        Vertex_handle v = c->vertex(i);
        if (dt.is_infinite(v) || !vseen.insert(v).second) continue;
        bool near = false;
        for (const Point& p : centres) near = near || CGAL::squared_distance(v->point(), p) <= r2;
        if (!near) continue;
        inc.clear();
        dt.incident_cells(v, std::back_inserter(inc));
        e.insert(inc.begin(), inc.end());
      }
    // Peel E from O, lowest weight first (the inverse of grow): a cell refused now is retried
    // when one of its facet neighbours leaves O.
    struct Item {
      int64_t weight;
      uint64_t order;
      Cell_handle cell;
      bool operator<(const Item& o) const {
        return weight != o.weight ? weight > o.weight : order > o.order;
      }
    };
    std::vector<std::pair<std::array<int64_t, 4>, Cell_handle>> start;
    for (Cell_handle c : e)
      if (c->info().in_o) start.push_back({CellKey(c), c});
    std::sort(start.begin(), start.end(),
              [](const auto& a, const auto& b) { return a.first < b.first; });
    std::priority_queue<Item> q;
    uint64_t order = 0;
    for (const auto& s : start) q.push({s.second->info().weight, order++, s.second});
    int64_t budget = static_cast<int64_t>(start.size()) * 4 * opt.shrink_passes + 16;
    bool ok = false;
    while (!q.empty() && budget-- > 0) {
      Cell_handle c = q.top().cell;
      q.pop();
      if (!c->info().in_o || !ToggleKeepsManifold(c)) continue;
      SetInO(c, false);
      ++stats.cells_shrunk;
      MarkDirty(c);
      for (int i = 0; i < 4; ++i) {
        Cell_handle n = c->neighbor(i);
        MarkDirty(n);
        if (n->info().in_o && e.count(n)) q.push({n->info().weight, order++, n});
      }
      if (!meets_o()) {
        ok = true;
        break;
      }
    }
    if (!ok) ok = !meets_o();
    stats.time.shrink += Seconds(t0, Clock::now());
    return ok;
  }

  // ---------------------------------------------------------------------------------------------
  // Transfer of weights from removed cells R to new cells A (efficient approach, paper §3.2).
  struct Removed {
    std::vector<double> centroids;
    std::vector<double> weights;
    std::vector<RayEntry> rays;  // kRays: rays stored in R (the set U of Lovi et al.).
  };

  void CollectRemoved(const std::vector<Cell_handle>& cells, Removed* r) {
    for (Cell_handle c : cells) {
      dirty.erase(c);
      Ledger(c->info().weight, 0);  // the cell is about to be destroyed
      if (dt.is_infinite(c)) continue;
      if (opt.visibility_mode == VisibilityMode::kRays) {
        r->rays.insert(r->rays.end(), c->info().rays.begin(), c->info().rays.end());
      } else {
        const Point g = Centroid(c);
        r->centroids.insert(r->centroids.end(), {g.x(), g.y(), g.z()});
        r->weights.push_back(FromUnits(c->info().weight));
      }
    }
  }

  // The point being inserted and its cameras, for transfer_camera_side (null: no such rule).
  const Point* side_apex = nullptr;
  const std::vector<uint32_t>* side_cams = nullptr;

  void AssignNewCells(const std::vector<Cell_handle>& added, const Removed& r, bool transfer) {
    std::vector<Cell_handle> finite;
    for (Cell_handle c : added)
      if (!dt.is_infinite(c)) finite.push_back(c);
    if (transfer && opt.visibility_mode == VisibilityMode::kWeights && !finite.empty()) {
      std::vector<double> centroids;
      centroids.reserve(3 * finite.size());
      for (Cell_handle c : finite) {
        const Point g = Centroid(c);
        centroids.insert(centroids.end(), {g.x(), g.y(), g.z()});
      }
      std::vector<double> out(finite.size(), 0.0);
      TransferInput in;
      in.removed_centroids = r.centroids.data();
      in.removed_weights = r.weights.data();
      in.removed_count = r.weights.size();
      in.new_centroids = centroids.data();
      in.new_count = finite.size();
      policy->Transfer(in, out.data());
      ++stats.policy_calls;
      if (record_transfers && recorded.size() < record_limit)
        recorded.push_back({r.centroids, r.weights, centroids});
      for (size_t i = 0; i < finite.size(); ++i) finite[i]->info().weight = ToUnits(out[i]);
      if (side_apex && side_cams && !side_cams->empty()) {
        // transfer_camera_side: a new cell whose centroid lies behind the point, on the far side
        // from its cameras (mean viewing direction), starts at 0: matter, not inherited carving.
        double d[3] = {0.0, 0.0, 0.0};
        for (uint32_t c : *side_cams) {
          const double v[3] = {cameras[c].x() - side_apex->x(), cameras[c].y() - side_apex->y(),
                               cameras[c].z() - side_apex->z()};
          const double n = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
          if (n > 0.0)
            for (int k = 0; k < 3; ++k) d[k] += v[k] / n;
        }
        for (size_t i = 0; i < finite.size(); ++i) {
          const double* g = &centroids[3 * i];
          const double dot = (g[0] - side_apex->x()) * d[0] + (g[1] - side_apex->y()) * d[1] +
                             (g[2] - side_apex->z()) * d[2];
          if (dot < 0.0) finite[i]->info().weight = 0;
        }
      }
    }
    for (Cell_handle c : added) Ledger(0, c->info().weight);
    for (Cell_handle c : finite)
      if (IsFree(c)) MarkDirty(c);
  }

  // Inserts p (conflict cells -> new cells). Returns a null handle when p is dropped: duplicate of
  // a vertex (*duplicate set) or its conflict zone still meets O after shrink. `rays` receives the
  // rays stored in the conflict cells (kRays).
  // `transfer`: new cells get weights through the policy (weights mode); else they start at 0.
  Vertex_handle InsertPoint(const Point& p, int64_t vertex_id, bool transfer, bool* duplicate,
                            std::vector<RayEntry>* rays) {
    *duplicate = false;
    if (dt.dimension() < 3) {
      // Only Steiner points get here (before the grid spans 3D): O is empty.
      const size_t before = dt.number_of_vertices();
      Vertex_handle v = dt.insert(p, last_vertex != Vertex_handle() ? last_vertex->cell()
                                                                    : Cell_handle());
      if (dt.number_of_vertices() == before) {
        *duplicate = true;
        return Vertex_handle();
      }
      v->info().id = vertex_id;
      last_vertex = v;
      return v;
    }
    Dt::Locate_type lt;
    int li, lj;
    Cell_handle loc = dt.locate(p, lt, li, lj,
                                last_vertex != Vertex_handle() ? last_vertex->cell() : Cell_handle());
    if (lt == Dt::VERTEX) {
      *duplicate = true;
      return Vertex_handle();
    }
    std::vector<Cell_handle> conflicts;
    Facet boundary;
    dt.find_conflicts(p, loc, CGAL::Oneset_iterator<Facet>(boundary), std::back_inserter(conflicts));
    if (!Shrink(conflicts, {p})) return Vertex_handle();
    Removed removed;
    CollectRemoved(conflicts, &removed);
    Vertex_handle v = dt.insert_in_hole(p, conflicts.begin(), conflicts.end(), boundary.first,
                                        boundary.second);
    v->info().id = vertex_id;
    last_vertex = v;
    std::vector<Cell_handle> added;
    dt.incident_cells(v, std::back_inserter(added));
    AssignNewCells(added, removed, transfer);
    if (rays) *rays = std::move(removed.rays);
    return v;
  }

  // Removes a vertex none of whose cells is in O; new cells get weights through the policy.
  void RemoveVertex(Vertex_handle v, std::vector<RayEntry>* rays) {
    std::vector<Cell_handle> inc;
    dt.incident_cells(v, std::back_inserter(inc));
    Removed removed;
    CollectRemoved(inc, &removed);
    if (last_vertex == v) last_vertex = Vertex_handle();
    std::vector<Cell_handle> added;
    dt.remove_and_give_new_cells(v, std::back_inserter(added));
    AssignNewCells(added, removed, true);
    if (rays) *rays = std::move(removed.rays);
  }

  // kRays: the whole-triangulation scan of Lovi et al. - remove from every cell the rays ending
  // at point pt, and their contribution to the weight.
  void ScanRemoveRays(uint32_t pt) {
    for (auto c = dt.finite_cells_begin(); c != dt.finite_cells_end(); ++c) {
      ++stats.rays_scan_cells;
      auto& rs = c->info().rays;
      for (size_t i = 0; i < rs.size();) {
        if (rs[i].point == pt) {
          Ledger(unit[rs[i].level], 0);
          c->info().weight -= unit[rs[i].level];
          rs.erase(rs.begin() + static_cast<std::ptrdiff_t>(i));
        } else {
          ++i;
        }
      }
    }
  }

  // Re-casts the rays of U (kRays), skipping rays of points no longer in the triangulation and,
  // if given, the rays of point `skip`.
  void RecastRays(std::vector<RayEntry> u, int64_t skip) {
    std::sort(u.begin(), u.end(), [](const RayEntry& a, const RayEntry& b) {
      return a.point != b.point ? a.point < b.point : a.camera < b.camera;
    });
    u.erase(std::unique(u.begin(), u.end(),
                        [](const RayEntry& a, const RayEntry& b) {
                          return a.point == b.point && a.camera == b.camera;
                        }),
            u.end());
    for (const RayEntry& r : u)
      if (static_cast<int64_t>(r.point) != skip) CastRay(r.camera, r.point, +1);
  }

  // ---------------------------------------------------------------------------------------------
  // Steiner grid: spacing steiner_spacing, covering every camera +- (max_ray_length + margin).
  void GrowSteinerGrid(const Point& c) {
    const double s = opt.steiner_spacing;
    const double reach = opt.max_ray_length + opt.steiner_margin;
    int64_t lo[3], hi[3];
    const double cc[3] = {c.x(), c.y(), c.z()};
    for (int d = 0; d < 3; ++d) {
      lo[d] = static_cast<int64_t>(std::floor((cc[d] - reach) / s - opt.steiner_origin[d]));
      hi[d] = static_cast<int64_t>(std::ceil((cc[d] + reach) / s - opt.steiner_origin[d]));
    }
    for (int64_t i = lo[0]; i <= hi[0]; ++i)
      for (int64_t j = lo[1]; j <= hi[1]; ++j)
        for (int64_t k = lo[2]; k <= hi[2]; ++k) {
          const uint64_t key = (static_cast<uint64_t>(i & 0x1FFFFF) << 42) |
                               (static_cast<uint64_t>(j & 0x1FFFFF) << 21) |
                               static_cast<uint64_t>(k & 0x1FFFFF);
          if (!steiner_keys.insert(key).second) continue;
          // Off the exact grid by a deterministic jitter (steiner_jitter): on a regular grid
          // eight points share every circumsphere and CGAL's predicates fall back to exact
          // arithmetic.
          const double jit = opt.steiner_jitter * s;
          const Point p((static_cast<double>(i) + opt.steiner_origin[0]) * s + jit * Jitter(key, 0),
                        (static_cast<double>(j) + opt.steiner_origin[1]) * s + jit * Jitter(key, 1),
                        (static_cast<double>(k) + opt.steiner_origin[2]) * s + jit * Jitter(key, 2));
          bool dup = false;
          std::vector<RayEntry> u;
          Vertex_handle v = InsertPoint(p, -(steiner_count + 1), opt.transfer_on_insert, &dup, &u);
          if (v == Vertex_handle()) {
            ++stats.steiner_dropped;
            continue;
          }
          ++steiner_count;
          ++stats.steiner_points;
          if (opt.visibility_mode == VisibilityMode::kRays) RecastRays(std::move(u), -1);
        }
  }

  // ---------------------------------------------------------------------------------------------
  Status Validate(const KeyframeUpdate& u) const {
    std::unordered_set<uint64_t> update_cams;
    for (const Camera& c : u.cameras) {
      if (!Finite(c.center)) {
        std::ostringstream m;
        m << "camera " << c.id << " has a non-finite centre";
        return Status::Error(m.str());
      }
      update_cams.insert(c.id);
    }
    auto known_cam = [&](uint64_t id) {
      return camera_index.count(id) > 0 || update_cams.count(id) > 0;
    };
    std::unordered_set<uint64_t> new_ids;
    for (const NewPoint& p : u.new_points) {
      std::ostringstream m;
      if (!Finite(p.position)) {
        m << "new point " << p.id << " has a non-finite position (NaN or inf)";
        return Status::Error(m.str());
      }
      if (point_index.count(p.id) || !new_ids.insert(p.id).second) {
        m << "new point " << p.id << " uses an id that is already known";
        return Status::Error(m.str());
      }
      for (uint64_t c : p.camera_ids)
        if (!known_cam(c)) {
          m << "new point " << p.id << " is observed by unknown camera " << c;
          return Status::Error(m.str());
        }
    }
    for (const MovedPoint& p : u.moved_points) {
      std::ostringstream m;
      if (!Finite(p.position)) {
        m << "moved point " << p.id << " has a non-finite position (NaN or inf)";
        return Status::Error(m.str());
      }
      if (!point_index.count(p.id)) {
        m << "moved point " << p.id << " is unknown";
        return Status::Error(m.str());
      }
      for (uint64_t c : p.camera_ids)
        if (!known_cam(c)) {
          m << "moved point " << p.id << " is observed by unknown camera " << c;
          return Status::Error(m.str());
        }
    }
    for (uint64_t id : u.removed_points)
      if (!point_index.count(id)) {
        std::ostringstream m;
        m << "removed point " << id << " is unknown";
        return Status::Error(m.str());
      }
    return Status::Ok();
  }

  void AddCameras(PointRecord& rec, const std::vector<uint64_t>& ids,
                  std::vector<uint32_t>* added) {
    for (uint64_t id : ids) {
      const uint32_t c = camera_index.at(id);
      if (std::find(rec.cameras.begin(), rec.cameras.end(), c) != rec.cameras.end()) continue;
      rec.cameras.push_back(c);
      if (added) added->push_back(c);
    }
  }

  void TimedCast(uint32_t cam, uint32_t pt, int sign) {
    const auto t0 = Clock::now();
    CastRay(cam, pt, sign);
    stats.time.cast += Seconds(t0, Clock::now());
  }
  void TimedRecast(std::vector<RayEntry> u, int64_t skip) {
    const auto t0 = Clock::now();
    RecastRays(std::move(u), skip);
    stats.time.cast += Seconds(t0, Clock::now());
  }

  void RemovePoint(uint32_t pt) {
    PointRecord& rec = points[pt];
    if (!rec.in_triangulation) return;
    std::vector<Cell_handle> inc;
    dt.incident_cells(rec.vertex, std::back_inserter(inc));
    if (!Shrink(inc, {rec.vertex->point()})) {
      ++stats.moves_skipped;  // Cannot be removed without breaking dO; keep it.
      return;
    }
    const bool rays_mode = opt.visibility_mode == VisibilityMode::kRays;
    if (!rays_mode)
      for (uint32_t c : Window(rec)) TimedCast(c, pt, -1);
    std::vector<RayEntry> u;
    RemoveVertex(rec.vertex, rays_mode ? &u : nullptr);
    rec.in_triangulation = false;
    rec.vertex = Vertex_handle();
    ++stats.points_removed;
    if (rays_mode) {
      const auto t0 = Clock::now();
      ScanRemoveRays(pt);
      stats.time.scan += Seconds(t0, Clock::now());
      TimedRecast(std::move(u), pt);
    }
  }

  // Move p_old -> p_new (paper §3): backward cast over the last W cameras, remove, transfer,
  // insert, transfer, forward cast; or, in kRays mode, the Refinement Event Handler of Lovi et al.
  void MovePoint(uint32_t pt, const MovedPoint& m) {
    PointRecord& rec = points[pt];
    rec.position = m.position;
    std::vector<uint32_t> added_cams;
    if (!rec.in_triangulation) {
      AddCameras(rec, m.camera_ids, nullptr);
      ++stats.moves_skipped;
      return;
    }
    const Point p_new = ToPoint(m.position);
    const Point p_old = rec.vertex->point();
    const bool rays_mode = opt.visibility_mode == VisibilityMode::kRays;
    auto cast_new_observations = [&]() {
      AddCameras(rec, m.camera_ids, &added_cams);
      if (rays_mode) {
        std::vector<RayEntry> u;
        for (uint32_t c : added_cams) u.push_back({c, pt, 0});
        TimedRecast(std::move(u), -1);
      } else {
        for (uint32_t c : added_cams) TimedCast(c, pt, +1);
      }
    };
    if (p_new == p_old) {
      cast_new_observations();
      return;
    }
    // D: the cells incident to the old vertex and the conflict zone of the new position.
    std::vector<Cell_handle> d;
    dt.incident_cells(rec.vertex, std::back_inserter(d));
    Dt::Locate_type lt;
    int li, lj;
    Cell_handle loc = dt.locate(p_new, lt, li, lj, rec.vertex->cell());
    if (lt == Dt::VERTEX) {
      ++stats.points_duplicate;
      ++stats.moves_skipped;
      cast_new_observations();
      return;
    }
    dt.find_conflicts(p_new, loc, CGAL::Emptyset_iterator(), std::back_inserter(d));
    std::sort(d.begin(), d.end());
    d.erase(std::unique(d.begin(), d.end()), d.end());
    if (!Shrink(d, {p_old, p_new})) {
      ++stats.moves_skipped;
      cast_new_observations();
      return;
    }
    std::vector<RayEntry> u;
    if (!rays_mode)
      for (uint32_t c : Window(rec)) TimedCast(c, pt, -1);
    RemoveVertex(rec.vertex, rays_mode ? &u : nullptr);
    rec.in_triangulation = false;
    bool dup = false;
    std::vector<RayEntry> u2;
    if (opt.transfer_camera_side) {
      side_apex = &p_new;
      side_cams = &rec.cameras;
    }
    Vertex_handle v = InsertPoint(p_new, pt, true, &dup, rays_mode ? &u2 : nullptr);
    side_apex = nullptr;
    side_cams = nullptr;
    u.insert(u.end(), u2.begin(), u2.end());
    if (v == Vertex_handle()) {
      // Cannot happen when D was shrunk out of O (the new conflict zone lies in D's cells or in
      // cells created by the removal); counted as a drop if it ever does.
      ++stats.points_dropped;
      rec.vertex = Vertex_handle();
      if (rays_mode) {
        const auto t0 = Clock::now();
        ScanRemoveRays(pt);
        stats.time.scan += Seconds(t0, Clock::now());
        TimedRecast(std::move(u), pt);
      }
      return;
    }
    rec.vertex = v;
    rec.in_triangulation = true;
    ++stats.points_moved;
    AddCameras(rec, m.camera_ids, &added_cams);
    if (rays_mode) {
      const auto t0 = Clock::now();
      ScanRemoveRays(pt);  // Rays ending at p_old, everywhere.
      stats.time.scan += Seconds(t0, Clock::now());
      for (uint32_t c : added_cams) u.push_back({c, pt, 0});  // New observations join U.
      TimedRecast(std::move(u), -1);  // Rays to p now end at p_new.
    } else {
      for (uint32_t c : Window(rec)) TimedCast(c, pt, +1);
    }
  }

  void InsertNewPoint(const NewPoint& np) {
    const uint32_t pt = static_cast<uint32_t>(points.size());
    point_index[np.id] = pt;
    points.push_back({});
    PointRecord& rec0 = points.back();
    rec0.id = np.id;
    rec0.position = np.position;
    AddCameras(rec0, np.camera_ids, nullptr);
    bool dup = false;
    std::vector<RayEntry> u;
    const bool rays_mode = opt.visibility_mode == VisibilityMode::kRays;
    const Point p = ToPoint(np.position);
    if (opt.transfer_camera_side) {
      side_apex = &p;
      side_cams = &points[pt].cameras;
    }
    Vertex_handle v = InsertPoint(p, pt, opt.transfer_on_insert, &dup, rays_mode ? &u : nullptr);
    side_apex = nullptr;
    side_cams = nullptr;
    PointRecord& rec = points[pt];
    if (v == Vertex_handle()) {
      if (dup) ++stats.points_duplicate;
      else ++stats.points_dropped;
      return;
    }
    rec.vertex = v;
    rec.in_triangulation = true;
    ++stats.points_inserted;
    if (rays_mode) {
      for (uint32_t c : rec.cameras) u.push_back({c, pt, 0});
      TimedRecast(std::move(u), -1);
    } else {
      for (uint32_t c : rec.cameras) TimedCast(c, pt, +1);
    }
  }

  // ---------------------------------------------------------------------------------------------
  // grow: a priority queue by weight (highest first). Seeds: the highest-weight free cell when O is
  // empty, else the free cells outside O touching dO among those that changed this keyframe.
  void Grow() {
    struct Item {
      int64_t weight;
      uint64_t order;
      Cell_handle cell;
      bool operator<(const Item& o) const {
        return weight != o.weight ? weight < o.weight : order > o.order;
      }
    };
    std::priority_queue<Item> q;
    uint64_t order = 0;
    auto candidate = [&](Cell_handle c) {
      return !dt.is_infinite(c) && !c->info().in_o && IsFree(c) && !HullAdjacent(c);
    };
    if (cells_in_o == 0) {
      Cell_handle best;
      for (auto c = dt.finite_cells_begin(); c != dt.finite_cells_end(); ++c)
        if (candidate(c) && (best == Cell_handle() || c->info().weight > best->info().weight))
          best = c;
      if (best != Cell_handle()) q.push({best->info().weight, order++, best});
    } else {
      // Deterministic seed order: by weight, then by the ids of the vertices.
      std::vector<std::pair<std::array<int64_t, 4>, Cell_handle>> seeds;
      for (Cell_handle c : dirty)
        if (candidate(c) && TouchesO(c)) seeds.push_back({CellKey(c), c});
      std::sort(seeds.begin(), seeds.end(),
                [](const auto& a, const auto& b) { return a.first < b.first; });
      for (const auto& s : seeds) q.push({s.second->info().weight, order++, s.second});
    }
    dirty.clear();
    while (!q.empty()) {
      Cell_handle c = q.top().cell;
      q.pop();
      if (!candidate(c)) continue;
      if (cells_in_o > 0 && !TouchesO(c)) continue;
      if (!ToggleKeepsManifold(c)) continue;
      SetInO(c, true);
      ++stats.cells_grown;
      for (int i = 0; i < 4; ++i) {
        Cell_handle n = c->neighbor(i);
        if (candidate(n)) q.push({n->info().weight, order++, n});
      }
    }
  }

  std::array<int64_t, 4> CellKey(Cell_handle c) const {
    std::array<int64_t, 4> k;
    for (int i = 0; i < 4; ++i)
      k[i] = dt.is_infinite(c->vertex(i)) ? std::numeric_limits<int64_t>::min()
                                          : c->vertex(i)->info().id;
    std::sort(k.begin(), k.end());
    return k;
  }

  // ---------------------------------------------------------------------------------------------
  Status ApplyUpdate(const KeyframeUpdate& u) {
    if (!init.ok()) return init;
    Status s = Validate(u);
    if (!s.ok()) return s;
    const auto t0 = Clock::now();
    for (const Camera& c : u.cameras) {
      if (camera_index.count(c.id)) continue;
      camera_index[c.id] = static_cast<uint32_t>(cameras.size());
      cameras.push_back(ToPoint(c.center));
      camera_ids.push_back(c.id);
      const auto ts = Clock::now();
      GrowSteinerGrid(cameras.back());
      stats.time.steiner += Seconds(ts, Clock::now());
    }
    // Removals and insertions are charged to "insert", moves to "move"; both without their ray
    // casting and shrinking, which have their own timers.
    auto timed = [&](double* phase, auto&& fn) {
      const double cast0 = stats.time.cast, shrink0 = stats.time.shrink;
      const double scan0 = stats.time.scan;
      const auto a = Clock::now();
      fn();
      *phase += Seconds(a, Clock::now()) - (stats.time.cast - cast0) -
                (stats.time.shrink - shrink0) - (stats.time.scan - scan0);
    };
    timed(&stats.time.insert, [&] {
      for (uint64_t id : u.removed_points) RemovePoint(point_index.at(id));
    });
    timed(&stats.time.move, [&] {
      for (const MovedPoint& m : u.moved_points) MovePoint(point_index.at(m.id), m);
    });
    timed(&stats.time.insert, [&] {
      for (const NewPoint& p : u.new_points) InsertNewPoint(p);
    });
    const auto tg = Clock::now();
    Grow();
    stats.time.grow += Seconds(tg, Clock::now());
    const double dt_s = Seconds(t0, Clock::now());
    stats.time.total += dt_s;
    stats.keyframe_seconds.push_back(dt_s);
    ++stats.updates;
    stats.vertices = static_cast<int64_t>(dt.number_of_vertices());
    stats.cells = static_cast<int64_t>(dt.tds().number_of_cells());
    stats.cells_in_o = cells_in_o;
    if (opt.check_after_update) {
      ManifoldCheckResult r = CheckInvariants();
      if (!r.ok) return Status::Error("invariant broken after update: " + r.message);
    }
    return Status::Ok();
  }

  // ---------------------------------------------------------------------------------------------
  // dO: facets between a cell of O and a cell outside O, oriented toward the O cell (free space).
  struct Triangle {
    Vertex_handle v[3];
  };
  std::vector<Triangle> Boundary() const {
    std::vector<Triangle> out;
    for (auto c = dt.finite_cells_begin(); c != dt.finite_cells_end(); ++c) {
      if (!c->info().in_o) continue;
      for (int i = 0; i < 4; ++i) {
        if (c->neighbor(i)->info().in_o) continue;
        // vertex_triple_index(i, .) orders facet i so that its normal points toward vertex i,
        // i.e. into this cell of O.
        out.push_back({{c->vertex(Dt::vertex_triple_index(i, 0)),
                        c->vertex(Dt::vertex_triple_index(i, 1)),
                        c->vertex(Dt::vertex_triple_index(i, 2))}});
      }
    }
    return out;
  }

  Mesh ToMesh(const std::vector<Triangle>& tris, SteinerExportRule rule) const {
    Mesh m;
    std::unordered_map<Vertex_handle, uint32_t> index;
    for (const Triangle& t : tris) {
      int steiner = 0;
      for (Vertex_handle v : t.v) steiner += v->info().id < 0 ? 1 : 0;
      if (rule == SteinerExportRule::kAllSteiner && steiner == 3) continue;
      if (rule == SteinerExportRule::kAnySteiner && steiner > 0) continue;
      for (Vertex_handle v : t.v) {
        auto [it, inserted] = index.emplace(v, static_cast<uint32_t>(index.size()));
        if (inserted) {
          const Point& p = v->point();
          m.vertices.insert(m.vertices.end(), {p.x(), p.y(), p.z()});
          const int64_t id = v->info().id;
          m.point_ids.push_back(id >= 0 ? static_cast<int64_t>(points[id].id) : -1);
        }
        m.faces.push_back(it->second);
      }
    }
    if (rule != SteinerExportRule::kNone) SplitPinchedVertices(&m);
    CanonicalizeMesh(&m);
    return m;
  }

  // A vertex as a user would find it: the point's id (or the Steiner point's number) and where
  // it is, for the messages of CheckInvariants.
  std::string DescribeVertex(Vertex_handle v) const {
    std::ostringstream s;
    s.precision(6);
    if (dt.is_infinite(v)) return "the infinite vertex";
    const int64_t id = v->info().id;
    if (id >= 0) s << "point " << points[static_cast<size_t>(id)].id;
    else s << "Steiner point " << (-id - 1);
    const Point& p = v->point();
    s << " (" << p.x() << ", " << p.y() << ", " << p.z() << ")";
    return s.str();
  }
  std::string DescribeCell(Cell_handle c) const {
    std::string s = "cell {";
    for (int i = 0; i < 4; ++i) s += (i ? "; " : "") + DescribeVertex(c->vertex(i));
    return s + "}";
  }

  // Weight consistency: every weight within what casting and transfer can make (>= 0 when
  // nonnegative_weights; in kRays mode at least what its stored rays added, with at most K of
  // them), and the cells' sum equal to the ledger kept by every change.
  void CheckWeights(const std::function<void(const std::string&)>& fail) const {
    const bool rays_mode = opt.visibility_mode == VisibilityMode::kRays;
    uint64_t sum = 0;
    for (auto c = dt.all_cells_begin(); c != dt.all_cells_end(); ++c) {
      const CellInfo& info = c->info();
      sum += static_cast<uint64_t>(info.weight);
      if (!rays_mode && opt.nonnegative_weights && info.weight < 0) {
        fail(DescribeCell(c) + " has weight " + std::to_string(FromUnits(info.weight)) +
             " < 0 although nonnegative_weights is on (a weight-transfer policy returned a "
             "negative weight?)");
      }
      if (rays_mode) {
        int64_t stored = 0;
        for (const RayEntry& e : info.rays) stored += unit[e.level];
        if (static_cast<int>(info.rays.size()) > opt.rays_per_cell)
          fail(DescribeCell(c) + " stores " + std::to_string(info.rays.size()) +
               " rays, more than rays_per_cell (" + std::to_string(opt.rays_per_cell) + ")");
        else if (info.weight < stored)
          fail(DescribeCell(c) + " has weight " + std::to_string(FromUnits(info.weight)) +
               ", less than its stored rays added (" + std::to_string(FromUnits(stored)) + ")");
      }
    }
    if (sum != weight_ledger)
      fail("the cells' weights sum to " + std::to_string(FromUnits(static_cast<int64_t>(sum))) +
           " but casting and transfer account for " +
           std::to_string(FromUnits(static_cast<int64_t>(weight_ledger))) +
           ": a weight or a cell changed outside them");
  }

  ManifoldCheckResult CheckInvariants() const {
    ManifoldCheckResult r;
    auto fail = [&](const std::string& s) {
      if (r.ok) r.message = s;
      r.ok = false;
    };
    int64_t in_o = 0;
    for (auto c = dt.all_cells_begin(); c != dt.all_cells_end(); ++c) {
      if (!c->info().in_o) continue;
      if (dt.is_infinite(c)) fail("an infinite " + DescribeCell(c) + " is in O");
      ++in_o;
    }
    r.cells_in_o = in_o;
    if (in_o != cells_in_o)
      fail("O holds " + std::to_string(in_o) + " cells but its counter says " +
           std::to_string(cells_in_o));
    // Each vertex's count of incident cells in O, from a sorted list (no per-vertex nodes).
    std::vector<const void*> o_corners;
    o_corners.reserve(4 * static_cast<size_t>(cells_in_o > 0 ? cells_in_o : 0));
    for (auto c = dt.finite_cells_begin(); c != dt.finite_cells_end(); ++c)
      if (c->info().in_o)
        for (int i = 0; i < 4; ++i) o_corners.push_back(&*c->vertex(i));
    std::sort(o_corners.begin(), o_corners.end());
    for (auto v = dt.finite_vertices_begin(); v != dt.finite_vertices_end(); ++v) {
      const auto range = std::equal_range(o_corners.begin(), o_corners.end(),
                                          static_cast<const void*>(&*v));
      const auto actual = static_cast<int32_t>(range.second - range.first);
      if (v->info().o_cells != actual) {
        fail(DescribeVertex(v) + " counts " + std::to_string(v->info().o_cells) +
             " incident cells in O, but " + std::to_string(actual) + " are");
        break;
      }
    }
    if (manifold_test_mismatches > 0) fail("the two forms of the manifold test disagreed");
    CheckWeights(fail);
    const std::vector<Triangle> tris = Boundary();
    r.boundary_triangles = static_cast<int64_t>(tris.size());
    // Orientation: the O cell's opposite vertex is on the positive side of each triangle.
    for (auto c = dt.finite_cells_begin(); c != dt.finite_cells_end(); ++c) {
      if (!c->info().in_o) continue;
      for (int i = 0; i < 4; ++i) {
        if (c->neighbor(i)->info().in_o) continue;
        const Point& a = c->vertex(Dt::vertex_triple_index(i, 0))->point();
        const Point& b = c->vertex(Dt::vertex_triple_index(i, 1))->point();
        const Point& d = c->vertex(Dt::vertex_triple_index(i, 2))->point();
        if (CGAL::orientation(a, b, d, c->vertex(i)->point()) != CGAL::POSITIVE)
          fail("the boundary triangle of " + DescribeCell(c) + " opposite " +
               DescribeVertex(c->vertex(i)) + " is not oriented toward free space");
      }
    }
    // Every directed edge once, and its reverse once: each edge in exactly two triangles with
    // opposite orientations. Sorted vectors, not maps: the check runs over all of dO (millions of
    // triangles in a long run; imr-soak measured the maps' memory and time).
    std::unordered_map<int64_t, Vertex_handle> handle;  // for the messages
    auto edge_name = [&](int64_t a, int64_t b) {
      return "the edge from " + DescribeVertex(handle.at(a)) + " to " + DescribeVertex(handle.at(b));
    };
    std::vector<std::pair<int64_t, int64_t>> directed;
    std::vector<std::array<int64_t, 3>> corners;  // vertex, then its opposite edge (link edge)
    directed.reserve(3 * tris.size());
    corners.reserve(3 * tris.size());
    for (const Triangle& t : tris) {
      int64_t id[3];
      for (int k = 0; k < 3; ++k) id[k] = t.v[k]->info().id;
      for (int k = 0; k < 3; ++k) {
        directed.push_back({id[k], id[(k + 1) % 3]});
        corners.push_back({id[k], id[(k + 1) % 3], id[(k + 2) % 3]});
      }
    }
    auto remember = [&](int64_t id) {
      for (const Triangle& t : tris)
        for (Vertex_handle v : t.v)
          if (v->info().id == id) {
            handle.emplace(id, v);
            return;
          }
    };
    std::sort(directed.begin(), directed.end());
    for (size_t i = 0; i < directed.size(); ++i) {
      const auto& [a, b] = directed[i];
      if (i + 1 < directed.size() && directed[i + 1] == directed[i]) {
        remember(a);
        remember(b);
        fail(edge_name(a, b) + " is in two boundary triangles with the same orientation");
        break;
      }
      if (!std::binary_search(directed.begin(), directed.end(), std::pair{b, a})) {
        remember(a);
        remember(b);
        fail(edge_name(a, b) +
             " is not shared by exactly two oppositely oriented boundary triangles");
        break;
      }
    }
    std::sort(corners.begin(), corners.end());
    std::vector<std::pair<int64_t, int64_t>> link;
    int64_t link_vertices = 0;
    for (size_t i = 0; i < corners.size();) {
      const int64_t v = corners[i][0];
      link.clear();
      for (; i < corners.size() && corners[i][0] == v; ++i) link.push_back({corners[i][1], corners[i][2]});
      ++link_vertices;
      if (r.ok && !LinkIsOneCycle(link)) {
        remember(v);
        fail(DescribeVertex(handle.at(v)) +
             " on dO is not regular (its boundary triangles are not one fan)");
      }
    }
    r.boundary_vertices = link_vertices;
    if (!dt.is_valid(false)) fail("the Delaunay triangulation is not valid");
    return r;
  }
};

// -------------------------------------------------------------------------------------------------

Engine::Engine(const EngineOptions& options, WeightTransferPolicy* policy)
    : impl_(std::make_unique<Impl>(options, policy)) {}
Engine::~Engine() = default;

const Status& Engine::init_status() const { return impl_->init; }

Status Engine::ApplyUpdate(const KeyframeUpdate& update) {
  try {
    return impl_->ApplyUpdate(update);
  } catch (const std::exception& e) {
    return Status::Error(std::string("engine failure: ") + e.what());
  } catch (...) {
    return Status::Error("engine failure: unknown exception");
  }
}

Mesh Engine::ExtractMesh() const {
  const auto t0 = Clock::now();
  Mesh m = impl_->ToMesh(impl_->Boundary(), impl_->opt.steiner_export);
  impl_->stats.time.extract += Seconds(t0, Clock::now());
  return m;
}

Mesh Engine::ExtractBoundary() const {
  return impl_->ToMesh(impl_->Boundary(), SteinerExportRule::kNone);
}

const EngineStats& Engine::Stats() const { return impl_->stats; }
const EngineOptions& Engine::options() const { return impl_->opt; }
ManifoldCheckResult Engine::CheckInvariants() const { return impl_->CheckInvariants(); }

Status Engine::CastPointRays(uint64_t point_id, const std::vector<uint64_t>& camera_ids,
                             int sign) {
  auto it = impl_->point_index.find(point_id);
  if (it == impl_->point_index.end())
    return Status::Error("unknown point " + std::to_string(point_id));
  if (sign != 1 && sign != -1) return Status::Error("sign must be +1 or -1");
  if (sign < 0 && impl_->opt.visibility_mode == VisibilityMode::kRays)
    return Status::Error("backward casting exists only in weights mode");
  for (uint64_t c : camera_ids) {
    auto ci = impl_->camera_index.find(c);
    if (ci == impl_->camera_index.end())
      return Status::Error("unknown camera " + std::to_string(c));
    impl_->CastRay(ci->second, it->second, sign);
  }
  return Status::Ok();
}

std::vector<std::pair<std::array<int64_t, 4>, int64_t>> Engine::CellWeights() const {
  std::vector<std::pair<std::array<int64_t, 4>, int64_t>> out;
  for (auto c = impl_->dt.finite_cells_begin(); c != impl_->dt.finite_cells_end(); ++c)
    out.push_back({impl_->CellKey(c), c->info().weight});
  std::sort(out.begin(), out.end());
  return out;
}

bool Engine::PointPosition(uint64_t point_id, Vec3* position) const {
  auto it = impl_->point_index.find(point_id);
  if (it == impl_->point_index.end()) return false;
  const auto& rec = impl_->points[it->second];
  if (!rec.in_triangulation) return false;
  const Point& p = rec.vertex->point();
  *position = {p.x(), p.y(), p.z()};
  return true;
}

size_t Engine::NumPoints() const {
  size_t n = 0;
  for (const auto& p : impl_->points) n += p.in_triangulation ? 1 : 0;
  return n;
}

// -------------------------------------------------------------------------------------------------
// Benchmark and diagnostic hooks (engine_internal.h).
namespace internal {

int64_t EngineInternals::TraverseOnly(Engine& e, uint64_t point_id, uint64_t camera_id) {
  Engine::Impl& m = *e.impl_;
  const auto pi = m.point_index.find(point_id);
  const auto ci = m.camera_index.find(camera_id);
  if (pi == m.point_index.end() || ci == m.camera_index.end()) return 0;
  const auto& rec = m.points[pi->second];
  if (!rec.in_triangulation || m.dt.dimension() != 3) return 0;
  int64_t n = 0;
  auto it = m.dt.segment_traverser_cells_begin(rec.vertex->point(), m.cameras[ci->second],
                                               rec.vertex->cell());
  const auto end = m.dt.segment_traverser_cells_end();
  for (; it != end && n < m.opt.max_cells_per_ray; ++it) {
    if (m.dt.is_infinite(Cell_handle(it))) break;
    ++n;
  }
  return n;
}

int64_t EngineInternals::CastRay(Engine& e, uint64_t point_id, uint64_t camera_id, int sign) {
  Engine::Impl& m = *e.impl_;
  const auto pi = m.point_index.find(point_id);
  const auto ci = m.camera_index.find(camera_id);
  if (pi == m.point_index.end() || ci == m.camera_index.end()) return 0;
  const int64_t before = m.stats.cells_weighted;
  m.CastRay(ci->second, pi->second, sign);
  return m.stats.cells_weighted - before;
}

std::vector<uint64_t> EngineInternals::WindowCameras(const Engine& e, uint64_t point_id) {
  const Engine::Impl& m = *e.impl_;
  std::vector<uint64_t> out;
  const auto pi = m.point_index.find(point_id);
  if (pi == m.point_index.end()) return out;
  for (uint32_t c : m.Window(m.points[pi->second])) out.push_back(m.camera_ids[c]);
  return out;
}

void EngineInternals::RecordTransfers(Engine& e, bool on, size_t limit) {
  e.impl_->record_transfers = on;
  e.impl_->record_limit = limit;
  if (on) e.impl_->recorded.clear();
}

const std::vector<RecordedTransfer>& EngineInternals::RecordedTransfers(const Engine& e) {
  return e.impl_->recorded;
}

size_t EngineInternals::CollectBoundaryCells(Engine& e, size_t limit) {
  Engine::Impl& m = *e.impl_;
  m.probe_cells.clear();
  for (auto c = m.dt.finite_cells_begin(); c != m.dt.finite_cells_end(); ++c) {
    if (m.probe_cells.size() >= limit) break;
    bool on_boundary = false;
    for (int i = 0; i < 4; ++i)
      on_boundary = on_boundary || c->neighbor(i)->info().in_o != c->info().in_o;
    if (on_boundary && !m.HullAdjacent(c)) m.probe_cells.push_back(c);
  }
  return m.probe_cells.size();
}

int64_t EngineInternals::TestCollectedCells(Engine& e, bool by_links) {
  Engine::Impl& m = *e.impl_;
  int64_t ok = 0;
  if (by_links)
    for (Cell_handle c : m.probe_cells) ok += m.ToggleKeepsManifoldByLinks(c) ? 1 : 0;
  else
    for (Cell_handle c : m.probe_cells) ok += m.ToggleKeepsManifold(c) ? 1 : 0;
  return ok;
}

void EngineInternals::CrossCheckManifoldTest(Engine& e, bool on) {
  e.impl_->cross_check_manifold_test = on;
}

int64_t EngineInternals::ManifoldTestMismatches(const Engine& e) {
  return e.impl_->manifold_test_mismatches;
}

int64_t EngineInternals::ShrinkAround(Engine& e, const Vec3& centre, double radius) {
  Engine::Impl& m = *e.impl_;
  const Point p = ToPoint(centre);
  std::vector<Cell_handle> d;
  const double r2 = radius * radius;
  for (auto c = m.dt.finite_cells_begin(); c != m.dt.finite_cells_end(); ++c) {
    bool near = false;
    for (int i = 0; i < 4 && !near; ++i)
      near = CGAL::squared_distance(c->vertex(i)->point(), p) <= r2;
    if (near) d.push_back(c);
  }
  const int64_t before = m.stats.cells_shrunk;
  // E = D here (a radius of 0 around the centre adds nothing beyond D's own cells).
  const double saved = m.opt.shrink_radius;
  m.opt.shrink_radius = 0.0;
  m.Shrink(d, {p});
  m.opt.shrink_radius = saved;
  return m.stats.cells_shrunk - before;
}

bool EngineInternals::ForceNonManifoldToggle(Engine& e) {
  Engine::Impl& m = *e.impl_;
  for (Cell_handle c : m.probe_cells) {
    if (m.ToggleKeepsManifoldByLinks(c)) continue;
    m.SetInO(c, !c->info().in_o);
    return true;
  }
  return false;
}
void EngineInternals::OverwriteCollectedWeight(Engine& e, size_t index, double weight) {
  Engine::Impl& m = *e.impl_;
  m.probe_cells.at(index)->info().weight = m.ToUnits(weight);
}
int64_t EngineInternals::Grow(Engine& e) {
  Engine::Impl& m = *e.impl_;
  const int64_t before = m.stats.cells_grown;
  m.Grow();
  return m.stats.cells_grown - before;
}

std::vector<BoundaryFacetProbe> EngineInternals::ProbeBoundary(const Engine& e) {
  const Engine::Impl& m = *e.impl_;
  std::vector<BoundaryFacetProbe> out;
  for (auto c = m.dt.finite_cells_begin(); c != m.dt.finite_cells_end(); ++c) {
    if (!c->info().in_o) continue;
    for (int i = 0; i < 4; ++i) {
      const Cell_handle n = c->neighbor(i);
      if (n->info().in_o) continue;
      BoundaryFacetProbe f;
      for (int k = 0; k < 3; ++k) {
        const Vertex_handle v = c->vertex(Dt::vertex_triple_index(i, k));
        const int64_t id = v->info().id;
        f.point_ids[k] = id >= 0 ? static_cast<int64_t>(m.points[id].id) : -1;
        f.vertices[k] = {v->point().x(), v->point().y(), v->point().z()};
      }
      f.weight_in_o = m.FromUnits(c->info().weight);
      f.weight_outside = m.FromUnits(n->info().weight);
      f.outside_free = m.IsFree(n);
      f.outside_hull_adjacent = m.dt.is_infinite(n) || m.HullAdjacent(n);
      out.push_back(f);
    }
  }
  return out;
}

}  // namespace internal

ManifoldCheckResult CheckMesh(const Mesh& mesh, bool closed) {
  ManifoldCheckResult r;
  auto fail = [&](const std::string& s) {
    if (r.ok) r.message = s;
    r.ok = false;
  };
  const size_t nv = mesh.vertices.size() / 3;
  std::map<std::pair<uint32_t, uint32_t>, int> directed;
  std::vector<std::vector<std::pair<uint32_t, uint32_t>>> links(nv);
  for (size_t t = 0; t + 2 < mesh.faces.size(); t += 3) {
    const uint32_t f[3] = {mesh.faces[t], mesh.faces[t + 1], mesh.faces[t + 2]};
    for (int k = 0; k < 3; ++k)
      if (f[k] >= nv) {
        fail("a face index is out of range");
        return r;
      }
    if (f[0] == f[1] || f[1] == f[2] || f[0] == f[2]) fail("a degenerate face");
    for (int k = 0; k < 3; ++k) {
      if (++directed[{f[k], f[(k + 1) % 3]}] > 1) fail("a directed edge repeats");
      links[f[k]].push_back({f[(k + 1) % 3], f[(k + 2) % 3]});
    }
  }
  r.boundary_triangles = static_cast<int64_t>(mesh.faces.size() / 3);
  for (const auto& [e, n] : directed) {
    (void)n;
    if (!directed.count({e.second, e.first}) && closed) {
      fail("an edge is in only one triangle of a mesh required closed");
      break;
    }
  }
  // Each vertex: its link edges (a -> b, consistently oriented) form one cycle or one path.
  for (size_t v = 0; v < nv; ++v) {
    const auto& l = links[v];
    if (l.empty()) continue;
    ++r.boundary_vertices;
    std::unordered_map<uint32_t, uint32_t> next;
    std::unordered_set<uint32_t> has_prev;
    bool bad = false;
    for (const auto& e : l) {
      if (!next.emplace(e.first, e.second).second || !has_prev.insert(e.second).second) bad = true;
    }
    uint32_t start = l[0].first;
    int starts = 0;
    for (const auto& e : l)
      if (!has_prev.count(e.first)) {
        start = e.first;
        ++starts;
      }
    if (!bad && starts <= 1 && !(closed && starts == 1)) {
      size_t steps = 0;
      uint32_t cur = start;
      while (next.count(cur) && steps <= l.size()) {
        cur = next[cur];
        ++steps;
        if (cur == start) break;
      }
      bad = steps != l.size();
    } else {
      bad = true;
    }
    if (bad) {
      fail("vertex " + std::to_string(v) + " is not one fan");
      break;
    }
  }
  return r;
}

}  // namespace imr::engine
