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
#include "host/engine/mesh_topology.h"
#include "host/util/thread_pool.h"

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
#include <queue>
#include <sstream>
#include <unordered_map>
#include <unordered_set>

namespace imr::engine {
namespace {

using K = CGAL::Exact_predicates_inexact_constructions_kernel;

// One ray stored in a cell. kRays: camera index, point, and the ring (level: 0 = T, 1 = N1,
// 2 = N2). kExact: the ray's index among its point's cameras (camera), the point, and the ray's
// generation when it was added (level): an entry whose generation is not the ray's current one
// is stale (the ray was un-cast since) and is dropped when met.
struct RayEntry {
  uint32_t camera;
  uint32_t point;
  uint32_t level;
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
  bool fresh = false;     // kExact: made by the triangulation change being processed.
  uint32_t slot = 0;      // kExact: index of the cell among those being made (scratch).
  uint32_t region = 0;    // Member of the region being peeled (Shrink's E, PeelAround's)
                          // when equal to Impl::region_mark; apart from `stamp`, which the
                          // manifold test uses while the region is peeled.
  std::vector<RayEntry> rays;  // kRays: at most K rays that raised this cell's weight; kExact:
                               // every ray that crosses it (and stale entries, see RayEntry).
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

}  // namespace

struct Engine::Impl {
  struct PointRecord {
    uint64_t id = 0;
    Vertex_handle vertex;        // Valid when in_triangulation.
    bool in_triangulation = false;
    bool removed = false;        // Removed by an update (never enters again); a point refused
                                 // at insertion (duplicate, dropped) tries again when it moves.
    Vec3 position{};             // Latest estimate received.
    std::vector<uint32_t> cameras;  // Observing cameras (internal indices), oldest first.
    // kExact, parallel to cameras: whether the ray is cast, and where it ended when it was (the
    // point's position then; a ray older than the window keeps its end when the point moves).
    std::vector<uint8_t> ray_cast;
    std::vector<uint32_t> ray_gen;  // generation: +1 at each un-cast (entries made before: stale)
    std::vector<Point> ray_end;
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
  uint32_t region_mark = 0;
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
    if (opt.visibility_mode == VisibilityMode::kExact) {
      // A cell's weight is w1 times the rays that cross it.
      if (unit[0] <= 0) init = Status::Error("invalid engine options: exact mode needs w1 > 0");
      threshold = unit[0] * opt.exact_min_rays - 1;
    }
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
    if (opt.visibility_mode == VisibilityMode::kExact) {
      const size_t k = RayIndex(rec, cam);
      if (k == static_cast<size_t>(-1)) return;
      if (sign > 0) ExactCast(pt, k);
      else ExactUncast(pt, k);
      return;
    }
    if (!rec.in_triangulation) return;
    if (dt.dimension() != 3) return;
    const Point& b = cameras[cam];
    Point a;
    if (!RaySegment(rec.vertex->point(), b, &a)) return;
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
      auto it = BeginWalk(a, b, rec.vertex->cell(), rec.vertex);
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

  // ---------------------------------------------------------------------------------------------
  // kExact: every cell holds the rays (camera, point) whose segment crosses it, so a cell's weight
  // is exactly w1 times their number. Casting adds a ray to the cells its segment crosses,
  // un-casting removes it from the same cells (the ray keeps the end it was cast with, so both
  // walk the same segment). When the triangulation replaces cells (an insertion's conflict zone,
  // a removed vertex's star), the new cells fill exactly the volume of the old ones: the rays
  // held by the old cells are walked again through that volume only, and nothing else changes.

  // CGAL's traversal of a -> b: from the vertex `from` when a is its point (a ray of a point
  // starts at its vertex: no point location, 9 % of the run on the street stream), else located from
  // `hint` (a cell near a). Every walk of a ray starts the same way, so all agree on the cells
  // of a ray that leaves its vertex along a facet or an edge.
  Dt::Segment_cell_iterator BeginWalk(const Point& a, const Point& b, Cell_handle hint,
                                      Vertex_handle from) const {
    if (from != Vertex_handle() && from->point() == a) return Dt::Segment_cell_iterator(&dt, from, b);
    return dt.segment_traverser_cells_begin(a, b, hint);
  }
  static Vertex_handle StartVertex(const PointRecord& rec) {
    return rec.in_triangulation ? rec.vertex : Vertex_handle();
  }

  // Walks the segment a -> b through the cells it crosses (BeginWalk), calling visit(cell) once
  // per finite cell. Stops at the hull or after max_cells_per_ray cells.
  template <class Visit>
  void Walk(const Point& a, const Point& b, Cell_handle hint, Vertex_handle from, Visit&& visit) {
    ++stamp;
    int steps = 0;
    try {
      auto it = BeginWalk(a, b, hint, from);
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
        visit(c);
      }
    } catch (...) {
      ++stats.rays_truncated;
    }
  }

  // Index of camera `cam` in a point's list, or npos.
  static size_t RayIndex(const PointRecord& rec, uint32_t cam) {
    for (size_t k = 0; k < rec.cameras.size(); ++k)
      if (rec.cameras[k] == cam) return k;
    return static_cast<size_t>(-1);
  }

  // A cell near where a walk of point pt's ray starts: the point's vertex when the ray ends
  // there, else any cell near it (the traverser locates the start from it).
  Cell_handle WalkHint(const PointRecord& rec) const {
    if (rec.in_triangulation) return rec.vertex->cell();
    return last_vertex != Vertex_handle() ? last_vertex->cell() : Cell_handle();
  }

  // kExact: is a cell's entry the current cast of its ray?
  bool Live(const RayEntry& e) const {
    const PointRecord& rec = points[e.point];
    return e.camera < rec.ray_cast.size() && rec.ray_cast[e.camera] &&
           rec.ray_gen[e.camera] == e.level;
  }

  // Adds ray k of point pt (its current generation) to a cell. A cell's list keeps stale entries
  // until it is destroyed or holds twice as many entries as rays: then it is compacted.
  void AddRay(Cell_handle c, uint32_t pt, uint32_t k) {
    const int64_t before = c->info().weight;
    if (PushRay(&c->info(), {k, pt, points[pt].ray_gen[k]})) MarkDirty(c);
    Ledger(before, c->info().weight);
  }
  // The entry and its weight; true when the cell just became free. Reads only the points' ray
  // states besides the cell: safe on several threads for distinct cells.
  bool PushRay(CellInfo* info, const RayEntry& e) const {
    const int64_t before = info->weight;
    const int64_t live = unit[0] > 0 ? before / unit[0] : 0;
    if (static_cast<int64_t>(info->rays.size()) >= 2 * live + 8) {
      info->rays.erase(std::remove_if(info->rays.begin(), info->rays.end(),
                                      [&](const RayEntry& x) { return !Live(x); }),
                       info->rays.end());
    }
    info->rays.push_back(e);
    info->weight += unit[0];
    return before <= threshold && info->weight > threshold;
  }

