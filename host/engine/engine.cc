// The reconstruction engine (Romanoni & Matteucci, sections 2-3): the conductor of a keyframe
// (Engine::Impl), the carving of O, weight transfer and the Steiner grid. The parts and how they
// share the triangulation: engine_parts.h; ray casting: ray_caster.cc; the invariant checker and
// the benchmark hooks: engine_checks.cc.
//
// Notes on choices the paper leaves open:
// - Weights are int64 multiples of weight_unit, so a backward cast restores weights bit for bit;
//   policy outputs are rounded to the unit.
// - transfer_on_insert defaults to false: for a NEW point the cells of its conflict zone are
//   replaced by cells that start at weight 0 and are then weighted by the point's own rays. With
//   the policy (paper §3.2) the big carved cells that straddle a surface before it is
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
#include "host/engine/engine_parts.h"
#include "host/engine/mesh_topology.h"

#include <CGAL/property_map.h>
#include <CGAL/spatial_sort.h>
#include <CGAL/Spatial_sort_traits_adapter_3.h>
#include <CGAL/utility.h>

#include <queue>
#include <sstream>

namespace imr::engine {
namespace detail {
namespace {

// A deterministic number in [-1, 1] from a key and an axis (splitmix64).
double Jitter(uint64_t key, int axis) {
  uint64_t z = key * 3 + static_cast<uint64_t>(axis) + 0x9E3779B97F4A7C15ull;
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  z ^= z >> 31;
  return static_cast<double>(z >> 11) / static_cast<double>(1ull << 52) - 1.0;
}

}  // namespace

EngineState::EngineState(const EngineOptions& o) : opt(o) {
  unit = {ToUnits(opt.w1), ToUnits(opt.w2), ToUnits(opt.w3)};
  threshold = ToUnits(opt.free_threshold);
  // Exact mode: a cell's weight is w1 times the rays that cross it.
  if (opt.visibility_mode == VisibilityMode::kExact) threshold = unit[0] * opt.exact_min_rays - 1;
}

// =================================================================================================
// Carving of O.

// Manifold test: toggling one cell in or out of O changes only the regularity of its
// four vertices; each must stay regular (its surface triangles form one closed fan).
bool Carving::VertexRegular(Vertex_handle v, Cell_handle toggled) {
  std::vector<Cell_handle>& cells = incident_;
  cells.clear();
  s_.dt.incident_cells(v, std::back_inserter(cells));
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
bool Carving::ToggleKeepsManifoldByLinks(Cell_handle c) {
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
bool Carving::ToggleKeepsManifold(Cell_handle c) {
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
  if (s_.hooks && s_.hooks->cross_check_manifold_test && keeps != ToggleKeepsManifoldByLinks(c))
    ++s_.hooks->manifold_test_mismatches;
  return keeps;
}

// Is vertex i of c on S through a cell other than c?
bool Carving::VertexTouchesSide(Cell_handle c, int i, bool adding) {
  const Vertex_handle v = c->vertex(i);
  if (adding) return v->info().o_cells > 0;  // c itself is not in O.
  // Leaving O: is any other cell around v outside O? A walk over v's star that stops at the
  // first one (cells around a vertex inside O are all in O: the walk then sees them all).
  ++s_.stamp;
  c->info().stamp = s_.stamp;
  std::vector<Cell_handle>& todo = star_;
  todo.clear();
  todo.push_back(c);
  while (!todo.empty()) {
    const Cell_handle x = todo.back();
    todo.pop_back();
    const int iv = x->index(v);
    for (int k = 0; k < 4; ++k) {
      if (k == iv) continue;
      const Cell_handle n = x->neighbor(k);
      if (n->info().stamp == s_.stamp) continue;
      n->info().stamp = s_.stamp;
      if (!n->info().in_o) return true;
      todo.push_back(n);
    }
  }
  return false;
}

// Is the edge (vertex i, vertex j) of c on S through a cell other than c?
bool Carving::EdgeTouchesSide(Cell_handle c, int i, int j, bool adding) const {
  Dt::Cell_circulator it = s_.dt.incident_cells(c, i, j), done = it;
  do {
    const Cell_handle x = it;
    if (x != c && x->info().in_o == adding) return true;
  } while (++it != done);
  return false;
}

void Carving::SetInO(Cell_handle c, bool in) {
  if (c->info().in_o == in) return;
  c->info().in_o = in;
  s_.cells_in_o += in ? 1 : -1;
  for (int i = 0; i < 4; ++i) c->vertex(i)->info().o_cells += in ? 1 : -1;
}

// shrink: remove from O, lowest weight first and keeping dO manifold, the cells of an enclosing
// set E of D (D plus the cells around D's vertices near the affected points). Returns whether
// D no longer meets O.
bool Carving::Shrink(const std::vector<Cell_handle>& d, const std::vector<Point>& centres,
                     const std::vector<Cell_handle>* planned_e) {
  auto meets_o = [&]() {
    for (Cell_handle c : d)
      if (c->info().in_o) return true;
    return false;
  };
  if (!meets_o()) return true;
  const auto t0 = Clock::now();
  if (!planned_e) {
    EnclosingSetInO(s_, d, centres.data(), centres.size(), &e_seen_, &star_seen_, &star_, &e_);
    planned_e = &e_;
  }
  // Cells leave O only while a keyframe's points move and enter: a cell of O now was one when
  // E was planned, and the rest of E does not matter.
  const bool sorted = planned_e != &e_;
  const uint32_t in_e = NewRegion();
  for (Cell_handle c : *planned_e) c->info().region = in_e;
  const bool ok = PeelFromO(
      *planned_e, [&](Cell_handle n) { return n->info().region == in_e; },
      [&] { return !meets_o(); }, sorted) || !meets_o();
  // forget: a final cell of O next to the change stays (PeelFromO leaves it): when the change
  // fails, that is what forgetting cost it (a point moved far or the cameras jumped), counted.
  if (!ok && s_.opt.forget)
    for (Cell_handle c : *planned_e)
      if (c->info().in_o && c->info().final) {
        ++s_.stats.shrinks_blocked_final;
        break;
      }
  s_.stats.time.shrink += SecondsSince(t0);
  return ok;
}

// E: D, its facet neighbours, and the cells around every vertex of D that lies within
// shrink_radius of an affected point; of them, those in O (shrink peels nothing else).
void Carving::EnclosingSetInO(const EngineState& s, const std::vector<Cell_handle>& d,
                              const Point* centres, size_t n_centres, ScratchMap<uint8_t>* seen,
                              ScratchMap<uint8_t>* star_seen, std::vector<Cell_handle>* star,
                              std::vector<Cell_handle>* e) {
  seen->Clear();
  e->clear();
  auto add = [&](Cell_handle c) {
    if (c->info().in_o && seen->Insert(ScratchMap<uint8_t>::Key(&*c), 1).second) e->push_back(c);
  };
  for (Cell_handle c : d) {
    add(c);
    for (int i = 0; i < 4; ++i) add(c->neighbor(i));
  }
  const double r2 = s.opt.shrink_radius * s.opt.shrink_radius;
  std::vector<Vertex_handle> verts;
  for (Cell_handle c : d)
    for (int i = 0; i < 4; ++i) {
      const Vertex_handle v = c->vertex(i);
      if (!s.dt.is_infinite(v) && v->info().o_cells > 0) verts.push_back(v);
    }
  std::sort(verts.begin(), verts.end());
  verts.erase(std::unique(verts.begin(), verts.end()), verts.end());
  // The cells of O around a vertex are joined across facets that contain it (dO is a manifold:
  // they are the cone over one disk of the vertex's link), and there are o_cells of them: a
  // walk around the vertex to the first of them, then through them alone.
  std::vector<Cell_handle>& todo = *star;
  for (Vertex_handle v : verts) {
    bool near = false;
    for (size_t k = 0; k < n_centres; ++k)
      near = near || CGAL::squared_distance(v->point(), centres[k]) <= r2;
    if (!near) continue;
    star_seen->Clear();
    todo.assign(1, v->cell());
    star_seen->Insert(ScratchMap<uint8_t>::Key(&*v->cell()), 1);
    Cell_handle first;
    while (!todo.empty() && first == Cell_handle()) {
      const Cell_handle c = todo.back();
      todo.pop_back();
      if (c->info().in_o) {
        first = c;
        break;
      }
      const int iv = c->index(v);
      for (int k = 0; k < 4; ++k) {
        const Cell_handle n = c->neighbor(k);
        if (k != iv && star_seen->Insert(ScratchMap<uint8_t>::Key(&*n), 1).second)
          todo.push_back(n);
      }
    }
    if (first == Cell_handle()) continue;
    star_seen->Clear();
    todo.assign(1, first);
    star_seen->Insert(ScratchMap<uint8_t>::Key(&*first), 1);
    for (int32_t found = 0; !todo.empty() && found < v->info().o_cells;) {
      const Cell_handle c = todo.back();
      todo.pop_back();
      add(c);
      ++found;
      const int iv = c->index(v);
      for (int k = 0; k < 4; ++k) {
        const Cell_handle n = c->neighbor(k);
        if (k != iv && n->info().in_o && star_seen->Insert(ScratchMap<uint8_t>::Key(&*n), 1).second)
          todo.push_back(n);
      }
    }
  }
}

// A fresh region mark (all cells' marks reset when the counter wraps).
uint32_t Carving::NewRegion() {
  if (++s_.region_mark == 0) {
    for (auto c = s_.dt.all_cells_begin(); c != s_.dt.all_cells_end(); ++c) c->info().region = 0;
    s_.region_mark = 1;
  }
  return s_.region_mark;
}

// Peels the cells of `region` from O, lowest weight first (the inverse of grow), keeping dO
// manifold: a cell refused now is retried when one of its facet neighbours leaves O (those in
// the region, `in_region`), up to shrink_passes tries per cell. Stops early, returning true,
// once `done()` holds after a cell left O; false when the queue or the budget ran out.
template <typename Cells, typename InRegion, typename Done>
bool Carving::PeelFromO(const Cells& region, InRegion in_region, Done done, bool sorted) {
  struct Item {
    int64_t weight;
    uint64_t order;
    Cell_handle cell;
    bool operator<(const Item& o) const {
      return weight != o.weight ? weight > o.weight : order > o.order;
    }
  };
  // Canonical order (CellKey), so equal weights peel the same way whatever the container.
  std::priority_queue<Item> q;
  uint64_t order = 0;
  if (sorted) {
    for (Cell_handle c : region)
      if (c->info().in_o) q.push({c->info().weight, order++, c});
  } else {
    std::vector<std::pair<std::array<int64_t, 4>, Cell_handle>> start;
    for (Cell_handle c : region)
      if (c->info().in_o) start.push_back({s_.CellKey(c), c});
    std::sort(start.begin(), start.end(),
              [](const auto& a, const auto& b) { return a.first < b.first; });
    for (const auto& s : start) q.push({s.second->info().weight, order++, s.second});
  }
  const size_t start_size = q.size();
  int64_t budget = static_cast<int64_t>(start_size) * 4 * s_.opt.shrink_passes + 16;
  while (!q.empty() && budget-- > 0) {
    Cell_handle c = q.top().cell;
    q.pop();
    if (!c->info().in_o || c->info().final || !ToggleKeepsManifold(c)) continue;
    SetInO(c, false);
    ++s_.stats.cells_shrunk;
    s_.MarkDirty(c);
    for (int i : s_.CanonicalFacets(c)) {
      Cell_handle n = c->neighbor(i);
      s_.MarkDirty(n);
      if (n->info().in_o && in_region(n)) q.push({n->info().weight, order++, n});
    }
    if (done()) return true;
  }
  return false;
}

// Takes out of O (keeping dO manifold, lowest weight first) every cell with a vertex within
// `radius` of one of the given vertices, so that the next grow labels that region again in
// weight order, as growing from scratch would, instead of in the order the points arrived.
void Carving::PeelAround(const std::vector<Vertex_handle>& centres, double radius) {
  const auto t0 = Clock::now();
  const double r2 = radius * radius;
  const uint32_t seen = NewRegion();
  std::vector<Cell_handle> region, todo, inc;
  for (Vertex_handle v : centres) {
    const Point& p = v->point();
    inc.clear();
    s_.dt.incident_cells(v, std::back_inserter(inc));
    todo.assign(inc.begin(), inc.end());
    while (!todo.empty()) {
      const Cell_handle c = todo.back();
      todo.pop_back();
      if (c->info().region == seen || s_.dt.is_infinite(c)) continue;
      bool near = false;
      for (int i = 0; i < 4 && !near; ++i)
        near = !s_.dt.is_infinite(c->vertex(i)) &&
               CGAL::squared_distance(c->vertex(i)->point(), p) <= r2;
      if (!near) continue;
      c->info().region = seen;
      region.push_back(c);
      for (int i = 0; i < 4; ++i) todo.push_back(c->neighbor(i));
    }
  }
  PeelFromO(
      region, [&](Cell_handle n) { return n->info().region == seen; }, [] { return false; });
  s_.stats.time.shrink += SecondsSince(t0);
}

// grow: a priority queue by weight (highest first). Seeds: the highest-weight free cell when O is
// empty, else the free cells outside O touching dO among those that changed this keyframe.
void Carving::Grow(Cell_handle new_component) {
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
    return !s_.dt.is_infinite(c) && !c->info().in_o && !c->info().final && s_.IsFree(c) &&
           !s_.HullAdjacent(c);
  };
  if (s_.cells_in_o == 0) {
    // The highest weight; among equal ones the smallest CellKey (not the container's order).
    Cell_handle best;
    std::array<int64_t, 4> best_key{};
    for (auto c = s_.dt.finite_cells_begin(); c != s_.dt.finite_cells_end(); ++c) {
      if (!candidate(c)) continue;
      if (best != Cell_handle() && c->info().weight < best->info().weight) continue;
      const std::array<int64_t, 4> key = s_.CellKey(c);
      if (best == Cell_handle() || c->info().weight > best->info().weight || key < best_key)
        best = c, best_key = key;
    }
    if (best != Cell_handle()) q.push({best->info().weight, order++, best});
  } else {
    // Deterministic seed order: by weight, then by the ids of the vertices.
    std::vector<std::pair<std::array<int64_t, 4>, Cell_handle>> seeds;
    s_.TakeDirty([&](Cell_handle c) {
      if (candidate(c) && s_.TouchesO(c)) seeds.push_back({s_.CellKey(c), c});
    });
    std::sort(seeds.begin(), seeds.end(),
              [](const auto& a, const auto& b) { return a.first < b.first; });
    for (const auto& s : seeds) q.push({s.second->info().weight, order++, s.second});
  }
  s_.TakeDirty([](Cell_handle) {});
  if (new_component != Cell_handle() && candidate(new_component) &&
      !s_.TouchesO(new_component) && ToggleKeepsManifold(new_component)) {
    SetInO(new_component, true);
    ++s_.stats.cells_grown;
    ++s_.stats.components_started;
    for (int i : s_.CanonicalFacets(new_component)) {
      Cell_handle n = new_component->neighbor(i);
      if (candidate(n)) q.push({n->info().weight, order++, n});
    }
  }
  while (!q.empty()) {
    Cell_handle c = q.top().cell;
    q.pop();
    if (!candidate(c)) continue;
    if (s_.cells_in_o > 0 && !s_.TouchesO(c)) continue;
    if (!ToggleKeepsManifold(c)) continue;
    SetInO(c, true);
    ++s_.stats.cells_grown;
    for (int i : s_.CanonicalFacets(c)) {
      Cell_handle n = c->neighbor(i);
      if (candidate(n)) q.push({n->info().weight, order++, n});
    }
  }
}

bool Carving::AddWithRepair(Cell_handle c, std::vector<Cell_handle>* added) {
  const size_t start = added->size();
  auto add = [&](Cell_handle x) {
    SetInO(x, true);
    added->push_back(x);
  };
  auto addable = [&](Cell_handle x) {
    return !s_.dt.is_infinite(x) && !x->info().in_o && !x->info().final && !s_.HullAdjacent(x);
  };
  if (!addable(c)) return false;
  add(c);
  std::vector<Vertex_handle> verts;
  std::vector<Cell_handle> star;
  for (int round = 0;; ++round) {
    verts.clear();
    for (size_t k = start; k < added->size(); ++k)
      for (int i = 0; i < 4; ++i) verts.push_back((*added)[k]->vertex(i));
    // By id, not address: which irregular vertex is repaired first decides what joins O.
    std::sort(verts.begin(), verts.end(), EngineState::ById);
    verts.erase(std::unique(verts.begin(), verts.end()), verts.end());
    Vertex_handle bad;
    for (Vertex_handle v : verts)
      if (!VertexRegular(v, Cell_handle())) {
        bad = v;
        break;
      }
    if (bad == Vertex_handle()) break;
    // The free cells around the irregular vertex join O; none left, or out of rounds: undo.
    star.clear();
    s_.dt.incident_cells(bad, std::back_inserter(star));
    size_t joined = 0;
    for (Cell_handle x : star)
      if (addable(x) && s_.IsFree(x)) add(x), ++joined;
    if (joined == 0) {
      // Only cells that no ray crossed are left around it: when they are few, a pocket of matter
      // in free space that no ray happened to cross, they join and the vertex is inside O.
      size_t rest = 0, blocked = 0;
      for (Cell_handle x : star)
        if (!x->info().in_o) ++rest, blocked += addable(x) ? 0 : 1;
      if (blocked == 0 && rest * 8 <= star.size())
        for (Cell_handle x : star)
          if (!x->info().in_o) add(x), ++joined;
    }
    if (joined == 0 || round >= s_.opt.camera_path_repair) {
      for (size_t k = added->size(); k-- > start;) SetInO((*added)[k], false);
      added->resize(start);
      return false;
    }
  }
  return true;
}

bool Carving::ForceCell(Cell_handle c) {
  std::vector<Cell_handle> added;
  bool ok = false;
  if (s_.TouchesO(c)) {
    ok = AddWithRepair(c, &added);
  } else if (ToggleKeepsManifold(c)) {  // a component of O of its own until grow joins it
    SetInO(c, true);
    added.push_back(c);
    ok = true;
  }
  SeedAround(added);
  return ok;
}

void Carving::SeedAround(const std::vector<Cell_handle>& added) {
  for (Cell_handle x : added) {
    s_.MarkDirty(x);
    for (int i = 0; i < 4; ++i) s_.MarkDirty(x->neighbor(i));
  }
}

int64_t Carving::OpenPath(const std::vector<Cell_handle>& path) {
  std::vector<Cell_handle> added;
  // Outward from the cells of the path that touch O: a pass adds those it can; again while any did.
  for (bool progress = true; progress;) {
    progress = false;
    for (Cell_handle c : path)
      if (!c->info().in_o && s_.TouchesO(c) && AddWithRepair(c, &added)) progress = true;
  }
  SeedAround(added);
  s_.stats.cells_opened += static_cast<int64_t>(added.size());
  return static_cast<int64_t>(added.size());
}

// =================================================================================================
// Weight transfer.

void WeightTransfer::CollectRemoved(const std::vector<Cell_handle>& cells, Removed* r) {
  if (s_.opt.visibility_mode == VisibilityMode::kExact) caster_.CollectHole(cells, &r->hole);
  for (Cell_handle c : cells) {
    c->info().dirty = false;         // out of the set: the cell is about to be destroyed
    if (c->info().final) --s_.stats.cells_final, ++s_.stats.final_cells_replaced;
    s_.Ledger(c->info().weight, 0);
    if (s_.dt.is_infinite(c)) continue;
    if (s_.opt.visibility_mode == VisibilityMode::kRays) {
      r->rays.insert(r->rays.end(), c->info().rays.begin(), c->info().rays.end());
    } else if (s_.opt.visibility_mode == VisibilityMode::kWeights) {  // the policy's input
      const Point g = s_.Centroid(c);
      r->centroids.insert(r->centroids.end(), {g.x(), g.y(), g.z()});
      r->weights.push_back(s_.FromUnits(c->info().weight));
    }
  }
}

void WeightTransfer::AssignNewCells(const std::vector<Cell_handle>& added, const Removed& r,
                                    bool transfer) {
  std::vector<Cell_handle> finite;
  for (Cell_handle c : added)
    if (!s_.dt.is_infinite(c)) finite.push_back(c);
  if (transfer && s_.opt.visibility_mode == VisibilityMode::kWeights && !finite.empty()) {
    std::vector<double> centroids;
    centroids.reserve(3 * finite.size());
    for (Cell_handle c : finite) {
      const Point g = s_.Centroid(c);
      centroids.insert(centroids.end(), {g.x(), g.y(), g.z()});
    }
    std::vector<double> out(finite.size(), 0.0);
    TransferInput in;
    in.removed_centroids = r.centroids.data();
    in.removed_weights = r.weights.data();
    in.removed_count = r.weights.size();
    in.new_centroids = centroids.data();
    in.new_count = finite.size();
    policy_->Transfer(in, out.data());
    ++s_.stats.policy_calls;
    if (s_.hooks && s_.hooks->record_transfers &&
        s_.hooks->recorded.size() < s_.hooks->record_limit)
      s_.hooks->recorded.push_back({r.centroids, r.weights, centroids});
    for (size_t i = 0; i < finite.size(); ++i) finite[i]->info().weight = s_.ToUnits(out[i]);
    if (side_apex_ && side_cams_ && !side_cams_->empty()) {
      // transfer_camera_side: a new cell whose centroid lies behind the point, on the far side
      // from its cameras (mean viewing direction), starts at 0: matter, not inherited carving.
      double d[3] = {0.0, 0.0, 0.0};
      for (uint32_t c : *side_cams_) {
        const double v[3] = {s_.cameras[c].x() - side_apex_->x(),
                             s_.cameras[c].y() - side_apex_->y(),
                             s_.cameras[c].z() - side_apex_->z()};
        const double n = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
        if (n > 0.0)
          for (int k = 0; k < 3; ++k) d[k] += v[k] / n;
      }
      for (size_t i = 0; i < finite.size(); ++i) {
        const double* g = &centroids[3 * i];
        const double dot = (g[0] - side_apex_->x()) * d[0] + (g[1] - side_apex_->y()) * d[1] +
                           (g[2] - side_apex_->z()) * d[2];
        if (dot < 0.0) finite[i]->info().weight = 0;
      }
    }
  }
  for (Cell_handle c : added) s_.Ledger(0, c->info().weight);
  if (s_.opt.visibility_mode == VisibilityMode::kExact) {
    const auto t0 = Clock::now();
    caster_.RefillHole(added, r.hole);
    s_.stats.time.cast += SecondsSince(t0);
  }
  for (Cell_handle c : finite)
    if (s_.IsFree(c)) s_.MarkDirty(c);
}

// =================================================================================================
// The Steiner grid and dO.

// The grid follows the rays (issue 47): a cube of +-(max_ray_length + margin) around each camera
// put most nodes behind, beside and above the cameras where no ray goes (a forward COLMAP model:
// 670,824 Steiner points for 4,217 points). The carving needs cells no larger than a grid step
// along the rays and a margin around them (a ray's cells, their neighbours and theirs are
// weighted); beyond that the cells are matter whatever their size.
Point SteinerGrid::NodePoint(const Node& n) const {
  const double s = opt_.steiner_spacing;
  return Point((static_cast<double>(n.i) + opt_.steiner_origin[0]) * s,
               (static_cast<double>(n.j) + opt_.steiner_origin[1]) * s,
               (static_cast<double>(n.k) + opt_.steiner_origin[2]) * s);
}

int64_t SteinerGrid::Visit(const Node& voxel, std::vector<Node>* fresh) {
  if (!voxels_.insert(voxel).second) return 1;
  const int64_t m = std::max<int64_t>(
      1, static_cast<int64_t>(std::ceil(opt_.steiner_margin / opt_.steiner_spacing - 1e-9)));
  for (int64_t i = voxel.i - m; i <= voxel.i + 1 + m; ++i)
    for (int64_t j = voxel.j - m; j <= voxel.j + 1 + m; ++j)
      for (int64_t k = voxel.k - m; k <= voxel.k + 1 + m; ++k)
        if (nodes_.insert({i, j, k}).second) fresh->push_back({i, j, k});
  return (2 * m + 2) * (2 * m + 2) * (2 * m + 2);
}

std::vector<Point> SteinerGrid::NewPoints(const std::vector<Segment>& segments,
                                          const std::function<bool()>& stop) {
  const double s = opt_.steiner_spacing;
  std::vector<Node> fresh;
  // The nodes looked at so far, and when to poll `stop` next.
  int64_t walked = 0, next_poll = 0x10000;
  auto visit = [&](const int64_t v[3]) {
    walked += Visit({v[0], v[1], v[2]}, &fresh);
    if (walked >= next_poll) {
      next_poll = walked + 0x10000;
      if (stop && stop())
        throw Stopped("stopped on request while placing the Steiner grid's nodes");
    }
  };
  for (const Segment& seg : segments) {
    // In node units; the voxel v holds [v, v + 1) on each axis.
    double ua[3] = {seg.a.x() / s - opt_.steiner_origin[0], seg.a.y() / s - opt_.steiner_origin[1],
                    seg.a.z() / s - opt_.steiner_origin[2]};
    double ub[3] = {seg.b.x() / s - opt_.steiner_origin[0], seg.b.y() / s - opt_.steiner_origin[1],
                    seg.b.z() / s - opt_.steiner_origin[2]};
    int64_t v[3], end[3], step[3];
    double t_max[3], t_delta[3];
    int64_t steps = 0;
    for (int d = 0; d < 3; ++d) {
      const double fa = std::floor(ua[d]), fb = std::floor(ub[d]);
      // Node numbers (with the margin) are exact integers in a double up to 2^53.
      if (!(std::abs(fa) < 0x1p52 && std::abs(fb) < 0x1p52))
        throw std::runtime_error("a ray to " + std::to_string(seg.b[d]) + " on axis " +
                                 std::to_string(d) +
                                 " is beyond the Steiner grid's node numbers (2^52 steps of "
                                 "steiner_spacing " + std::to_string(s) +
                                 "): raise steiner_spacing");
      v[d] = static_cast<int64_t>(fa);
      end[d] = static_cast<int64_t>(fb);
      steps += std::abs(end[d] - v[d]);
      const double du = ub[d] - ua[d];
      step[d] = end[d] > v[d] ? 1 : end[d] < v[d] ? -1 : 0;
      t_delta[d] = step[d] != 0 ? 1.0 / std::abs(du) : HUGE_VAL;
      t_max[d] = step[d] > 0   ? (fa + 1.0 - ua[d]) / du
                 : step[d] < 0 ? (fa - ua[d]) / du
                               : HUGE_VAL;
    }
    // Every voxel the segment crosses, in order (Amanatides & Woo), ending in the last one's even
    // when rounding would stop the walk short: steps bounds it.
    visit(v);
    for (int64_t n = 0; n < steps; ++n) {
      int d = t_max[0] <= t_max[1] ? (t_max[0] <= t_max[2] ? 0 : 2)
                                   : (t_max[1] <= t_max[2] ? 1 : 2);
      if (v[d] == end[d]) {  // rounding: step on an axis that still has steps to go
        for (int e = 0; e < 3; ++e)
          if (v[e] != end[e]) d = e;
      }
      v[d] += step[d];
      t_max[d] += t_delta[d];
      visit(v);
    }
  }
  // Named in the grid's order, whatever order the rays came in.
  std::sort(fresh.begin(), fresh.end());
  std::vector<Point> out;
  out.reserve(fresh.size());
  for (const Node& n : fresh) {
    // Off the exact grid by a deterministic jitter (steiner_jitter): on a regular grid eight
    // points share every circumsphere and CGAL's predicates fall back to exact arithmetic. The
    // jitter's seed packs the node in 63 bits (it only needs to vary).
    const uint64_t key = (static_cast<uint64_t>(n.i & 0x1FFFFF) << 42) |
                         (static_cast<uint64_t>(n.j & 0x1FFFFF) << 21) |
                         static_cast<uint64_t>(n.k & 0x1FFFFF);
    const double jit = opt_.steiner_jitter * s;
    const Point p = NodePoint(n);
    out.emplace_back(p.x() + jit * Jitter(key, 0), p.y() + jit * Jitter(key, 1),
                     p.z() + jit * Jitter(key, 2));
  }
  return out;
}

void SteinerGrid::Forget(const std::function<bool(const Point&)>& gone) {
  for (auto* set : {&nodes_, &voxels_})
    for (auto it = set->begin(); it != set->end();)
      it = gone(NodePoint(*it)) ? set->erase(it) : std::next(it);
}

// dO: facets between a cell of O and a cell outside O, oriented toward the O cell (free space).
std::vector<Triangle> Boundary(const EngineState& s, bool live) {
  std::vector<Triangle> out;
  for (auto c = s.dt.finite_cells_begin(); c != s.dt.finite_cells_end(); ++c) {
    if (!c->info().in_o) continue;
    for (int i = 0; i < 4; ++i) {
      if (c->neighbor(i)->info().in_o) continue;
      if (live && c->info().final && c->neighbor(i)->info().final) continue;
      // vertex_triple_index(i, .) orders facet i so that its normal points toward vertex i,
      // i.e. into this cell of O.
      out.push_back({{c->vertex(Dt::vertex_triple_index(i, 0)),
                      c->vertex(Dt::vertex_triple_index(i, 1)),
                      c->vertex(Dt::vertex_triple_index(i, 2))}});
    }
  }
  return out;
}

}  // namespace detail

// =================================================================================================
// The conductor.

using detail::Boundary;
using detail::Clock;
using detail::Dt;
using detail::Facet;
using detail::PointRecord;
using detail::Removed;
using detail::ToPoint;
using detail::Triangle;

namespace {

bool Finite(const Vec3& p) {
  return std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2]);
}

}  // namespace

