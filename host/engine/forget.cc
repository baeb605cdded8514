// Long drives (EngineOptions::forget, DESIGN.md section 10): what no live change can reach is
// final; its part of dO is handed out, its rays freed at once, and its vertices leave the
// triangulation when enough of them have gathered (engine_parts.h, Forgetting); and its entry in
// the keyframe (Engine::Impl::WithoutRetired, Forget).
#include "host/engine/engine_parts.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <unordered_map>

namespace imr::engine::detail {

uint64_t Forgetting::Voxel(const Point& p, double size) {
  // Through int64_t: a negative coordinate's cell, converted straight to unsigned, is undefined.
  auto axis = [&](double x) {
    return static_cast<uint64_t>(static_cast<int64_t>(std::floor(x / size))) & 0x1FFFFF;
  };
  return axis(p.x()) << 42 | axis(p.y()) << 21 | axis(p.z());
}

bool Forgetting::Returned() const {
  if (!have_camera_ || left_.empty()) return false;
  const double size = 2.0 * s_.opt.steiner_spacing;
  // The voxel of the camera and its neighbours: within a voxel of a place left.
  for (int dx = -1; dx <= 1; ++dx)
    for (int dy = -1; dy <= 1; ++dy)
      for (int dz = -1; dz <= 1; ++dz)
        if (left_.count(Voxel(Point(newest_.x() + dx * size, newest_.y() + dy * size,
                                    newest_.z() + dz * size),
                              size)))
          return true;
  return false;
}

void Forgetting::AddUpdateCameras(std::vector<Point> centres) {
  if (!centres.empty()) {
    newest_ = centres.back();
    if (!have_camera_) last_step_ = centres.front();  // the first step measures from here
    have_camera_ = true;
  }
  const double size = 2.0 * s_.opt.steiner_spacing, d = s_.opt.ForgetDistance();
  for (const Point& c : centres)
    if (path_.empty() || CGAL::squared_distance(path_.back(), c) >= size * size)
      path_.push_back(c);
  while (!path_.empty() && CGAL::squared_distance(path_.front(), newest_) > d * d) {
    left_.insert(Voxel(path_.front(), size));
    path_.pop_front();
  }
  recent_.push_back(std::move(centres));
  // The updates that hold the last `window` cameras (every camera of the newest one).
  size_t held = 0;
  for (const auto& update : recent_) held += update.size();
  while (recent_.size() > 1 && held - recent_.front().size() >= static_cast<size_t>(s_.opt.window)) {
    held -= recent_.front().size();
    recent_.pop_front();
  }
}

bool Forgetting::Due() const {
  return have_camera_ &&
         CGAL::squared_distance(newest_, last_step_) >= s_.opt.ForgetStep() * s_.opt.ForgetStep();
}

// Entirely (a ball of `radius` around p) behind the newest camera, on the side the cameras came
// from, and forget_distance beyond every live camera.
bool Forgetting::FarBehind(const Point& p, double radius) const {
  const double along = (p.x() - newest_.x()) * behind_[0] + (p.y() - newest_.y()) * behind_[1] +
                       (p.z() - newest_.z()) * behind_[2];
  if (along <= radius) return false;
  const double reach = s_.opt.ForgetDistance() + radius + live_radius_;
  for (const Point& c : live_)
    if (CGAL::squared_distance(p, c) <= reach * reach) return false;
  return true;
}

// A cell becomes final when the ball around its vertices is far behind (FarBehind) and none of
// them is a point named with the last `window` cameras (a point still tracked may move).
bool Forgetting::BecomesFinal(Cell_handle c) const {
  // Most cells are on the newest camera's side of the plane: one vertex there says no.
  for (int i = 0; i < 4; ++i) {
    const Vertex_handle v = c->vertex(i);
    if (s_.dt.is_infinite(v)) continue;
    const Point& p = v->point();
    if ((p.x() - newest_.x()) * behind_[0] + (p.y() - newest_.y()) * behind_[1] +
            (p.z() - newest_.z()) * behind_[2] <= 0.0)
      return false;
  }
  double m[3] = {0, 0, 0};
  const Point* p[4];
  int n = 0;
  for (int i = 0; i < 4; ++i) {
    const Vertex_handle v = c->vertex(i);
    if (s_.dt.is_infinite(v)) continue;
    const int64_t id = v->info().id;
    if (id >= 0 && Live(s_.points[static_cast<size_t>(id)])) return false;
    p[n++] = &v->point();
    m[0] += v->point().x(), m[1] += v->point().y(), m[2] += v->point().z();
  }
  const Point g(m[0] / n, m[1] / n, m[2] / n);
  double r2 = 0.0;
  for (int i = 0; i < n; ++i) r2 = std::max(r2, CGAL::squared_distance(g, *p[i]));
  return FarBehind(g, std::sqrt(r2));
}

namespace {

// How far `points` spread: the median distance from their per-axis median (robust to outliers;
// pipeline/scale.cc measures the scale's cameras and points alike).
double Spread(std::vector<Vec3> points) {
  if (points.empty()) return 0.0;
  auto median = [](std::vector<double>& v) {
    std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
    return v[v.size() / 2];
  };
  std::vector<double> v(points.size());
  Vec3 m{};
  for (int a = 0; a < 3; ++a) {
    for (size_t i = 0; i < points.size(); ++i) v[i] = points[i][a];
    m[a] = median(v);
  }
  for (size_t i = 0; i < points.size(); ++i)
    v[i] = std::hypot(points[i][0] - m[0], points[i][1] - m[1], points[i][2] - m[2]);
  return median(v);
}

}  // namespace

bool Forgetting::Travelled() {
  if (s_.stats.updates == 0 || s_.cameras.size() < 2) return false;
  std::vector<double> steps;
  steps.reserve(s_.cameras.size() - 1);
  for (size_t i = 1; i < s_.cameras.size(); ++i)
    steps.push_back(std::sqrt(CGAL::squared_distance(s_.cameras[i - 1], s_.cameras[i])));
  std::nth_element(steps.begin(), steps.begin() + steps.size() / 2, steps.end());
  s_.stats.forget_camera_step = steps[steps.size() / 2];
  std::vector<Vec3> centres, points;
  centres.reserve(s_.cameras.size());
  for (const Point& c : s_.cameras) centres.push_back({c.x(), c.y(), c.z()});
  points.reserve(s_.points.size());
  for (const PointRecord& rec : s_.points)
    if (!rec.removed) points.push_back(rec.position);
  s_.stats.forget_camera_spread = Spread(std::move(centres));
  s_.stats.forget_point_spread = Spread(std::move(points));
  return s_.stats.forget_camera_step < 0.5 * s_.opt.ForgetDistance() &&
         s_.stats.forget_camera_spread <= kAroundAnObject * s_.stats.forget_point_spread;
}

void Forgetting::Freeze(std::vector<Triangle>* facets, std::vector<Vertex_handle>* deep) {
  facets->clear();
  deep->clear();
  last_step_ = newest_;
  ++s_.stats.forget_steps;
  // The live cameras, thinned: one stands for those within live_radius_ of it (a ball test
  // against it, widened by that radius, is the test against each).
  live_radius_ = 0.5 * s_.opt.steiner_spacing;
  live_.clear();
  const Point* oldest = nullptr;
  for (const auto& update : recent_)
    for (const Point& c : update) {
      if (!oldest) oldest = &c;
      if (live_.empty() || CGAL::squared_distance(live_.back(), c) > live_radius_ * live_radius_)
        live_.push_back(c);
    }
  // The direction the cameras came from: from the newest to the oldest live camera. Standing
  // still (less than a grid step over the window) nothing is behind.
  if (!oldest) return;
  const double d[3] = {oldest->x() - newest_.x(), oldest->y() - newest_.y(),
                       oldest->z() - newest_.z()};
  const double len = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
  if (len < s_.opt.steiner_spacing) return;
  for (int k = 0; k < 3; ++k) behind_[k] = d[k] / len;

  // Every vertex of a cell that becomes final lies behind the newest camera and forget_distance
  // beyond every live camera (the cell's ball does): the cells are found around the vertices
  // that do and are not deep yet, read in storage order, instead of all cells with their four
  // vertices each (cache misses: a third of the engine's time on a long drive).
  std::vector<Cell_handle> now, around;
  const uint64_t tested = ++s_.stamp;  // stamps are only compared for equality
  for (auto v = s_.dt.finite_vertices_begin(); v != s_.dt.finite_vertices_end(); ++v) {
    if (v->info().deep || !FarBehind(v->point(), 0.0)) continue;
    around.clear();
    s_.dt.incident_cells(v, std::back_inserter(around));
    for (Cell_handle c : around) {
      if (c->info().final || c->info().stamp == tested) continue;
      c->info().stamp = tested;
      if (BecomesFinal(c)) now.push_back(c);
    }
  }
  // kAuto: the first step with something to make final decides; until then nothing was.
  if (!s_.forgetting && !now.empty()) {
    if (!Travelled()) {
      ++s_.stats.forget_steps_held;
      return;
    }
    s_.forgetting = true;
    s_.stats.forget_on_update = s_.stats.updates + 1;
  }
  const uint64_t mark = ++s_.stamp;
  for (Cell_handle c : now) {
    CellInfo& info = c->info();
    info.final = true;
    info.dirty = false;  // out of the growing seeds (its entry in the list is skipped)
    info.stamp = mark;
    std::vector<RayEntry>().swap(info.rays);
  }
  s_.stats.cells_finalized += static_cast<int64_t>(now.size());
  s_.stats.cells_final += static_cast<int64_t>(now.size());

  // The facets of dO between a cell final now and a final cell, each once, oriented toward the
  // cell in O. A cell made final by a rebuild (forgotten) never meets one final now: its
  // neighbours were all final when it was made.
  for (Cell_handle c : now) {
    if (s_.dt.is_infinite(c)) continue;
    for (int i = 0; i < 4; ++i) {
      const Cell_handle n = c->neighbor(i);
      const CellInfo& ni = n->info();
      if (!ni.final || ni.forgotten || s_.dt.is_infinite(n)) continue;
      if (ni.stamp == mark && &*n < &*c) continue;  // both final now: the lower one hands it out
      if (ni.in_o == c->info().in_o) continue;
      const Cell_handle o = c->info().in_o ? c : n;
      const int j = o == c ? i : n->index(c);
      facets->push_back({{o->vertex(Dt::vertex_triple_index(j, 0)),
                          o->vertex(Dt::vertex_triple_index(j, 1)),
                          o->vertex(Dt::vertex_triple_index(j, 2))}});
    }
  }

  // The vertices of those cells (and of the cells born final since the last step that are
  // still there) whose every cell is final now.
  std::vector<Vertex_handle> candidates;
  auto candidate = [&](Cell_handle c) {
    for (int i = 0; i < 4; ++i)
      if (!s_.dt.is_infinite(c->vertex(i)) && !c->vertex(i)->info().deep)
        candidates.push_back(c->vertex(i));
  };
  for (Cell_handle c : now) candidate(c);
  for (Cell_handle c : s_.born_final)
    if (s_.dt.tds().cells().is_used(c) && c->info().final) candidate(c);
  s_.born_final.clear();
  std::sort(candidates.begin(), candidates.end());
  candidates.erase(std::unique(candidates.begin(), candidates.end()), candidates.end());
  std::vector<Cell_handle> star;
  for (Vertex_handle v : candidates) {
    star.clear();
    s_.dt.incident_cells(v, std::back_inserter(star));
    bool all = true;
    for (Cell_handle c : star) all = all && c->info().final;
    if (!all) continue;
    v->info().deep = true;
    deep->push_back(v);
  }
  deep_since_rebuild_ += static_cast<int64_t>(deep->size());
}

void Forgetting::MaybeRebuild() {
  const int64_t vertices = static_cast<int64_t>(s_.dt.number_of_vertices());
  if (2 * deep_since_rebuild_ < vertices) return;
  // The vertices that can go: deep, and every neighbour deep (or the infinite vertex); a
  // point's only when no update of the window named it (a move of this update may follow).
  std::vector<Vertex_handle> gone, around;
  int64_t deep = 0;
  for (auto v = s_.dt.finite_vertices_begin(); v != s_.dt.finite_vertices_end(); ++v) {
    if (!v->info().deep) continue;
    ++deep;
    const int64_t id = v->info().id;
    if (id >= 0 && Live(s_.points[static_cast<size_t>(id)])) continue;
    around.clear();
    s_.dt.adjacent_vertices(v, std::back_inserter(around));
    bool all = true;
    for (Vertex_handle u : around) all = all && (s_.dt.is_infinite(u) || u->info().deep);
    if (all) gone.push_back(v);
  }
  // The deep vertices that stay count toward the next rebuild.
  deep_since_rebuild_ = deep - static_cast<int64_t>(gone.size());
  if (2 * static_cast<int64_t>(gone.size()) < vertices) return;
  const auto t0 = Clock::now();
  Rebuild(gone);
  s_.stats.time.rebuild += SecondsSince(t0);
}

namespace {

struct KeyHash {
  size_t operator()(const std::array<int64_t, 4>& k) const {
    uint64_t h = 0x9E3779B97F4A7C15ull;
    for (int64_t x : k) {
      h ^= static_cast<uint64_t>(x) + 0x9E3779B97F4A7C15ull + (h << 6) + (h >> 2);
      h *= 0xBF58476D1CE4E5B9ull;
    }
    return static_cast<size_t>(h ^ (h >> 31));
  }
};

}  // namespace

// Rebuild's plan: which vertices go, which points retire, and the points' new numbers.
struct Forgetting::Renumbering {
  static constexpr uint32_t kFreed = ~0u;
  std::vector<Vertex_handle> gone;  // sorted
  std::vector<uint8_t> retire;      // per point: retired now or before
  std::vector<uint32_t> number;     // per point: its new number, or kFreed (its record goes)
  uint32_t kept = 0;                // records that stay