  // The segment a ray carves: from its point to its camera, or, for a ray longer than
  // max_ray_length with long_rays = near_camera, the max_ray_length next to the camera (the
  // space near the camera is free whatever the far end is). False: the ray carves nothing.
  bool RaySegment(const Point& p, const Point& cam, Point* start) {
    const double len2 = CGAL::squared_distance(p, cam);
    if (len2 <= 0.0) return false;  // A point at the camera centre carves nothing.
    if (len2 <= opt.max_ray_length * opt.max_ray_length) {
      *start = p;
      return true;
    }
    ++stats.rays_skipped_too_long;
    if (opt.long_rays == LongRays::kSkip) return false;
    ++stats.rays_truncated_to_camera;
    const double f = opt.max_ray_length / std::sqrt(len2);
    *start = Point(cam.x() + f * (p.x() - cam.x()), cam.y() + f * (p.y() - cam.y()),
                   cam.z() + f * (p.z() - cam.z()));
    return true;
  }

  // Ray k of point pt, cast from the point's current position.
  void ExactCast(uint32_t pt, size_t k) {
    PointRecord& rec = points[pt];
    if (!rec.in_triangulation || rec.ray_cast[k] || dt.dimension() != 3) return;
    const uint32_t cam = rec.cameras[k];
    const Point& b = cameras[cam];
    Point a;
    if (!RaySegment(rec.vertex->point(), b, &a)) return;
    ++stats.rays_cast;
    int64_t n = 0;
    rec.ray_cast[k] = 1;
    rec.ray_end[k] = a;
    Walk(a, b, rec.vertex->cell(), rec.vertex, [&](Cell_handle c) {
      AddRay(c, pt, static_cast<uint32_t>(k));
      ++n;
    });
    stats.cells_traversed += n;
    stats.cells_weighted += n;
  }

  // Takes ray k of point pt out of the cells it was cast into: the same segment walked again
  // takes one off each cell's count; its entries there become stale (a new generation).
  // A short list is searched first (a cell reached only by a walk that disagrees with the one
  // that gave it the ray, through an edge or a vertex, keeps its count); a long one, deep in free
  // space, is not: that would cost more than all the rest.
  void ExactUncast(uint32_t pt, size_t k) {
    PointRecord& rec = points[pt];
    if (!rec.ray_cast[k]) return;
    const RayEntry mine{static_cast<uint32_t>(k), pt, rec.ray_gen[k]};
    rec.ray_cast[k] = 0;
    ++rec.ray_gen[k];
    ++stats.rays_cast_backward;
    const uint32_t cam = rec.cameras[k];
    Walk(rec.ray_end[k], cameras[cam], WalkHint(rec), StartVertex(rec), [&](Cell_handle c) {
      const int64_t before = c->info().weight;
      if (!Holds(c->info(), mine)) {
        ++stats.ray_mismatches;
        return;
      }
      c->info().weight -= unit[0];
      Ledger(before, c->info().weight);
    });
  }
  // Whether an un-cast may take the ray `mine` off the cell (see ExactUncast).
  bool Holds(const CellInfo& info, const RayEntry& mine) const {
    if (info.weight < unit[0]) return false;
    if (info.rays.size() > kSearchUncastBelow) return true;
    for (const RayEntry& e : info.rays)
      if (e.point == mine.point && e.camera == mine.camera && e.level == mine.level) return true;
    return false;
  }
  static constexpr size_t kSearchUncastBelow = 32;

  // ---------------------------------------------------------------------------------------------
  // kExact batches: the rays a keyframe casts (or un-casts) together, walked on several threads.
  // The walks only read the triangulation; what they found is then applied cell by cell, each
  // cell by one thread and its rays in batch order, so weights, ray lists and all that follows
  // are the same for any number of threads.
  struct BatchRay {
    uint32_t point;
    uint32_t k;    // the ray's index among its point's cameras
    uint32_t gen;  // cast: its new generation; un-cast: the generation taken out
    Point a, b;    // the segment walked (end -> camera)
    Cell_handle hint;
    Vertex_handle from;  // see BeginWalk
    uint32_t worker = 0, offset = 0, count = 0;  // its cells in walk_cells[worker]
    bool truncated = false;
  };
  struct BatchPart {  // what one apply task changed besides the cells
    uint64_t ledger = 0;
    int64_t cells = 0, mismatches = 0;
    std::vector<Cell_handle> became_free;
  };
  std::unique_ptr<util::ThreadPool> pool;
  std::vector<std::vector<Cell_handle>> walk_cells;  // per worker

  util::ThreadPool& Pool() {
    if (!pool) pool = std::make_unique<util::ThreadPool>(util::ResolveThreads(opt.num_threads));
    return *pool;
  }

  // Which apply task owns a cell: a hash of its address (fixed while the cell lives).
  static size_t Owner(Cell_handle c, size_t parts) {
    const uint64_t h = (reinterpret_cast<uintptr_t>(&*c) >> 4) * 0x9E3779B97F4A7C15ull;
    return static_cast<size_t>((h >> 32) % parts);
  }

  // The finite cells the segment a -> b crosses, in order, as Walk visits them but without its
  // stamps (a cell may repeat; the apply step skips repeats). Thread-safe: reads only.
  bool Trace(const BatchRay& r, std::vector<Cell_handle>* out) const {
    int steps = 0;
    try {
      auto it = BeginWalk(r.a, r.b, r.hint, r.from);
      const auto end = dt.segment_traverser_cells_end();
      for (; it != end; ++it) {
        Cell_handle c = it;
        if (dt.is_infinite(c)) break;
        if (++steps > opt.max_cells_per_ray) return false;
        out->push_back(c);
      }
    } catch (...) {
      return false;
    }
    return true;
  }