Engine::Impl::Impl(const EngineOptions& o, WeightTransferPolicy* p)
    : s(o), caster(s), transfer(s, p, caster), carving(s), steiner(s.opt),
      planner(s, caster, carving), forgetting(s, caster, steiner) {
  if (const std::string error = s.opt.Check(); !error.empty()) {
    init = Status::Error("invalid engine options: " + error);
  } else if (const std::string grid = s.opt.CheckSteinerGrid(); !grid.empty()) {
    init = Status::Error("invalid engine options: " + grid);
  } else if (s.opt.visibility_mode == VisibilityMode::kWeights && p == nullptr) {
    init = Status::Error("visibility_mode 'weights' needs a weight-transfer policy");
  }
  if (s.opt.visibility_mode == VisibilityMode::kExact && s.unit[0] <= 0)
    init = Status::Error("invalid engine options: exact mode needs w1 > 0");
}

Status Engine::Impl::Validate(const KeyframeUpdate& u) const {
  std::unordered_set<uint64_t> update_cams;
  if (s.opt.visibility_mode == VisibilityMode::kRays) {
    size_t added = 0;
    for (const Camera& c : u.cameras) added += s.camera_index.count(c.id) ? 0 : 1;
    if (s.cameras.size() + added > detail::RayEntry::kMaxCameras)
      return Status::Error("visibility_mode 'rays' (the baseline of Lovi et al.) keeps at most " +
                           std::to_string(detail::RayEntry::kMaxCameras) +
                           " cameras; use 'exact' or 'weights' for longer sequences");
  }
  for (const Camera& c : u.cameras) {
    if (!Finite(c.center)) {
      std::ostringstream m;
      m << "camera " << c.id << " has a non-finite centre";
      return Status::Error(m.str());
    }
    update_cams.insert(c.id);
  }
  auto known_cam = [&](uint64_t id) {
    return s.camera_index.count(id) > 0 || update_cams.count(id) > 0;
  };
  // A new or moved point: a finite position, a usable id (`id_problem`: null, or why not),
  // known cameras.
  auto check_point = [&](const char* kind, uint64_t id, const Vec3& position,
                         const std::vector<uint64_t>& camera_ids, const char* id_problem) {
    std::ostringstream m;
    m << kind << " point " << id;
    if (!Finite(position)) {
      m << " has a non-finite position (NaN or inf)";
      return Status::Error(m.str());
    }
    if (id_problem) {
      m << " " << id_problem;
      return Status::Error(m.str());
    }
    for (uint64_t c : camera_ids)
      if (!known_cam(c)) {
        m << " is observed by unknown camera " << c;
        return Status::Error(m.str());
      }
    return Status::Ok();
  };
  std::unordered_set<uint64_t> new_ids;
  for (const NewPoint& p : u.new_points) {
    const char* taken = nullptr;
    if (s.point_index.count(p.id) || !new_ids.insert(p.id).second)
      taken = "uses an id that is already known";
    else if (forgetting.Retired(p.id))
      taken = "uses the id of a point that was forgotten (engine.forget): ids must not be reused";
    const Status st = check_point("new", p.id, p.position, p.camera_ids, taken);
    if (!st.ok()) return st;
  }
  // A retired point (forget) may still be named: its update is ignored (WithoutRetired).
  auto known = [&](uint64_t id) { return s.point_index.count(id) || forgetting.Retired(id); };
  for (const MovedPoint& p : u.moved_points) {
    const Status st =
        check_point("moved", p.id, p.position, p.camera_ids, known(p.id) ? nullptr : "is unknown");
    if (!st.ok()) return st;
  }
  for (uint64_t id : u.removed_points)
    if (!known(id)) {
      std::ostringstream m;
      m << "removed point " << id << " is unknown";
      return Status::Error(m.str());
    }
  return Status::Ok();
}

