// Casting of viewing rays (engine_parts.h, RayCaster): one ray at a time in the weights and rays
// modes; in exact mode, the ray sets of the cells, cast and un-cast in keyframe batches on the
// thread pool, and the holes a change of the triangulation opens in them.
#include "host/engine/engine_parts.h"

#include <algorithm>
#include <array>
#include <cmath>

namespace imr::engine::detail {

void RayCaster::Cast(uint32_t cam, uint32_t pt, int sign) {
  if (s_.opt.visibility_mode != VisibilityMode::kExact) {
    CastWeights(cam, pt, sign);
    return;
  }
  const size_t k = RayIndex(s_.points[pt], cam);
  if (k == static_cast<size_t>(-1)) return;
  if (sign > 0) ExactCast(pt, k);
  else ExactUncast(pt, k);
}

// cast_rays: one viewing ray, camera centre -> point. T = traversed cells, N1 = their
// neighbours, N2 = neighbours of N1; each cell once per ray (paper §2.1).
void RayCaster::CastWeights(uint32_t cam, uint32_t pt, int sign) {
  const PointRecord& rec = s_.points[pt];
  if (!rec.in_triangulation) return;
  if (s_.dt.dimension() != 3) return;
  const Point& b = s_.cameras[cam];
  Point a;
  if (!RaySegment(rec.vertex->point(), b, &a)) return;
  if (sign > 0) ++s_.stats.rays_cast;
  else ++s_.stats.rays_cast_backward;
  ring_[0].clear();
  ring_[1].clear();
  const bool rays_mode = s_.opt.visibility_mode == VisibilityMode::kRays;
  // Each cell is weighted when it is first reached (T, then N1, then N2), while it is in cache;
  // only T and N1 are kept, to find the next ring.
  auto weigh = [&](Cell_handle c, int level) {
    CellInfo& info = c->info();
    if (info.final) return;  // forget: nothing changes a final cell
    const int64_t before = info.weight;
    const bool was_free = before > s_.threshold;
    if (rays_mode) {
      // Lovi et al.: a cell remembers the rays that raised its weight (at most K, oldest
      // forgotten); a ray already stored is not counted twice when it is re-cast.
      for (const RayEntry& e : info.rays)
        if (e.camera == cam && e.point == pt) return;
      info.weight += s_.unit[level];
      info.rays.push_back({cam, pt, static_cast<uint8_t>(level)});
      if (static_cast<int>(info.rays.size()) > s_.opt.rays_per_cell)
        info.rays.erase(info.rays.begin());
    } else {
      info.weight += sign * s_.unit[level];
      if (s_.opt.nonnegative_weights && info.weight < 0) info.weight = 0;
    }
    s_.Ledger(before, info.weight);
    if (!was_free && info.weight > s_.threshold) s_.MarkDirty(c);
  };
  // T: the walk from the point's own vertex (no point location, ~15x faster than a walk from an
  // arbitrary cell), to the cell holding the camera, the hull or max_cells_per_ray cells. N1 and
  // N2 are found with the walk's stamp.
  Walk(
      a, b, rec.vertex->cell(), rec.vertex,
      [&](Cell_handle c) {
        ring_[0].push_back(c);
        weigh(c, 0);
      },
      cam);
  s_.stats.cells_traversed += static_cast<int64_t>(ring_[0].size());
  int64_t weighted = static_cast<int64_t>(ring_[0].size());
  for (int level = 1; level < 3; ++level)
    for (Cell_handle c : ring_[level - 1])
      for (int i = 0; i < 4; ++i) {
        Cell_handle n = c->neighbor(i);
        if (n->info().stamp == s_.stamp || s_.dt.is_infinite(n)) continue;
        n->info().stamp = s_.stamp;
        if (level == 1) ring_[1].push_back(n);
        weigh(n, level);
        ++weighted;
      }
  s_.stats.cells_weighted += weighted;
}

// Index of camera `cam` in a point's list, or npos.
size_t RayCaster::RayIndex(const PointRecord& rec, uint32_t cam) {
  for (size_t k = 0; k < rec.cameras.size(); ++k)
    if (rec.cameras[k] == cam) return k;
  return static_cast<size_t>(-1);
}

// Adds ray k of point pt (its current generation) to a cell. A cell's list keeps stale entries
// until it is destroyed or holds twice as many entries as rays: then it is compacted.
void RayCaster::AddRay(Cell_handle c, uint32_t pt, uint32_t k) {
  if (c->info().final) return;  // forget: nothing changes a final cell
  PointRecord& rec = s_.points[pt];
  const int64_t before = c->info().weight;
  if (PushRay(&c->info(), {k, pt, rec.Gen(k)})) s_.MarkDirty(c);
  s_.Ledger(before, c->info().weight);
  if (rec.Listed(k)) s_.list_extra[EngineState::RayKey(pt, k)].push_back(c);
}

// One batch's worth of storage is kept for the next batch's walks, the larger of each worker's
// two buffers (no allocation per ray, nor per batch once the largest batch has been seen).
void RayCaster::DropLists() {
  for (const auto& [pt, k] : listed_) {  // an un-cast ray lost its flag with its cast
    PointRecord& rec = s_.points[pt];
    if (k < rec.ray_state.size()) rec.ray_state[k] &= ~uint32_t{PointRecord::kListed};
  }
  listed_.clear();
  for (size_t w = 0; w < s_.list_cells.size(); ++w) {
    if (w >= walk_cells_.size()) walk_cells_.resize(w + 1);
    std::vector<Cell_handle>& kept = walk_cells_[w];
    if (s_.list_cells[w].capacity() > kept.capacity()) kept.swap(s_.list_cells[w]);
  }
  std::vector<std::vector<Cell_handle>>().swap(s_.list_cells);
  s_.list_extra.clear();
}

// The entry and its weight; true when the cell just became free. Reads only the points' ray
// states besides the cell: safe on several threads for distinct cells.
bool RayCaster::PushRay(CellInfo* info, const RayEntry& e) const {
  const int64_t before = info->weight;
  // Compacted when it holds 2 live + 8 entries or more; the weight is unit[0] times the live
  // entries, so compared without a division (this runs once per cell a ray crosses).
  const int64_t u = s_.unit[0], n = static_cast<int64_t>(info->rays.size());
  if (u > 0 ? n * u >= 2 * before + 8 * u : n >= 8) {
    info->rays.erase(std::remove_if(info->rays.begin(), info->rays.end(),
                                    [&](const RayEntry& x) { return !s_.Live(x); }),
                     info->rays.end());
  }
  // Grown by a quarter, not doubled: the lists are most of a long drive's memory, and a
  // quarter is about the allocator's size classes (doubling left 45 % of the capacity unused
  // on the dense street).
  std::vector<RayEntry>& rays = info->rays;
  if (rays.size() == rays.capacity()) rays.reserve(rays.size() + rays.size() / 4 + 2);
  rays.push_back(e);
  info->weight += s_.unit[0];
  return before <= s_.threshold && info->weight > s_.threshold;
}

// The segment a ray carves: from its point to its camera, or, for a ray longer than
// max_ray_length with long_rays = near_camera, the max_ray_length next to the camera (the
// space near the camera is free whatever the far end is). False: the ray carves nothing.
bool RayCaster::RaySegment(const Point& p, const Point& cam, Point* start) {
  const double len2 = CGAL::squared_distance(p, cam);
  if (len2 <= 0.0) return false;  // A point at the camera centre carves nothing.
  if (len2 <= s_.opt.max_ray_length * s_.opt.max_ray_length) {
    *start = p;
    return true;
  }
  ++s_.stats.rays_skipped_too_long;
  if (s_.opt.long_rays == LongRays::kSkip) return false;
  ++s_.stats.rays_truncated_to_camera;
  const double f = s_.opt.max_ray_length / std::sqrt(len2);
  *start = Point(cam.x() + f * (p.x() - cam.x()), cam.y() + f * (p.y() - cam.y()),
                 cam.z() + f * (p.z() - cam.z()));
  return true;
}

// Ray k of point pt, cast from the point's current position.
void RayCaster::ExactCast(uint32_t pt, size_t k) {
  PointRecord& rec = s_.points[pt];
  if (!rec.in_triangulation || rec.Cast(k) || s_.dt.dimension() != 3) return;
  const uint32_t cam = rec.cameras[k];
  const Point& b = s_.cameras[cam];
  Point a;
  if (!RaySegment(rec.vertex->point(), b, &a)) return;
  ++s_.stats.rays_cast;
  int64_t n = 0;
  rec.SetFlags(k, PointRecord::kCast);
  rec.ray_end[k].end = a;
  Walk(
      a, b, rec.vertex->cell(), rec.vertex,
      [&](Cell_handle c) {
        AddRay(c, pt, static_cast<uint32_t>(k));
        ++n;
      },
      cam);
  s_.stats.cells_traversed += n;
  s_.stats.cells_weighted += n;
}

// Takes ray k of point pt out of the cells it was cast into: the same segment walked again
// takes one off each cell's count; its entries there become stale (a new generation).
// A short list is searched first (a cell reached only by a walk that disagrees with the one
// that gave it the ray, through an edge or a vertex, keeps its count); a long one, deep in free
// space, is not: that would cost more than all the rest.
void RayCaster::ExactUncast(uint32_t pt, size_t k) {
  PointRecord& rec = s_.points[pt];
  if (!rec.Cast(k)) return;
  const RayEntry mine{static_cast<uint32_t>(k), pt, rec.Gen(k)};
  const bool listed = rec.Listed(k);
  rec.Uncast(k);
  ++s_.stats.rays_cast_backward;
  if (listed) {  // its cells are known: no walk
    ++s_.stats.rays_uncast_listed;
    ++s_.stamp;
    s_.ForEachListed(pt, k, [&](Cell_handle c) {
      if (c->info().stamp == s_.stamp || c->info().final) return;
      c->info().stamp = s_.stamp;
      s_.Ledger(c->info().weight, c->info().weight - s_.unit[0]);
      c->info().weight -= s_.unit[0];
    });
    return;
  }
  const uint32_t cam = rec.cameras[k];
  Walk(
      rec.ray_end[k].end, s_.cameras[cam], WalkHint(rec), StartVertex(rec),
      [&](Cell_handle c) {
        if (c->info().final) return;  // it kept the ray's unit when it became final
        const int64_t before = c->info().weight;
        if (!Holds(c->info(), mine)) {
          ++s_.stats.ray_mismatches;
          return;
        }
        c->info().weight -= s_.unit[0];
        s_.Ledger(before, c->info().weight);
      },
      cam);
}

// Whether an un-cast may take the ray `mine` off the cell (see ExactUncast).
bool RayCaster::Holds(const CellInfo& info, const RayEntry& mine) const {
  if (info.weight < s_.unit[0]) return false;
  if (info.rays.size() > kSearchUncastBelow) return true;
  for (const RayEntry& e : info.rays)
    if (e.point == mine.point && e.camera == mine.camera && e.level == mine.level) return true;
  return false;
}

// kExact batches: the rays a keyframe casts (or un-casts) together, walked on several threads.
// The walks only read the triangulation; what they found is then applied cell by cell, each
// cell by one thread and its rays in batch order, so weights, ray lists and all that follows
// are the same for any number of threads.
// Which apply task owns a cell: a hash of its address's 4 KB page (fixed while the cell lives;
// neighbours in memory go to the same task, which writes their cache lines alone).
size_t RayCaster::Owner(Cell_handle c, size_t parts) {
  const uint64_t h = (reinterpret_cast<uintptr_t>(&*c) >> 12) * 0x9E3779B97F4A7C15ull;
  return static_cast<size_t>(((h >> 32) * parts) >> 32);  // in [0, parts) without a division
}

// The finite cells the segment a -> b crosses, in order, as Walk visits them but without its
// stamps (a cell may repeat; the apply step skips repeats). Thread-safe: reads only.
bool RayCaster::Trace(const BatchRay& r, std::vector<Cell_handle>* out) const {
  int steps = 0;
  try {
    auto it = BeginWalk(r.a, r.b, r.hint, r.from);
    const auto end = s_.dt.segment_traverser_cells_end();
    for (; it != end; ++it) {
      Cell_handle c = it;
      if (s_.dt.is_infinite(c)) break;
      if (++steps > s_.opt.max_cells_per_ray) return false;
      out->push_back(c);
    }
  } catch (...) {
    return false;
  }
  return true;
}

namespace {

// A vertex met by a filtered walk, its terms relative to the ray a + t d: r = p - a, w = d x r,
// and m = max |r_i|. The side of the ray's line against the edge (u, v) is
// S(u, v) = d . (r_u x r_v) = w_u . r_v (CGAL's orientation(a, u, v, b)), computed in double
// with a rounding bound of kWalkErr |d|_1 m_u m_v: each of the determinant's six terms
// d_j r_uk r_vi carries at most eight roundings (d, r_u, r_v, the cross product, the dot
// product), so the error is below 8 * 2^-53 (1 + tiny) times their absolute sum, which is at
// most 2 |d|_1 m_u m_v: 1.8e-15 |d|_1 m_u m_v; 1e-14 leaves a factor 5.
struct WalkVertex {
  const void* v = nullptr;
  double r[3], w[3], m;
};
constexpr double kWalkErr = 1e-14;

}  // namespace

// The cell strictly holding each camera the batch's walks end at (CameraEnd once per camera
// and batch, serial: the walks then stop by comparing cells, not with a test per cell).
void RayCaster::LocateEnds(std::vector<BatchRay>& rays) {
  batch_ends_.clear();
  if (!s_.opt.filtered_walk || s_.dt.dimension() != 3) return;
  if (camera_end_slot_.size() < s_.cameras.size()) camera_end_slot_.resize(s_.cameras.size(), -1);
  std::vector<uint32_t> used;
  for (BatchRay& r : rays) {
    if (r.listed || r.from == Vertex_handle() || r.from->point() != r.a) continue;
    const uint32_t cam = s_.points[r.point].cameras[r.k];
    int32_t& slot = camera_end_slot_[cam];
    if (slot < 0) {
      slot = static_cast<int32_t>(batch_ends_.size());
      batch_ends_.push_back(CameraEnd(cam, r.b, r.hint));
      used.push_back(cam);
    }
    if (batch_ends_[static_cast<size_t>(slot)].usable) r.end_slot = slot;
  }
  for (uint32_t cam : used) camera_end_slot_[cam] = -1;
}

RayCaster::WalkEnd RayCaster::CameraEnd(uint32_t camera, const Point& b, Cell_handle hint) {
  WalkEnd e;
  if (s_.dt.dimension() != 3) return e;
  if (camera_cell_.size() < s_.cameras.size()) camera_cell_.resize(s_.cameras.size());
  Cell_handle& last = camera_cell_[camera];
  Dt::Locate_type lt = Dt::OUTSIDE_AFFINE_HULL;
  int li = 0, lj = 0;
  // A destroyed cell stays in CGAL's container, marked free (or reused for another cell).
  if (last != Cell_handle() && s_.dt.tds().cells().is_used(last) && !s_.dt.is_infinite(last) &&
      s_.dt.side_of_cell(b, last, lt, li, lj) == CGAL::ON_BOUNDED_SIDE && lt == Dt::CELL) {
    e.cell = last, e.usable = true;
    return e;
  }
  last = s_.dt.locate(b, lt, li, lj, hint);
  if (lt == Dt::CELL) {
    e.cell = last, e.usable = true;
  } else {
    last = Cell_handle();
    e.usable = lt == Dt::OUTSIDE_CONVEX_HULL;  // the walks stop at the hull
  }
  return e;
}

// check_invariants: whether a filtered walk's cells (or its truncation) differ from CGAL's walk
// of the same ray.
bool RayCaster::DiffersFromCgal(const BatchRay& r, const Cell_handle* cells, size_t count,
                                bool truncated) const {
  std::vector<Cell_handle> cgal;
  const bool whole = Trace(r, &cgal);
  return whole == truncated || cgal.size() != count || !std::equal(cgal.begin(), cgal.end(), cells);
}

// CGAL's regular step (Triangulation_segment_cell_iterator_3::walk_to_next_3, a cell entered
// through facet i, the new vertex q = vertex i): with (j0, j1, j2) = vertex_triple_index(i, .),
// S(q, j0) > 0 and S(q, j1) < 0 -> leave through facet j2; S(q, j0) > 0 and S(q, j1) > 0 -> j0;
// S(q, j0) < 0 and S(q, j2) > 0 -> j1; S(q, j0) < 0 and S(q, j2) < 0 -> j0; a zero sign is
// its degenerate case (an edge or a vertex on the line): here, any sign within rounding gives
// the ray back to CGAL. Its test of the camera against the exit facet becomes end == cell.
RayCaster::Walked RayCaster::FilteredTrace(const Point& a, const Point& b, Vertex_handle s,
                                           Cell_handle end, std::vector<Cell_handle>* out) const {
  const double d[3] = {b.x() - a.x(), b.y() - a.y(), b.z() - a.z()};
  const double err = kWalkErr * (std::fabs(d[0]) + std::fabs(d[1]) + std::fabs(d[2]));
  auto make = [&](Vertex_handle vh, WalkVertex* o) {
    const Point& p = vh->point();
    o->v = &*vh;
    o->r[0] = p.x() - a.x(), o->r[1] = p.y() - a.y(), o->r[2] = p.z() - a.z();
    o->w[0] = d[1] * o->r[2] - d[2] * o->r[1];
    o->w[1] = d[2] * o->r[0] - d[0] * o->r[2];
    o->w[2] = d[0] * o->r[1] - d[1] * o->r[0];
    o->m = std::max(std::fabs(o->r[0]), std::max(std::fabs(o->r[1]), std::fabs(o->r[2])));
  };
  // S(u, v) as +1 / -1, 0 when within rounding.
  auto side = [&](const WalkVertex& u, const WalkVertex& v) {
    const double x = u.w[0] * v.r[0] + u.w[1] * v.r[1] + u.w[2] * v.r[2];
    const double t = err * u.m * v.m;
    return x > t ? 1 : (x < -t ? -1 : 0);
  };
  // The terms of the current cell's vertices, by index, taken from the previous cell's where
  // shared (a step computes only its new vertex's).
  WalkVertex terms[2][4];
  WalkVertex* cur = terms[0];
  WalkVertex* prev = terms[1];
  auto fill = [&](Cell_handle c) {
    std::swap(cur, prev);
    for (int k = 0; k < 4; ++k) {
      const Vertex_handle vh = c->vertex(k);
      const void* id = &*vh;
      int h = 0;
      while (h < 4 && prev[h].v != id) ++h;
      if (h < 4) cur[k] = prev[h];
      else make(vh, &cur[k]);
    }
  };

  // The start: the cell of s's star that the ray enters, found by walking around s (its
  // facet opposite s, as (j0, j1, j2), has S < 0 on its three edges when the ray enters the
  // cell from s: the ray leaves the cell through that facet). s's own terms are 0.
  Cell_handle c = s->cell();
  int inf = 0;
  if (c->has_vertex(s_.dt.infinite_vertex(), inf)) c = c->neighbor(inf);
  int i = 0;
  for (int step = 0;; ++step) {
    if (step > 64 || s_.dt.is_infinite(c)) return Walked::kUndecided;
    i = c->index(s);
    fill(c);
    const int j0 = Dt::vertex_triple_index(i, 0), j1 = Dt::vertex_triple_index(i, 1),
              j2 = Dt::vertex_triple_index(i, 2);
    const int s01 = side(cur[j0], cur[j1]), s12 = side(cur[j1], cur[j2]),
              s20 = side(cur[j2], cur[j0]);
    if (s01 == 0 || s12 == 0 || s20 == 0) return Walked::kUndecided;
    if (s01 < 0 && s12 < 0 && s20 < 0) break;
    // The ray is on the far side of the plane through s and an edge (u, v) with S > 0: cross
    // the facet of s on that plane.
    c = c->neighbor(s01 > 0 ? j2 : (s12 > 0 ? j0 : j1));
  }

  int exit = i;
  int steps = 0;
  for (;;) {
    if (++steps > s_.opt.max_cells_per_ray) return Walked::kTruncated;
    out->push_back(c);
    if (c == end) return Walked::kDone;
    const Cell_handle n = c->neighbor(exit);
    if (s_.dt.is_infinite(n)) return Walked::kDone;
    const int e = n->index(c);
    fill(n);
    const int j0 = Dt::vertex_triple_index(e, 0), j1 = Dt::vertex_triple_index(e, 1),
              j2 = Dt::vertex_triple_index(e, 2);
    const int t0 = side(cur[e], cur[j0]);
    if (t0 > 0) {
      const int t1 = side(cur[e], cur[j1]);
      if (t1 == 0) return Walked::kUndecided;
      exit = t1 < 0 ? j2 : j0;
    } else if (t0 < 0) {
      const int t2 = side(cur[e], cur[j2]);
      if (t2 == 0) return Walked::kUndecided;
      exit = t2 > 0 ? j1 : j0;
    } else {
      return Walked::kUndecided;
    }
    c = n;
  }
}

// Walks every ray of the batch (in parallel), then calls apply(ray, cell, part) for each cell
// each ray crosses, once per ray and cell, in batch order per cell; returns the parts.
// append: the walks go after those already in walk_cells_ (a cast batch's groups, listed).
template <class Apply>
std::vector<RayCaster::BatchPart> RayCaster::RunBatch(std::vector<BatchRay>& rays,
                                                      bool split_apply, bool append,
                                                      Apply&& apply) {
  util::ThreadPool& tp = s_.Pool();
  const size_t workers = static_cast<size_t>(tp.size());
  LocateEnds(rays);
  walk_cells_.resize(workers);
  if (!append)
    for (auto& w : walk_cells_) w.clear();
  constexpr size_t kChunk = 32;
  const size_t chunks = (rays.size() + kChunk - 1) / kChunk;
  tp.Run(chunks, [&](size_t chunk, int worker) {
    // The buffer taken out of walk_cells_ for the chunk: the workers' vector headers share a
    // cache line there, and a push_back per cell writes one.
    std::vector<Cell_handle> out;
    out.swap(walk_cells_[static_cast<size_t>(worker)]);
    for (size_t i = chunk * kChunk; i < std::min(rays.size(), (chunk + 1) * kChunk); ++i) {
      BatchRay& r = rays[i];
      r.worker = static_cast<uint32_t>(worker);
      r.offset = static_cast<uint32_t>(out.size());
      if (r.listed && !s_.list_extra.count(EngineState::RayKey(r.point, r.k))) {
        const PointRecord::RayList& l = s_.points[r.point].ray_list[r.k];
        r.from_list = true;  // read in place (its destroyed cells are null: skipped)
        r.worker = l.worker, r.offset = l.offset, r.count = l.count;
        continue;
      }
      if (r.listed) {
        s_.ForEachListed(r.point, r.k, [&](Cell_handle c) { out.push_back(c); });
      } else {
        Walked w = Walked::kUndecided;
        if (r.end_slot >= 0)
          w = FilteredTrace(r.a, r.b, r.from, batch_ends_[static_cast<size_t>(r.end_slot)].cell,
                            &out);
        if (w == Walked::kUndecided) {
          out.resize(r.offset);
          r.exact_walk = true;
          r.truncated = !Trace(r, &out);
          // CGAL's walk may meet a cell twice (through an edge or a vertex); a list holds each
          // cell once (the un-cast batch takes a unit off each listed cell).
          std::sort(out.begin() + r.offset, out.end());
          out.erase(std::unique(out.begin() + r.offset, out.end()), out.end());
        } else {
          r.truncated = w == Walked::kTruncated;
          if (s_.opt.check_invariants)
            r.walk_differs = DiffersFromCgal(r, out.data() + r.offset, out.size() - r.offset,
                                             r.truncated);
        }
      }
      r.count = static_cast<uint32_t>(out.size() - r.offset);
      if (r.list_to) s_.points[r.point].ray_list[r.k] = {r.worker, r.offset, r.count};
    }
    out.swap(walk_cells_[static_cast<size_t>(worker)]);
  });
  const size_t parts = rays.size() < 64 || !split_apply ? 1 : workers;
  std::vector<BatchPart> part(parts);
  const uint64_t base = s_.stamp + 1;
  s_.stamp += rays.size();
  tp.Run(parts, [&](size_t t, int) {
    BatchPart& p = part[t];
    // A ray's cells in pieces: the task's own picked first without a branch per cell (which
    // task owns a cell is a coin toss: a mispredicted branch for every other cell), then
    // applied, each once per ray (its stamp).
    constexpr uint32_t kPiece = 256;
    std::array<Tds::Cell*, kPiece> mine;
    for (size_t i = 0; i < rays.size(); ++i) {
      const BatchRay& r = rays[i];
      const Cell_handle* cells =
          (r.from_list ? s_.list_cells : walk_cells_)[r.worker].data() + r.offset;
      const uint64_t s = base + i;
      for (uint32_t j0 = 0; j0 < r.count; j0 += kPiece) {
        const uint32_t j1 = std::min(r.count, j0 + kPiece);
        uint32_t n = 0;
        for (uint32_t j = j0; j < j1; ++j) {
          const Cell_handle c = cells[j];
          mine[n] = c.operator->();  // null for a destroyed cell: not counted
          n += c != Cell_handle() && (parts == 1 || Owner(c, parts) == t) ? 1 : 0;
        }
        for (uint32_t j = 0; j < n; ++j) {
          const Cell_handle c = Tds::Cell_handle(mine[j]);
          if (c->info().stamp == s) continue;
          c->info().stamp = s;
          apply(r, c, p);
        }
      }
    }
  });
  for (const BatchRay& r : rays) {
    s_.stats.rays_truncated += r.truncated ? 1 : 0;
    s_.stats.rays_walked_exact += r.exact_walk ? 1 : 0;
    s_.stats.ray_mismatches += r.walk_differs ? 1 : 0;
  }
  return part;
}

void RayCaster::MergeParts(const std::vector<BatchPart>& parts) {
  for (const BatchPart& p : parts) {
    s_.weight_ledger += p.ledger;
    s_.stats.ray_mismatches += p.mismatches;
    for (Cell_handle c : p.became_free) s_.MarkDirty(c);
  }
}

// Casts the rays (point, k) that are not cast yet, from their points' current positions, in
// groups of kGroupRays rays (walked, then applied, in the batch's order: the same entries in
// each cell, in the same order, as one walk of the whole batch). The walks are kept as the
// rays' lists while they hold at most kListedCells cells; past that the batch lists nothing
// (its rays are walked if they are ever un-cast), so that a batch of long rays crossing many
// cells (a model seen from 100 units away, all in one keyframe: 33 M cells) does not hold
// every walk at once (8 bytes a cell: 400 MB).
void RayCaster::CastBatch(const std::vector<std::pair<uint32_t, uint32_t>>& todo,
                          bool weights_only) {
  if (s_.dt.dimension() != 3) return;
  DropLists();  // the walks below become the lists
  std::vector<BatchRay>& rays = batch_rays_;  // kept: a batch's worth of memory, touched once
  rays.clear();
  for (const auto& [pt, k] : todo) {
    PointRecord& rec = s_.points[pt];
    if (!rec.in_triangulation || rec.Cast(k)) continue;
    const Point& b = s_.cameras[rec.ray_end[k].camera];
    Point a;
    if (!RaySegment(rec.vertex->point(), b, &a)) continue;
    ++s_.stats.rays_cast;
    rec.ray_end[k].end = a;
    rays.push_back({pt, k, rec.Gen(k), a, b, rec.vertex->cell(), rec.vertex});
    if (weights_only) {
      rec.SetFlags(k, PointRecord::kCast);
      continue;
    }
    // Its walk is its list (each thread writes the list places of its own rays).
    rec.SetFlags(k, PointRecord::kCast | PointRecord::kListed);
    listed_.push_back({pt, k});
    rays.back().list_to = true;
  }
  for (auto& w : walk_cells_) w.clear();  // DropLists left the old lists' storage there
  const auto apply = [&](const BatchRay& r, Cell_handle c, BatchPart& p) {
    if (c->info().final) return;  // forget: nothing changes a final cell
    CellInfo& info = c->info();
    if (weights_only) {
      const bool was_free = info.weight > s_.threshold;
      info.weight += s_.unit[0];
      if (!was_free && info.weight > s_.threshold) p.became_free.push_back(c);
    } else if (PushRay(&info, {r.k, r.point, r.gen})) {
      p.became_free.push_back(c);
    }
    p.ledger += static_cast<uint64_t>(s_.unit[0]);
    ++p.cells;
  };
  bool listing = !weights_only;
  InGroups(rays, [&](std::vector<BatchRay>& group) {
    if (!listing)
      for (BatchRay& r : group) r.list_to = false;
    const std::vector<BatchPart> parts =
        RunBatch(group, /*split_apply=*/true, /*append=*/listing, apply);
    MergeParts(parts);
    for (const BatchPart& p : parts)
      s_.stats.cells_traversed += p.cells, s_.stats.cells_weighted += p.cells;
    size_t walked = 0;
    for (const auto& w : walk_cells_) walked += w.size();
    if (listing && walked > ListedCells()) {  // too many to keep: this batch lists no ray
      listing = false;
      for (const auto& [pt, k] : listed_)
        s_.points[pt].ray_state[k] &= ~uint32_t{PointRecord::kListed};
      listed_.clear();
    }
  });
  if (listing) {
    std::swap(s_.list_cells, walk_cells_);  // the walks are the lists now
  } else {  // a rare batch, or the last: its storage goes
    for (auto& w : walk_cells_) std::vector<Cell_handle>().swap(w);
  }
}

// Takes the rays (point, k) that are cast out of their cells (as ExactUncast does, together).
void RayCaster::UncastBatch(const std::vector<std::pair<uint32_t, uint32_t>>& todo) {
  std::vector<BatchRay>& rays = batch_rays_;
  rays.clear();
  std::vector<std::pair<uint32_t, uint32_t>>& listed = uncast_listed_;
  listed.clear();
  for (const auto& [pt, k] : todo) {
    PointRecord& rec = s_.points[pt];
    if (!rec.Cast(k)) continue;
    if (rec.Listed(k)) {
      listed.push_back({pt, k});
      ++s_.stats.rays_uncast_listed;
    } else {
      rays.push_back({pt, k, rec.Gen(k), rec.ray_end[k].end, s_.cameras[rec.ray_end[k].camera],
                      WalkHint(rec), StartVertex(rec)});
    }
    rec.Uncast(k);  // and no longer listed (DropLists forgets the lists' storage)
    ++s_.stats.rays_cast_backward;
  }
  // A listed ray's cells are known, each once: a unit off each, on this thread (split among
  // the threads, the subtractions would have to be atomic, as rays of different threads share
  // cells: twice as slow on two threads as one plain pass, measured).
  uint64_t taken = 0;
  const int64_t unit = s_.unit[0];
  for (const auto& [pt, k] : listed)
    s_.ForEachListed(pt, k, [&](Cell_handle c) {
      if (c->info().final) return;  // the cast skipped it
      c->info().weight -= unit;
      ++taken;
    });
  s_.weight_ledger -= taken * static_cast<uint64_t>(unit);
  auto take_out = [&](const BatchRay& r, Cell_handle c, BatchPart& p) {
    CellInfo& info = c->info();
    if (info.final) return;  // it kept the ray's unit when it became final
    if (!Holds(info, {r.k, r.point, r.gen})) {
      ++p.mismatches;
      return;
    }
    info.weight -= s_.unit[0];
    p.ledger -= static_cast<uint64_t>(s_.unit[0]);
  };
  // In groups, as a cast batch (their walks are not kept).
  InGroups(rays, [&](std::vector<BatchRay>& group) {
    MergeParts(RunBatch(group, /*split_apply=*/false, /*append=*/false, take_out));
  });
}

TetPlanes PlanesOf(const Point& c0, const Point& c1, const Point& c2, const Point& c3) {
  const Point* corner[4] = {&c0, &c1, &c2, &c3};
  TetPlanes t;
  for (int i = 0; i < 4; ++i) {
    const Point& p0 = *corner[(i + 1) & 3];
    const Point& p1 = *corner[(i + 2) & 3];
    const Point& p2 = *corner[(i + 3) & 3];
    const Point& q = *corner[i];
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

bool ClipSegment(const TetPlanes& t, const double a[3], const double d[3], Clip* out) {
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

// kExact, before cells are destroyed: the rays they hold and where.
void RayCaster::CollectHole(const std::vector<Cell_handle>& cells, Hole* hole) {
  std::vector<HoleRay>& out = hole->rays;
  out.clear();
  ++hole_count_;
  if (point_hole_mark_.size() < s_.points.size()) {
    point_hole_mark_.resize(s_.points.size(), 0);
    point_hole_head_.resize(s_.points.size(), 0);
  }
  for (Cell_handle c : cells) c->info().fresh = true;  // "destroyed" while collecting
  for (Cell_handle c : cells) {
    if (s_.dt.is_infinite(c) || c->info().rays.empty()) continue;
    const TetPlanes planes = PlanesOf(c);
    for (const RayEntry& e : c->info().rays) {
      if (!s_.Live(e)) continue;  // a stale entry: dropped with the cell
      PointRecord& rec = s_.points[e.point];
      const size_t k = e.camera;
      if (rec.Listed(k)) s_.Unlist(e.point, k, c);  // RefillHole lists the new cells
      const Point& end = rec.ray_end[k].end;
      const Point& cam = s_.cameras[rec.ray_end[k].camera];
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
      if (point_hole_mark_[e.point] == hole_count_) {
        for (uint32_t i = point_hole_head_[e.point];; i = out[i].next) {
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
        point_hole_mark_[e.point] = hole_count_;
        point_hole_head_[e.point] = static_cast<uint32_t>(out.size());
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
    if (s_.dt.is_infinite(b) || b->info().fresh) continue;  // entered at an edge: ambiguous
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
void RayCaster::RefillHole(const std::vector<Cell_handle>& added, const Hole& h) {
  const std::vector<HoleRay>& hole = h.rays;
  if (hole.empty()) return;
  Cell_handle hint;
  fresh_planes_.clear();
  for (Cell_handle c : added) {
    if (s_.dt.is_infinite(c)) continue;
    c->info().fresh = true;
    c->info().slot = static_cast<uint32_t>(fresh_planes_.size());
    fresh_planes_.push_back(PlanesOf(c));
    if (hint == Cell_handle()) hint = c;
  }
  constexpr double kPad = 1e-6;
  // A face-to-face walk meets each new cell once per ray; when it gives up part way, the exact
  // walk skips the cells it already gave the ray.
  std::vector<Cell_handle>& given = given_;
  auto add = [&](Cell_handle c, const HoleRay& r, bool check) {
    if (!c->info().fresh) return;
    if (check && std::find(given.begin(), given.end(), c) != given.end()) return;
    if (!check) given.push_back(c);
    AddRay(c, r.point, r.camera);
    ++s_.stats.cells_rewalked;
  };
  for (const HoleRay& r : hole) {
    const PointRecord& rec = s_.points[r.point];
    const size_t k = r.camera;  // the ray's index among its point's s_.cameras
    const Point& e = rec.ray_end[k].end;
    const Point& cam = s_.cameras[rec.ray_end[k].camera];
    given.clear();
    const double a[3] = {e.x(), e.y(), e.z()};
    const double d[3] = {cam.x() - a[0], cam.y() - a[1], cam.z() - a[2]};
    const double t_end = std::min(1.0, r.t1 + kPad);
    ++s_.stats.rays_rewalked;
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
        if (s_.dt.is_infinite(x) || !x->has_vertex(rec.vertex)) continue;
        Clip cl;
        if (ClipSegment(fresh_planes_[x->info().slot], a, d, &cl) && cl.lo <= 1e-9 &&
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
      if (steps > s_.opt.max_cells_per_ray) {
        exact = true;
        break;
      }
      Clip cl;
      const bool ok = c->info().fresh
                          ? ClipSegment(fresh_planes_[c->info().slot], a, d, &cl)
                          : ClipSegment(PlanesOf(c), a, d, &cl);
      if (!ok || cl.hi_tie || cl.grazing || cl.hi_face < 0 || cl.hi < t - 1e-9) {
        exact = true;
        break;
      }
      add(c, r, false);
      if (cl.hi >= t_end) break;
      const Cell_handle next = c->neighbor(cl.hi_face);
      if (s_.dt.is_infinite(next)) break;
      t = cl.hi;
      c = next;
    }
    if (exact) {
      // The whole ray with exact predicates, as casting and un-casting walk it (cells already
      // given the ray are skipped): where a part of it runs through an edge or a vertex, a
      // walk of that part alone could choose other cells than the whole walk does.
      ++s_.stats.rays_rewalked_exact;
      Walk(e, cam, rec.in_triangulation ? WalkHint(rec) : hint, StartVertex(rec),
           [&](Cell_handle x) { add(x, r, true); });
    }
  }
  for (Cell_handle c : added) c->info().fresh = false;
}

void RayCaster::RefillExact(uint32_t pt, uint32_t k, const std::vector<Cell_handle>& given,
                            Cell_handle hint) {
  const PointRecord& rec = s_.points[pt];
  ++s_.stats.rays_rewalked_exact;
  const PointRecord::RayEnd& r = rec.ray_end[k];
  Walk(r.end, s_.cameras[r.camera], rec.in_triangulation ? WalkHint(rec) : hint,
       StartVertex(rec), [&](Cell_handle x) {
         if (!x->info().fresh || std::find(given.begin(), given.end(), x) != given.end()) return;
         AddRay(x, pt, k);
         ++s_.stats.cells_rewalked;
       });
}

// kRays: the whole-triangulation scan of Lovi et al. - remove from every cell the rays ending
// at point pt, and their contribution to the weight.
void RayCaster::ScanRemoveRays(uint32_t pt) {
  for (auto c = s_.dt.finite_cells_begin(); c != s_.dt.finite_cells_end(); ++c) {
    ++s_.stats.rays_scan_cells;
    auto& rs = c->info().rays;
    for (size_t i = 0; i < rs.size();) {
      if (rs[i].point == pt) {
        s_.Ledger(s_.unit[rs[i].level], 0);
        c->info().weight -= s_.unit[rs[i].level];
        rs.erase(rs.begin() + static_cast<std::ptrdiff_t>(i));
      } else {
        ++i;
      }
    }
  }
}

// Re-casts the rays of U (kRays), skipping rays of points no longer in the triangulation and,
// if given, the rays of point `skip`.
void RayCaster::RecastRays(std::vector<RayEntry> u, int64_t skip) {
  std::sort(u.begin(), u.end(), [](const RayEntry& a, const RayEntry& b) {
    return a.point != b.point ? a.point < b.point : a.camera < b.camera;
  });
  u.erase(std::unique(u.begin(), u.end(),
                      [](const RayEntry& a, const RayEntry& b) {
                        return a.point == b.point && a.camera == b.camera;
                      }),
          u.end());
  for (const RayEntry& r : u)
    if (static_cast<int64_t>(r.point) != skip) Cast(r.camera, r.point, +1);
}

}  // namespace imr::engine::detail