  // Walks every ray of the batch (in parallel), then calls apply(ray, cell, part) for each cell
  // each ray crosses, once per ray and cell, in batch order per cell; returns the parts.
  template <class Apply>
  std::vector<BatchPart> RunBatch(std::vector<BatchRay>& rays, Apply&& apply) {
    util::ThreadPool& tp = Pool();
    const size_t workers = static_cast<size_t>(tp.size());
    walk_cells.resize(workers);
    for (auto& w : walk_cells) w.clear();
    constexpr size_t kChunk = 32;
    const size_t chunks = (rays.size() + kChunk - 1) / kChunk;
    tp.Run(chunks, [&](size_t chunk, int worker) {
      std::vector<Cell_handle>& out = walk_cells[static_cast<size_t>(worker)];
      for (size_t i = chunk * kChunk; i < std::min(rays.size(), (chunk + 1) * kChunk); ++i) {
        BatchRay& r = rays[i];
        r.worker = static_cast<uint32_t>(worker);
        r.offset = static_cast<uint32_t>(out.size());
        r.truncated = !Trace(r, &out);
        r.count = static_cast<uint32_t>(out.size() - r.offset);
      }
    });
    const size_t parts = rays.size() < 64 ? 1 : workers;
    std::vector<BatchPart> part(parts);
    const uint64_t base = stamp + 1;
    stamp += rays.size();
    tp.Run(parts, [&](size_t t, int) {
      BatchPart& p = part[t];
      for (size_t i = 0; i < rays.size(); ++i) {
        const BatchRay& r = rays[i];
        const Cell_handle* cells = walk_cells[r.worker].data() + r.offset;
        const uint64_t s = base + i;
        for (uint32_t j = 0; j < r.count; ++j) {
          const Cell_handle c = cells[j];
          if ((parts > 1 && Owner(c, parts) != t) || c->info().stamp == s) continue;
          c->info().stamp = s;
          apply(r, c, p);
        }
      }
    });
    for (const BatchRay& r : rays) stats.rays_truncated += r.truncated ? 1 : 0;
    return part;
  }

  void MergeParts(const std::vector<BatchPart>& parts) {
    for (const BatchPart& p : parts) {
      weight_ledger += p.ledger;
      stats.ray_mismatches += p.mismatches;
      for (Cell_handle c : p.became_free) MarkDirty(c);
    }
  }

  // Casts the rays (point, k) that are not cast yet, from their points' current positions.
  void CastBatch(const std::vector<std::pair<uint32_t, uint32_t>>& todo) {
    if (dt.dimension() != 3) return;
    std::vector<BatchRay> rays;
    for (const auto& [pt, k] : todo) {
      PointRecord& rec = points[pt];
      if (!rec.in_triangulation || rec.ray_cast[k]) continue;
      const Point& b = cameras[rec.cameras[k]];
      Point a;
      if (!RaySegment(rec.vertex->point(), b, &a)) continue;
      ++stats.rays_cast;
      rec.ray_cast[k] = 1;
      rec.ray_end[k] = a;
      rays.push_back({pt, k, rec.ray_gen[k], a, b, rec.vertex->cell(), rec.vertex});
    }
    const std::vector<BatchPart> parts =
        RunBatch(rays, [&](const BatchRay& r, Cell_handle c, BatchPart& p) {
          if (PushRay(&c->info(), {r.k, r.point, r.gen})) p.became_free.push_back(c);
          p.ledger += static_cast<uint64_t>(unit[0]);
          ++p.cells;
        });
    MergeParts(parts);
    for (const BatchPart& p : parts) stats.cells_traversed += p.cells, stats.cells_weighted += p.cells;
  }

  // Takes the rays (point, k) that are cast out of their cells (as ExactUncast does, together).
  void UncastBatch(const std::vector<std::pair<uint32_t, uint32_t>>& todo) {
    std::vector<BatchRay> rays;
    for (const auto& [pt, k] : todo) {
      PointRecord& rec = points[pt];
      if (!rec.ray_cast[k]) continue;
      rays.push_back({pt, k, rec.ray_gen[k], rec.ray_end[k], cameras[rec.cameras[k]],
                      WalkHint(rec), StartVertex(rec)});
      rec.ray_cast[k] = 0;
      ++rec.ray_gen[k];
      ++stats.rays_cast_backward;
    }
    MergeParts(RunBatch(rays, [&](const BatchRay& r, Cell_handle c, BatchPart& p) {
      CellInfo& info = c->info();
      if (!Holds(info, {r.k, r.point, r.gen})) {
        ++p.mismatches;
        return;
      }
      info.weight -= unit[0];
      p.ledger -= static_cast<uint64_t>(unit[0]);
    }));
  }

  // A tetrahedron's four face planes, oriented so that inside is n . x >= off on each.
  struct TetPlanes {
    double n[4][3];
    double off[4];
  };
  static TetPlanes PlanesOf(Cell_handle c) {
    TetPlanes t;
    for (int i = 0; i < 4; ++i) {
      const Point& p0 = c->vertex((i + 1) & 3)->point();
      const Point& p1 = c->vertex((i + 2) & 3)->point();
      const Point& p2 = c->vertex((i + 3) & 3)->point();
      const Point& q = c->vertex(i)->point();
      const double u[3] = {p1.x() - p0.x(), p1.y() - p0.y(), p1.z() - p0.z()};
      const double v[3] = {p2.x() - p0.x(), p2.y() - p0.y(), p2.z() - p0.z()};
      double* n = t.n[i];
      n[0] = u[1] * v[2] - u[2] * v[1];
      n[1] = u[2] * v[0] - u[0] * v[2];
      n[2] = u[0] * v[1] - u[1] * v[0];
      const double nn = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
      double off = n[0] * p0.x() + n[1] * p0.y() + n[2] * p0.z();
      const double side = n[0] * q.x() + n[1] * q.y() + n[2] * q.z() - off;
      const double sign = (side < 0.0 ? -1.0 : 1.0) / (nn > 0.0 ? nn : 1.0);
      for (int k = 0; k < 3; ++k) n[k] *= sign;
      t.off[i] = off * sign;
    }
    return t;
  }