void Engine::Impl::AddCameras(PointRecord& rec, const std::vector<uint64_t>& ids,
                              std::vector<uint32_t>* added) {
  for (uint64_t id : ids) {
    const uint32_t c = s.camera_index.at(id);
    if (std::find(rec.cameras.begin(), rec.cameras.end(), c) != rec.cameras.end()) continue;
    if (rec.cameras.size() >= detail::RayEntry::kMaxCameras) {  // a cell's entry names the ray
      ++s.stats.observations_over_limit;                       // by its index in 16 bits
      continue;
    }
    rec.cameras.push_back(c);
    if (s.opt.visibility_mode == VisibilityMode::kExact) {
      rec.ray_state.push_back(0);
      rec.ray_end.push_back({Point(0, 0, 0), c});
      rec.ray_list.emplace_back();
    }
    if (added) added->push_back(c);
  }
}

// Inserts p (conflict cells -> new cells). Returns a null handle when p is dropped: duplicate of
// a vertex (*duplicate set) or its conflict zone still meets O after shrink. `rays` receives the
// rays stored in the conflict cells (kRays).
// `with_policy`: new cells get weights through the policy (weights mode); else they start at 0.
Engine::Impl::Vertex_handle Engine::Impl::InsertPoint(const Point& p, int64_t vertex_id,
                                                      bool with_policy, bool* duplicate,
                                                      std::vector<RayEntry>* rays) {
  *duplicate = false;
  if (s.dt.dimension() < 3) {
    // Only Steiner points get here (before the grid spans 3D): O is empty.
    const size_t before = s.dt.number_of_vertices();
    Vertex_handle v =
        s.dt.insert(p, s.WalkHint());
    if (s.dt.number_of_vertices() == before) {
      *duplicate = true;
      return Vertex_handle();
    }
    v->info().id = vertex_id;
    s.last_vertex = v;
    return v;
  }
  Dt::Locate_type lt;
  int li, lj;
  Cell_handle loc = s.dt.locate(
      p, lt, li, lj, s.WalkHint());
  if (lt == Dt::VERTEX) {
    *duplicate = true;
    return Vertex_handle();
  }
  std::vector<Cell_handle> conflicts;
  Facet boundary;
  s.dt.find_conflicts(p, loc, CGAL::Oneset_iterator<Facet>(boundary),
                      std::back_inserter(conflicts));
  if (s.BlockedByFinal(conflicts) || !carving.Shrink(conflicts, {p})) return Vertex_handle();
  Removed removed;
  transfer.CollectRemoved(conflicts, &removed);
  Vertex_handle v =
      s.dt.insert_in_hole(p, conflicts.begin(), conflicts.end(), boundary.first, boundary.second);
  v->info().id = vertex_id;
  s.last_vertex = v;
  std::vector<Cell_handle> added;
  s.dt.incident_cells(v, std::back_inserter(added));
  s.BornFinal(added);
  transfer.AssignNewCells(added, removed, with_policy);
  if (rays) *rays = std::move(removed.rays);
  return v;
}

