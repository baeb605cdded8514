// kExact moves planned ahead (engine_parts.h, MovePlanner): what a move does to D, its cells,
// computed from the triangulation without writing to it, then committed in the keyframe's move
// order.
#include "host/engine/engine_parts.h"

#include <algorithm>
#include <cmath>

namespace imr::engine::detail {
namespace {

// CGAL's in-sphere test with its symbolic perturbation, on points given one by one (a cell's
// points with the moving vertex at its new place). Protected in Delaunay_triangulation_3; the
// member pointer taken through a derived class reaches it on any triangulation.
struct DtPredicates : Dt {
  static CGAL::Bounded_side SideOfSphere(const Dt& dt, const Point& p0, const Point& p1,
                                         const Point& p2, const Point& p3, const Point& q) {
    return static_cast<CGAL::Bounded_side>(
        (dt.*(&DtPredicates::side_of_oriented_sphere))(p0, p1, p2, p3, q, true));
  }
};

}  // namespace

// A plan's sets and lists (one per worker).
struct MovePlanner::Scratch {
  ScratchMap<uint8_t> star_seen, tested, e_seen, e_star_seen;
  ScratchMap<int32_t> d_index, vert_index, facet_index;
  ScratchMap<uint32_t> hole_index;
  std::vector<Cell_handle> star, stack, e_star;
  std::vector<std::pair<std::array<int64_t, 4>, Cell_handle>> keyed, e_keyed;
  std::vector<int32_t> outer_of;    // per facet of D's cells (4 i + f): its index in outer, or -1
  std::vector<int32_t> outer_cell;  // per facet of outer: the local cell behind it, inside D
  struct Part {                     // a ray's part in D (CollectHole's HoleRay)
    uint32_t point, k;
    double t0, t1;
    int32_t first;  // the cell of D (index) where the part starts through facet `entry`
    int entry;
    int32_t entries;  // where it enters D from outside (a list in `entries`), -1: nowhere
  };
  struct Entry {
    double t;
    int32_t outer;  // the facet of MovePlan::outer
    int32_t next;
  };
  std::vector<Part> hole;
  std::vector<Entry> entries;
  std::vector<TetPlanes> planes;  // per local cell
  std::vector<std::pair<uint32_t, RayEntry>> adds;
  std::vector<int32_t> given;
  std::vector<uint8_t> used;  // FillIsDelaunay: per point of V, whether a cell has it
  std::vector<double> xyz;    // FillHole (fast): V's points, x y z each
  // FillHole's open facets: the vertices in the order that makes the cell on the open side
  // positive with its fourth vertex last, and who holds the facet.
  struct Open {
    int32_t v[3];
    int32_t cell;  // >= 0: a new cell (its facet `face`); < 0: the facet -(cell + 1) of outer
    int face;
    bool open;
  };
  std::vector<Open> open;
};

MovePlanner::MovePlanner(EngineState& s, RayCaster& caster, Carving& carving)
    : s_(s), caster_(caster), carving_(carving) {}
MovePlanner::~MovePlanner() = default;

void MovePlanner::Workers(int n) const {
  while (scratch_.size() < static_cast<size_t>(n)) scratch_.push_back(std::make_unique<Scratch>());
}

// Whether v can move to p keeping its cells: no cell of its star infinite, the star with v at p
// positively oriented, and every facet of it locally Delaunay (CGAL's perturbed in-sphere
// test). Reads only: v is not moved to test it.
bool MovePlanner::StarStaysDelaunay(const Dt& dt, Vertex_handle v, const Point& p,
                                    const std::vector<Cell_handle>& star) {
  auto at = [&](Vertex_handle u) -> const Point& { return u == v ? p : u->point(); };
  for (Cell_handle c : star)
    if (dt.is_infinite(c)) return false;
  for (Cell_handle c : star)
    if (CGAL::orientation(at(c->vertex(0)), at(c->vertex(1)), at(c->vertex(2)),
                          at(c->vertex(3))) != CGAL::POSITIVE)
      return false;
  for (Cell_handle c : star) {
    const int iv = c->index(v);
    for (int j = 0; j < 4; ++j) {
      const Cell_handle n = c->neighbor(j);
      if (j != iv && &*n < &*c) continue;  // a facet between two star cells: tested once
      if (dt.is_infinite(n)) return false;
      const Point q = at(c->vertex(j));
      if (DtPredicates::SideOfSphere(dt, at(n->vertex(0)), at(n->vertex(1)), at(n->vertex(2)),
                                     at(n->vertex(3)), q) != CGAL::ON_UNBOUNDED_SIDE)
        return false;
    }
  }
  return true;
}

void MovePlanner::Plan(uint32_t pt, const Point& p_new, int worker, MovePlan* plan) const {
  Scratch& sc = *scratch_[static_cast<size_t>(worker)];
  MovePlan& m = *plan;
  Reset(pt, p_new, &m);
  const PointRecord& rec = s_.points[pt];
  if (!rec.in_triangulation || s_.dt.dimension() != 3) return;
  m.v = rec.vertex;
  m.p_old = m.v->point();
  if (p_new == m.p_old) {
    m.kind = MovePlan::Kind::kKeep;
    return;
  }
  if (!FindRegion(&m, sc)) return;
  IndexRegion(&m, sc);
  CollectHoleRays(&m, sc);
  if (!PlanCells(&m, sc)) return;
  WalkRays(&m, sc);
  PlanEnclosingSet(&m, sc);
}

// A plan for moving pt to p_new before anything is known: left to CGAL (kSerial), its lists
// emptied (their capacity kept for the next plan on this worker).
void MovePlanner::Reset(uint32_t pt, const Point& p_new, MovePlan* plan) {
  MovePlan& m = *plan;
  m.kind = MovePlan::Kind::kSerial;
  m.pt = pt;
  m.p_new = p_new;
  m.v = Vertex_handle();
  m.d.clear(), m.outer.clear(), m.serials.clear(), m.verts.clear(), m.cells.clear();
  m.ray_begin.clear(), m.rays.clear(), m.listed.clear(), m.deferred.clear(), m.given.clear();
  m.extra.clear(), m.extra_cells.clear();
  m.e.clear(), m.e_serials.clear();
  m.rays_rewalked = 0;
  m.e_planned = false;
}

// D: the star, reshaped in place when it can be (kInPlace); else the star and p_new's conflict
// zone (kHole). False when the plan ends here: a vertex at p_new already (kDuplicate), or the move
// left to CGAL (kSerial: on the hull, or D holds a final cell).
bool MovePlanner::FindRegion(MovePlan* plan, Scratch& sc) const {
  MovePlan& m = *plan;
  const Vertex_handle v = m.v;
  const Point& p_new = m.p_new;
  StarOf(v, &sc.star_seen, &sc.star);
  bool hull = false;
  for (Cell_handle c : sc.star) hull = hull || s_.dt.is_infinite(c);
  std::vector<Cell_handle>& d = m.d;
  d = sc.star;
  if (!hull && StarStaysDelaunay(s_.dt, v, p_new, sc.star)) {
    m.kind = MovePlan::Kind::kInPlace;
  } else {
    Dt::Locate_type lt;
    int li, lj;
    const Cell_handle loc = s_.dt.locate(p_new, lt, li, lj, v->cell());
    if (lt == Dt::VERTEX) {
      m.kind = MovePlan::Kind::kDuplicate;
      return false;
    }
    if (hull || s_.dt.is_infinite(loc) ||
        s_.dt.side_of_sphere(loc, p_new, true) != CGAL::ON_BOUNDED_SIDE)
      return false;  // left to CGAL (kSerial)
    // The conflict zone, as CGAL's find_conflicts finds it (a cell whose perturbed sphere holds
    // p_new), walked from the cell holding p_new; D is the star and it.
    sc.tested.Clear();
    sc.stack.assign(1, loc);
    sc.tested.Insert(ScratchMap<uint8_t>::Key(&*loc), 1);
    while (!sc.stack.empty()) {
      const Cell_handle c = sc.stack.back();
      sc.stack.pop_back();
      if (s_.dt.is_infinite(c)) return false;  // p_new outside the hull: left to CGAL
      if (sc.star_seen.Insert(ScratchMap<uint8_t>::Key(&*c), 1).second) d.push_back(c);
      for (int i = 0; i < 4; ++i) {
        const Cell_handle n = c->neighbor(i);
        if (!sc.tested.Insert(ScratchMap<uint8_t>::Key(&*n), 1).second) continue;
        if (s_.dt.side_of_sphere(n, p_new, true) == CGAL::ON_BOUNDED_SIDE) sc.stack.push_back(n);
      }
    }
    m.kind = MovePlan::Kind::kHole;
  }
  for (Cell_handle c : d)
    if (c->info().final) {
      m.kind = MovePlan::Kind::kSerial;  // forget: made at its turn, which refuses it
      return false;
    }
  return true;
}

// D in CellKey order, its boundary facets, and the serials of both; the vertices of D but v, by
// id (their indices in sc.vert_index).
void MovePlanner::IndexRegion(MovePlan* plan, Scratch& sc) const {
  MovePlan& m = *plan;
  std::vector<Cell_handle>& d = m.d;
  const Vertex_handle v = m.v;
  sc.keyed.clear();
  for (Cell_handle c : d) sc.keyed.push_back({s_.CellKey(c), c});
  std::sort(sc.keyed.begin(), sc.keyed.end(),
            [](const auto& a, const auto& b) { return a.first < b.first; });
  sc.d_index.Clear();
  for (size_t i = 0; i < d.size(); ++i) {
    d[i] = sc.keyed[i].second;
    sc.d_index.Insert(ScratchMap<int32_t>::Key(&*d[i]), static_cast<int32_t>(i));
  }
  sc.outer_of.assign(4 * d.size(), -1);
  for (size_t i = 0; i < d.size(); ++i) {
    const Cell_handle c = d[i];
    for (int f : s_.CanonicalFacets(c)) {
      const Cell_handle n = c->neighbor(f);
      if (sc.d_index.Contains(ScratchMap<int32_t>::Key(&*n))) continue;
      sc.outer_of[4 * i + static_cast<size_t>(f)] = static_cast<int32_t>(m.outer.size());
      m.outer.push_back(Facet(n, n->index(c)));
    }
  }
  for (Cell_handle c : d) m.serials.push_back(c->info().serial);
  for (const Facet& f : m.outer) m.serials.push_back(f.first->info().serial);
  sc.vert_index.Clear();
  for (Cell_handle c : d)
    for (int k = 0; k < 4; ++k) {
      const Vertex_handle u = c->vertex(k);
      if (u != v && sc.vert_index.Insert(ScratchMap<int32_t>::Key(&*u), 0).second)
        m.verts.push_back(u);
    }
  std::sort(m.verts.begin(), m.verts.end(), [](Vertex_handle a, Vertex_handle b) {
    return a->info().id < b->info().id;
  });
  for (size_t i = 0; i < m.verts.size(); ++i)
    *sc.vert_index.Find(ScratchMap<int32_t>::Key(&*m.verts[i])) = static_cast<int32_t>(i);
}

// The rays D's cells hold, each with the part of it in D (CollectHole's merge: the hull of its
// parts, entered at the first), and where each enters D from outside.
void MovePlanner::CollectHoleRays(MovePlan* plan, Scratch& sc) const {
  MovePlan& m = *plan;
  const std::vector<Cell_handle>& d = m.d;
  sc.hole.clear();
  sc.entries.clear();
  sc.hole_index.Clear();
  for (size_t i = 0; i < d.size(); ++i) {
    const Cell_handle c = d[i];
    if (c->info().rays.empty()) continue;
    const TetPlanes planes = PlanesOf(c);
    for (const RayEntry& e : c->info().rays) {
      if (!s_.Live(e)) continue;
      const PointRecord& owner = s_.points[e.point];
      const uint32_t k = e.camera;
      if (owner.Listed(k)) m.listed.push_back({e.point, k, static_cast<uint32_t>(i)});
      const Point& end = owner.ray_end[k].end;
      const Point& cam = s_.cameras[owner.ray_end[k].camera];
      const double a[3] = {end.x(), end.y(), end.z()};
      const double dir[3] = {cam.x() - a[0], cam.y() - a[1], cam.z() - a[2]};
      Scratch::Part part{e.point, k, 0.0, 1.0, -1, -1, -1};
      Clip cl;
      int32_t from_outside = -1;
      if (ClipSegment(planes, a, dir, &cl)) {
        part.t0 = cl.lo, part.t1 = cl.hi;
        if (cl.lo_face >= 0 && !cl.lo_tie) {
          part.first = static_cast<int32_t>(i), part.entry = cl.lo_face;
          from_outside = sc.outer_of[4 * i + static_cast<size_t>(cl.lo_face)];
        }
      }
      const auto [at, added] = sc.hole_index.Insert((uint64_t{e.point} << 32) | k,
                                                    static_cast<uint32_t>(sc.hole.size()));
      if (added) sc.hole.push_back(part);
      Scratch::Part& x = sc.hole[*at];
      if (!added) {
        if (part.t0 < x.t0) x.t0 = part.t0, x.first = part.first, x.entry = part.entry;
        x.t1 = std::max(x.t1, part.t1);
      }
      if (from_outside >= 0) {
        sc.entries.push_back({cl.lo, from_outside, x.entries});
        x.entries = static_cast<int32_t>(sc.entries.size()) - 1;
      }
    }
  }
}

// The cells after the move: D's, reshaped, or those that fill it. False when no fill was found
// (the move is then left to CGAL: kSerial).
bool MovePlanner::PlanCells(MovePlan* plan, Scratch& sc) const {
  MovePlan& m = *plan;
  const std::vector<Cell_handle>& d = m.d;
  const Vertex_handle v = m.v;
  sc.outer_cell.assign(m.outer.size(), -1);
  if (m.kind == MovePlan::Kind::kInPlace) {
    for (size_t i = 0; i < d.size(); ++i) {
      MovePlan::NewCell nc;
      for (int k = 0; k < 4; ++k) {
        const Vertex_handle u = d[i]->vertex(k);
        nc.v[k] = u == v ? -1 : *sc.vert_index.Find(ScratchMap<int32_t>::Key(&*u));
        const int32_t o = sc.outer_of[4 * i + static_cast<size_t>(k)];
        if (o >= 0) {
          nc.n[k] = -(o + 1);
          sc.outer_cell[static_cast<size_t>(o)] = static_cast<int32_t>(i);
        } else {
          nc.n[k] = *sc.d_index.Find(ScratchMap<int32_t>::Key(&*d[i]->neighbor(k)));
        }
      }
      m.cells.push_back(nc);
    }
  } else {
    // The floating-point fill, checked; the exact one when the check fails (rare: ties, or
    // points within rounding of a facet's plane).
    Hooks* hooks = s_.hooks.get();
    const bool fast = !(hooks && hooks->exact_fill_only);
    if (fast && FillHole(&m, sc, true) && FillIsDelaunay(m, sc)) {
      if (hooks) ++hooks->fills_fast;
    } else if (FillHole(&m, sc, false)) {
      if (hooks) ++hooks->fills_exact;
    } else {
      m.kind = MovePlan::Kind::kSerial;  // CGAL's removal and insertion decide (never seen)
      return false;
    }
  }
  return true;
}

// E for shrink, when D meets O now (it is checked again at commit).
void MovePlanner::PlanEnclosingSet(MovePlan* plan, Scratch& sc) const {
  MovePlan& m = *plan;
  const std::vector<Cell_handle>& d = m.d;
  bool meets_o = false;
  for (Cell_handle c : d) meets_o = meets_o || c->info().in_o;
  if (meets_o) {
    const Point centres[2] = {m.p_old, m.p_new};
    Carving::EnclosingSetInO(s_, d, centres, 2, &sc.e_seen, &sc.e_star_seen, &sc.e_star, &m.e);
    // In CellKey order, the order shrink peels equal weights in: sorted here, on the threads.
    sc.e_keyed.clear();
    for (Cell_handle c : m.e) sc.e_keyed.push_back({s_.CellKey(c), c});
    std::sort(sc.e_keyed.begin(), sc.e_keyed.end(),
              [](const auto& a, const auto& b) { return a.first < b.first; });
    for (size_t i = 0; i < m.e.size(); ++i) m.e[i] = sc.e_keyed[i].second;
    for (Cell_handle c : m.e) m.e_serials.push_back(c->info().serial);
    m.e_planned = true;
  }
}

// kHole: the cells that fill D. They are cells of the Delaunay triangulation of all the points
// after the move, so of that of D's vertices and p_new alone (V), and they fill D from its
// boundary facets: grown from them inward by Delaunay wrapping. Across an open facet, the cell
// is made with the point of V on the facet's open side whose sphere through the facet holds no
// other such point (CGAL's in-sphere test with its symbolic perturbation orders the spheres
// through a facet totally, so the first point no later one falls inside is that one); its other
// facets are glued to open facets with the same vertices or left open. It ends when no facet is
// open. False when that fails (never seen; the move is then left to CGAL).
//
// fast: the apex picked in floating point instead (the sphere through the facet and a point q
// on its open side has its centre at c + t(q) n, c the facet's circumcentre and n its normal;
// a point lies inside q's sphere when its t is smaller, so the apex has the smallest t). Rounding
// and ties (cospherical points, which CGAL's perturbation orders) can pick another point; the
// caller checks the result with FillIsDelaunay and fills again exactly when it fails. A fill that
// passes is the exact one cell for cell, in the same order: each facet's apex is unique.
bool MovePlanner::FillHole(MovePlan* plan, Scratch& sc, bool fast) const {
  MovePlan& m = *plan;
  const int32_t n_verts = static_cast<int32_t>(m.verts.size());
  auto point = [&](int32_t i) -> const Point& { return m.PointOf(i); };
  using Open = Scratch::Open;
  std::vector<Open>& open = sc.open;
  open.clear();
  sc.facet_index.Clear();
  auto key = [&](int32_t a, int32_t b, int32_t c) {  // the facet, whatever its orientation
    if (a > b) std::swap(a, b);
    if (b > c) std::swap(b, c);
    if (a > b) std::swap(a, b);
    return (static_cast<uint64_t>(a + 1) << 42) | (static_cast<uint64_t>(b + 1) << 21) |
           static_cast<uint64_t>(c + 1);
  };
  // D's boundary facets, open toward D (vertex_triple_index(i, .) and vertex i make a positive
  // tetrahedron: the triple as the cell inside D sees it).
  for (size_t f = 0; f < m.outer.size(); ++f) {
    const Cell_handle o = m.outer[f].first;
    const Cell_handle in = o->neighbor(m.outer[f].second);
    const int j = in->index(o);
    Open x{{0, 0, 0}, -static_cast<int32_t>(f) - 1, 0, true};
    for (int k = 0; k < 3; ++k) {
      const int32_t* i =
          sc.vert_index.Find(ScratchMap<int32_t>::Key(&*in->vertex(Dt::vertex_triple_index(j, k))));
      if (!i) return false;
      x.v[k] = *i;
    }
    if (!sc.facet_index.Insert(key(x.v[0], x.v[1], x.v[2]), static_cast<int32_t>(open.size()))
             .second)
      return false;
    open.push_back(x);
  }
  sc.outer_cell.assign(m.outer.size(), -1);
  m.cells.clear();
  const size_t max_cells = 8 * m.outer.size() + 64;
  if (fast) {  // V's points side by side: p_new, then verts
    sc.xyz.resize(3 * (static_cast<size_t>(n_verts) + 1));
    for (int32_t q = -1; q < n_verts; ++q) {
      const Point& p = point(q);
      double* x = sc.xyz.data() + 3 * static_cast<size_t>(q + 1);
      x[0] = p.x(), x[1] = p.y(), x[2] = p.z();
    }
  }
  for (size_t next = 0; next < open.size(); ++next) {
    if (!open[next].open) continue;
    const Open f = open[next];
    const Point& a = point(f.v[0]);
    const Point& b = point(f.v[1]);
    const Point& c = point(f.v[2]);
    // The side of the facet's plane a point q is on: n . (q - a), n = (b - a) x (c - a).
    const double u[3] = {b.x() - a.x(), b.y() - a.y(), b.z() - a.z()};
    const double w[3] = {c.x() - a.x(), c.y() - a.y(), c.z() - a.z()};
    const double n[3] = {u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2],
                         u[0] * w[1] - u[1] * w[0]};
    int32_t best = INT32_MIN;
    if (fast) {
      // The circumcentre relative to a, (|u|^2 (w x n) + |w|^2 (n x u)) / (2 |n|^2); t(q) as
      // num / side with num = |r|^2 - 2 centre . r, compared without dividing (sides > 0).
      const double uu = u[0] * u[0] + u[1] * u[1] + u[2] * u[2];
      const double ww = w[0] * w[0] + w[1] * w[1] + w[2] * w[2];
      const double nn2 = 2.0 * (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
      const double wxn[3] = {w[1] * n[2] - w[2] * n[1], w[2] * n[0] - w[0] * n[2],
                             w[0] * n[1] - w[1] * n[0]};
      const double nxu[3] = {n[1] * u[2] - n[2] * u[1], n[2] * u[0] - n[0] * u[2],
                             n[0] * u[1] - n[1] * u[0]};
      double c2[3];
      for (int k = 0; k < 3; ++k) c2[k] = (uu * wxn[k] + ww * nxu[k]) / nn2 * 2.0;
      if (!std::isfinite(c2[0] + c2[1] + c2[2])) return false;  // a flat facet: the exact fill
      double best_num = 0.0, best_side = 0.0;
      const double* xyz = sc.xyz.data();
      const double ax = a.x(), ay = a.y(), az = a.z();
      for (int32_t q = -1; q < n_verts; ++q) {
        const double* pq = xyz + 3 * static_cast<size_t>(q + 1);
        const double r0 = pq[0] - ax, r1 = pq[1] - ay, r2 = pq[2] - az;
        const double side = n[0] * r0 + n[1] * r1 + n[2] * r2;
        const double num = r0 * r0 + r1 * r1 + r2 * r2 - (c2[0] * r0 + c2[1] * r1 + c2[2] * r2);
        if (side > 0.0 && (best == INT32_MIN || num * best_side < best_num * side) &&
            q != f.v[0] && q != f.v[1] && q != f.v[2])
          best = q, best_num = num, best_side = side;
      }
    } else {
      // The side with a rounding bound (each of the determinant's six terms carries at most
      // eight roundings: below 9e-16 of it, and their sum is at most 6 m_u m_v m_w); CGAL's
      // test within it.
      const double m_uw = std::max({std::fabs(u[0]), std::fabs(u[1]), std::fabs(u[2])}) *
                          std::max({std::fabs(w[0]), std::fabs(w[1]), std::fabs(w[2])});
      for (int32_t q = -1; q < n_verts; ++q) {
        if (q == f.v[0] || q == f.v[1] || q == f.v[2]) continue;
        const Point& pq = point(q);
        const double r[3] = {pq.x() - a.x(), pq.y() - a.y(), pq.z() - a.z()};
        const double side = n[0] * r[0] + n[1] * r[1] + n[2] * r[2];
        const double bound =
            1e-14 * m_uw * std::max({std::fabs(r[0]), std::fabs(r[1]), std::fabs(r[2])});
        if (side <= -bound) continue;
        if ((side <= bound || bound < 1e-280) &&
            CGAL::orientation(a, b, c, pq) != CGAL::POSITIVE)
          continue;
        if (best == INT32_MIN ||
            DtPredicates::SideOfSphere(s_.dt, a, b, c, point(best), pq) == CGAL::ON_BOUNDED_SIDE)
          best = q;
      }
    }
    if (best == INT32_MIN || m.cells.size() >= max_cells) return false;
    // The new cell (a, b, c, best): facet 3 is f, the others open or glued.
    const int32_t cell = static_cast<int32_t>(m.cells.size());
    MovePlan::NewCell nc;
    nc.v[0] = f.v[0], nc.v[1] = f.v[1], nc.v[2] = f.v[2], nc.v[3] = best;
    nc.n[3] = f.cell;
    m.cells.push_back(nc);
    auto glue = [&](Open& g, int32_t with_cell, int with_face) {
      g.open = false;
      if (g.cell >= 0) {
        m.cells[static_cast<size_t>(g.cell)].n[g.face] = with_cell;
      } else {
        sc.outer_cell[static_cast<size_t>(-g.cell - 1)] = with_cell;
      }
      m.cells[static_cast<size_t>(with_cell)].n[with_face] = g.cell;
    };
    glue(open[next], cell, 3);
    for (int i = 0; i < 3; ++i) {
      int32_t t[3];
      for (int k = 0; k < 3; ++k) t[k] = nc.v[Dt::vertex_triple_index(i, k)];
      const auto [at, added] =
          sc.facet_index.Insert(key(t[0], t[1], t[2]), static_cast<int32_t>(open.size()));
      if (added) {  // open toward the far side from vertex i: the other orientation
        open.push_back({{t[0], t[2], t[1]}, cell, i, true});
      } else {
        Open& g = open[static_cast<size_t>(*at)];
        if (!g.open) return false;  // a facet met a third time: not a triangulation
        glue(g, cell, i);
      }
    }
  }
  for (const int32_t x : sc.outer_cell)
    if (x < 0) return false;
  return true;
}

// Whether a fill (FillHole) is the Delaunay one: every point of V a vertex of it, every cell
// positively oriented (CGAL's exact test), and every facet of its cells locally Delaunay, across
// a new facet and across D's boundary (CGAL's perturbed in-sphere test). Outside D neither the
// cells nor their points changed, so the whole triangulation is then one of all the points and
// locally Delaunay, hence the Delaunay triangulation, which the perturbation makes unique.
bool MovePlanner::FillIsDelaunay(const MovePlan& m, Scratch& sc) const {
  auto point = [&](int32_t i) -> const Point& { return m.PointOf(i); };
  sc.used.assign(m.verts.size() + 1, 0);
  for (const MovePlan::NewCell& c : m.cells)
    for (int k = 0; k < 4; ++k) sc.used[static_cast<size_t>(c.v[k] + 1)] = 1;
  for (const uint8_t u : sc.used)
    if (!u) return false;
  for (size_t i = 0; i < m.cells.size(); ++i) {
    const MovePlan::NewCell& c = m.cells[i];
    if (CGAL::orientation(point(c.v[0]), point(c.v[1]), point(c.v[2]), point(c.v[3])) !=
        CGAL::POSITIVE)
      return false;
    for (int k = 0; k < 4; ++k) {
      const Point* q = nullptr;
      if (c.n[k] >= 0) {
        if (static_cast<size_t>(c.n[k]) < i) continue;  // tested from the other cell
        const MovePlan::NewCell& o = m.cells[static_cast<size_t>(c.n[k])];
        for (int j = 0; j < 4; ++j)
          if (o.n[j] == static_cast<int32_t>(i)) q = &point(o.v[j]);
      } else {
        const Facet& f = m.outer[static_cast<size_t>(-c.n[k] - 1)];
        if (s_.dt.is_infinite(f.first)) continue;  // a hull facet, not changed by the move
        q = &f.first->vertex(f.second)->point();
      }
      if (q == nullptr ||
          DtPredicates::SideOfSphere(s_.dt, point(c.v[0]), point(c.v[1]), point(c.v[2]),
                                     point(c.v[3]), *q) != CGAL::ON_UNBOUNDED_SIDE)
        return false;
    }
  }
  return true;
}

// Each ray of the hole walked through the cells after the move (RefillHole's walk): from the
// facet where it entered D, or from its end's vertex, face to face while the part lasts. A ray
// that passes within rounding of an edge or a vertex, that starts nowhere known, or that leaves
// D before its part ends (to enter it again) is deferred: walked whole with exact predicates at
// commit, as RefillHole does.
void MovePlanner::WalkRays(MovePlan* plan, Scratch& sc) const {
  MovePlan& m = *plan;
  const size_t n_cells = m.cells.size();
  sc.planes.resize(n_cells);
  for (size_t i = 0; i < n_cells; ++i) {
    const MovePlan::NewCell& c = m.cells[i];
    sc.planes[i] = PlanesOf(m.PointOf(c.v[0]), m.PointOf(c.v[1]), m.PointOf(c.v[2]),
                            m.PointOf(c.v[3]));
  }
  constexpr double kPad = 1e-6;
  sc.adds.clear();
  for (const Scratch::Part& r : sc.hole) {
    const PointRecord& rec = s_.points[r.point];
    const Point& e = rec.ray_end[r.k].end;
    const Point& cam = s_.cameras[rec.ray_end[r.k].camera];
    const double a[3] = {e.x(), e.y(), e.z()};
    const double dir[3] = {cam.x() - a[0], cam.y() - a[1], cam.z() - a[2]};
    const double t_end = std::min(1.0, r.t1 + kPad);
    const RayEntry entry{r.k, r.point, rec.Gen(r.k)};
    ++m.rays_rewalked;
    const size_t given_begin = sc.adds.size();
    int32_t c = -1;
    double t = r.t0;
    if (r.first >= 0 && r.t0 > 0.0) {
      const int32_t o = sc.outer_of[4 * static_cast<size_t>(r.first) + static_cast<size_t>(r.entry)];
      if (o >= 0 && !s_.dt.is_infinite(m.outer[static_cast<size_t>(o)].first))
        c = sc.outer_cell[static_cast<size_t>(o)];
    } else if (r.t0 <= 0.0 && rec.in_triangulation) {
      // The ray's end is a vertex after the move: the cell around it that the ray leaves into
      // (none or two: the exact walk decides).
      const bool moving = r.point == m.pt;
      const Point& at = moving ? m.p_new : rec.vertex->point();
      const int32_t* vi = moving ? nullptr
                                 : sc.vert_index.Find(ScratchMap<int32_t>::Key(&*rec.vertex));
      if (at == e && (moving || vi)) {
        const int32_t want = moving ? -1 : *vi;
        int found = 0;
        for (size_t i = 0; i < n_cells; ++i) {
          const MovePlan::NewCell& x = m.cells[i];
          if (x.v[0] != want && x.v[1] != want && x.v[2] != want && x.v[3] != want) continue;
          Clip cl;
          if (ClipSegment(sc.planes[i], a, dir, &cl) && cl.lo <= 1e-9 && cl.hi > 1e-9) {
            c = static_cast<int32_t>(i);
            if (++found > 1 || cl.hi_tie || cl.grazing) break;
          }
        }
        if (found != 1) c = -1;
        t = 0.0;
      }
    }
    bool exact = c < 0;
    for (int steps = 0; !exact; ++steps) {
      Clip cl;
      const bool ok = ClipSegment(sc.planes[static_cast<size_t>(c)], a, dir, &cl);
      if (steps > s_.opt.max_cells_per_ray || !ok || cl.hi_tie || cl.grazing || cl.hi_face < 0 ||
          cl.hi < t - 1e-9) {
        exact = true;
        break;
      }
      sc.adds.push_back({static_cast<uint32_t>(c), entry});
      if (cl.hi >= t_end) break;
      int32_t next = m.cells[static_cast<size_t>(c)].n[cl.hi_face];
      t = cl.hi;
      if (next < 0) {
        // Out of D. Done unless the part goes on: then on from where the ray enters D again
        // (the first entry after t; one within rounding of t passes through an edge or a vertex
        // of D's boundary: the exact walk decides).
        if (t >= r.t1 - 1e-9) break;
        double best = 2.0;
        for (int32_t x = r.entries; x >= 0; x = sc.entries[static_cast<size_t>(x)].next) {
          const Scratch::Entry& en = sc.entries[static_cast<size_t>(x)];
          if (en.t < t - 1e-9) continue;
          if (en.t <= t + 1e-9) {
            best = 2.0;
            break;
          }
          if (en.t < best) best = en.t, next = sc.outer_cell[static_cast<size_t>(en.outer)];
        }
        if (best > 1.0 || next < 0) {
          exact = true;
          break;
        }
        t = best;
      }
      c = next;
    }
    if (rec.Listed(r.k) && sc.adds.size() > given_begin) {
      m.extra.push_back({r.point, r.k, static_cast<uint32_t>(m.extra_cells.size()),
                         static_cast<uint32_t>(sc.adds.size() - given_begin)});
      for (size_t i = given_begin; i < sc.adds.size(); ++i)
        m.extra_cells.push_back(static_cast<int32_t>(sc.adds[i].first));
    }
    if (exact) {
      MovePlan::Deferred df{r.point, r.k, static_cast<uint32_t>(m.given.size()), 0};
      for (size_t i = given_begin; i < sc.adds.size(); ++i)
        m.given.push_back(static_cast<int32_t>(sc.adds[i].first));
      df.given_count = static_cast<uint32_t>(m.given.size()) - df.given_begin;
      m.deferred.push_back(df);
    }
  }
  // By cell, in the order the walks gave them.
  m.ray_begin.assign(n_cells + 1, 0);
  for (const auto& [cell, entry] : sc.adds) ++m.ray_begin[cell + 1];
  for (size_t i = 0; i < n_cells; ++i) m.ray_begin[i + 1] += m.ray_begin[i];
  m.rays.resize(sc.adds.size());
  std::vector<int32_t>& fill = sc.given;
  fill.assign(m.ray_begin.begin(), m.ray_begin.end() - 1);
  for (const auto& [cell, entry] : sc.adds) m.rays[static_cast<size_t>(fill[cell]++)] = entry;
}

bool MovePlanner::Valid(const MovePlan& m) const {
  if (m.kind == MovePlan::Kind::kSerial || m.kind == MovePlan::Kind::kDuplicate) return false;
  const PointRecord& rec = s_.points[m.pt];
  if (!rec.in_triangulation || rec.vertex != m.v || m.v->point() != m.p_old) return false;
  if (m.kind == MovePlan::Kind::kKeep) return true;
  const auto& cells = s_.dt.tds().cells();
  size_t i = 0;
  for (Cell_handle c : m.d)
    if (!cells.is_used(c) || c->info().serial != m.serials[i++]) return false;
  for (const Facet& f : m.outer)
    if (!cells.is_used(f.first) || f.first->info().serial != m.serials[i++]) return false;
  return true;
}

bool MovePlanner::Commit(MovePlan& m) {
  PointRecord& rec = s_.points[m.pt];
  // E's cells in O now are those of the plan's that are still there: a cell leaves O before it
  // is destroyed, and none enters O while points move.
  const auto& cells = s_.dt.tds().cells();
  e_live_.clear();
  for (size_t i = 0; i < m.e.size(); ++i)
    if (cells.is_used(m.e[i]) && m.e[i]->info().serial == m.e_serials[i]) e_live_.push_back(m.e[i]);
  if (!carving_.Shrink(m.d, {m.p_old, m.p_new}, m.e_planned ? &e_live_ : nullptr)) {
    ++s_.stats.moves_skipped;
    return false;
  }
  // What D's cells held leaves the ledger and the ray lists (CollectRemoved, CollectHole).
  for (Cell_handle c : m.d) {
    c->info().dirty = false;
    s_.Ledger(c->info().weight, 0);
  }
  for (const MovePlan::Listed& l : m.listed)
    if (s_.points[l.point].Listed(l.k)) s_.Unlist(l.point, l.k, m.d[l.cell]);
  std::vector<Cell_handle>& made = made_;
  if (m.kind == MovePlan::Kind::kInPlace) {
    for (Cell_handle c : m.d) {
      c->info().weight = 0;
      c->info().rays.clear();
      c->info().serial = NextCellSerial();  // the same cell, another shape
    }
    m.v->set_point(m.p_new);
    made = m.d;
  } else {
    Tds& tds = s_.dt.tds();
    if (s_.last_vertex == m.v) s_.last_vertex = Vertex_handle();
    tds.delete_cells(m.d.begin(), m.d.end());  // first: the new cells take their places
    tds.delete_vertex(m.v);
    const Vertex_handle nv = tds.create_vertex();
    nv->set_point(m.p_new);
    nv->info().id = m.pt;
    auto vertex = [&](int32_t i) { return i < 0 ? nv : m.verts[static_cast<size_t>(i)]; };
    made.clear();
    for (const MovePlan::NewCell& nc : m.cells)
      made.push_back(tds.create_cell(vertex(nc.v[0]), vertex(nc.v[1]), vertex(nc.v[2]),
                                     vertex(nc.v[3])));
    for (size_t i = 0; i < made.size(); ++i) {
      const MovePlan::NewCell& nc = m.cells[i];
      for (int k = 0; k < 4; ++k) {
        if (nc.n[k] >= 0) {
          made[i]->set_neighbor(k, made[static_cast<size_t>(nc.n[k])]);
        } else {
          const Facet& f = m.outer[static_cast<size_t>(-nc.n[k] - 1)];
          made[i]->set_neighbor(k, f.first);
          f.first->set_neighbor(f.second, made[i]);
        }
        made[i]->vertex(k)->set_cell(made[i]);
      }
    }
    rec.vertex = nv;
    s_.last_vertex = nv;
  }
  // The rays the plan walked, then those it deferred.
  for (size_t i = 0; i < made.size(); ++i) {
    const Cell_handle c = made[i];
    CellInfo& info = c->info();
    const auto first = m.rays.begin() + m.ray_begin[i], last = m.rays.begin() + m.ray_begin[i + 1];
    info.rays.assign(first, last);
    info.weight = s_.unit[0] * static_cast<int64_t>(last - first);
    s_.Ledger(0, info.weight);
    if (s_.IsFree(c)) s_.MarkDirty(c);
  }
  for (const MovePlan::Extra& x : m.extra) {
    std::vector<Cell_handle>& cells_of = s_.list_extra[EngineState::RayKey(x.point, x.k)];
    for (uint32_t j = 0; j < x.count; ++j)
      cells_of.push_back(made[static_cast<size_t>(m.extra_cells[x.begin + j])]);
  }
  s_.stats.rays_rewalked += m.rays_rewalked;
  s_.stats.cells_rewalked += static_cast<int64_t>(m.rays.size());
  if (!m.deferred.empty()) {
    for (Cell_handle c : made) c->info().fresh = true;
    for (const MovePlan::Deferred& df : m.deferred) {
      given_.clear();
      for (uint32_t j = 0; j < df.given_count; ++j)
        given_.push_back(made[static_cast<size_t>(m.given[df.given_begin + j])]);
      caster_.RefillExact(df.point, df.k, given_, made.front());
    }
    for (Cell_handle c : made) c->info().fresh = false;
  }
  ++s_.stats.points_moved;
  if (m.kind == MovePlan::Kind::kInPlace) ++s_.stats.moves_in_place;
  return true;
}

}  // namespace imr::engine::detail