  // The part t in [lo, hi] of segment a + t d (t in [0, 1]) inside a tetrahedron, the faces that
  // bound it (-1: the segment's own end), and whether another face bounds it within rounding
  // (the segment passes through an edge or a vertex there: the caller walks with exact
  // predicates instead).
  struct Clip {
    double lo = 0.0, hi = 1.0;
    int lo_face = -1, hi_face = -1;
    bool lo_tie = false, hi_tie = false;
    bool grazing = false;  // the segment runs within rounding of a face's plane
  };
  static bool ClipSegment(const TetPlanes& t, const double a[3], const double d[3], Clip* out) {
    Clip c;
    const double len = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    const double eps = 1e-9;  // in t: well below any cell a ray crosses
    for (int i = 0; i < 4; ++i) {
      const double f0 = t.n[i][0] * a[0] + t.n[i][1] * a[1] + t.n[i][2] * a[2] - t.off[i];
      const double fd = t.n[i][0] * d[0] + t.n[i][1] * d[1] + t.n[i][2] * d[2];
      if (std::abs(fd) <= 1e-12 * len) {
        if (f0 < -1e-9 * len) return false;
        if (f0 <= 1e-9 * len) c.grazing = true;
        continue;
      }
      const double ti = -f0 / fd;
      if (fd > 0.0) {  // entering through face i
        if (ti > c.lo + eps) c.lo = ti, c.lo_face = i, c.lo_tie = false;
        else if (ti > c.lo - eps && c.lo_face >= 0) c.lo_tie = true;
      } else {  // leaving through face i
        if (ti < c.hi - eps) c.hi = ti, c.hi_face = i, c.hi_tie = false;
        else if (ti < c.hi + eps && c.hi_face >= 0) c.hi_tie = true;
      }
    }
    *out = c;
    return c.lo <= c.hi + eps;
  }

  // The rays held by cells about to be destroyed, each with the part of its segment (parameter
  // t in [0, 1] from its end to its camera) that lies in those cells, and the facet through
  // which it enters them (the cell before it, which survives, and the facet's index there).
  struct HoleRay {
    uint32_t camera;
    uint32_t point;
    double t0, t1;
    Cell_handle before;  // null: the part starts inside (at the ray's end) or is ambiguous
    int facet;
    Cell_handle first;   // the destroyed cell where the part starts (scratch)
    int entry_face;
    uint32_t next;       // next ray of the same point in the list (scratch)
  };
  struct Hole {
    std::vector<HoleRay> rays;
  };
  std::vector<uint64_t> point_hole_mark;  // per point: the hole that lists its rays
  std::vector<uint32_t> point_hole_head;  // per point: its first ray in that hole's list
  uint64_t hole_count = 0;
  std::vector<TetPlanes> fresh_planes;    // planes of the cells being made, by their slot

  // kExact, before cells are destroyed: the rays they hold and where.
  void CollectHoleRays(const std::vector<Cell_handle>& cells, Hole* hole) {
    std::vector<HoleRay>& out = hole->rays;
    out.clear();
    ++hole_count;
    if (point_hole_mark.size() < points.size()) {
      point_hole_mark.resize(points.size(), 0);
      point_hole_head.resize(points.size(), 0);
    }
    for (Cell_handle c : cells) c->info().fresh = true;  // "destroyed" while collecting
    for (Cell_handle c : cells) {
      if (dt.is_infinite(c) || c->info().rays.empty()) continue;
      const TetPlanes planes = PlanesOf(c);
      for (const RayEntry& e : c->info().rays) {
        if (!Live(e)) continue;  // a stale entry: dropped with the cell
        const PointRecord& rec = points[e.point];
        const size_t k = e.camera;
        const Point& end = rec.ray_end[k];
        const Point& cam = cameras[rec.cameras[k]];
        const double a[3] = {end.x(), end.y(), end.z()};
        const double d[3] = {cam.x() - a[0], cam.y() - a[1], cam.z() - a[2]};
        Clip cl;
        HoleRay r{e.camera, e.point, 0.0, 1.0, Cell_handle(), -1, Cell_handle(), -1, 0};
        if (ClipSegment(planes, a, d, &cl)) {
          r.t0 = cl.lo;
          r.t1 = cl.hi;
          if (cl.lo_face >= 0 && !cl.lo_tie) r.first = c, r.entry_face = cl.lo_face;
        }
        // Merge with the ray's other parts: the hull of the parts, entered at the first one.
        uint32_t* link = nullptr;
        bool merged = false;
        if (point_hole_mark[e.point] == hole_count) {
          for (uint32_t i = point_hole_head[e.point];; i = out[i].next) {
            HoleRay& x = out[i];
            if (x.camera == e.camera) {
              if (r.t0 < x.t0) x.t0 = r.t0, x.first = r.first, x.entry_face = r.entry_face;
              x.t1 = std::max(x.t1, r.t1);
              merged = true;
              break;
            }
            if (x.next == 0xFFFFFFFFu) {
              link = &x.next;
              break;
            }
          }
        } else {
          point_hole_mark[e.point] = hole_count;
          point_hole_head[e.point] = static_cast<uint32_t>(out.size());
        }
        if (merged) continue;
        r.next = 0xFFFFFFFFu;
        if (link) *link = static_cast<uint32_t>(out.size());
        out.push_back(r);
      }
    }
    for (HoleRay& r : out) {
      if (r.first == Cell_handle() || r.t0 <= 0.0) continue;
      const Cell_handle b = r.first->neighbor(r.entry_face);
      if (dt.is_infinite(b) || b->info().fresh) continue;  // entered at an edge: ambiguous
      r.before = b;
      r.facet = b->index(r.first);
    }
    for (Cell_handle c : cells) c->info().fresh = false;
  }