// Removes a vertex none of whose cells is in O; new cells get weights through the policy.
void Engine::Impl::RemoveVertex(Vertex_handle v, std::vector<RayEntry>* rays) {
  std::vector<Cell_handle> inc;
  s.dt.incident_cells(v, std::back_inserter(inc));
  Removed removed;
  transfer.CollectRemoved(inc, &removed);
  if (s.last_vertex == v) s.last_vertex = Vertex_handle();
  std::vector<Cell_handle> added;
  s.dt.remove_and_give_new_cells(v, std::back_inserter(added));
  s.BornFinal(added);
  transfer.AssignNewCells(added, removed, true);
  if (rays) *rays = std::move(removed.rays);
}

// The Steiner points the update's rays newly reach (a point refused - a duplicate, or its
// conflict zone could not leave O - is counted and not tried again): the segments camera -> point
// of its new points and of its moved points' new positions (as they are cast: a ray longer than
// max_ray_length only near the camera, or not at all), and each new camera's path from the one
// before when within max_ray_length (camera_path opens it). The grid's order names them (their
// vertex ids, which the canonical orders of growing and peeling read); they are inserted along a
// Hilbert curve (CGAL's spatial sort), each located from the last and near it: the street
// stream's 22 k Steiner points took 0.76 s in the grid's order, 0.30-0.37 s along the curve (the
// same triangulation and mesh bytes).
void Engine::Impl::PlaceSteinerPoints(const KeyframeUpdate& update, size_t first_new_camera) {
  using Segment = detail::SteinerGrid::Segment;
  std::vector<Segment> segments;
  const double max_len = s.opt.max_ray_length;
  auto ray = [&](const Point& c, const Point& p) {
    const double len2 = CGAL::squared_distance(c, p);
    if (len2 <= max_len * max_len) {
      segments.push_back({c, p});
    } else if (s.opt.long_rays == LongRays::kNearCamera) {
      const double f = max_len / std::sqrt(len2);
      segments.push_back({c, c + f * (p - c)});
    }
  };
  // A camera's path from the one before, when it is a step (not a jump to another place).
  for (size_t c = first_new_camera; c < s.cameras.size(); ++c) {
    const bool step = c > 0 && s.opt.camera_path > 0 &&
                      CGAL::squared_distance(s.cameras[c - 1], s.cameras[c]) <= max_len * max_len;
    segments.push_back({step ? s.cameras[c - 1] : s.cameras[c], s.cameras[c]});
  }
  for (const NewPoint& p : update.new_points) {
    const Point end = ToPoint(p.position);
    for (uint64_t cam : p.camera_ids) ray(s.cameras[s.camera_index.at(cam)], end);
  }
  // A moved point's rays from its last `window` cameras are cast again to its new position
  // (older ones keep their end), and those from its new cameras. Its window's rays are followed
  // again once it is a quarter step from where they were last followed: a ray within a quarter
  // step of one followed has nodes at least the margin less a quarter step around it (following
  // them at every move of every point took imr-bench speed's Steiner phase from 0.6 to 1.3 s;
  // this takes 0.1 s and places the same nodes there).
  const double again = 0.25 * s.opt.steiner_spacing;
  for (const MovedPoint& m : update.moved_points) {
    PointRecord& rec = s.points[s.point_index.at(m.id)];
    if (rec.removed) continue;
    const Point end = ToPoint(m.position);
    for (uint64_t cam : m.camera_ids) ray(s.cameras[s.camera_index.at(cam)], end);
    if (CGAL::squared_distance(ToPoint(rec.grid_end), end) <= again * again) continue;
    rec.grid_end = m.position;
    for (uint32_t cam : s.Window(rec)) ray(s.cameras[cam], end);
  }
  std::vector<std::pair<Point, int64_t>> points;
  for (const Point& p : steiner.NewPoints(segments, stop_requested))
    points.emplace_back(p, -(++steiner_nodes_));
  using PointOf = CGAL::First_of_pair_property_map<std::pair<Point, int64_t>>;
  CGAL::spatial_sort(points.begin(), points.end(),
                     CGAL::Spatial_sort_traits_adapter_3<detail::K, PointOf>());
  size_t placed = 0;
  for (const auto& [p, id] : points) {
    if ((++placed & 0x3FF) == 0 && stop_requested && stop_requested())
      throw detail::Stopped("stopped on request while inserting the Steiner grid's points");
    bool dup = false;
    std::vector<RayEntry> u;
    Vertex_handle v = InsertPoint(p, id, s.opt.transfer_on_insert, &dup, &u);
    if (v == Vertex_handle()) {
      ++s.stats.steiner_dropped;
      continue;
    }
    ++s.stats.steiner_points;
    if (s.opt.visibility_mode == VisibilityMode::kRays) caster.RecastRays(std::move(u), -1);
  }
}

void Engine::Impl::TimedCast(uint32_t cam, uint32_t pt, int sign) {
  const auto t0 = Clock::now();
  caster.Cast(cam, pt, sign);
  s.stats.time.cast += SecondsSince(t0);
}

void Engine::Impl::TimedRecast(std::vector<RayEntry> u, int64_t skip) {
  const auto t0 = Clock::now();
  caster.RecastRays(std::move(u), skip);
  s.stats.time.cast += SecondsSince(t0);
}

void Engine::Impl::TimedScan(uint32_t pt) {
  const auto t0 = Clock::now();
  caster.ScanRemoveRays(pt);
  s.stats.time.scan += SecondsSince(t0);
}

void Engine::Impl::RemovePoint(uint32_t pt) {
  PointRecord& rec = s.points[pt];
  if (s.opt.visibility_mode == VisibilityMode::kExact) {
    ExactRemovePoint(pt);
    return;
  }
  if (!rec.in_triangulation) {
    rec.removed = true;
    return;
  }
  std::vector<Cell_handle> inc;
  s.dt.incident_cells(rec.vertex, std::back_inserter(inc));
  if (s.BlockedByFinal(inc) || !carving.Shrink(inc, {rec.vertex->point()})) {
    ++s.stats.moves_skipped;  // Cannot be removed without breaking dO; keep it.
    return;
  }
  const bool rays_mode = s.opt.visibility_mode == VisibilityMode::kRays;
  if (!rays_mode)
    for (uint32_t c : s.Window(rec)) TimedCast(c, pt, -1);
  std::vector<RayEntry> u;
  RemoveVertex(rec.vertex, rays_mode ? &u : nullptr);
  rec.in_triangulation = false;
  rec.removed = true;
  rec.vertex = Vertex_handle();
  ++s.stats.points_removed;
  if (rays_mode) {
    TimedScan(pt);
    TimedRecast(std::move(u), pt);
  }
}

