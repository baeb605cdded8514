// The engine's checks (engine_parts.h, InvariantChecker) and its benchmark and diagnostic hooks
// (engine_internal.h): what a run calls only when asked (check_invariants, tests, imr-microbench).
#include "host/engine/engine_parts.h"

#include <sstream>
#include <cstdint>

namespace imr::engine {
namespace detail {

// A vertex as a user would find it: the point's id (or the Steiner point's number) and where
// it is, for the messages of CheckInvariants.
std::string InvariantChecker::DescribeVertex(Vertex_handle v) const {
  std::ostringstream s;
  s.precision(6);
  if (s_.dt.is_infinite(v)) return "the infinite vertex";
  const int64_t id = v->info().id;
  if (id >= 0) s << "point " << s_.points[static_cast<size_t>(id)].id;
  else s << "Steiner point " << (-id - 1);
  const Point& p = v->point();
  s << " (" << p.x() << ", " << p.y() << ", " << p.z() << ")";
  return s.str();
}

std::string InvariantChecker::DescribeCell(Cell_handle c) const {
  std::string s = "cell {";
  for (int i = 0; i < 4; ++i) s += (i ? "; " : "") + DescribeVertex(c->vertex(i));
  return s + "}";
}

namespace {

// Every ray of every point numbered: ray k of point pt is first[pt] + k.
std::vector<std::size_t> RayNumbers(const EngineState& s) {
  std::vector<std::size_t> first(s.points.size() + 1, 0);
  for (std::size_t pt = 0; pt < s.points.size(); ++pt)
    first[pt + 1] = first[pt] + s.points[pt].ray_state.size();
  return first;
}

// A cell handle's value scrambled (splitmix64's finaliser): sums of these over two lists agree
// when the lists hold the same cells, and differ with probability 1 - 2^-64 otherwise.
uint64_t Scramble(const void* p) {
  uint64_t x = static_cast<uint64_t>(reinterpret_cast<std::uintptr_t>(p));
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}

}  // namespace

// kExact: each listed ray (EngineState::list_cells) names exactly the cells that hold it, each
// once. Empty when so, else the first ray that does not. Handles are compared, never followed:
// a list that kept a destroyed cell shows as a cell no live cell matches. One pass over the
// lists and one over the cells, each ray's cells summed as scrambled handles on both sides:
// linear time and 16 bytes per ray (sorting the holders, 16 bytes per entry, took 60 % of a
// far-ahead model's run and 140 MB at its end: 33 M entries).
std::string InvariantChecker::CheckRayLists() const {
  const std::vector<std::size_t> first = RayNumbers(s_);
  struct Tally {
    uint32_t listed = 0, held = 0;
    uint64_t sum = 0;  // the listed cells' scrambled handles minus the holders' (mod 2^64)
  };
  std::vector<Tally> tally(first.back());
  for (uint32_t pt = 0; pt < s_.points.size(); ++pt) {
    const PointRecord& rec = s_.points[pt];
    for (uint32_t k = 0; k < rec.ray_state.size(); ++k) {
      if (!rec.Listed(k)) continue;
      Tally& t = tally[first[pt] + k];
      s_.ForEachListed(pt, k, [&](Cell_handle c) {
        if (c->info().final) return;  // a cast skips final cells (forget)
        ++t.listed;
        t.sum += Scramble(c.operator->());
      });
    }
  }
  for (auto c = s_.dt.finite_cells_begin(); c != s_.dt.finite_cells_end(); ++c)
    for (const RayEntry& e : c->info().rays)
      if (s_.Live(e) && s_.points[e.point].Listed(e.camera)) {
        Tally& t = tally[first[e.point] + e.camera];
        ++t.held;
        t.sum -= Scramble(static_cast<Cell_handle>(c).operator->());
      }
  for (uint32_t pt = 0; pt < s_.points.size(); ++pt) {
    const PointRecord& rec = s_.points[pt];
    for (uint32_t k = 0; k < rec.ray_state.size(); ++k) {
      const Tally& t = tally[first[pt] + k];
      if (!rec.Listed(k) || (t.listed == t.held && t.sum == 0)) continue;
      return "the ray of point " + std::to_string(rec.id) + " from camera " +
             std::to_string(s_.camera_ids[rec.cameras[k]]) + " lists " +
             std::to_string(t.listed) + " cells but " + std::to_string(t.held) +
             " cells hold it" + (t.listed == t.held ? " (not the same cells)" : "");
    }
  }
  return {};
}

// Weight consistency: every weight within what casting and transfer can make (>= 0 when
// nonnegative_weights; in kRays mode at least what its stored rays added, with at most K of
// them), and the cells' sum equal to the ledger kept by every change.
void InvariantChecker::CheckWeights(const std::function<void(const std::string&)>& fail) const {
  const bool rays_mode = s_.opt.visibility_mode == VisibilityMode::kRays;
  const bool exact = s_.opt.visibility_mode == VisibilityMode::kExact;
  // kExact: the last cell (numbered from 1) that held each ray, so that a ray held twice by one
  // cell shows without sorting the cell's entries.
  const std::vector<std::size_t> first = exact ? RayNumbers(s_) : std::vector<std::size_t>{};
  std::vector<uint64_t> last_holder(exact ? first.back() : 0, 0);
  uint64_t cell_number = 0;
  uint64_t sum = 0;
  for (auto c = s_.dt.all_cells_begin(); c != s_.dt.all_cells_end(); ++c) {
    const CellInfo& info = c->info();
    sum += static_cast<uint64_t>(info.weight);
    if (!rays_mode && s_.opt.nonnegative_weights && info.weight < 0) {
      fail(DescribeCell(c) + " has weight " + std::to_string(s_.FromUnits(info.weight)) +
           " < 0 although nonnegative_weights is on (a weight-transfer policy returned a "
           "negative weight?)");
    }
    // A final cell (forget) kept its weight and let its ray list go.
    if (exact && !s_.dt.is_infinite(c) && !info.final) {
      // The count is the number of live entries, each ray at most once.
      ++cell_number;
      int64_t live = 0;
      bool twice = false;
      for (const RayEntry& e : info.rays) {
        if (!s_.Live(e)) continue;
        ++live;
        uint64_t& last = last_holder[first[e.point] + e.camera];
        twice = twice || last == cell_number;
        last = cell_number;
      }
      if (twice) fail(DescribeCell(c) + " holds a ray twice");
      // The last update's rays (EngineState::sealed) left their units without entries.
      if (s_.sealed ? info.weight < s_.unit[0] * live : info.weight != s_.unit[0] * live)
        fail(DescribeCell(c) + " has weight " + std::to_string(s_.FromUnits(info.weight)) +
             " but holds " + std::to_string(live) + " rays");
    }
    if (rays_mode) {
      int64_t stored = 0;
      for (const RayEntry& e : info.rays) stored += s_.unit[e.level];
      if (static_cast<int>(info.rays.size()) > s_.opt.rays_per_cell)
        fail(DescribeCell(c) + " stores " + std::to_string(info.rays.size()) +
             " rays, more than rays_per_cell (" + std::to_string(s_.opt.rays_per_cell) + ")");
      else if (info.weight < stored)
        fail(DescribeCell(c) + " has weight " + std::to_string(s_.FromUnits(info.weight)) +
             ", less than its stored rays added (" + std::to_string(s_.FromUnits(stored)) + ")");
    }
  }
  if (sum != s_.weight_ledger)
    fail("the cells' weights sum to " + std::to_string(s_.FromUnits(static_cast<int64_t>(sum))) +
         " but casting and transfer account for " +
         std::to_string(s_.FromUnits(static_cast<int64_t>(s_.weight_ledger))) +
         ": a weight or a cell changed outside them");
}

ManifoldCheckResult InvariantChecker::Check() const {
  ManifoldCheckResult r;
  auto fail = [&](const std::string& s) {
    if (r.ok) r.message = s;
    r.ok = false;
  };
  int64_t in_o = 0;
  for (auto c = s_.dt.all_cells_begin(); c != s_.dt.all_cells_end(); ++c) {
    if (!c->info().in_o) continue;
    if (s_.dt.is_infinite(c)) fail("an infinite " + DescribeCell(c) + " is in O");
    ++in_o;
  }
  r.cells_in_o = in_o;
  if (in_o != s_.cells_in_o)
    fail("O holds " + std::to_string(in_o) + " cells but its counter says " +
         std::to_string(s_.cells_in_o));
  // Each vertex's count of incident cells in O, from a sorted list (no per-vertex nodes).
  std::vector<const void*> o_corners;
  o_corners.reserve(4 * static_cast<size_t>(s_.cells_in_o > 0 ? s_.cells_in_o : 0));
  for (auto c = s_.dt.finite_cells_begin(); c != s_.dt.finite_cells_end(); ++c)
    if (c->info().in_o)
      for (int i = 0; i < 4; ++i) o_corners.push_back(&*c->vertex(i));
  std::sort(o_corners.begin(), o_corners.end());
  for (auto v = s_.dt.finite_vertices_begin(); v != s_.dt.finite_vertices_end(); ++v) {
    const auto range = std::equal_range(o_corners.begin(), o_corners.end(),
                                        static_cast<const void*>(&*v));
    const auto actual = static_cast<int32_t>(range.second - range.first);
    if (v->info().o_cells != actual) {
      fail(DescribeVertex(v) + " counts " + std::to_string(v->info().o_cells) +
           " incident cells in O, but " + std::to_string(actual) + " are");
      break;
    }
  }
  if (s_.hooks && s_.hooks->manifold_test_mismatches > 0)
    fail("the two forms of the manifold test disagreed");
  CheckWeights(fail);
  if (s_.opt.visibility_mode == VisibilityMode::kExact) {
    const std::string lists = CheckRayLists();
    if (!lists.empty()) fail(lists);
  }
  const std::vector<Triangle> tris = Boundary(s_);
  r.boundary_triangles = static_cast<int64_t>(tris.size());
  // Orientation: the O cell's opposite vertex is on the positive side of each triangle.
  for (auto c = s_.dt.finite_cells_begin(); c != s_.dt.finite_cells_end(); ++c) {
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
  // forget: around a deep vertex the cells may have been rebuilt (forgotten vertices) and dO
  // there is not the surface any more (that was handed out when the vertex became deep); every
  // vertex with a live cell, and every edge with such a vertex, is checked.
  std::vector<std::pair<int64_t, int64_t>> directed;
  std::vector<std::array<int64_t, 3>> corners;  // vertex, then its opposite edge (link edge)
  directed.reserve(3 * tris.size());
  corners.reserve(3 * tris.size());
  for (const Triangle& t : tris) {
    int64_t id[3];
    bool deep[3];
    for (int k = 0; k < 3; ++k) id[k] = t.v[k]->info().id, deep[k] = t.v[k]->info().deep;
    for (int k = 0; k < 3; ++k) {
      if (!deep[k] || !deep[(k + 1) % 3]) directed.push_back({id[k], id[(k + 1) % 3]});
      if (!deep[k]) corners.push_back({id[k], id[(k + 1) % 3], id[(k + 2) % 3]});
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
    for (; i < corners.size() && corners[i][0] == v; ++i)
      link.push_back({corners[i][1], corners[i][2]});
    ++link_vertices;
    if (r.ok && !LinkIsOneCycle(link)) {
      remember(v);
      fail(DescribeVertex(handle.at(v)) +
           " on dO is not regular (its boundary triangles are not one fan)");
    }
  }
  r.boundary_vertices = link_vertices;
  if (!s_.dt.is_valid(false)) fail("the Delaunay triangulation is not valid");
  return r;
}

}  // namespace detail

// -------------------------------------------------------------------------------------------------
// Benchmark and diagnostic hooks (engine_internal.h).
using detail::Cell_handle;
using detail::Dt;
using detail::Hooks;
using detail::InvariantChecker;
using detail::Point;
using detail::RayEntry;
using detail::ToPoint;
using detail::Vertex_handle;

namespace {

// The hooks' state, made on first use.
Hooks& H(detail::EngineState& s) {
  if (!s.hooks) s.hooks = std::make_unique<Hooks>();
  return *s.hooks;
}

}  // namespace

namespace internal {

int64_t EngineInternals::TraverseOnly(Engine& e, uint64_t point_id, uint64_t camera_id) {
  Engine::Impl& m = *e.impl_;
  const auto pi = m.s.point_index.find(point_id);
  const auto ci = m.s.camera_index.find(camera_id);
  if (pi == m.s.point_index.end() || ci == m.s.camera_index.end()) return 0;
  const auto& rec = m.s.points[pi->second];
  if (!rec.in_triangulation || m.s.dt.dimension() != 3) return 0;
  int64_t n = 0;
  auto it = m.caster.BeginWalk(rec.vertex->point(), m.s.cameras[ci->second], rec.vertex->cell(),
                               rec.vertex);
  const auto end = m.s.dt.segment_traverser_cells_end();
  for (; it != end && n < m.s.opt.max_cells_per_ray; ++it) {
    if (m.s.dt.is_infinite(Cell_handle(it))) break;
    ++n;
  }
  return n;
}

int64_t EngineInternals::CastRay(Engine& e, uint64_t point_id, uint64_t camera_id, int sign) {
  Engine::Impl& m = *e.impl_;
  const auto pi = m.s.point_index.find(point_id);
  const auto ci = m.s.camera_index.find(camera_id);
  if (pi == m.s.point_index.end() || ci == m.s.camera_index.end()) return 0;
  const int64_t before = m.s.stats.cells_weighted;
  m.caster.Cast(ci->second, pi->second, sign);
  return m.s.stats.cells_weighted - before;
}

std::vector<uint64_t> EngineInternals::WindowCameras(const Engine& e, uint64_t point_id) {
  const Engine::Impl& m = *e.impl_;
  std::vector<uint64_t> out;
  const auto pi = m.s.point_index.find(point_id);
  if (pi == m.s.point_index.end()) return out;
  for (uint32_t c : m.s.Window(m.s.points[pi->second])) out.push_back(m.s.camera_ids[c]);
  return out;
}

void EngineInternals::RecordTransfers(Engine& e, bool on, size_t limit) {
  Hooks& h = H(e.impl_->s);
  h.record_transfers = on;
  h.record_limit = limit;
  if (on) h.recorded.clear();
}

const std::vector<RecordedTransfer>& EngineInternals::RecordedTransfers(const Engine& e) {
  static const std::vector<RecordedTransfer> kNone;
  const Engine::Impl& m = *e.impl_;
  return m.s.hooks ? m.s.hooks->recorded : kNone;
}

size_t EngineInternals::CollectBoundaryCells(Engine& e, size_t limit) {
  Engine::Impl& m = *e.impl_;
  std::vector<Cell_handle>& probe = H(m.s).probe_cells;
  probe.clear();
  for (auto c = m.s.dt.finite_cells_begin(); c != m.s.dt.finite_cells_end(); ++c) {
    if (probe.size() >= limit) break;
    bool on_boundary = false;
    for (int i = 0; i < 4; ++i)
      on_boundary = on_boundary || c->neighbor(i)->info().in_o != c->info().in_o;
    if (on_boundary && !m.s.HullAdjacent(c)) probe.push_back(c);
  }
  return probe.size();
}

int64_t EngineInternals::TestCollectedCells(Engine& e, bool by_links) {
  Engine::Impl& m = *e.impl_;
  const std::vector<Cell_handle>& probe = H(m.s).probe_cells;
  int64_t ok = 0;
  if (by_links)
    for (Cell_handle c : probe) ok += m.carving.ToggleKeepsManifoldByLinks(c) ? 1 : 0;
  else
    for (Cell_handle c : probe) ok += m.carving.ToggleKeepsManifold(c) ? 1 : 0;
  return ok;
}

void EngineInternals::CrossCheckManifoldTest(Engine& e, bool on) {
  H(e.impl_->s).cross_check_manifold_test = on;
}

int64_t EngineInternals::ManifoldTestMismatches(const Engine& e) {
  const Engine::Impl& m = *e.impl_;
  return m.s.hooks ? m.s.hooks->manifold_test_mismatches : 0;
}

void EngineInternals::ExactFillOnly(Engine& e, bool on) { H(e.impl_->s).exact_fill_only = on; }

void EngineInternals::SetBatchBounds(Engine& e, size_t group_rays, size_t listed_cells) {
  H(e.impl_->s).group_rays = group_rays;
  H(e.impl_->s).listed_cells = listed_cells;
}

std::array<int64_t, 2> EngineInternals::FillCounts(const Engine& e) {
  const Hooks* h = e.impl_->s.hooks.get();
  if (!h) return {0, 0};
  return {h->fills_fast.load(), h->fills_exact.load()};
}

int64_t EngineInternals::ShrinkAround(Engine& e, const Vec3& centre, double radius) {
  Engine::Impl& m = *e.impl_;
  const Point p = ToPoint(centre);
  std::vector<Cell_handle> d;
  const double r2 = radius * radius;
  for (auto c = m.s.dt.finite_cells_begin(); c != m.s.dt.finite_cells_end(); ++c) {
    bool near = false;
    for (int i = 0; i < 4 && !near; ++i)
      near = CGAL::squared_distance(c->vertex(i)->point(), p) <= r2;
    if (near) d.push_back(c);
  }
  const int64_t before = m.s.stats.cells_shrunk;
  // E = D here (a radius of 0 around the centre adds nothing beyond D's own cells).
  const double saved = m.s.opt.shrink_radius;
  m.s.opt.shrink_radius = 0.0;
  m.carving.Shrink(d, {p});
  m.s.opt.shrink_radius = saved;
  return m.s.stats.cells_shrunk - before;
}

bool EngineInternals::ForceNonManifoldToggle(Engine& e) {
  Engine::Impl& m = *e.impl_;
  for (Cell_handle c : H(m.s).probe_cells) {
    if (m.carving.ToggleKeepsManifoldByLinks(c)) continue;
    m.carving.SetInO(c, !c->info().in_o);
    return true;
  }
  return false;
}
void EngineInternals::OverwriteCollectedWeight(Engine& e, size_t index, double weight) {
  Engine::Impl& m = *e.impl_;
  H(m.s).probe_cells.at(index)->info().weight = m.s.ToUnits(weight);
}
int64_t EngineInternals::UnlistOneCell(Engine& e) {
  detail::EngineState& s = e.impl_->s;
  for (uint32_t pt = 0; pt < s.points.size(); ++pt)
    for (uint32_t k = 0; k < s.points[pt].ray_state.size(); ++k) {
      if (!s.points[pt].Listed(k)) continue;
      Cell_handle first;
      s.ForEachListed(pt, k, [&](Cell_handle c) {
        if (first == Cell_handle() && !c->info().final) first = c;
      });
      if (first == Cell_handle()) continue;
      s.Unlist(pt, k, first);
      return static_cast<int64_t>(s.points[pt].id);
    }
  return -1;
}
int64_t EngineInternals::Grow(Engine& e) {
  Engine::Impl& m = *e.impl_;
  const int64_t before = m.s.stats.cells_grown;
  m.carving.Grow();
  return m.s.stats.cells_grown - before;
}

std::vector<BoundaryFacetProbe> EngineInternals::ProbeBoundary(const Engine& e) {
  const Engine::Impl& m = *e.impl_;
  std::vector<BoundaryFacetProbe> out;
  for (auto c = m.s.dt.finite_cells_begin(); c != m.s.dt.finite_cells_end(); ++c) {
    if (!c->info().in_o) continue;
    for (int i = 0; i < 4; ++i) {
      const Cell_handle n = c->neighbor(i);
      if (n->info().in_o) continue;
      BoundaryFacetProbe f;
      for (int k = 0; k < 3; ++k) {
        const Vertex_handle v = c->vertex(Dt::vertex_triple_index(i, k));
        const int64_t id = v->info().id;
        f.point_ids[k] = id >= 0 ? static_cast<int64_t>(m.s.points[id].id) : -1;
        f.vertices[k] = {v->point().x(), v->point().y(), v->point().z()};
      }
      f.weight_in_o = m.s.FromUnits(c->info().weight);
      f.weight_outside = m.s.FromUnits(n->info().weight);
      f.outside_free = m.s.IsFree(n);
      f.outside_hull_adjacent = m.s.dt.is_infinite(n) || m.s.HullAdjacent(n);
      out.push_back(f);
    }
  }
  return out;
}

std::vector<CellProbe> EngineInternals::ProbeCells(const Engine& e) {
  const Engine::Impl& m = *e.impl_;
  std::vector<CellProbe> out;
  for (auto c = m.s.dt.finite_cells_begin(); c != m.s.dt.finite_cells_end(); ++c) {
    CellProbe p;
    for (int k = 0; k < 4; ++k) {
      const Vertex_handle v = c->vertex(k);
      const int64_t id = v->info().id;
      p.point_ids[k] = id >= 0 ? static_cast<int64_t>(m.s.points[id].id) : -1;
      p.vertices[k] = {v->point().x(), v->point().y(), v->point().z()};
    }
    p.weight = m.s.FromUnits(c->info().weight);
    p.in_o = c->info().in_o;
    p.free = m.s.IsFree(c);
    out.push_back(p);
  }
  return out;
}

std::string EngineInternals::CheckRaySets(Engine& e) {
  Engine::Impl& m = *e.impl_;
  if (m.s.opt.visibility_mode != VisibilityMode::kExact) return "not in exact mode";
  int64_t live = 0, visits = 0;
  for (auto c = m.s.dt.finite_cells_begin(); c != m.s.dt.finite_cells_end(); ++c)
    for (const RayEntry& r : c->info().rays) live += m.s.Live(r) ? 1 : 0;
  for (uint32_t pt = 0; pt < m.s.points.size(); ++pt) {
    const auto& rec = m.s.points[pt];
    for (size_t k = 0; k < rec.cameras.size(); ++k) {
      if (!rec.Cast(k)) continue;
      std::string missing;
      m.caster.Walk(rec.ray_end[k].end, m.s.cameras[rec.cameras[k]], m.caster.WalkHint(rec),
                    m.caster.StartVertex(rec), [&](Cell_handle c) {
                      ++visits;
                      bool held = false;
                      for (const RayEntry& r : c->info().rays)
                        held = held || (r.point == pt && r.camera == k && m.s.Live(r));
                      if (!held && missing.empty()) missing = InvariantChecker(m.s).DescribeCell(c);
                    });
      if (!missing.empty())
        return "the ray of point " + std::to_string(rec.id) + " from camera " +
               std::to_string(m.s.camera_ids[rec.cameras[k]]) + " crosses " + missing +
               ", which does not hold it";
    }
  }
  if (live != visits)
    return "the cells hold " + std::to_string(live) + " rays, the rays cross " +
           std::to_string(visits) + " cells";
  return {};
}

void EngineInternals::DropRayLists(Engine& e) { e.impl_->caster.DropLists(); }

void EngineInternals::Regrow(Engine& e) {
  Engine::Impl& m = *e.impl_;
  for (auto c = m.s.dt.all_cells_begin(); c != m.s.dt.all_cells_end(); ++c)
    m.carving.SetInO(c, false);
  m.s.TakeDirty([](Cell_handle) {});
  m.carving.Grow();
}

void EngineInternals::RecastAllAndRegrow(Engine& e) {
  Engine::Impl& m = *e.impl_;
  for (auto c = m.s.dt.all_cells_begin(); c != m.s.dt.all_cells_end(); ++c) {
    m.carving.SetInO(c, false);
    m.s.Ledger(c->info().weight, 0);
    c->info().weight = 0;
    c->info().rays.clear();
  }
  m.caster.DropLists();
  for (auto& rec : m.s.points)
    for (uint32_t& state : rec.ray_state) state &= ~detail::PointRecord::kFlags;
  m.s.TakeDirty([](Cell_handle) {});
  for (uint32_t pt = 0; pt < m.s.points.size(); ++pt)
    for (uint32_t cam : m.s.points[pt].cameras) m.caster.Cast(cam, pt, +1);
  m.s.TakeDirty([](Cell_handle) {});
  m.carving.Grow();
}

}  // namespace internal

}  // namespace imr::engine