  // kExact, after the new cells exist: each ray of the hole walked again over its part inside
  // the hole (a little beyond, for rounding), adding it to the new cells it crosses. The walk
  // starts at the surviving facet where the ray entered the hole (or at its end's vertex) and
  // steps from face to face; where it passes within rounding of an edge or a vertex, it walks
  // with CGAL's exact traversal instead.
  void RefillHole(const std::vector<Cell_handle>& added, const Hole& h) {
    const std::vector<HoleRay>& hole = h.rays;
    if (hole.empty()) return;
    Cell_handle hint;
    fresh_planes.clear();
    for (Cell_handle c : added) {
      if (dt.is_infinite(c)) continue;
      c->info().fresh = true;
      c->info().slot = static_cast<uint32_t>(fresh_planes.size());
      fresh_planes.push_back(PlanesOf(c));
      if (hint == Cell_handle()) hint = c;
    }
    constexpr double kPad = 1e-6;
    // A face-to-face walk meets each new cell once per ray; when it gives up part way, the exact
    // walk skips the cells it already gave the ray.
    std::vector<Cell_handle>& given = incident_scratch;
    auto add = [&](Cell_handle c, const HoleRay& r, bool check) {
      if (!c->info().fresh) return;
      if (check && std::find(given.begin(), given.end(), c) != given.end()) return;
      if (!check) given.push_back(c);
      AddRay(c, r.point, r.camera);
      ++stats.cells_rewalked;
    };
    for (const HoleRay& r : hole) {
      const PointRecord& rec = points[r.point];
      const size_t k = r.camera;  // the ray's index among its point's cameras
      const Point& e = rec.ray_end[k];
      const Point& cam = cameras[rec.cameras[k]];
      given.clear();
      const double a[3] = {e.x(), e.y(), e.z()};
      const double d[3] = {cam.x() - a[0], cam.y() - a[1], cam.z() - a[2]};
      const double t_end = std::min(1.0, r.t1 + kPad);
      ++stats.rays_rewalked;
      // The start: the cell behind the entry facet, or the new cell at the ray's end vertex.
      Cell_handle c;
      double t = r.t0;
      if (r.before != Cell_handle()) {
        c = r.before->neighbor(r.facet);
      } else if (r.t0 <= 0.0 && rec.in_triangulation && rec.vertex->point() == e) {
        // The new cell at the ray's end vertex that the ray leaves into; none or two (it leaves
        // along a facet or an edge): the exact walk decides.
        int found = 0;
        for (Cell_handle x : added) {
          if (dt.is_infinite(x) || !x->has_vertex(rec.vertex)) continue;
          Clip cl;
          if (ClipSegment(fresh_planes[x->info().slot], a, d, &cl) && cl.lo <= 1e-9 &&
              cl.hi > 1e-9) {
            c = x;
            if (++found > 1 || cl.hi_tie || cl.grazing) break;
          }
        }
        if (found != 1) c = Cell_handle();
        t = 0.0;
      }
      bool exact = c == Cell_handle();
      for (int steps = 0; !exact; ++steps) {
        if (steps > opt.max_cells_per_ray) {
          exact = true;
          break;
        }
        Clip cl;
        const bool ok = c->info().fresh
                            ? ClipSegment(fresh_planes[c->info().slot], a, d, &cl)
                            : ClipSegment(PlanesOf(c), a, d, &cl);
        if (!ok || cl.hi_tie || cl.grazing || cl.hi_face < 0 || cl.hi < t - 1e-9) {
          exact = true;
          break;
        }
        add(c, r, false);
        if (cl.hi >= t_end) break;
        const Cell_handle next = c->neighbor(cl.hi_face);
        if (dt.is_infinite(next)) break;
        t = cl.hi;
        c = next;
      }
      if (exact) {
        // The whole ray with exact predicates, as casting and un-casting walk it (cells already
        // given the ray are skipped): where a part of it runs through an edge or a vertex, a
        // walk of that part alone could choose other cells than the whole walk does.
        ++stats.rays_rewalked_exact;
        Walk(e, cam, rec.in_triangulation ? WalkHint(rec) : hint, StartVertex(rec),
             [&](Cell_handle x) { add(x, r, true); });
      }
    }
    for (Cell_handle c : added) c->info().fresh = false;
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
    // E as a list, its members marked with a stamp (no hash set: this runs at every move).
    const uint32_t in_e = NewRegion();
    std::vector<Cell_handle> e;
    auto add = [&](Cell_handle c) {
      if (c->info().region == in_e) return;
      c->info().region = in_e;
      e.push_back(c);
    };
    std::vector<Vertex_handle> verts;
    for (Cell_handle c : d) {
      add(c);
      for (int i = 0; i < 4; ++i) {
        add(c->neighbor(i));
        if (!dt.is_infinite(c->vertex(i))) verts.push_back(c->vertex(i));
      }
    }
    std::sort(verts.begin(), verts.end());
    verts.erase(std::unique(verts.begin(), verts.end()), verts.end());
    const double r2 = opt.shrink_radius * opt.shrink_radius;
    std::vector<Cell_handle> inc;
    for (Vertex_handle v : verts) {
      bool near = false;
      for (const Point& p : centres) near = near || CGAL::squared_distance(v->point(), p) <= r2;
      if (!near) continue;
      inc.clear();
      dt.incident_cells(v, std::back_inserter(inc));
      for (Cell_handle c : inc) add(c);
    }
    const bool ok = PeelFromO(
        e, [&](Cell_handle n) { return n->info().region == in_e; }, [&] { return !meets_o(); }) ||
                    !meets_o();
    stats.time.shrink += Seconds(t0, Clock::now());
    return ok;
  }

  // A fresh region mark (all cells' marks reset when the counter wraps).
  uint32_t NewRegion() {
    if (++region_mark == 0) {
      for (auto c = dt.all_cells_begin(); c != dt.all_cells_end(); ++c) c->info().region = 0;
      region_mark = 1;
    }
    return region_mark;
  }

  // Peels the cells of `region` from O, lowest weight first (the inverse of grow), keeping dO
  // manifold: a cell refused now is retried when one of its facet neighbours leaves O (those in
  // the region, `in_region`), up to shrink_passes tries per cell. Stops early, returning true,
  // once `done()` holds after a cell left O; false when the queue or the budget ran out.
  template <typename Cells, typename InRegion, typename Done>
  bool PeelFromO(const Cells& region, InRegion in_region, Done done) {
    struct Item {
      int64_t weight;
      uint64_t order;
      Cell_handle cell;
      bool operator<(const Item& o) const {
        return weight != o.weight ? weight > o.weight : order > o.order;
      }
    };
    // Canonical order (CellKey), so equal weights peel the same way whatever the container.
    std::vector<std::pair<std::array<int64_t, 4>, Cell_handle>> start;
    for (Cell_handle c : region)
      if (c->info().in_o) start.push_back({CellKey(c), c});
    std::sort(start.begin(), start.end(),
              [](const auto& a, const auto& b) { return a.first < b.first; });
    std::priority_queue<Item> q;
    uint64_t order = 0;
    for (const auto& s : start) q.push({s.second->info().weight, order++, s.second});
    int64_t budget = static_cast<int64_t>(start.size()) * 4 * opt.shrink_passes + 16;
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
        if (n->info().in_o && in_region(n)) q.push({n->info().weight, order++, n});
      }
      if (done()) return true;
    }
    return false;
  }