// kExact removal: every ray of the point out of its cells, then the vertex (its star's other
// rays walked again through the new cells).
void Engine::Impl::ExactRemovePoint(uint32_t pt) {
  PointRecord& rec = s.points[pt];
  if (rec.in_triangulation) {
    std::vector<Cell_handle> inc;
    s.dt.incident_cells(rec.vertex, std::back_inserter(inc));
    if (s.BlockedByFinal(inc) || !carving.Shrink(inc, {rec.vertex->point()})) {
      ++s.stats.moves_skipped;  // Cannot be removed without breaking dO; keep it.
      return;
    }
  }
  const auto t0 = Clock::now();
  for (size_t k = 0; k < rec.cameras.size(); ++k) caster.ExactUncast(pt, k);
  s.stats.time.cast += SecondsSince(t0);
  rec.removed = true;
  if (rec.in_triangulation) {
    const Vertex_handle v = rec.vertex;
    rec.in_triangulation = false;
    rec.vertex = Vertex_handle();
    RemoveVertex(v, nullptr);
    ++s.stats.points_removed;
  }
}

// D of a move p_old -> p_new: the old vertex's star (given in *d) and the conflict zone of the
// new position, taken out of O. False (counted as skipped) when a vertex sits at p_new already
// or D cannot leave O while dO stays manifold.
bool Engine::Impl::ShrinkMoveRegion(Vertex_handle v, const Point& p_old, const Point& p_new,
                                    std::vector<Cell_handle>* d) {
  Dt::Locate_type lt;
  int li, lj;
  Cell_handle loc = s.dt.locate(p_new, lt, li, lj, v->cell());
  if (lt == Dt::VERTEX) {
    ++s.stats.moves_duplicate;
    ++s.stats.moves_skipped;
    return false;
  }
  s.dt.find_conflicts(p_new, loc, CGAL::Emptyset_iterator(), std::back_inserter(*d));
  std::sort(d->begin(), d->end());
  d->erase(std::unique(d->begin(), d->end()), d->end());
  if (s.BlockedByFinal(*d) || !carving.Shrink(*d, {p_old, p_new})) {
    ++s.stats.moves_skipped;
    return false;
  }
  return true;
}

// kExact move: in place when the cells stay (MovePlanner::StarStaysDelaunay), else the vertex
// removed and re-inserted at the new position, the region both change taken as one hole. Its rays
// are not touched here: ApplyUpdate un-casts the window's rays of every moving point before the
// moves and casts them again after (UncastMoving, CastUpdated), so the holes of the moves carry
// fewer rays.
void Engine::Impl::ExactMovePoint(uint32_t pt, const MovedPoint& m) {
  PointRecord& rec = s.points[pt];
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
  s.dt.incident_cells(rec.vertex, std::back_inserter(d));
  if (detail::MovePlanner::StarStaysDelaunay(s.dt, rec.vertex, p_new, d)) {
    // The same cells, reshaped: only the star's rays are walked again.
    if (s.BlockedByFinal(d, /*strict=*/true) || !carving.Shrink(d, {p_old, p_new})) {
      ++s.stats.moves_skipped;
      return;
    }
    Removed removed;
    transfer.CollectRemoved(d, &removed);
    for (Cell_handle c : d) {
      c->info().weight = 0;
      c->info().rays.clear();
    }
    rec.vertex->set_point(p_new);
    transfer.AssignNewCells(d, removed, false);
    ++s.stats.points_moved;
    ++s.stats.moves_in_place;
    return;
  }
  if (!ShrinkMoveRegion(rec.vertex, p_old, p_new, &d)) return;
  const Vertex_handle v_old = rec.vertex;
  // Removal and insertion change D's cells only (a cell outside D was not in conflict with
  // p_new, and stays so without v), and none is in O: one hole, D's rays collected before
  // and walked once through the cells that fill D after both.
  Removed removed;
  transfer.CollectRemoved(d, &removed);
  if (s.last_vertex == v_old) s.last_vertex = Vertex_handle();
  std::vector<Cell_handle> made;
  s.dt.remove_and_give_new_cells(v_old, std::back_inserter(made));
  Dt::Locate_type lt;
  int li, lj;
  const Cell_handle loc = s.dt.locate(p_new, lt, li, lj, made.front());
  std::vector<Cell_handle> conflicts;
  Facet boundary;
  if (lt != Dt::VERTEX)  // ShrinkMoveRegion found no vertex there
    s.dt.find_conflicts(p_new, loc, CGAL::Oneset_iterator<Facet>(boundary),
                        std::back_inserter(conflicts));
  // The cells the insertion destroys of those the removal made never held anything.
  const uint64_t doomed = ++s.stamp;  // stamps are only compared for equality
  for (Cell_handle c : conflicts) c->info().stamp = doomed;
  std::vector<Cell_handle> added;
  for (Cell_handle c : made)
    if (c->info().stamp != doomed) added.push_back(c);
  if (conflicts.empty()) {
    rec.in_triangulation = false;
    rec.vertex = Vertex_handle();
    s.BornFinal(added);
    transfer.AssignNewCells(added, removed, false);
    ++s.stats.points_dropped;  // Cannot happen: counted if it ever does.
    return;
  }
  const Vertex_handle v = s.dt.insert_in_hole(p_new, conflicts.begin(), conflicts.end(),
                                              boundary.first, boundary.second);
  v->info().id = pt;
  s.last_vertex = v;
  rec.vertex = v;
  s.dt.incident_cells(v, std::back_inserter(added));
  s.BornFinal(added);
  transfer.AssignNewCells(added, removed, false);
  ++s.stats.points_moved;
}

// kExact: the update's moves in MoveOrder's order, planned ahead on the engine's threads in
// batches and committed one by one (MovePlanner). A plan an earlier commit of its batch made
// stale is made again at its turn; plans do not depend on when they are made, so the cells,
// weights and mesh are the same for any number of threads. On one thread (or planned_moves
// false) each move is made with CGAL's removal and insertion: the same cells.
void Engine::Impl::ExactMoves(const KeyframeUpdate& u) {
  const size_t n = u.moved_points.size();
  MoveOrder(u);
  util::ThreadPool& tp = s.Pool();
  const int threads = tp.size();
  if (threads <= 1 || !s.opt.planned_moves) {
    for (size_t i : move_order_) MoveOne(u, i);
    return;
  }
  planner.Workers(threads);
  if (plans_.size() < kMoveStrata) plans_.resize(kMoveStrata);
  for (size_t i0 = 0; i0 < n; i0 += kMoveStrata) {
    const size_t i1 = std::min(n, i0 + kMoveStrata);
    const auto t0 = Clock::now();
    tp.Run(i1 - i0, [&](size_t j, int worker) {
      PlanMove(u, move_order_[i0 + j], worker, &plans_[j]);
    });
    s.stats.time.threaded += SecondsSince(t0);
    s.stats.moves_planned_ahead += static_cast<int64_t>(i1 - i0);
    for (size_t j = i0; j < i1; ++j) {
      detail::MovePlan& plan = plans_[j - i0];
      if (!planner.Valid(plan)) {
        ++s.stats.moves_replanned;
        PlanMove(u, move_order_[j], 0, &plan);
      }
      CommitMove(u, move_order_[j], plan);
    }
  }
}

// The order of a keyframe's moves (kExact), the same for any number of threads: along a
// Morton curve over the points' positions, dealt out in turn from kMoveStrata stretches of it,
// so that the moves planned together lie far apart and seldom change one another's cells.
void Engine::Impl::MoveOrder(const KeyframeUpdate& u) {
  const size_t n = u.moved_points.size();
  std::vector<std::array<double, 3>> at(n);
  double lo[3] = {0, 0, 0}, hi[3] = {0, 0, 0};
  for (size_t i = 0; i < n; ++i) {
    const PointRecord& rec = s.points[s.point_index.at(u.moved_points[i].id)];
    const Vec3& p = rec.position;
    at[i] = rec.in_triangulation
                ? std::array<double, 3>{rec.vertex->point().x(), rec.vertex->point().y(),
                                        rec.vertex->point().z()}
                : std::array<double, 3>{p[0], p[1], p[2]};
    for (int k = 0; k < 3; ++k) {
      lo[k] = i == 0 ? at[i][k] : std::min(lo[k], at[i][k]);
      hi[k] = i == 0 ? at[i][k] : std::max(hi[k], at[i][k]);
    }
  }
  std::vector<std::pair<uint64_t, size_t>> keyed(n);
  for (size_t i = 0; i < n; ++i) {
    uint64_t code = 0;
    for (int k = 0; k < 3; ++k) {
      const double span = hi[k] - lo[k];
      const double f = span > 0.0 && std::isfinite(span) ? (at[i][k] - lo[k]) / span : 0.0;
      const uint64_t q = static_cast<uint64_t>(std::clamp(f, 0.0, 1.0) * 2097151.0);
      for (int b = 0; b < 21; ++b) code |= ((q >> b) & 1u) << (3 * b + k);
    }
    keyed[i] = {code, i};
  }
  std::sort(keyed.begin(), keyed.end());
  const size_t stretch = (n + kMoveStrata - 1) / kMoveStrata;
  move_order_.clear();
  for (size_t j = 0; j < stretch; ++j)
    for (size_t b = 0; b < kMoveStrata; ++b)
      if (b * stretch + j < n) move_order_.push_back(keyed[b * stretch + j].second);
}

// Move i of the update as it is made: one shorter than min_move_fraction is held, the vertex
// kept where it is (what is left of the move is adding its new cameras; EndHeldMove after).
// Returns the update's move, or *kept when held.
const MovedPoint& Engine::Impl::MoveAsMade(const KeyframeUpdate& u, size_t i, MovedPoint* kept,
                                           bool* held) const {
  const MovedPoint& m = u.moved_points[i];
  const PointRecord& rec = s.points[s.point_index.at(m.id)];
  *held = short_move_[i] && rec.in_triangulation;
  if (!*held) return m;
  *kept = m;
  const Point& v = rec.vertex->point();
  kept->position = {v.x(), v.y(), v.z()};
  return *kept;
}

// A held move made: the point's position is the update's, its vertex where it was.
void Engine::Impl::EndHeldMove(const MovedPoint& m, uint32_t pt) {
  s.points[pt].position = m.position;
  ++s.stats.moves_below_min;
}

// Move i of the update, made at once.
void Engine::Impl::MoveOne(const KeyframeUpdate& u, size_t i) {
  MovedPoint kept;
  bool held = false;
  const MovedPoint& made = MoveAsMade(u, i, &kept, &held);
  const uint32_t pt = s.point_index.at(made.id);
  MovePoint(pt, made);
  if (held) EndHeldMove(u.moved_points[i], pt);
}

// Move i of the update planned.
void Engine::Impl::PlanMove(const KeyframeUpdate& u, size_t i, int worker,
                            detail::MovePlan* plan) {
  MovedPoint kept;
  bool held = false;
  const MovedPoint& made = MoveAsMade(u, i, &kept, &held);
  planner.Plan(s.point_index.at(made.id), ToPoint(made.position), worker, plan);
}