  bool Goes(Vertex_handle v) const { return std::binary_search(gone.begin(), gone.end(), v); }
  // A vertex's id in the new triangulation (a point's new number; the infinite vertex lowest).
  int64_t NewId(const Dt& dt, Vertex_handle v) const {
    if (dt.is_infinite(v)) return std::numeric_limits<int64_t>::min();
    const int64_t id = v->info().id;
    return id < 0 ? id : static_cast<int64_t>(number[static_cast<size_t>(id)]);
  }
};

// The triangulation of every vertex but `gone`; cells whose vertices all stay keep their infos,
// the rest are final and forgotten. Points whose vertex goes are retired (and those never in
// the triangulation that lie far behind); their records are freed unless a live cell still
// holds one of their rays, and the records that stay are numbered again, in the same order (the
// canonical orders of growing and peeling read the numbers: they see the same order as before).
void Forgetting::Rebuild(const std::vector<Vertex_handle>& gone) {
  const Renumbering r = Renumber(gone);
  Dt dt;
  std::vector<std::pair<Cell_handle, Cell_handle>> matched;  // (new, old)
  if (!TriangulateKept(r, &dt) || !MatchCells(r, dt, &matched)) {
    ++s_.stats.rebuilds_abandoned;
    return;
  }
  MoveCellInfos(r, &dt, &matched);
  int64_t retired_now = 0, freed = 0;
  KeepRecords(r, &retired_now, &freed);
  Install(&dt);
  // The Steiner grid forgets the nodes that no camera to come can place again: beyond a
  // camera's reach (its cube's corner) behind the final region.
  const double corner = std::sqrt(3.0) * (s_.opt.max_ray_length + s_.opt.steiner_margin);
  steiner_.Forget([&](const Point& node) { return FarBehind(node, corner); });

  ++s_.stats.rebuilds;
  s_.stats.vertices_forgotten += static_cast<int64_t>(gone.size());
  s_.stats.points_forgotten += retired_now;
  s_.stats.point_records_freed += freed;
}

// Which points retire, which records go (retired, and no live cell holds a current ray of
// theirs), and the new numbers of the rest.
Forgetting::Renumbering Forgetting::Renumber(const std::vector<Vertex_handle>& gone) const {
  Renumbering r;
  r.gone = gone;
  std::sort(r.gone.begin(), r.gone.end());
  const size_t n_points = s_.points.size();
  r.retire.assign(n_points, 0);
  std::vector<uint8_t> held(n_points, 0);
  for (size_t pt = 0; pt < n_points; ++pt) {
    const PointRecord& rec = s_.points[pt];
    if (rec.retired) {
      r.retire[pt] = 1;
    } else if (rec.in_triangulation) {
      r.retire[pt] = r.Goes(rec.vertex) ? 1 : 0;
    } else {
      r.retire[pt] = !Live(rec) &&
                     FarBehind(ToPoint(rec.position), 0.0);
    }
  }
  if (s_.opt.visibility_mode == VisibilityMode::kExact)
    for (auto c = s_.dt.finite_cells_begin(); c != s_.dt.finite_cells_end(); ++c)
      if (!c->info().final)
        for (const RayEntry& e : c->info().rays)
          if (r.retire[e.point] && s_.Live(e)) held[e.point] = 1;
  r.number.assign(n_points, Renumbering::kFreed);
  for (size_t pt = 0; pt < n_points; ++pt)
    if (!r.retire[pt] || held[pt]) r.number[pt] = r.kept++;
  return r;
}

// The new triangulation: the vertices that stay, with their infos and new ids. False when it
// does not hold them all in 3D.
bool Forgetting::TriangulateKept(const Renumbering& r, Dt* dt) const {
  std::vector<std::pair<Point, VertexInfo>> kept;
  kept.reserve(s_.dt.number_of_vertices() - r.gone.size());
  for (auto v = s_.dt.finite_vertices_begin(); v != s_.dt.finite_vertices_end(); ++v) {
    if (r.Goes(v)) continue;
    VertexInfo info = v->info();
    info.id = r.NewId(s_.dt, v);
    info.o_cells = 0;  // counted again by Install
    kept.emplace_back(v->point(), info);
  }
  dt->insert(kept.begin(), kept.end());
  return dt->number_of_vertices() == kept.size() && dt->dimension() == 3;
}

// Old cells whose vertices all stay, by their vertices' new ids; each new cell finds its own.
// Every live cell must be found, and every new cell touch deep vertices only (what the choice of
// `gone` promises); else false, and the old triangulation stays (counted: not expected).
bool Forgetting::MatchCells(const Renumbering& r, const Dt& dt,
                            std::vector<std::pair<Cell_handle, Cell_handle>>* matched) const {
  using Key = std::array<int64_t, 4>;
  auto key_of = [](auto ids) {
    std::sort(ids.begin(), ids.end());
    return ids;
  };
  std::unordered_map<Key, Cell_handle, KeyHash> old_cells;
  old_cells.reserve(s_.dt.number_of_cells());
  int64_t live_kept = 0;
  for (auto c = s_.dt.all_cells_begin(); c != s_.dt.all_cells_end(); ++c) {
    bool stays = true;
    Key k;
    for (int i = 0; i < 4; ++i) {
      stays = stays && !r.Goes(c->vertex(i));
      k[i] = r.NewId(s_.dt, c->vertex(i));
    }
    if (!stays) continue;
    old_cells.emplace(key_of(k), c);
    live_kept += c->info().final ? 0 : 1;
  }
  matched->reserve(old_cells.size());
  int64_t live_found = 0;
  bool new_cells_deep = true;
  for (auto c = dt.all_cells_begin(); c != dt.all_cells_end(); ++c) {
    Key k;
    for (int i = 0; i < 4; ++i)
      k[i] = dt.is_infinite(c->vertex(i)) ? std::numeric_limits<int64_t>::min()
                                          : c->vertex(i)->info().id;
    const auto it = old_cells.find(key_of(k));
    if (it == old_cells.end()) {
      for (int i = 0; i < 4; ++i)
        new_cells_deep =
            new_cells_deep && (dt.is_infinite(c->vertex(i)) || c->vertex(i)->info().deep);
      continue;
    }
    matched->push_back({c, it->second});
    live_found += it->second->info().final ? 0 : 1;
  }
  return live_found == live_kept && new_cells_deep;
}

// Cell infos move over, their rays renumbered (entries of freed records dropped); the new cells
// where the forgotten vertices were are final.
void Forgetting::MoveCellInfos(const Renumbering& r, Dt* dt,
                               std::vector<std::pair<Cell_handle, Cell_handle>>* matched) {
  for (auto c = dt->all_cells_begin(); c != dt->all_cells_end(); ++c) {
    CellInfo& info = c->info();
    info.final = info.forgotten = true;
  }
  for (auto& [c, old] : *matched) {
    c->info() = std::move(old->info());
    std::vector<RayEntry>& rays = c->info().rays;
    if (rays.empty()) continue;
    // Entries of freed records are stale (a live cell held none of their current rays).
    rays.erase(std::remove_if(rays.begin(), rays.end(),
                              [&](const RayEntry& e) {
                                return r.number[e.point] == Renumbering::kFreed;
                              }),
               rays.end());
    for (RayEntry& e : rays) e.point = r.number[e.point];
  }
  *matched = {};
}

// The points: retired ids out of the index, records freed or numbered again.
void Forgetting::KeepRecords(const Renumbering& r, int64_t* retired_now, int64_t* freed) {
  std::vector<PointRecord> points;
  points.reserve(r.kept);
  for (size_t pt = 0; pt < s_.points.size(); ++pt) {
    PointRecord& rec = s_.points[pt];
    if (r.retire[pt] && !rec.retired) {
      rec.retired = true;
      ++*retired_now;
      retired_.Add(rec.id);
      s_.point_index.erase(rec.id);
    }
    if (r.number[pt] == Renumbering::kFreed) {
      ++*freed;
      continue;
    }
    if (rec.retired) rec.in_triangulation = false, rec.vertex = Vertex_handle();
    if (!rec.retired) s_.point_index[rec.id] = r.number[pt];
    points.push_back(std::move(rec));
  }
  s_.points.swap(points);
}

// The new triangulation in place (the old one is freed with *dt), and what pointed into the old
// one: O's counters, the ledger, the dirty cells, the points' vertices, the ray lists.
void Forgetting::Install(Dt* dt) {
  s_.dt.swap(*dt);
  s_.last_vertex = Vertex_handle();
  s_.cells_in_o = 0;
  s_.stats.cells_final = 0;
  s_.weight_ledger = 0;
  s_.dirty.clear();
  for (auto c = s_.dt.all_cells_begin(); c != s_.dt.all_cells_end(); ++c) {
    const CellInfo& info = c->info();
    s_.weight_ledger += static_cast<uint64_t>(info.weight);
    s_.stats.cells_final += info.final ? 1 : 0;
    if (info.dirty) s_.dirty.push_back(c);
    if (!info.in_o) continue;
    ++s_.cells_in_o;
    for (int i = 0; i < 4; ++i) ++c->vertex(i)->info().o_cells;
  }
  for (auto v = s_.dt.finite_vertices_begin(); v != s_.dt.finite_vertices_end(); ++v) {
    const int64_t id = v->info().id;
    if (id < 0) continue;
    PointRecord& rec = s_.points[static_cast<size_t>(id)];
    rec.vertex = v;
    s_.last_vertex = v;
  }
  caster_.ForgetCells();
  if (s_.hooks) s_.hooks->probe_cells.clear();
}

}  // namespace imr::engine::detail

namespace imr::engine {

using detail::Clock;
using detail::Triangle;

// Forgetting's entry in the keyframe: the update without what it says of retired points, and a
// step (what became final handed out as a part, then maybe a rebuild).
std::unique_ptr<KeyframeUpdate> Engine::Impl::WithoutRetired(const KeyframeUpdate& u) {
  if (!s.forgetting || forgetting.retired().empty()) return nullptr;
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

}  // namespace imr::engine