  // ---------------------------------------------------------------------------------------------
  // Transfer of weights from removed cells R to new cells A (efficient approach, paper §3.2).
  struct Removed {
    std::vector<double> centroids;
    std::vector<double> weights;
    std::vector<RayEntry> rays;  // kRays: rays stored in R (the set U of Lovi et al.).
    Hole hole;                   // kExact: the rays R's cells hold, and where.
  };

  void CollectRemoved(const std::vector<Cell_handle>& cells, Removed* r) {
    if (opt.visibility_mode == VisibilityMode::kExact) CollectHoleRays(cells, &r->hole);
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
    if (opt.visibility_mode == VisibilityMode::kExact) {
      const auto t0 = Clock::now();
      RefillHole(added, r.hole);
      stats.time.cast += Seconds(t0, Clock::now());
    }
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
      if (opt.visibility_mode == VisibilityMode::kExact) {
        rec.ray_cast.push_back(0);
        rec.ray_gen.push_back(0);
        rec.ray_end.push_back(Point(0, 0, 0));
      }
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
    if (opt.visibility_mode == VisibilityMode::kExact) {
      ExactRemovePoint(pt);
      return;
    }
    if (!rec.in_triangulation) {
      rec.removed = true;
      return;
    }
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
    rec.removed = true;
    rec.vertex = Vertex_handle();
    ++stats.points_removed;
    if (rays_mode) {
      const auto t0 = Clock::now();
      ScanRemoveRays(pt);
      stats.time.scan += Seconds(t0, Clock::now());
      TimedRecast(std::move(u), pt);
    }
  }

  // kExact removal: every ray of the point out of its cells, then the vertex (its star's other
  // rays walked again through the new cells).
  void ExactRemovePoint(uint32_t pt) {
    PointRecord& rec = points[pt];
    if (rec.in_triangulation) {
      std::vector<Cell_handle> inc;
      dt.incident_cells(rec.vertex, std::back_inserter(inc));
      if (!Shrink(inc, {rec.vertex->point()})) {
        ++stats.moves_skipped;  // Cannot be removed without breaking dO; keep it.
        return;
      }
    }
    const auto t0 = Clock::now();
    for (size_t k = 0; k < rec.cameras.size(); ++k) ExactUncast(pt, k);
    stats.time.cast += Seconds(t0, Clock::now());
    rec.removed = true;
    if (rec.in_triangulation) {
      const Vertex_handle v = rec.vertex;
      rec.in_triangulation = false;
      rec.vertex = Vertex_handle();
      RemoveVertex(v, nullptr);
      ++stats.points_removed;
    }
  }

  // Whether moving v to p keeps the triangulation Delaunay with the same cells: its star stays
  // positively oriented and every facet of the star stays locally Delaunay (CGAL's perturbed
  // in-sphere test, as its insertions decide ties). Not for a star on the hull.
  bool DelaunayAfterMove(Vertex_handle v, const Point& p, const std::vector<Cell_handle>& star) {
    for (Cell_handle c : star)
      if (dt.is_infinite(c)) return false;
    const Point old = v->point();
    v->set_point(p);
    bool ok = true;
    for (size_t s = 0; s < star.size() && ok; ++s) {
      const Cell_handle c = star[s];
      ok = CGAL::orientation(c->vertex(0)->point(), c->vertex(1)->point(), c->vertex(2)->point(),
                             c->vertex(3)->point()) == CGAL::POSITIVE;
    }
    for (size_t s = 0; s < star.size() && ok; ++s) {
      const Cell_handle c = star[s];
      const int iv = c->index(v);
      for (int j = 0; j < 4 && ok; ++j) {
        const Cell_handle n = c->neighbor(j);
        if (j != iv && &*n < &*c) continue;  // a facet between two star cells: tested once
        ok = !dt.is_infinite(n) &&
             dt.side_of_sphere(n, c->vertex(j)->point(), true) == CGAL::ON_UNBOUNDED_SIDE;
      }
    }
    v->set_point(old);
    return ok;
  }

  // kExact move: in place when the cells stay (DelaunayAfterMove), else the vertex removed and
  // re-inserted at the new position. Its rays are not
  // touched here: ApplyUpdate un-casts the window's rays of every moving point before the moves
  // and casts them again after (ExactBatch), so the holes of the moves carry fewer rays.
  void ExactMovePoint(uint32_t pt, const MovedPoint& m) {
    PointRecord& rec = points[pt];
    if (!rec.in_triangulation) {
      MoveAbsentPoint(pt, m);
      return;
    }
    rec.position = m.position;
    const Point p_new = ToPoint(m.position);
    const Point p_old = rec.vertex->point();
    AddCameras(rec, m.camera_ids, nullptr);
    if (p_new == p_old) return;
    std::vector<Cell_handle> d;
    dt.incident_cells(rec.vertex, std::back_inserter(d));
    if (DelaunayAfterMove(rec.vertex, p_new, d)) {
      // The same cells, reshaped: only the star's rays are walked again.
      if (!Shrink(d, {p_old, p_new})) {
        ++stats.moves_skipped;
        return;
      }
      Removed removed;
      CollectRemoved(d, &removed);
      for (Cell_handle c : d) {
        c->info().weight = 0;
        c->info().rays.clear();
      }
      rec.vertex->set_point(p_new);
      AssignNewCells(d, removed, false);
      ++stats.points_moved;
      ++stats.moves_in_place;
      return;
    }
    Dt::Locate_type lt;
    int li, lj;
    Cell_handle loc = dt.locate(p_new, lt, li, lj, rec.vertex->cell());
    if (lt == Dt::VERTEX) {
      ++stats.moves_duplicate;
      ++stats.moves_skipped;
      return;
    }
    dt.find_conflicts(p_new, loc, CGAL::Emptyset_iterator(), std::back_inserter(d));
    std::sort(d.begin(), d.end());
    d.erase(std::unique(d.begin(), d.end()), d.end());
    if (!Shrink(d, {p_old, p_new})) {
      ++stats.moves_skipped;
      return;
    }
    const Vertex_handle v_old = rec.vertex;
    rec.in_triangulation = false;
    rec.vertex = Vertex_handle();
    RemoveVertex(v_old, nullptr);
    bool dup = false;
    Vertex_handle v = InsertPoint(p_new, pt, false, &dup, nullptr);
    if (v == Vertex_handle()) {
      ++stats.points_dropped;  // Cannot happen once D was shrunk; counted if it ever does.
      return;
    }
    rec.vertex = v;
    rec.in_triangulation = true;
    ++stats.points_moved;
  }