void Engine::Impl::CommitMove(const KeyframeUpdate& u, size_t i, detail::MovePlan& plan) {
  using Kind = detail::MovePlan::Kind;
  MovedPoint kept;
  bool held = false;
  const MovedPoint& made = MoveAsMade(u, i, &kept, &held);
  const uint32_t pt = plan.pt;
  if (plan.kind == Kind::kSerial) {
    ExactMovePoint(pt, made);
  } else {
    PointRecord& rec = s.points[pt];
    rec.position = made.position;
    AddCameras(rec, made.camera_ids, nullptr);
    if (plan.kind == Kind::kDuplicate) {
      ++s.stats.moves_duplicate;
      ++s.stats.moves_skipped;
    } else if (plan.kind != Kind::kKeep) {
      planner.Commit(plan);
    }
  }
  if (held) EndHeldMove(u.moved_points[i], pt);
}

// Move p_old -> p_new (paper §3): backward cast over the last W cameras, remove, transfer,
// insert, transfer, forward cast; or, in kRays mode, the Refinement Event Handler of Lovi et al.
void Engine::Impl::MovePoint(uint32_t pt, const MovedPoint& m) {
  if (s.opt.visibility_mode == VisibilityMode::kExact) {
    ExactMovePoint(pt, m);
    return;
  }
  PointRecord& rec = s.points[pt];
  if (!rec.in_triangulation) {
    MoveAbsentPoint(pt, m);
    return;
  }
  rec.position = m.position;
  std::vector<uint32_t> added_cams;
  const Point p_new = ToPoint(m.position);
  const Point p_old = rec.vertex->point();
  const bool rays_mode = s.opt.visibility_mode == VisibilityMode::kRays;
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
  s.dt.incident_cells(rec.vertex, std::back_inserter(d));
  if (!ShrinkMoveRegion(rec.vertex, p_old, p_new, &d)) {
    cast_new_observations();
    return;
  }
  std::vector<RayEntry> u;
  if (!rays_mode)
    for (uint32_t c : s.Window(rec)) TimedCast(c, pt, -1);
  RemoveVertex(rec.vertex, rays_mode ? &u : nullptr);
  rec.in_triangulation = false;
  bool dup = false;
  std::vector<RayEntry> u2;
  if (s.opt.transfer_camera_side) {
    transfer.SetCameraSide(&p_new, &rec.cameras);
  }
  Vertex_handle v = InsertPoint(p_new, pt, true, &dup, rays_mode ? &u2 : nullptr);
  transfer.SetCameraSide(nullptr, nullptr);
  u.insert(u.end(), u2.begin(), u2.end());
  if (v == Vertex_handle()) {
    // Cannot happen when D was shrunk out of O (the new conflict zone lies in D's cells or in
    // cells created by the removal); counted as a drop if it ever does.
    ++s.stats.points_dropped;
    rec.vertex = Vertex_handle();
    if (rays_mode) {
      TimedScan(pt);
      TimedRecast(std::move(u), pt);
    }
    return;
  }
  rec.vertex = v;
  rec.in_triangulation = true;
  ++s.stats.points_moved;
  AddCameras(rec, m.camera_ids, &added_cams);
  if (rays_mode) {
    TimedScan(pt);  // Rays ending at p_old, everywhere.
    for (uint32_t c : added_cams) u.push_back({c, pt, 0});  // New observations join U.
    TimedRecast(std::move(u), -1);  // Rays to p now end at p_new.
  } else {
    for (uint32_t c : s.Window(rec)) TimedCast(c, pt, +1);
  }
}

void Engine::Impl::InsertNewPoint(const NewPoint& np) {
  const uint32_t pt = static_cast<uint32_t>(s.points.size());
  s.point_index[np.id] = pt;
  s.points.push_back({});
  PointRecord& rec0 = s.points.back();
  rec0.id = np.id;
  rec0.named = static_cast<int64_t>(s.cameras.size());
  rec0.position = np.position;
  rec0.grid_end = np.position;  // PlaceSteinerPoints followed its rays there
  AddCameras(rec0, np.camera_ids, nullptr);
  Enter(pt, /*again=*/false);
}

bool Engine::Impl::Enter(uint32_t pt, bool again) {
  bool dup = false;
  std::vector<RayEntry> u;
  const bool rays_mode = s.opt.visibility_mode == VisibilityMode::kRays;
  const Point p = ToPoint(s.points[pt].position);
  if (s.opt.transfer_camera_side) {
    transfer.SetCameraSide(&p, &s.points[pt].cameras);
  }
  const int64_t refused_before = s.stats.changes_refused_final;
  Vertex_handle v = InsertPoint(p, pt, s.opt.transfer_on_insert, &dup, rays_mode ? &u : nullptr);
  transfer.SetCameraSide(nullptr, nullptr);
  PointRecord& rec = s.points[pt];
  if (v == Vertex_handle()) {
    if (!again) ++(dup ? s.stats.points_duplicate : s.stats.points_dropped);
    // A new point in space already handed out (forget): dropped for that, said apart.
    if (!again && s.stats.changes_refused_final > refused_before) ++s.stats.points_refused_final;
    return false;
  }
  rec.vertex = v;
  rec.in_triangulation = true;
  ++(again ? s.stats.points_reentered : s.stats.points_inserted);
  if (rays_mode) {
    for (uint32_t c : rec.cameras) u.push_back({c, pt, 0});
    TimedRecast(std::move(u), -1);
  } else if (s.opt.visibility_mode == VisibilityMode::kExact) {
    entered_.push_back(pt);  // its rays are cast with the keyframe's batch
  } else {
    for (uint32_t c : rec.cameras) TimedCast(c, pt, +1);
  }
  return true;
}

// A move of a point that is not in the triangulation: removed ones stay out; one refused at
// insertion (a duplicate, or dropped) tries again at its new position.
void Engine::Impl::MoveAbsentPoint(uint32_t pt, const MovedPoint& m) {
  PointRecord& rec = s.points[pt];
  rec.position = m.position;
  AddCameras(rec, m.camera_ids, nullptr);
  if (rec.removed || !Enter(pt, /*again=*/true)) ++s.stats.moves_skipped;
}

// kExact keyframe: the window's rays of every point that moves are un-cast together before any
// move and cast together after the moves and insertions. The holes the moves make then carry
// only the rays of points that stay (a fifteenth of them on the street stream), and both
// batches run on all threads. A ray that leaves the window during the move (its point gained
// cameras) is not cast again: a moving point keeps the rays of its last W cameras only, which
// the quality bench prefers (street stream F 0.742 against 0.705 keeping them).
// The (point, ray index) pairs of point pt's window.
void Engine::Impl::WindowRays(uint32_t pt, std::vector<std::pair<uint32_t, uint32_t>>* out) const {
  const PointRecord& rec = s.points[pt];
  for (size_t k = s.WindowBegin(rec); k < rec.cameras.size(); ++k)
    out->push_back({pt, static_cast<uint32_t>(k)});
}

// Which moves of the update are shorter than min_move_fraction of the distance from the point's
// vertex to its nearest neighbour (decided on the triangulation before any move, so the order
// of the moves does not matter).
void Engine::Impl::FindShortMoves(const KeyframeUpdate& u) {
  short_move_.assign(u.moved_points.size(), 0);
  const double f2 = s.opt.min_move_fraction * s.opt.min_move_fraction;
  if (f2 <= 0.0 || s.dt.dimension() != 3) return;
  std::vector<Vertex_handle> around;
  for (size_t i = 0; i < u.moved_points.size(); ++i) {
    const PointRecord& rec = s.points[s.point_index.at(u.moved_points[i].id)];
    if (!rec.in_triangulation) continue;
    const Point& p = rec.vertex->point();
    const double d2 = CGAL::squared_distance(p, ToPoint(u.moved_points[i].position));
    if (d2 == 0.0) continue;
    around.clear();
    s.dt.finite_adjacent_vertices(rec.vertex, std::back_inserter(around));
    double nearest2 = std::numeric_limits<double>::infinity();
    for (Vertex_handle v : around)
      nearest2 = std::min(nearest2, CGAL::squared_distance(p, v->point()));
    short_move_[i] = d2 < f2 * nearest2 ? 1 : 0;
  }
}

void Engine::Impl::UncastMoving(const KeyframeUpdate& u) {
  std::vector<std::pair<uint32_t, uint32_t>> rays;
  for (size_t i = 0; i < u.moved_points.size(); ++i) {
    const MovedPoint& m = u.moved_points[i];
    const uint32_t pt = s.point_index.at(m.id);
    const PointRecord& rec = s.points[pt];
    if (rec.in_triangulation && !short_move_[i] && ToPoint(m.position) != rec.vertex->point())
      WindowRays(pt, &rays);
  }
  caster.UncastBatch(rays);
  caster.DropLists();  // the lists of the points that do not move: walked if they ever do
}

// What is not cast: the window's rays of the moved points (also of those that kept their
// position but gained a camera), every ray of the points that entered the triangulation.
void Engine::Impl::CastUpdated(const KeyframeUpdate& u) {
  std::vector<std::pair<uint32_t, uint32_t>> rays;
  std::vector<uint32_t> sorted = entered_;
  std::sort(sorted.begin(), sorted.end());
  for (const MovedPoint& m : u.moved_points) {
    const uint32_t pt = s.point_index.at(m.id);
    if (s.points[pt].in_triangulation && !std::binary_search(sorted.begin(), sorted.end(), pt))
      WindowRays(pt, &rays);
  }
  for (uint32_t pt : entered_)
    for (size_t k = 0; k < s.points[pt].cameras.size(); ++k)
      rays.push_back({pt, static_cast<uint32_t>(k)});
  caster.CastBatch(rays, /*weights_only=*/u.last);
}

