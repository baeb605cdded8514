// A keyframe's moves (paper section 3): a point's vertex from p_old to p_new, its region D shrunk
// out of O, the weights transferred and its rays cast again; in kExact the moves in their order
// (MoveOrder), planned ahead on the thread pool (move_planner.cc) and committed one by one, with
// the rays of the moving points un-cast and cast in two batches around them.
#include "host/engine/engine_parts.h"

namespace imr::engine {

using detail::Clock;
using detail::Dt;
using detail::Facet;
using detail::PointRecord;
using detail::Removed;
using detail::ToPoint;

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

}  // namespace imr::engine