  // Move p_old -> p_new (paper §3): backward cast over the last W cameras, remove, transfer,
  // insert, transfer, forward cast; or, in kRays mode, the Refinement Event Handler of Lovi et al.
  void MovePoint(uint32_t pt, const MovedPoint& m) {
    if (opt.visibility_mode == VisibilityMode::kExact) {
      ExactMovePoint(pt, m);
      return;
    }
    PointRecord& rec = points[pt];
    if (!rec.in_triangulation) {
      MoveAbsentPoint(pt, m);
      return;
    }
    rec.position = m.position;
    std::vector<uint32_t> added_cams;
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
      ++stats.moves_duplicate;
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
    Enter(pt, /*again=*/false);
  }

  // A point not in the triangulation enters it at its latest position, with its rays; false
  // when refused (a vertex there already, or its conflict zone could not leave O). `again`: a
  // point refused before, trying again as it moves.
  std::vector<uint32_t> entered;  // kExact: points that entered during this update
  bool Enter(uint32_t pt, bool again) {
    bool dup = false;
    std::vector<RayEntry> u;
    const bool rays_mode = opt.visibility_mode == VisibilityMode::kRays;
    const Point p = ToPoint(points[pt].position);
    if (opt.transfer_camera_side) {
      side_apex = &p;
      side_cams = &points[pt].cameras;
    }
    Vertex_handle v = InsertPoint(p, pt, opt.transfer_on_insert, &dup, rays_mode ? &u : nullptr);
    side_apex = nullptr;
    side_cams = nullptr;
    PointRecord& rec = points[pt];
    if (v == Vertex_handle()) {
      if (!again) ++(dup ? stats.points_duplicate : stats.points_dropped);
      return false;
    }
    rec.vertex = v;
    rec.in_triangulation = true;
    ++(again ? stats.points_reentered : stats.points_inserted);
    if (rays_mode) {
      for (uint32_t c : rec.cameras) u.push_back({c, pt, 0});
      TimedRecast(std::move(u), -1);
    } else if (opt.visibility_mode == VisibilityMode::kExact) {
      entered.push_back(pt);  // its rays are cast with the keyframe's batch
    } else {
      for (uint32_t c : rec.cameras) TimedCast(c, pt, +1);
    }
    return true;
  }

  // A move of a point that is not in the triangulation: removed ones stay out; one refused at
  // insertion (a duplicate, or dropped) tries again at its new position.
  void MoveAbsentPoint(uint32_t pt, const MovedPoint& m) {
    PointRecord& rec = points[pt];
    rec.position = m.position;
    AddCameras(rec, m.camera_ids, nullptr);
    if (rec.removed || !Enter(pt, /*again=*/true)) ++stats.moves_skipped;
  }