Status Engine::Impl::ApplyUpdate(const KeyframeUpdate& update) {
  if (!init.ok()) return init;
  if (s.sealed)
    return Status::Error("an update after the last one (KeyframeUpdate::last): its rays were cast "
                         "as weights only, and a change of the cells would lose them");
  const Status valid = Validate(update);
  if (!valid.ok()) return valid;
  const std::unique_ptr<KeyframeUpdate> filtered = WithoutRetired(update);
  const KeyframeUpdate& u = filtered ? *filtered : update;
  const auto t0 = Clock::now();
  std::vector<Point> centres;
  for (const Camera& c : u.cameras) {
    if (s.camera_index.count(c.id)) continue;
    s.camera_index[c.id] = static_cast<uint32_t>(s.cameras.size());
    s.cameras.push_back(ToPoint(c.center));
    s.camera_ids.push_back(c.id);
    centres.push_back(s.cameras.back());
  }
  {
    const auto ts = Clock::now();
    PlaceSteinerPoints(u, s.cameras.size() - centres.size());
    s.stats.time.steiner += SecondsSince(ts);
  }
  if (s.opt.forget) forgetting.AddUpdateCameras(centres);  // a copy: measured below too
  const int64_t known = static_cast<int64_t>(s.cameras.size());
  for (const MovedPoint& m : u.moved_points) s.points[s.point_index.at(m.id)].named = known;
  for (uint64_t id : u.removed_points) s.points[s.point_index.at(id)].named = known;
  // Removals and insertions are charged to "insert", moves to "move"; both without their ray
  // casting and shrinking, which have their own timers.
  auto timed = [&](double* phase, auto&& fn) {
    const double cast0 = s.stats.time.cast, shrink0 = s.stats.time.shrink;
    const double scan0 = s.stats.time.scan;
    const auto a = Clock::now();
    fn();
    *phase += SecondsSince(a) - (s.stats.time.cast - cast0) -
              (s.stats.time.shrink - shrink0) - (s.stats.time.scan - scan0);
  };
  timed(&s.stats.time.insert, [&] {
    for (uint64_t id : u.removed_points) RemovePoint(s.point_index.at(id));
  });
  const bool exact = s.opt.visibility_mode == VisibilityMode::kExact;
  entered_.clear();
  auto timed_batch = [&](auto&& fn) {  // the batches are ray casting
    const auto a = Clock::now();
    fn();
    const double dt = SecondsSince(a);
    s.stats.time.cast += dt;
    s.stats.time.threaded += dt;
  };
  FindShortMoves(u);
  if (exact && s.opt.check_invariants) {
    // The lists are consumed next: check them after the Steiner points and removals changed
    // the cells (the check after the update sees them only as the cast batch made them).
    const std::string lists = detail::InvariantChecker(s).CheckRayLists();
    if (!lists.empty()) return Status::Error("invariant broken before the un-cast batch: " + lists);
  }
  if (exact) timed_batch([&] { UncastMoving(u); });
  // Between the batches no ray lists are kept: the triangulation may be rebuilt.
  if (s.opt.forget && forgetting.Due()) Forget();
  timed(&s.stats.time.move, [&] {
    if (exact) {
      ExactMoves(u);
      return;
    }
    for (size_t i = 0; i < u.moved_points.size(); ++i) MoveOne(u, i);
  });
  timed(&s.stats.time.insert, [&] {
    for (const NewPoint& p : u.new_points) InsertNewPoint(p);
  });
  if (exact) timed_batch([&] { CastUpdated(u); });
  if (u.last) s.sealed = true;  // before the checks below: weights without entries
  const auto tg = Clock::now();
  if (s.opt.regrow_radius > 0.0) {
    std::vector<Vertex_handle> changed;
    for (size_t i = 0; i < u.moved_points.size(); ++i) {
      const PointRecord& rec = s.points[s.point_index.at(u.moved_points[i].id)];
      if (rec.in_triangulation && !short_move_[i]) changed.push_back(rec.vertex);
    }
    for (const NewPoint& p : u.new_points) {
      const PointRecord& rec = s.points[s.point_index.at(p.id)];
      if (rec.in_triangulation) changed.push_back(rec.vertex);
    }
    carving.PeelAround(changed, s.opt.regrow_radius);
  }
  // The camera path (camera_path) is free space: its cells join O before grow, so that O grows
  // on from them; after it, again, and a camera whose cell is still outside O has O peeled around
  // it and grown again from its cell (OpenCameraPath).
  const bool open_path = s.opt.camera_path > 0 && s.dt.dimension() == 3;
  const std::vector<Cell_handle> path = open_path ? CameraPathCells() : std::vector<Cell_handle>();
  if (open_path && s.cells_in_o > 0) carving.OpenPath(path);
  carving.Grow(s.opt.forget ? CameraCell() : Cell_handle());
  if (open_path && s.cells_in_o > 0) OpenCameraPath(path);
  s.stats.time.grow += SecondsSince(tg);
  const double dt_s = SecondsSince(t0);
  s.stats.time.total += dt_s;
  s.stats.keyframe_seconds.push_back(dt_s);
  ++s.stats.updates;
  s.stats.vertices = static_cast<int64_t>(s.dt.number_of_vertices());
  s.stats.cells = static_cast<int64_t>(s.dt.tds().number_of_cells());
  s.stats.cells_in_o = s.cells_in_o;
  // Where the new cameras are now: in O (free space), or inside matter. Not in the keyframe's time.
  // Before O exists there is nothing to be in or outside of: such cameras (the first keyframe's)
  // are checked at the first update that has an O, the camera path having been opened for them.
  s.unchecked_centres.insert(s.unchecked_centres.end(), centres.begin(), centres.end());
  if (s.dt.dimension() == 3 && s.cells_in_o > 0) {
    for (const Point& c : s.unchecked_centres) {
      ++s.stats.cameras_checked;
      // From the newest point's cell: the cameras are near what they just saw.
      const Cell_handle cell = s.dt.locate(c, s.WalkHint());
      if (!s.dt.is_infinite(cell) && cell->info().in_o) ++s.stats.cameras_in_o;
    }
    s.unchecked_centres.clear();
  }
  if (s.opt.check_invariants) {
    ManifoldCheckResult r = detail::InvariantChecker(s).Check();
    if (!r.ok) return Status::Error("invariant broken after update: " + r.message);
  }
  return Status::Ok();
}

Mesh Engine::Impl::ToMesh(const std::vector<Triangle>& tris, SteinerExportRule rule) const {
  Mesh m;
  std::unordered_map<Vertex_handle, uint32_t> index;
  for (const Triangle& t : tris) {
    int steiner_vertices = 0;
    for (Vertex_handle v : t.v) steiner_vertices += v->info().id < 0 ? 1 : 0;
    if (rule == SteinerExportRule::kAllSteiner && steiner_vertices == 3) continue;
    if (rule == SteinerExportRule::kAnySteiner && steiner_vertices > 0) continue;
    for (Vertex_handle v : t.v) {
      auto [it, inserted] = index.emplace(v, static_cast<uint32_t>(index.size()));
      if (inserted) {
        const Point& p = v->point();
        m.vertices.insert(m.vertices.end(), {p.x(), p.y(), p.z()});
        const int64_t id = v->info().id;
        m.point_ids.push_back(id >= 0 ? static_cast<int64_t>(s.points[id].id) : -1);
      }
      m.faces.push_back(it->second);
    }
  }
  CanonicalizeMesh(&m);
  return m;
}

// The triangles as a SurfacePart: through the Steiner filter, in a canonical order (the vertices'
// internal ids, which do not depend on CGAL's storage: the same part for any number of threads),
// each vertex with its key (given here when the vertex is named for the first time).
SurfacePart Engine::Impl::MakePart(std::vector<Triangle> tris) {
  const SteinerExportRule rule = s.opt.steiner_export;
  using Ids = std::array<int64_t, 3>;
  std::vector<std::pair<Ids, Triangle>> kept;
  kept.reserve(tris.size());
  for (const Triangle& t : tris) {
    int steiner_vertices = 0;
    for (Vertex_handle v : t.v) steiner_vertices += v->info().id < 0 ? 1 : 0;
    if (rule == SteinerExportRule::kAllSteiner && steiner_vertices == 3) continue;
    if (rule == SteinerExportRule::kAnySteiner && steiner_vertices > 0) continue;
    // Rotated to start at its smallest id, orientation kept.
    int first = 0;
    for (int k = 1; k < 3; ++k)
      if (t.v[k]->info().id < t.v[first]->info().id) first = k;
    Triangle r;
    for (int k = 0; k < 3; ++k) r.v[k] = t.v[(first + k) % 3];
    kept.push_back({{r.v[0]->info().id, r.v[1]->info().id, r.v[2]->info().id}, r});
  }
  std::sort(kept.begin(), kept.end(),
            [](const auto& a, const auto& b) { return a.first < b.first; });
  SurfacePart part;
  part.update = s.stats.updates;
  std::unordered_map<Vertex_handle, uint32_t> index;
  for (const auto& [ids, t] : kept)
    for (Vertex_handle v : t.v) {
      auto [it, inserted] = index.emplace(v, static_cast<uint32_t>(index.size()));
      if (inserted) {
        const Point& p = v->point();
        part.vertices.insert(part.vertices.end(), {p.x(), p.y(), p.z()});
        if (v->info().key < 0) v->info().key = next_key_++;
        part.keys.push_back(v->info().key);
        const int64_t id = v->info().id;
        part.point_ids.push_back(id >= 0 ? static_cast<int64_t>(s.points[id].id) : -1);
      }
      part.faces.push_back(it->second);
    }
  return part;
}

// A facet of dO between two final cells was handed out when the second became final (or, next
// to a forgotten cell, lies where forgotten vertices were: never a surface).
std::vector<Triangle> Engine::Impl::LiveBoundary() const { return Boundary(s, /*live=*/true); }

std::unique_ptr<KeyframeUpdate> Engine::Impl::WithoutRetired(const KeyframeUpdate& u) {
  if (!s.opt.forget || forgetting.retired().runs() == 0) return nullptr;
  auto retired = [&](uint64_t id) { return !s.point_index.count(id); };  // Validate: retired
  const int64_t moves = std::count_if(u.moved_points.begin(), u.moved_points.end(),
                                      [&](const MovedPoint& m) { return retired(m.id); });
  const int64_t removals = std::count_if(u.removed_points.begin(), u.removed_points.end(), retired);
  if (moves + removals == 0) return nullptr;
  s.stats.updates_of_forgotten_points += moves + removals;
  auto out = std::make_unique<KeyframeUpdate>();
  out->cameras = u.cameras;
  out->new_points = u.new_points;
  for (const MovedPoint& m : u.moved_points)
    if (!retired(m.id)) out->moved_points.push_back(m);
  for (uint64_t id : u.removed_points)
    if (!retired(id)) out->removed_points.push_back(id);
  out->last = u.last;
  return out;
}

// What became final since the last step, handed out; its vertices that nothing can change any
// more are completed.
void Engine::Impl::Forget() {
  const auto t0 = Clock::now();
  std::vector<Triangle> facets;
  std::vector<Vertex_handle> deep;
  forgetting.Freeze(&facets, &deep);
  SurfacePart part = MakePart(std::move(facets));
  for (Vertex_handle v : deep)
    if (v->info().key >= 0) part.completed.push_back(v->info().key);
  std::sort(part.completed.begin(), part.completed.end());
  if (!part.faces.empty() || !part.completed.empty()) {
    ++s.stats.parts;
    s.stats.part_triangles += static_cast<int64_t>(part.faces.size() / 3);
    final_parts_.push_back(std::move(part));
  }
  forgetting.MaybeRebuild();
  s.stats.live_samples.push_back(
      {s.stats.updates, static_cast<int64_t>(s.dt.number_of_cells()) - s.stats.cells_final,
       static_cast<int64_t>(s.points.size()), static_cast<int64_t>(s.dt.number_of_vertices())});
  s.stats.time.forget += SecondsSince(t0);
}

