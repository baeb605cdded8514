// The reconstruction engine (Romanoni & Matteucci, sections 2-3): the conductor of a keyframe
// (Engine::Impl::ApplyUpdate) and the Engine's public face. The parts and how they share the
// triangulation: engine_parts.h. A keyframe's steps, each in a file named for it:
//   the update validated, the points' cameras, insertion and removal
//     with the weight transfer (paper section 3.2)            point_updates.cc
//   the Steiner points the new rays reach                     steiner_grid.cc
//   the moves (section 3), in order, planned ahead            moves.cc, move_planner.cc
//   the viewing rays cast and un-cast (section 2.1)           ray_caster.cc
//   forgetting on long drives                                 forget.cc
//   shrink, peel and grow of O (section 2.2)                  carving.cc
//   the camera path opened in O                               camera_path.cc
//   dO as a mesh or in parts                                  surface_export.cc
// The invariant checker and the benchmark hooks: engine_checks.cc.
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
#include "host/engine/engine_parts.h"

namespace imr::engine {
namespace detail {

EngineState::EngineState(const EngineOptions& o) : opt(o) {
  forgetting = opt.forget == ForgetMode::kOn;
  if (forgetting) stats.forget_on_update = 1;
  unit = {ToUnits(opt.w1), ToUnits(opt.w2), ToUnits(opt.w3)};
  threshold = ToUnits(opt.free_threshold);
  // Exact mode: a cell's weight is w1 times the rays that cross it.
  if (opt.visibility_mode == VisibilityMode::kExact) threshold = unit[0] * opt.exact_min_rays - 1;
}

}  // namespace detail

// =================================================================================================
// The conductor.

using detail::Clock;
using detail::PointRecord;
using detail::ToPoint;

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
  const std::vector<Point> centres = AddNewCameras(u);
  {
    const auto ts = Clock::now();
    PlaceSteinerPoints(u, s.cameras.size() - centres.size());
    s.stats.time.steiner += SecondsSince(ts);
  }
  if (forgetting.Armed()) forgetting.AddUpdateCameras(centres);  // a copy: measured below too
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
  if (forgetting.Armed() && forgetting.Due()) Forget();
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
  PeelChanged(u);
  Grow();
  s.stats.time.grow += SecondsSince(tg);
  EndKeyframe(SecondsSince(t0));
  CheckCameras(centres);  // not in the keyframe's time
  if (s.opt.check_invariants) {
    ManifoldCheckResult r = detail::InvariantChecker(s).Check();
    if (!r.ok) return Status::Error("invariant broken after update: " + r.message);
  }
  return Status::Ok();
}

// The update's cameras not seen before, indexed in arrival order; their centres.
std::vector<Engine::Impl::Point> Engine::Impl::AddNewCameras(const KeyframeUpdate& u) {
  std::vector<Point> centres;
  for (const Camera& c : u.cameras) {
    if (s.camera_index.count(c.id)) continue;
    s.camera_index[c.id] = static_cast<uint32_t>(s.cameras.size());
    s.cameras.push_back(ToPoint(c.center));
    s.camera_ids.push_back(c.id);
    centres.push_back(s.cameras.back());
  }
  return centres;
}

// regrow_radius: O peeled around the points that moved or entered, so that grow labels their
// region again in weight order.
void Engine::Impl::PeelChanged(const KeyframeUpdate& u) {
  if (s.opt.regrow_radius <= 0.0) return;
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

// grow (paper section 2.2). The camera path (camera_path) is free space: its cells join O before
// grow, so that O grows on from them; after it, again, and a camera whose cell is still outside O
// has O peeled around it and grown again from its cell (OpenCameraPath).
void Engine::Impl::Grow() {
  const bool open_path = s.opt.camera_path > 0 && s.dt.dimension() == 3;
  const std::vector<Cell_handle> path = open_path ? CameraPathCells() : std::vector<Cell_handle>();
  if (open_path && s.cells_in_o > 0) carving.OpenPath(path);
  carving.Grow(s.forgetting ? CameraCell() : Cell_handle());
  if (open_path && s.cells_in_o > 0) OpenCameraPath(path);
}

// The keyframe counted: its time and the triangulation's size.
void Engine::Impl::EndKeyframe(double seconds) {
  s.stats.time.total += seconds;
  s.stats.keyframe_seconds.push_back(seconds);
  ++s.stats.updates;
  s.stats.vertices = static_cast<int64_t>(s.dt.number_of_vertices());
  s.stats.cells = static_cast<int64_t>(s.dt.tds().number_of_cells());
  s.stats.cells_in_o = s.cells_in_o;
}

// Where the new cameras are now: in O (free space), or inside matter. Before O exists there is
// nothing to be in or outside of: such cameras (the first keyframe's) are checked at the first
// update that has an O, the camera path having been opened for them.
void Engine::Impl::CheckCameras(const std::vector<Point>& centres) {
  s.unchecked_centres.insert(s.unchecked_centres.end(), centres.begin(), centres.end());
  if (s.dt.dimension() != 3 || s.cells_in_o == 0) return;
  for (const Point& c : s.unchecked_centres) {
    ++s.stats.cameras_checked;
    // From the newest point's cell: the cameras are near what they just saw.
    const Cell_handle cell = s.dt.locate(c, s.WalkHint());
    if (!s.dt.is_infinite(cell) && cell->info().in_o) ++s.stats.cameras_in_o;
  }
  s.unchecked_centres.clear();
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
  m.points += impl_->forgetting.retired().MemoryBytes();
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
bool Engine::forgetting() const { return impl_->s.forgetting; }
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