  // Takes out of O (keeping dO manifold, lowest weight first) every cell with a vertex within
  // `radius` of one of the given vertices, so that the next grow labels that region again in
  // weight order, as growing from scratch would, instead of in the order the points arrived.
  void PeelAround(const std::vector<Vertex_handle>& centres, double radius) {
    const auto t0 = Clock::now();
    const double r2 = radius * radius;
    const uint32_t seen = NewRegion();
    std::vector<Cell_handle> region, todo, inc;
    for (Vertex_handle v : centres) {
      const Point& p = v->point();
      inc.clear();
      dt.incident_cells(v, std::back_inserter(inc));
      todo.assign(inc.begin(), inc.end());
      while (!todo.empty()) {
        const Cell_handle c = todo.back();
        todo.pop_back();
        if (c->info().region == seen || dt.is_infinite(c)) continue;
        bool near = false;
        for (int i = 0; i < 4 && !near; ++i)
          near = !dt.is_infinite(c->vertex(i)) &&
                 CGAL::squared_distance(c->vertex(i)->point(), p) <= r2;
        if (!near) continue;
        c->info().region = seen;
        region.push_back(c);
        for (int i = 0; i < 4; ++i) todo.push_back(c->neighbor(i));
      }
    }
    PeelFromO(
        region, [&](Cell_handle n) { return n->info().region == seen; }, [] { return false; });
    stats.time.shrink += Seconds(t0, Clock::now());
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
  // kExact keyframe: the window's rays of every point that moves are un-cast together before any
  // move and cast together after the moves and insertions. The holes the moves make then carry
  // only the rays of points that stay (a fifteenth of them on the street stream), and both
  // batches run on all threads. A ray that leaves the window during the move (its point gained
  // cameras) is not cast again: a moving point keeps the rays of its last W cameras only, which
  // the quality bench prefers (street stream F 0.742 against 0.705 keeping them).
  template <class Fn>
  void TimedBatch(Fn&& fn) {
    const auto t0 = Clock::now();
    fn();
    stats.time.cast += Seconds(t0, Clock::now());
  }
  static void WindowRays(const PointRecord& rec, int window, uint32_t pt,
                         std::vector<std::pair<uint32_t, uint32_t>>* out) {
    const size_t n = rec.cameras.size(), w = static_cast<size_t>(window);
    for (size_t k = n > w ? n - w : 0; k < n; ++k) out->push_back({pt, static_cast<uint32_t>(k)});
  }
  void UncastMoving(const KeyframeUpdate& u) {
    std::vector<std::pair<uint32_t, uint32_t>> rays;
    for (const MovedPoint& m : u.moved_points) {
      const uint32_t pt = point_index.at(m.id);
      const PointRecord& rec = points[pt];
      if (rec.in_triangulation && ToPoint(m.position) != rec.vertex->point())
        WindowRays(rec, opt.window, pt, &rays);
    }
    UncastBatch(rays);
  }
  // What is not cast: the window's rays of the moved points (also of those that kept their
  // position but gained a camera), every ray of the points that entered the triangulation.
  void CastUpdated(const KeyframeUpdate& u) {
    std::vector<std::pair<uint32_t, uint32_t>> rays;
    std::vector<uint32_t> sorted = entered;
    std::sort(sorted.begin(), sorted.end());
    for (const MovedPoint& m : u.moved_points) {
      const uint32_t pt = point_index.at(m.id);
      if (points[pt].in_triangulation && !std::binary_search(sorted.begin(), sorted.end(), pt))
        WindowRays(points[pt], opt.window, pt, &rays);
    }
    for (uint32_t pt : entered)
      for (size_t k = 0; k < points[pt].cameras.size(); ++k)
        rays.push_back({pt, static_cast<uint32_t>(k)});
    CastBatch(rays);
  }

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
    const bool exact = opt.visibility_mode == VisibilityMode::kExact;
    entered.clear();
    if (exact) TimedBatch([&] { UncastMoving(u); });
    timed(&stats.time.move, [&] {
      for (const MovedPoint& m : u.moved_points) MovePoint(point_index.at(m.id), m);
    });
    timed(&stats.time.insert, [&] {
      for (const NewPoint& p : u.new_points) InsertNewPoint(p);
    });
    if (exact) TimedBatch([&] { CastUpdated(u); });
    const auto tg = Clock::now();
    if (opt.regrow_radius > 0.0) {
      std::vector<Vertex_handle> changed;
      for (const MovedPoint& m : u.moved_points) {
        const PointRecord& rec = points[point_index.at(m.id)];
        if (rec.in_triangulation) changed.push_back(rec.vertex);
      }
      for (const NewPoint& p : u.new_points) {
        const PointRecord& rec = points[point_index.at(p.id)];
        if (rec.in_triangulation) changed.push_back(rec.vertex);
      }
      PeelAround(changed, opt.regrow_radius);
    }
    Grow();
    stats.time.grow += Seconds(tg, Clock::now());
    const double dt_s = Seconds(t0, Clock::now());
    stats.time.total += dt_s;
    stats.keyframe_seconds.push_back(dt_s);
    ++stats.updates;
    stats.vertices = static_cast<int64_t>(dt.number_of_vertices());
    stats.cells = static_cast<int64_t>(dt.tds().number_of_cells());
    stats.cells_in_o = cells_in_o;
    if (opt.check_invariants) {
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
      if (opt.visibility_mode == VisibilityMode::kExact && !dt.is_infinite(c)) {
        // The count is the number of live entries, each ray at most once.
        std::vector<std::pair<uint32_t, uint32_t>> live;
        for (const RayEntry& e : info.rays)
          if (Live(e)) live.push_back({e.point, e.camera});
        std::sort(live.begin(), live.end());
        if (std::adjacent_find(live.begin(), live.end()) != live.end())
          fail(DescribeCell(c) + " holds a ray twice");
        if (info.weight != unit[0] * static_cast<int64_t>(live.size()))
          fail(DescribeCell(c) + " has weight " + std::to_string(FromUnits(info.weight)) +
               " but holds " + std::to_string(live.size()) + " rays");
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
  const EngineOptions& o = impl_->opt;
  if (o.fill_holes_perimeter > 0.0 || o.smoothing_iterations > 0) {
    FillSmallHoles(&m, o.fill_holes_perimeter);
    SmoothTaubin(&m, o.smoothing_iterations);
    CanonicalizeMesh(&m);
  }
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
  auto it = m.BeginWalk(rec.vertex->point(), m.cameras[ci->second], rec.vertex->cell(), rec.vertex);
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

std::vector<CellProbe> EngineInternals::ProbeCells(const Engine& e) {
  const Engine::Impl& m = *e.impl_;
  std::vector<CellProbe> out;
  for (auto c = m.dt.finite_cells_begin(); c != m.dt.finite_cells_end(); ++c) {
    CellProbe p;
    for (int k = 0; k < 4; ++k) {
      const Vertex_handle v = c->vertex(k);
      const int64_t id = v->info().id;
      p.point_ids[k] = id >= 0 ? static_cast<int64_t>(m.points[id].id) : -1;
      p.vertices[k] = {v->point().x(), v->point().y(), v->point().z()};
    }
    p.weight = m.FromUnits(c->info().weight);
    p.in_o = c->info().in_o;
    p.free = m.IsFree(c);
    out.push_back(p);
  }
  return out;
}

std::string EngineInternals::CheckRaySets(Engine& e) {
  Engine::Impl& m = *e.impl_;
  if (m.opt.visibility_mode != VisibilityMode::kExact) return "not in exact mode";
  int64_t live = 0, visits = 0;
  for (auto c = m.dt.finite_cells_begin(); c != m.dt.finite_cells_end(); ++c)
    for (const RayEntry& r : c->info().rays) live += m.Live(r) ? 1 : 0;
  for (uint32_t pt = 0; pt < m.points.size(); ++pt) {
    const auto& rec = m.points[pt];
    for (size_t k = 0; k < rec.cameras.size(); ++k) {
      if (!rec.ray_cast[k]) continue;
      std::string missing;
      m.Walk(rec.ray_end[k], m.cameras[rec.cameras[k]], m.WalkHint(rec), m.StartVertex(rec),
             [&](Cell_handle c) {
        ++visits;
        bool held = false;
        for (const RayEntry& r : c->info().rays)
          held = held || (r.point == pt && r.camera == k && m.Live(r));
        if (!held && missing.empty()) missing = m.DescribeCell(c);
      });
      if (!missing.empty())
        return "the ray of point " + std::to_string(rec.id) + " from camera " +
               std::to_string(m.camera_ids[rec.cameras[k]]) + " crosses " + missing +
               ", which does not hold it";
    }
  }
  if (live != visits)
    return "the cells hold " + std::to_string(live) + " rays, the rays cross " +
           std::to_string(visits) + " cells";
  return {};
}

void EngineInternals::Regrow(Engine& e) {
  Engine::Impl& m = *e.impl_;
  for (auto c = m.dt.all_cells_begin(); c != m.dt.all_cells_end(); ++c) m.SetInO(c, false);
  m.dirty.clear();
  m.Grow();
}

void EngineInternals::RecastAllAndRegrow(Engine& e) {
  Engine::Impl& m = *e.impl_;
  for (auto c = m.dt.all_cells_begin(); c != m.dt.all_cells_end(); ++c) {
    m.SetInO(c, false);
    m.Ledger(c->info().weight, 0);
    c->info().weight = 0;
    c->info().rays.clear();
  }
  for (auto& rec : m.points) std::fill(rec.ray_cast.begin(), rec.ray_cast.end(), 0);
  m.dirty.clear();
  for (uint32_t pt = 0; pt < m.points.size(); ++pt)
    for (uint32_t cam : m.points[pt].cameras) m.CastRay(cam, pt, +1);
  m.dirty.clear();
  m.Grow();
}

}  // namespace internal

}  // namespace imr::engine