// The cell holding the newest camera when the cameras are back where they were long ago
// (Forgetting::Returned) and no cell of O lies within two grid steps of it: the O that was there
// is forgotten, and O must start there again.
Engine::Impl::Cell_handle Engine::Impl::CameraCell() {
  if (s.cameras.empty() || s.dt.dimension() != 3 || s.cells_in_o == 0 || !forgetting.Returned())
    return Cell_handle();
  const Point& camera = s.cameras.back();
  Dt::Locate_type lt;
  int li, lj;
  const Cell_handle c = s.dt.locate(camera, lt, li, lj, s.WalkHint());
  if (lt != Dt::CELL || s.dt.is_infinite(c) || c->info().in_o) return Cell_handle();
  const double r = 2.0 * s.opt.steiner_spacing;
  const uint64_t seen = ++s.stamp;  // stamps are only compared for equality
  std::vector<Cell_handle> todo = {c};
  c->info().stamp = seen;
  for (size_t i = 0; i < todo.size(); ++i) {
    for (int k = 0; k < 4; ++k) {
      const Cell_handle n = todo[i]->neighbor(k);
      if (n->info().stamp == seen || s.dt.is_infinite(n)) continue;
      n->info().stamp = seen;
      if (n->info().in_o) return Cell_handle();
      if (CGAL::squared_distance(s.Centroid(n), camera) <= r * r) todo.push_back(n);
    }
  }
  return c;
}

std::vector<Engine::Impl::Cell_handle> Engine::Impl::CameraPathCells() {
  std::vector<Cell_handle> path;
  const size_t n = s.cameras.size();
  const size_t k = std::min(n, static_cast<size_t>(s.opt.camera_path));
  const uint64_t seen = ++s.stamp;  // stamps are only compared for equality
  Cell_handle hint = s.WalkHint();
  auto visit = [&](const Point& p) {
    const Cell_handle c = s.dt.locate(p, hint);
    if (s.dt.is_infinite(c)) return;
    hint = c;
    if (c->info().stamp == seen) return;
    c->info().stamp = seen;
    path.push_back(c);
  };
  // Samples a tenth of the Steiner spacing apart (cells along the path are larger: the Steiner
  // grid keeps points around the cameras that far apart), at most 256 per segment.
  const double step = s.opt.steiner_spacing > 0.0 ? s.opt.steiner_spacing / 10.0 : 0.5;
  for (size_t i = n - k; i < n; ++i) {
    const Point& b = s.cameras[i];
    if (i > n - k) {
      const Point& a = s.cameras[i - 1];
      const double len = std::sqrt(CGAL::squared_distance(a, b));
      const int samples = static_cast<int>(std::min(256.0, std::ceil(len / step)));
      for (int j = 1; j < samples; ++j) {
        const double t = static_cast<double>(j) / samples;
        visit(Point(a.x() + t * (b.x() - a.x()), a.y() + t * (b.y() - a.y()),
                    a.z() + t * (b.z() - a.z())));
      }
    }
    visit(b);
  }
  return path;
}

void Engine::Impl::OpenCameraPath(const std::vector<Cell_handle>& path) {
  if (carving.OpenPath(path) > 0) carving.Grow();
  if (s.opt.camera_path_radius <= 0.0) return;
  const size_t n = s.cameras.size();
  const size_t k = std::min(n, static_cast<size_t>(s.opt.camera_path));
  std::vector<Vertex_handle> around;
  for (size_t i = n - k; i < n; ++i) {
    const Cell_handle c = s.dt.locate(s.cameras[i], s.WalkHint());
    if (s.dt.is_infinite(c) || c->info().in_o || c->info().final || s.HullAdjacent(c)) continue;
    // Its cell could not join O as O is around it: O leaves the cells near it, its cell joins
    // first (touching O, with the free cells that keep dO manifold; else on its own) and O grows
    // again into the rest in weight order.
    // By id: PeelAround's region depends on the order of its centres, and a cell's vertex order
    // on the cell's history (CGAL's moves and the planned ones make the same cell differently).
    around.clear();
    for (int j = 0; j < 4; ++j) around.push_back(c->vertex(j));
    std::sort(around.begin(), around.end(), detail::EngineState::ById);
    carving.PeelAround(around, s.opt.camera_path_radius);
    carving.ForceCell(c);
    carving.Grow();  // labels only change: c is still a cell
    ++s.stats.camera_regrowths;
    if (c->info().in_o) ++s.stats.camera_cells_regrown;
  }
}

std::vector<SurfacePart> Engine::TakeFinalParts() {
  std::vector<SurfacePart> out;
  out.swap(impl_->final_parts_);
  return out;
}

SurfacePart Engine::FinishSurface() {
  Impl& m = *impl_;
  SurfacePart part = m.MakePart(m.LiveBoundary());
  // Every vertex named so far and not completed by a step is complete now, this part's too.
  for (auto v = m.s.dt.finite_vertices_begin(); v != m.s.dt.finite_vertices_end(); ++v)
    if (v->info().key >= 0 && !v->info().deep) part.completed.push_back(v->info().key);
  std::sort(part.completed.begin(), part.completed.end());
  ++m.s.stats.parts;
  m.s.stats.part_triangles += static_cast<int64_t>(part.faces.size() / 3);
  return part;
}

// -------------------------------------------------------------------------------------------------

Engine::Engine(const EngineOptions& options, WeightTransferPolicy* policy)
    : impl_(std::make_unique<Impl>(options, policy)) {}
Engine::~Engine() = default;

const Status& Engine::init_status() const { return impl_->init; }

void Engine::SetStopCheck(std::function<bool()> stop_requested) {
  impl_->stop_requested = std::move(stop_requested);
}

Status Engine::ApplyUpdate(const KeyframeUpdate& update) {
  try {
    return impl_->ApplyUpdate(update);
  } catch (const detail::Stopped& e) {
    return Status::Error(e.what());
  } catch (const std::exception& e) {
    return Status::Error(std::string("engine failure: ") + e.what());
  } catch (...) {
    return Status::Error("engine failure: unknown exception");
  }
}

Mesh Engine::ExtractMesh() const {
  const auto t0 = Clock::now();
  Mesh m = impl_->ToMesh(impl_->LiveBoundary(), impl_->s.opt.steiner_export);
  FinishExportedMesh(&m, impl_->s.opt);
  impl_->s.stats.time.extract += SecondsSince(t0);
  return m;
}

Mesh Engine::ExtractBoundary() const {
  return impl_->ToMesh(Boundary(impl_->s), SteinerExportRule::kNone);
}

const EngineStats& Engine::Stats() const { return impl_->s.stats; }

EngineMemory Engine::Memory() const {
  const detail::EngineState& s = impl_->s;
  // A hash map's node: the value, the next pointer and the cached hash (libstdc++).
  auto map_bytes = [](size_t size, size_t value, size_t buckets) {
    return static_cast<int64_t>(size * (value + 2 * sizeof(void*)) + buckets * sizeof(void*));
  };
  EngineMemory m;
  m.cells = static_cast<int64_t>(s.dt.tds().cells().capacity() * sizeof(detail::Tds::Cell));
  m.vertices = static_cast<int64_t>(s.dt.tds().vertices().capacity() * sizeof(detail::Tds::Vertex));
  for (auto c = s.dt.all_cells_begin(); c != s.dt.all_cells_end(); ++c) {
    const auto& rays = c->info().rays;
    m.ray_entries += static_cast<int64_t>(rays.capacity() * sizeof(detail::RayEntry));
    m.ray_entries_used += static_cast<int64_t>(rays.size());
    if (s.opt.visibility_mode == VisibilityMode::kExact)
      for (const detail::RayEntry& e : rays) m.ray_entries_live += s.Live(e) ? 1 : 0;
  }
  m.points = static_cast<int64_t>(s.points.capacity() * sizeof(PointRecord)) +
             map_bytes(s.point_index.size(), sizeof(std::pair<uint64_t, uint32_t>),
                       s.point_index.bucket_count());
  for (const PointRecord& r : s.points)
    m.points += static_cast<int64_t>(
        r.cameras.capacity() * sizeof(uint32_t) + r.ray_state.capacity() * sizeof(uint32_t) +
        r.ray_end.capacity() * sizeof(PointRecord::RayEnd) +
        r.ray_list.capacity() * sizeof(PointRecord::RayList));
  for (const auto& l : s.list_cells)
    m.ray_batch_lists += static_cast<int64_t>(l.capacity() * sizeof(detail::Cell_handle));
  for (const auto& [key, cells] : s.list_extra)
    m.ray_batch_lists += static_cast<int64_t>(cells.capacity() * sizeof(detail::Cell_handle));
  m.ray_batch_lists += map_bytes(s.list_extra.size(), sizeof(uint64_t) + 3 * sizeof(void*),
                                 s.list_extra.bucket_count());
  m.steiner_nodes = impl_->steiner.MemoryBytes();
  m.cameras = static_cast<int64_t>(s.cameras.capacity() * sizeof(detail::Point) +
                                   s.camera_ids.capacity() * sizeof(uint64_t)) +
              map_bytes(s.camera_index.size(), sizeof(std::pair<uint64_t, uint32_t>),
                        s.camera_index.bucket_count());
  return m;
}
const EngineOptions& Engine::options() const { return impl_->s.opt; }
ManifoldCheckResult Engine::CheckInvariants() const {
  return detail::InvariantChecker(impl_->s).Check();
}

Status Engine::CastPointRays(uint64_t point_id, const std::vector<uint64_t>& camera_ids,
                             int sign) {
  auto it = impl_->s.point_index.find(point_id);
  if (it == impl_->s.point_index.end())
    return Status::Error("unknown point " + std::to_string(point_id));
  if (sign != 1 && sign != -1) return Status::Error("sign must be +1 or -1");
  if (sign < 0 && impl_->s.opt.visibility_mode == VisibilityMode::kRays)
    return Status::Error("backward casting exists only in weights mode");
  for (uint64_t c : camera_ids) {
    auto ci = impl_->s.camera_index.find(c);
    if (ci == impl_->s.camera_index.end())
      return Status::Error("unknown camera " + std::to_string(c));
    impl_->caster.Cast(ci->second, it->second, sign);
  }
  return Status::Ok();
}

std::vector<std::pair<std::array<int64_t, 4>, int64_t>> Engine::CellWeights() const {
  std::vector<std::pair<std::array<int64_t, 4>, int64_t>> out;
  for (auto c = impl_->s.dt.finite_cells_begin(); c != impl_->s.dt.finite_cells_end(); ++c)
    out.push_back({impl_->s.CellKey(c), c->info().weight});
  std::sort(out.begin(), out.end());
  return out;
}

bool Engine::PointPosition(uint64_t point_id, Vec3* position) const {
  auto it = impl_->s.point_index.find(point_id);
  if (it == impl_->s.point_index.end()) return false;
  const auto& rec = impl_->s.points[it->second];
  if (!rec.in_triangulation) return false;
  const detail::Point& p = rec.vertex->point();
  *position = {p.x(), p.y(), p.z()};
  return true;
}

size_t Engine::NumPoints() const {
  size_t n = 0;
  for (const auto& p : impl_->s.points) n += p.in_triangulation ? 1 : 0;
  return n;
}

// -------------------------------------------------------------------------------------------------
// Benchmark and diagnostic hooks (engine_internal.h).

}  // namespace imr::engine
