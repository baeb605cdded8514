// The carving of O (paper section 2.2; engine_parts.h, Carving): the manifold test of one cell
// toggled, shrink (the cells of an enclosing set peeled out of O, lowest weight first), peel
// around changed points, and grow (the free cells touching dO join O, highest weight first).
// - O never contains a cell adjacent to an infinite cell, so dO is always closed and finite.
// - Growing after the first keyframe is seeded with the cells whose state changed during the
//   keyframe (became free, were created, or were shrunk), not with all of dO, so the cost of a
//   keyframe does not grow with the size of the reconstruction.
// The camera path's forced joins (OpenPath, ForceCell): camera_path.cc.
#include "host/engine/engine_parts.h"

#include <queue>

namespace imr::engine::detail {

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
  if (!ok && s_.forgetting)
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

}  // namespace imr::engine::detail
