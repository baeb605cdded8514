// The update's points (paper section 3): the update validated before anything changes, the
// cameras a point is seen from, a point inserted (its conflict zone shrunk out of O, its cells
// replaced) or removed, and a new or refused point entering the triangulation; the weight
// transfer (section 3.2, engine_parts.h, WeightTransfer) gives the cells a change makes their
// weights from those it destroys.
#include "host/engine/engine_parts.h"

#include <sstream>

namespace imr::engine {
namespace detail {

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

}  // namespace detail

using detail::Clock;
using detail::Dt;
using detail::Facet;
using detail::PointRecord;
using detail::Removed;

namespace {

bool Finite(const Vec3& p) {
  return std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2]);
}

}  // namespace

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
  const Point p = detail::ToPoint(s.points[pt].position);
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

}  // namespace imr::engine
