// The engine's named parts over one Delaunay triangulation (paper sections 2-3). Private to
// host/engine: it includes CGAL, and only the engine's CGAL translation units include it (the
// CMake list names them). Engine::Impl conducts a keyframe through them (engine.cc); each part is
// a class over the shared EngineState:
//   RayCaster         viewing rays (paper §2.1): T, N1 and N2 weighted by one ray (weights and
//                     rays modes); the exact mode's ray sets, cast in batches on the thread pool,
//                     and the holes a change of the triangulation opens in them (ray_caster.cc)
//   WeightTransfer    the weights of the cells a change makes, from those it destroys (§3.2)
//                     (point_updates.cc)
//   Carving           O, the outside cells: the manifold test, shrink, peel and grow (§2.2)
//                     (carving.cc; the camera path's forced joins: camera_path.cc)
//   SteinerGrid       the Steiner points along the rays (steiner_grid.cc)
//   MovePlanner       exact mode's moves planned on the thread pool and made in order
//                     (move_planner.cc)
//   Forgetting        long drives (EngineOptions::forget): what no live change can reach is
//                     final, its part of dO handed out, its cells, rays and points freed
//                     (forget.cc)
//   InvariantChecker  dO closed, oriented and manifold; the weights against their ledger
//                     (engine_checks.cc)
// The benchmark and diagnostic hooks (engine_internal.h, engine_checks.cc) keep their state in
// Hooks, which a normal run never allocates.
#pragma once

#include "host/engine/engine.h"
#include "host/engine/engine_internal.h"
#include "host/engine/retired_ids.h"
#include "host/util/clock.h"
#include "host/util/thread_pool.h"

#include <CGAL/Delaunay_triangulation_3.h>
#include <CGAL/Delaunay_triangulation_cell_base_3.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Triangulation_cell_base_with_info_3.h>
#include <CGAL/Triangulation_vertex_base_with_info_3.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <deque>
#include <functional>
#include <limits>
#include <map>
#include <memory>
#include <stdexcept>
#include <string>
#include <unordered_map>
#include <unordered_set>
#include <utility>
#include <vector>

namespace imr::engine::detail {

using K = CGAL::Exact_predicates_inexact_constructions_kernel;

// One ray stored in a cell, 8 bytes (the cells' lists are most of the engine's memory: 12 bytes
// took a third more on the dense street). kRays: camera index (at most kMaxCameras), point, and
// the ring (level: 0 = T, 1 = N1, 2 = N2). kExact: the ray's index among its point's cameras
// (camera; a point keeps at most kMaxCameras), the point, and the ray's generation when it was
// added, modulo 2^16 (level): an entry whose generation is not the ray's current one is stale
// (the ray was un-cast since) and is dropped when met. Modulo 2^16, a stale entry would pass for
// current only if it outlived 65,536 un-casts of its ray in a cell never compacted nor
// destroyed meanwhile.
struct RayEntry {
  static constexpr uint32_t kMaxCameras = 0xFFFF;
  RayEntry() = default;
  RayEntry(uint32_t camera_, uint32_t point_, uint32_t level_)
      : point(point_), camera(static_cast<uint16_t>(camera_)),
        level(static_cast<uint16_t>(level_)) {}
  uint32_t point = 0;
  uint16_t camera = 0;
  uint16_t level = 0;
};
static_assert(sizeof(RayEntry) == 8);

struct VertexInfo {
  int64_t id = -1;     // >= 0: internal point index; < 0: Steiner point number -(k + 1).
  int32_t o_cells = 0;  // Incident cells in O (kept by SetInO: cells of O are never destroyed,
                        // shrink takes them out of O before the triangulation changes).
  int64_t key = -1;     // SurfacePart::keys: given when a part first names the vertex (a vertex
                        // handed out never moves again), -1 before.
  bool deep = false;    // forget: every incident cell is final, so nothing around the vertex
                        // changes again (its surface is complete: SurfacePart::completed).
};

// Serial numbers of cells (CellInfo::serial): unique within the process, so that a cell made
// where another was destroyed never passes for it.
inline std::atomic<uint64_t> g_next_cell_serial{1};
inline uint64_t NextCellSerial() { return g_next_cell_serial.fetch_add(1, std::memory_order_relaxed); }

struct CellInfo {
  int64_t weight = 0;     // In units of EngineOptions::weight_unit.
  uint64_t stamp = 0;     // Ray stamp: a cell joins T, N1 or N2 once per ray.
  bool in_o = false;      // Member of O (outside, the manifold part of free space).
  bool fresh = false;     // kExact: made by the triangulation change being processed.
  bool dirty = false;     // In EngineState::dirty (and not taken out since).
  bool final = false;     // forget: no live change may touch it any more: never destroyed,
                          // toggled or weighted again (its ray list is freed); its facets of dO
                          // with other final cells were handed out (Forgetting).
  bool forgotten = false;  // forget: made by a rebuild where forgotten vertices were: final,
                           // never in O, its facets never handed out.
  uint32_t slot = 0;      // kExact: index of the cell among those being made (scratch).
  uint32_t region = 0;    // Member of the region being peeled (Shrink's E, PeelAround's)
                          // when equal to EngineState::region_mark; apart from `stamp`, which
                          // the manifold test uses while the region is peeled.
  std::vector<RayEntry> rays;  // kRays: at most K rays that raised this cell's weight; kExact:
                               // every ray that crosses it (and stale entries, see RayEntry).
  uint64_t serial = NextCellSerial();  // Which cell this is: new for each cell made, and renewed
                                       // when a move reshapes it (MovePlan's validity).
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

inline Point ToPoint(const Vec3& p) { return Point(p[0], p[1], p[2]); }

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

struct PointRecord {
  uint64_t id = 0;
  Vertex_handle vertex;        // Valid when in_triangulation.
  bool in_triangulation = false;
  bool removed = false;        // Removed by an update (never enters again); a point refused
                               // at insertion (duplicate, dropped) tries again when it moves.
  bool retired = false;        // forget: its vertex was forgotten (or it never had one and lies
                               // where everything is final): its updates are ignored; the record
                               // stays only while a live cell holds one of its rays.
  int64_t named = 0;           // The cameras known when an update last named it (the newest
                               // camera's index + 1): a point named with the last `window`
                               // cameras may still move (Forgetting::Live).
  Vec3 position{};             // Latest estimate received.
  Vec3 grid_end{};             // Where the Steiner grid last followed its window's rays to.
  std::vector<uint32_t> cameras;  // Observing cameras (internal indices), oldest first.
  // kExact, parallel to cameras: each ray's state, its generation (+1 at each un-cast: entries
  // made before are stale) << 2 with kCast (and kListed, see ray_list) while it is cast. One word
  // a ray: a cell's entries are tested one by one (EngineState::Live) for rays scattered over
  // the points, and a point's rays then share a cache line (one struct of all a ray's fields
  // measured 20 % more L2 misses: cachegrind, 512 KB LL, 2026-11-27).
  static constexpr uint32_t kCast = 1, kListed = 2, kFlags = kCast | kListed;
  std::vector<uint32_t> ray_state;
  // Where the ray ended when it was cast (the point's position then; a ray older than the window
  // keeps its end when the point moves), with its camera: read together for each ray clipped.
  struct RayEnd {
    Point end;
    uint32_t camera;  // cameras[k]
  };
  std::vector<RayEnd> ray_end;
  // When ray_state has kListed, where the cells that hold the ray are listed
  // (EngineState::list_cells), so that un-casting it needs no walk.
  struct RayList {
    uint32_t worker = 0, offset = 0, count = 0;
  };
  std::vector<RayList> ray_list;
  bool Cast(size_t k) const { return (ray_state[k] & kCast) != 0; }
  bool Listed(size_t k) const { return (ray_state[k] & kListed) != 0; }
  uint32_t Gen(size_t k) const { return ray_state[k] >> 2; }
  void SetFlags(size_t k, uint32_t flags) { ray_state[k] = (ray_state[k] & ~kFlags) | flags; }
  // Un-cast: the flags down, the generation up (30 bits: a billion un-casts of one ray).
  void Uncast(size_t k) { ray_state[k] = (ray_state[k] & ~kFlags) + 4; }
};

// The state of the benchmark and diagnostic hooks (engine_internal.h).
struct Hooks {
  bool cross_check_manifold_test =
      false;  // Run both forms of the manifold test, count differences.
  int64_t manifold_test_mismatches = 0;
  bool record_transfers = false;
  size_t record_limit = 0;
  std::vector<internal::RecordedTransfer> recorded;
  std::vector<Cell_handle> probe_cells;
  // Planned moves' fills (MovePlanner::FillHole): exact_fill_only skips the floating-point
  // apexes; the counters (bumped on the planning threads) say how fills were made.
  bool exact_fill_only = false;
  std::atomic<int64_t> fills_fast{0}, fills_exact{0};
  // RayCaster's batch bounds when not 0 (EngineInternals::SetBatchBounds).
  size_t group_rays = 0, listed_cells = 0;
};

// What the parts share: the triangulation with its cells' weights and O, the points and cameras,
// the counters.
struct EngineState {
  explicit EngineState(const EngineOptions& o);

  EngineOptions opt;
  // Whether the engine forgets: opt.forget kOn, or kAuto once Forgetting's rule said so.
  bool forgetting = false;
  Dt dt;
  std::array<int64_t, 3> unit{};  // w1, w2, w3 in weight units.
  int64_t threshold = 0;          // T_w in weight units: a cell is free above it.

  std::vector<Point> cameras;
  // Centres of keyframes that came before there was an O to be in (the triangulation not yet 3D,
  // or no cell free yet): checked (stats cameras_in_o) at the first update where O exists.
  std::vector<Point> unchecked_centres;
  std::vector<uint64_t> camera_ids;
  std::unordered_map<uint64_t, uint32_t> camera_index;
  std::vector<PointRecord> points;
  std::unordered_map<uint64_t, uint32_t> point_index;
  Vertex_handle last_vertex;  // Locate hint.

  uint64_t stamp = 0;        // CellInfo::stamp of the current walk or star visit.
  uint32_t region_mark = 0;  // CellInfo::region of the region being peeled.
  // Cells whose state changed this keyframe (became free, created, shrunk): growing seeds. A
  // cell is in the set while its `dirty` flag is up; the list may also hold cells destroyed
  // since (their slots free, or another cell's whose flag is down) and repeats.
  std::vector<Cell_handle> dirty;
  int64_t cells_in_o = 0;
  // kExact: the cells of the rays the last cast batch listed (PointRecord::ray_list), kept from
  // that batch to the next keyframe's un-cast batch: the batch's walks as they were, per worker,
  // a cell destroyed since set to null; the cells a listed ray gained since (holes refilled) in
  // list_extra. Every cell that holds a listed ray, once or more (a walk may repeat a cell).
  std::vector<std::vector<Cell_handle>> list_cells;
  std::unordered_map<uint64_t, std::vector<Cell_handle>> list_extra;
  static uint64_t RayKey(uint32_t pt, size_t k) { return (uint64_t{pt} << 32) | k; }
  template <class Visit>
  void ForEachListed(uint32_t pt, size_t k, Visit&& visit) const {
    const PointRecord::RayList& l = points[pt].ray_list[k];
    const Cell_handle* cells = list_cells[l.worker].data() + l.offset;
    for (uint32_t i = 0; i < l.count; ++i)
      if (cells[i] != Cell_handle()) visit(cells[i]);
    if (auto it = list_extra.find(RayKey(pt, k)); it != list_extra.end())
      for (Cell_handle c : it->second) visit(c);
  }
  // A cell about to be destroyed leaves listed ray k of point pt (its cells after are listed by
  // whoever walks the ray through them).
  void Unlist(uint32_t pt, size_t k, Cell_handle c) {
    const PointRecord::RayList& l = points[pt].ray_list[k];
    Cell_handle* at = list_cells[l.worker].data() + l.offset;
    std::replace(at, at + l.count, c, Cell_handle());
    if (auto it = list_extra.find(RayKey(pt, k)); it != list_extra.end()) {
      std::vector<Cell_handle>& x = it->second;
      x.erase(std::remove(x.begin(), x.end(), c), x.end());
    }
  }
  // Sum of every cell's weight (finite and infinite), kept by each change of a weight and of the
  // cells: CheckInvariants compares it with the cells' own sum, so a weight changed or a cell made
  // or destroyed outside casting and transfer shows. Modulo 2^64 (unsigned wrap is exact).
  uint64_t weight_ledger = 0;
  // The last update (KeyframeUpdate::last) was applied: no update may follow; kExact cast its
  // rays as weights only, so a cell's weight may exceed its entries' units.
  bool sealed = false;
  EngineStats stats;
  std::unique_ptr<Hooks> hooks;  // null unless a benchmark or a test asked for them
  // The engine's threads (num_threads; kExact: the batches of rays and the moves' plans).
  util::ThreadPool& Pool() {
    if (!pool) pool = std::make_unique<util::ThreadPool>(util::ResolveThreads(opt.num_threads));
    return *pool;
  }
  std::unique_ptr<util::ThreadPool> pool;

  int64_t ToUnits(double w) const {
    if (!std::isfinite(w)) return 0;
    // A policy may return any finite double: saturate far below int64's range (llround of an
    // unrepresentable value is unspecified) while leaving room for rays added on top.
    constexpr double kMaxUnits = 4611686018427387904.0;  // 2^62
    const double u = std::clamp(w / opt.weight_unit, -kMaxUnits, kMaxUnits);
    return static_cast<int64_t>(std::llround(u));
  }
  double FromUnits(int64_t w) const { return static_cast<double>(w) * opt.weight_unit; }
  void Ledger(int64_t before, int64_t after) {
    weight_ledger += static_cast<uint64_t>(after) - static_cast<uint64_t>(before);
  }

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
    if (dt.is_infinite(c) || c->info().in_o || c->info().dirty) return;
    c->info().dirty = true;
    dirty.push_back(c);
  }
  // forget: whether a change that destroys these cells must be refused: one of them is final
  // and not inert (in O, or next to a cell of O: a facet of the surface handed out, or to be);
  // counted. An inert final cell may go: nothing of the surface was or will be made of it, and
  // the cells made in its place are final where they touch a deep vertex (BornFinal).
  // `strict`: any final cell refuses (a move in place reshapes the cells it keeps).
  bool BlockedByFinal(const std::vector<Cell_handle>& cells, bool strict = false) {
    if (!forgetting) return false;
    for (Cell_handle c : cells) {
      if (!c->info().final) continue;
      bool inert = !strict && !c->info().in_o;
      for (int i = 0; i < 4 && inert; ++i) inert = !c->neighbor(i)->info().in_o;
      if (!inert) {
        ++stats.changes_refused_final;
        return true;
      }
    }
    return false;
  }
  // forget: cells just made (before any ray reaches them) that touch a deep vertex are final:
  // nothing around a deep vertex changes (it was completed), and inert final cells are all
  // that a change there may have destroyed.
  void BornFinal(const std::vector<Cell_handle>& made) {
    if (!forgetting) return;
    for (Cell_handle c : made) {
      bool deep = false;
      for (int i = 0; i < 4 && !deep; ++i)
        deep = !dt.is_infinite(c->vertex(i)) && c->vertex(i)->info().deep;
      if (!deep || c->info().final) continue;
      c->info().final = true;
      ++stats.cells_final;
      ++stats.cells_finalized;
      born_final.push_back(c);
    }
  }
  std::vector<Cell_handle> born_final;  // since the last step: their vertices may be deep now
  // The cells in the dirty set, which is then empty.
  template <class Visit>
  void TakeDirty(Visit&& visit) {
    for (Cell_handle c : dirty) {
      if (!dt.tds().cells().is_used(c) || !c->info().dirty) continue;
      c->info().dirty = false;
      visit(c);
    }
    dirty.clear();
  }
  // The cell's vertex ids, sorted: a key that does not depend on memory addresses.
  // Vertices by id, not address: where their order decides something.
  static bool ById(Vertex_handle a, Vertex_handle b) { return a->info().id < b->info().id; }
  // Where to start a walk (locate, insert): the newest point's cell, near the newest cameras.
  Cell_handle WalkHint() const {
    return last_vertex != Vertex_handle() ? last_vertex->cell() : Cell_handle();
  }
  std::array<int64_t, 4> CellKey(Cell_handle c) const {
    std::array<int64_t, 4> k;
    for (int i = 0; i < 4; ++i)
      k[i] = dt.is_infinite(c->vertex(i)) ? std::numeric_limits<int64_t>::min()
                                          : c->vertex(i)->info().id;
    std::sort(k.begin(), k.end());
    return k;
  }
  // A cell's facets in the order of the ids of the vertices they are opposite (ids are unique):
  // where the order in which neighbours are visited decides something (growing and peeling O
  // among equal weights), it then depends on the triangulation, not on the order CGAL keeps a
  // cell's vertices in, which differs with the history of the cell.
  std::array<int, 4> CanonicalFacets(Cell_handle c) const {
    std::array<int64_t, 4> k;
    for (int i = 0; i < 4; ++i)
      k[i] = dt.is_infinite(c->vertex(i)) ? std::numeric_limits<int64_t>::min()
                                          : c->vertex(i)->info().id;
    std::array<int, 4> order = {0, 1, 2, 3};
    std::sort(order.begin(), order.end(), [&](int a, int b) { return k[a] < k[b]; });
    return order;
  }
  // kExact: is a cell's entry the current cast of its ray?
  bool Live(const RayEntry& e) const {
    const PointRecord& rec = points[e.point];
    if (e.camera >= rec.ray_state.size()) return false;
    const uint32_t state = rec.ray_state[e.camera];
    return (state & PointRecord::kCast) && static_cast<uint16_t>(state >> 2) == e.level;
  }
  // Where a point's last W cameras start in its list: the rays a move re-casts.
  size_t WindowBegin(const PointRecord& rec) const {
    const size_t w = static_cast<size_t>(opt.window), n = rec.cameras.size();
    return n > w ? n - w : 0;
  }
  // Those cameras (internal indices).
  std::vector<uint32_t> Window(const PointRecord& rec) const {
    const auto begin = rec.cameras.begin() + static_cast<std::ptrdiff_t>(WindowBegin(rec));
    return std::vector<uint32_t>(begin, rec.cameras.end());
  }
};

// -------------------------------------------------------------------------------------------------
// A map from 64-bit keys (addresses, or ray keys) to values, emptied in O(1) by a new generation:
// the scratch of code that may not mark the cells it visits (several threads read them).
template <class Value>
class ScratchMap {
 public:
  void Clear() {
    size_ = 0;
    if (++gen_ == 0) {  // the generation wrapped: forget every slot
      for (Slot& x : slots_) x.gen = 0;
      gen_ = 1;
    }
  }
  // The value of `key`, inserting `init` when absent; the bool says whether it was absent.
  std::pair<Value*, bool> Insert(uint64_t key, const Value& init) {
    if (2 * (size_ + 1) > slots_.size()) Rehash();
    for (size_t i = Home(key);; i = (i + 1) & mask_) {
      Slot& x = slots_[i];
      if (x.gen != gen_) {
        x.gen = gen_, x.key = key, x.value = init;
        ++size_;
        return {&x.value, true};
      }
      if (x.key == key) return {&x.value, false};
    }
  }
  Value* Find(uint64_t key) {
    if (slots_.empty()) return nullptr;
    for (size_t i = Home(key);; i = (i + 1) & mask_) {
      Slot& x = slots_[i];
      if (x.gen != gen_) return nullptr;
      if (x.key == key) return &x.value;
    }
  }
  bool Contains(uint64_t key) { return Find(key) != nullptr; }
  static uint64_t Key(const void* p) { return static_cast<uint64_t>(reinterpret_cast<uintptr_t>(p)); }

 private:
  struct Slot {
    uint64_t key = 0;
    uint32_t gen = 0;
    Value value{};
  };
  size_t Home(uint64_t key) const {
    return static_cast<size_t>(((key >> 4) * 0x9E3779B97F4A7C15ull) >> shift_);
  }
  void Rehash() {
    std::vector<Slot> old;
    old.swap(slots_);
    const size_t n = old.empty() ? 256 : 2 * old.size();
    slots_.assign(n, Slot());
    mask_ = n - 1;
    shift_ = 64;
    for (size_t m = n; m > 1; m >>= 1) --shift_;
    const uint32_t old_gen = gen_;
    gen_ = 1;
    size_ = 0;
    for (const Slot& x : old)
      if (x.gen == old_gen) Insert(x.key, x.value);
  }
  std::vector<Slot> slots_;
  uint32_t gen_ = 1;
  size_t size_ = 0, mask_ = 0;
  int shift_ = 64;
};

// The cells incident to v (its star, infinite cells included), without marking them: a walk
// across the facets that contain v. `seen` is the walk's scratch (cleared here).
inline void StarOf(Vertex_handle v, ScratchMap<uint8_t>* seen, std::vector<Cell_handle>* out) {
  seen->Clear();
  out->clear();
  const Cell_handle first = v->cell();
  seen->Insert(ScratchMap<uint8_t>::Key(&*first), 1);
  out->push_back(first);
  for (size_t i = 0; i < out->size(); ++i) {
    const Cell_handle c = (*out)[i];
    const int iv = c->index(v);
    for (int k = 0; k < 4; ++k) {
      if (k == iv) continue;
      const Cell_handle n = c->neighbor(k);
      if (seen->Insert(ScratchMap<uint8_t>::Key(&*n), 1).second) out->push_back(n);
    }
  }
}

// -------------------------------------------------------------------------------------------------
// kExact: the rays held by cells about to be destroyed, each with the part of its segment
// (parameter t in [0, 1] from its end to its camera) that lies in those cells, and the facet
// through which it enters them (the cell before it, which survives, and the facet's index there).
struct HoleRay {
  uint32_t camera;  // the ray's index among its point's cameras
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

// A tetrahedron's four face planes, oriented so that inside is n . x >= off on each.
struct TetPlanes {
  double n[4][3];
  double off[4];
};
TetPlanes PlanesOf(const Point& p0, const Point& p1, const Point& p2, const Point& p3);
inline TetPlanes PlanesOf(Cell_handle c) {
  return PlanesOf(c->vertex(0)->point(), c->vertex(1)->point(), c->vertex(2)->point(),
                  c->vertex(3)->point());
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
bool ClipSegment(const TetPlanes& t, const double a[3], const double d[3], Clip* out);

// Casting of viewing rays (paper §2.1). kWeights and kRays: one ray weights the cells
// it traverses (T), their neighbours (N1) and theirs (N2), each cell once per ray. kExact: every
// cell holds the rays (camera, point) whose segment crosses it, so a cell's weight is exactly w1
// times their number; casting adds a ray to the cells its segment crosses, un-casting removes it
// from the same cells (the ray keeps the end it was cast with, so both walk the same segment).
// When the triangulation replaces cells (an insertion's conflict zone, a removed vertex's star),
// the new cells fill exactly the volume of the old ones: the rays held by the old cells are
// walked again through that volume only (CollectHole, RefillHole), and nothing else changes.
class RayCaster {
 public:
  explicit RayCaster(EngineState& s) : s_(s) {}

  // Camera cam -> point pt, cast (+1) or un-cast (-1); kExact: the point's ray from that camera.
  void Cast(uint32_t cam, uint32_t pt, int sign);
  // kExact: ray k of point pt out of its cells.
  void ExactUncast(uint32_t pt, size_t k);
  // kExact batches: the rays (point, k) cast (those not cast yet, from their points' current
  // positions) or un-cast together, walked on the thread pool. Deterministic: the same weights,
  // ray lists and free cells for any number of threads.
  // A cast batch lists each ray's cells (EngineState::list_cells) and the next un-cast batch
  // takes the listed rays out of those cells without walking; DropLists forgets the lists.
  // weights_only: the last update's batch (KeyframeUpdate::last): each cell crossed gains the
  // ray's unit, no entry and no list (EngineState::sealed).
  void CastBatch(const std::vector<std::pair<uint32_t, uint32_t>>& todo, bool weights_only);
  void UncastBatch(const std::vector<std::pair<uint32_t, uint32_t>>& todo);
  void DropLists();
  // forget: the triangulation was rebuilt (Forgetting): the cells and points remembered for
  // the next walks are gone.
  void ForgetCells() {
    camera_cell_.clear();
    point_hole_mark_.clear();
    point_hole_head_.clear();
  }
  // kExact, before cells are destroyed: the rays they hold and where.
  void CollectHole(const std::vector<Cell_handle>& cells, Hole* hole);
  // kExact, after the new cells exist: each ray of the hole walked again through them.
  void RefillHole(const std::vector<Cell_handle>& added, const Hole& hole);
  // kExact: ray k of point pt walked whole with exact predicates, added to the cells marked
  // fresh that it crosses, except those in `given` (a planned walk gave it those already).
  void RefillExact(uint32_t pt, uint32_t k, const std::vector<Cell_handle>& given,
                   Cell_handle hint);
  // kRays: the whole-triangulation scan of Lovi et al., taking point pt's rays out of every cell.
  void ScanRemoveRays(uint32_t pt);
  // kRays: re-casts the rays of U, skipping points no longer in the triangulation and, if given,
  // the rays of point `skip`.
  void RecastRays(std::vector<RayEntry> u, int64_t skip);

  // CGAL's traversal of a -> b: from the vertex `from` when a is its point (a ray of a point
  // starts at its vertex: no point location, 9 % of the run on the street stream), else located
  // from `hint` (a cell near a). Every walk of a ray starts the same way, so all agree on the
  // cells of a ray that leaves its vertex along a facet or an edge.
  Dt::Segment_cell_iterator BeginWalk(const Point& a, const Point& b, Cell_handle hint,
                                      Vertex_handle from) const {
    if (from != Vertex_handle() && from->point() == a)
      return Dt::Segment_cell_iterator(&s_.dt, from, b);
    return s_.dt.segment_traverser_cells_begin(a, b, hint);
  }
  static Vertex_handle StartVertex(const PointRecord& rec) {
    return rec.in_triangulation ? rec.vertex : Vertex_handle();
  }
  // A cell near where a walk of a point's ray starts: the point's vertex when the ray ends
  // there, else any cell near it (the traverser locates the start from it).
  Cell_handle WalkHint(const PointRecord& rec) const {
    if (rec.in_triangulation) return rec.vertex->cell();
    return s_.WalkHint();
  }

  // Walks the segment a -> b through the cells it crosses (BeginWalk), calling visit(cell) once
  // per finite cell. Stops at the hull or after max_cells_per_ray cells. A ray of a point from
  // camera `camera` (b its centre) is walked with FilteredTrace when it can be (the same cells).
  template <class Visit>
  void Walk(const Point& a, const Point& b, Cell_handle hint, Vertex_handle from, Visit&& visit,
            int64_t camera = -1) {
    ++s_.stamp;
    if (camera >= 0 && s_.opt.filtered_walk && from != Vertex_handle() && from->point() == a) {
      const WalkEnd e = CameraEnd(static_cast<uint32_t>(camera), b, hint);
      single_cells_.clear();
      const Walked w = e.usable ? FilteredTrace(a, b, from, e.cell, &single_cells_)
                                : Walked::kUndecided;
      if (w != Walked::kUndecided) {
        if (s_.opt.check_invariants) {
          BatchRay r{};
          r.a = a, r.b = b, r.hint = hint, r.from = from;
          if (DiffersFromCgal(r, single_cells_.data(), single_cells_.size(),
                              w == Walked::kTruncated))
            ++s_.stats.ray_mismatches;
        }
        for (Cell_handle c : single_cells_) {
          if (c->info().stamp == s_.stamp) continue;
          c->info().stamp = s_.stamp;
          visit(c);
        }
        if (w == Walked::kTruncated) ++s_.stats.rays_truncated;
        return;
      }
    }
    if (camera >= 0) ++s_.stats.rays_walked_exact;
    int steps = 0;
    try {
      auto it = BeginWalk(a, b, hint, from);
      const auto end = s_.dt.segment_traverser_cells_end();
      for (; it != end; ++it) {
        Cell_handle c = it;
        if (s_.dt.is_infinite(c)) break;
        if (++steps > s_.opt.max_cells_per_ray) {
          ++s_.stats.rays_truncated;
          break;
        }
        if (c->info().stamp == s_.stamp) continue;
        c->info().stamp = s_.stamp;
        visit(c);
      }
    } catch (...) {
      ++s_.stats.rays_truncated;
    }
  }

 private:
  // A ray of a keyframe batch and where its walk's cells are.
  struct BatchRay {
    uint32_t point;
    uint32_t k;    // the ray's index among its point's cameras
    uint32_t gen;  // cast: its new generation; un-cast: the generation taken out
    Point a, b;    // the segment walked (end -> camera)
    Cell_handle hint;
    Vertex_handle from;  // see BeginWalk
    bool listed = false;     // un-cast: its listed cells, taken instead of a walk
    bool list_to = false;    // cast: its walk lists the ray
    bool from_list = false;  // its cells are in EngineState::list_cells, not walk_cells_
    uint32_t worker = 0, offset = 0, count = 0;  // its cells in walk_cells_[worker]
    int32_t end_slot = -1;   // its camera in batch_ends_ (-1: walked with CGAL)
    bool truncated = false;
    bool exact_walk = false;  // walked with CGAL's traverser (FilteredTrace could not decide)
    bool walk_differs = false;  // check_invariants: FilteredTrace's cells are not CGAL's
  };
  // Where walks to a camera end: the cell strictly holding its centre (exact predicates), or
  // none when the centre is outside the hull (the walks stop there). usable is false when the
  // centre lies on a facet, edge or vertex: those rays are walked with CGAL.
  struct WalkEnd {
    Cell_handle cell;
    bool usable = false;
  };
  struct alignas(64) BatchPart {  // what one apply task changed besides the cells (a cache
                                  // line each: the tasks count every cell)
    uint64_t ledger = 0;
    int64_t cells = 0, mismatches = 0;
    std::vector<Cell_handle> became_free;
  };
  void CastWeights(uint32_t cam, uint32_t pt, int sign);  // kWeights and kRays
  void ExactCast(uint32_t pt, size_t k);
  bool RaySegment(const Point& p, const Point& cam, Point* start);
  static size_t RayIndex(const PointRecord& rec, uint32_t cam);
  void AddRay(Cell_handle c, uint32_t pt, uint32_t k);
  bool PushRay(CellInfo* info, const RayEntry& e) const;
  bool Holds(const CellInfo& info, const RayEntry& mine) const;
  static constexpr size_t kSearchUncastBelow = 32;

  static size_t Owner(Cell_handle c, size_t parts);
  bool Trace(const BatchRay& r, std::vector<Cell_handle>* out) const;
  // The walk of Trace with double-precision tests on terms cached per vertex of the ray, for a
  // ray that starts at its point's vertex and ends in a cell that strictly holds its camera
  // (or outside the hull): kUndecided when a test is within rounding (the caller walks with
  // CGAL from the start), else the same cells as Trace.
  enum class Walked { kDone, kTruncated, kUndecided };
  Walked FilteredTrace(const Point& a, const Point& b, Vertex_handle from, Cell_handle end,
                       std::vector<Cell_handle>* out) const;
  void LocateEnds(std::vector<BatchRay>& rays);
  // Where walks to a camera end: the cell that held its centre last time while it still does
  // (a cell of the triangulation, holding the centre strictly: exact test), else located again;
  // no cell (usable) when the centre is outside the hull.
  WalkEnd CameraEnd(uint32_t camera, const Point& b, Cell_handle hint);
  bool DiffersFromCgal(const BatchRay& r, const Cell_handle* cells, size_t count,
                       bool truncated) const;
  // split_apply: the apply runs as one task per thread, each on the cells it owns (every task
  // scans all the batch's cells: worth it when applying costs more than scanning, as a cast's
  // list entries do; an un-cast's weight decrement does not).
  template <class Apply>
  std::vector<BatchPart> RunBatch(std::vector<BatchRay>& rays, bool split_apply, bool append,
                                  Apply&& apply);
  // A batch is walked kGroupRays rays at a time (a group's walks: ~20 MB at 128 cells a ray);
  // a cast batch keeps its walks as lists while they hold at most kListedCells cells (32 MB).
  static constexpr size_t kGroupRays = 1 << 14;
  static constexpr size_t kListedCells = size_t{1} << 22;
  size_t GroupRays() const {
    return s_.hooks && s_.hooks->group_rays ? s_.hooks->group_rays : kGroupRays;
  }
  size_t ListedCells() const {
    return s_.hooks && s_.hooks->listed_cells ? s_.hooks->listed_cells : kListedCells;
  }
  // fn(group) for the batch's rays GroupRays() at a time, in order (group_rays_ holds a copy).
  template <class Fn>
  void InGroups(const std::vector<BatchRay>& rays, Fn&& fn) {
    const size_t n = GroupRays();
    for (size_t begin = 0; begin < rays.size(); begin += n) {
      const auto first = rays.begin() + static_cast<std::ptrdiff_t>(begin);
      const auto count = static_cast<std::ptrdiff_t>(std::min(n, rays.size() - begin));
      group_rays_.assign(first, first + count);
      fn(group_rays_);
    }
  }
  void MergeParts(const std::vector<BatchPart>& parts);

  EngineState& s_;
  std::vector<Cell_handle> ring_[2];  // T and N1 of the ray being cast.
  std::vector<Cell_handle> given_;    // RefillHole: new cells given the ray being walked.
  std::vector<std::vector<Cell_handle>> walk_cells_;  // per worker
  std::vector<WalkEnd> batch_ends_;       // the batch's cameras (LocateEnds)
  std::vector<int32_t> camera_end_slot_;  // per camera: its slot in batch_ends_, or -1
  std::vector<Cell_handle> camera_cell_;  // per camera: CameraEnd's last cell (may be gone)
  std::vector<Cell_handle> single_cells_;  // Walk's filtered walk
  std::vector<uint64_t> point_hole_mark_;  // per point: the hole that lists its rays
  std::vector<uint32_t> point_hole_head_;  // per point: its first ray in that hole's list
  uint64_t hole_count_ = 0;
  std::vector<TetPlanes> fresh_planes_;    // planes of the cells being made, by their slot
  std::vector<std::pair<uint32_t, uint32_t>> listed_;  // rays listed by the last cast batch
  std::vector<std::pair<uint32_t, uint32_t>> uncast_listed_;  // UncastBatch's scratch
  std::vector<BatchRay> batch_rays_;                          // a batch's rays
  std::vector<BatchRay> group_rays_;                          // the group being walked
};

// -------------------------------------------------------------------------------------------------
// What the cells a change destroys (R) hand to the cells it makes (A).
struct Removed {
  std::vector<double> centroids;
  std::vector<double> weights;
  std::vector<RayEntry> rays;  // kRays: rays stored in R (the set U of Lovi et al.).
  Hole hole;                   // kExact: the rays R's cells hold, and where.
};

// Transfer of weights from removed cells R to new cells A (efficient approach, paper §3.2): the
// weight-transfer policy in weights mode, the rays of the hole walked again in exact mode.
class WeightTransfer {
 public:
  WeightTransfer(EngineState& s, WeightTransferPolicy* policy, RayCaster& caster)
      : s_(s), policy_(policy), caster_(caster) {}

  // Before the cells are destroyed: what they hand over (their weights leave the ledger).
  void CollectRemoved(const std::vector<Cell_handle>& cells, Removed* r);
  // After the new cells exist: their weights. `transfer`: through the policy (weights mode);
  // else they start at 0.
  void AssignNewCells(const std::vector<Cell_handle>& added, const Removed& r, bool transfer);
  // transfer_camera_side for the changes that follow: the point being inserted and its cameras
  // (null: no such rule). The pointers must stay valid until the next call.
  void SetCameraSide(const Point* apex, const std::vector<uint32_t>* cameras) {
    side_apex_ = apex;
    side_cams_ = cameras;
  }

 private:
  EngineState& s_;
  WeightTransferPolicy* policy_;
  RayCaster& caster_;
  const Point* side_apex_ = nullptr;
  const std::vector<uint32_t>* side_cams_ = nullptr;
};

// -------------------------------------------------------------------------------------------------
// O, the manifold set of outside cells, and its boundary dO (paper §2.2).
class Carving {
 public:
  explicit Carving(EngineState& s) : s_(s) {}

  // Toggling one cell in or out of O keeps dO a 2-manifold: the combinatorial form the engine
  // uses, and the reference form (each of the cell's four vertices' links rebuilt).
  bool ToggleKeepsManifold(Cell_handle c);
  bool ToggleKeepsManifoldByLinks(Cell_handle c);
  void SetInO(Cell_handle c, bool in);
  // shrink: removes from O the cells of an enclosing set E of D; returns whether D no longer
  // meets O. `planned_e`: E's cells in O as EnclosingSetInO found them earlier in the keyframe's
  // moves, none destroyed since, in CellKey order (null: found here).
  bool Shrink(const std::vector<Cell_handle>& d, const std::vector<Point>& centres,
              const std::vector<Cell_handle>* planned_e = nullptr);
  // The cells of O in E for D (D, its facet neighbours, and the cells around each vertex of D
  // within shrink_radius of a centre). Reads only (the sets are the caller's scratch), so
  // several threads may find them at once while nothing changes.
  static void EnclosingSetInO(const EngineState& s, const std::vector<Cell_handle>& d,
                              const Point* centres, size_t n_centres, ScratchMap<uint8_t>* seen,
                              ScratchMap<uint8_t>* star_seen, std::vector<Cell_handle>* star,
                              std::vector<Cell_handle>* e);
  // Takes out of O every cell with a vertex within `radius` of one of the given vertices.
  void PeelAround(const std::vector<Vertex_handle>& centres, double radius);
  // grow: the free cells touching dO join O, highest weight first, while dO stays manifold.
  // `new_component`: a free cell that may start a component of O of its own (forget: where
  // the cameras come back to space that was forgotten, O is no longer there to grow from).
  void Grow(Cell_handle new_component = Cell_handle());
  // The camera path: the cells of `path` (in path order) join O even if not free, each with the
  // fewest free cells around it that keep dO manifold (AddWithRepair); a cell that cannot,
  // or that touches no cell of O yet, waits for the next pass. Returns the cells that joined.
  int64_t OpenPath(const std::vector<Cell_handle>& path);
  // c joins O even if not free: touching O, as AddWithRepair; else alone if that keeps dO
  // manifold. Returns whether it did; its neighbours are then grow's seeds.
  bool ForceCell(Cell_handle c);

 private:
  // c joins O; while a vertex of the cells added is not regular, the free cells around it that
  // are not in O join too (up to camera_path_repair rounds). All or none: on failure O is back
  // as it was. The cells added are appended to `added`.
  bool AddWithRepair(Cell_handle c, std::vector<Cell_handle>* added);
  // Cells that joined O outside grow: their neighbours become grow's seeds.
  void SeedAround(const std::vector<Cell_handle>& added);
  bool VertexRegular(Vertex_handle v, Cell_handle toggled);
  bool VertexTouchesSide(Cell_handle c, int i, bool adding);
  bool EdgeTouchesSide(Cell_handle c, int i, int j, bool adding) const;
  uint32_t NewRegion();
  // `sorted`: the region is in CellKey order already (a plan sorted it on its thread).
  template <typename Cells, typename InRegion, typename Done>
  bool PeelFromO(const Cells& region, InRegion in_region, Done done, bool sorted = false);

  EngineState& s_;
  std::vector<Cell_handle> incident_;  // scratch
  std::vector<Cell_handle> star_, e_;  // scratch
  ScratchMap<uint8_t> e_seen_, star_seen_;
};

// -------------------------------------------------------------------------------------------------
// The Steiner grid: spacing steiner_spacing, placed only where the rays go (issue 47): the cells of
// the grid (voxels between eight nodes) that a ray segment crosses, each with the nodes up to
// ceil(steiner_margin / steiner_spacing) steps (at least one) beyond its corners, so every point
// of a ray has nodes at least steiner_margin away on every side. Each point off its node by a
// deterministic jitter. A node is placed once; later rays add the nodes they newly reach.
class SteinerGrid {
 public:
  explicit SteinerGrid(const EngineOptions& opt) : opt_(opt) {}
  // A ray (or a camera's path) as the grid sees it: from a camera centre to the end it carves.
  struct Segment {
    Point a, b;
  };
  // The grid's points within reach of the segments that were not placed before, in the grid's
  // order (by node numbers: the same names whatever order the segments come in). `stop` is
  // polled as the voxels are walked (throws Stopped when it says so); throws std::runtime_error
  // when a segment is too far from the origin for the grid's node numbers.
  std::vector<Point> NewPoints(const std::vector<Segment>& segments,
                               const std::function<bool()>& stop);
  // Bytes its record of placed nodes and visited voxels takes.
  int64_t MemoryBytes() const {
    return static_cast<int64_t>(
        (nodes_.size() + voxels_.size()) * (sizeof(Node) + 2 * sizeof(void*)) +
        (nodes_.bucket_count() + voxels_.bucket_count()) * sizeof(void*));
  }
  int64_t nodes() const { return static_cast<int64_t>(nodes_.size()); }
  // forget: drops the record of the placed nodes (and visited voxels, by their first corner) for
  // which gone(node position) holds (where everything is final: a ray that reaches there again
  // finds its cells final and places nothing).
  void Forget(const std::function<bool(const Point&)>& gone);

 private:
  // A node (or the voxel whose first corner it is) by its integer coordinates, exactly (packing
  // them in 64 bits would alias nodes 2^21 steps apart).
  struct Node {
    int64_t i, j, k;
    bool operator==(const Node& o) const { return i == o.i && j == o.j && k == o.k; }
    bool operator<(const Node& o) const {
      return i != o.i ? i < o.i : j != o.j ? j < o.j : k < o.k;
    }
  };
  struct NodeHash {
    size_t operator()(const Node& n) const {
      uint64_t h = static_cast<uint64_t>(n.i) * 0x9E3779B97F4A7C15ull;
      h ^= static_cast<uint64_t>(n.j) + 0x7F4A7C159E3779B9ull + (h << 6) + (h >> 2);
      h ^= static_cast<uint64_t>(n.k) + 0x94D049BB133111EBull + (h << 6) + (h >> 2);
      return static_cast<size_t>(h);
    }
  };
  // The voxel a segment enters: its nodes and those within the margin, the new ones to `fresh`.
  // Returns the nodes looked at.
  int64_t Visit(const Node& voxel, std::vector<Node>* fresh);
  Point NodePoint(const Node& n) const;
  const EngineOptions& opt_;
  std::unordered_set<Node, NodeHash> nodes_;   // nodes placed
  std::unordered_set<Node, NodeHash> voxels_;  // voxels a segment crossed (by first corner)
};

// Thrown from a long loop when the engine's stop check says so (Engine::SetStopCheck).
struct Stopped : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// -------------------------------------------------------------------------------------------------
// Long drives (EngineOptions::forget, DESIGN.md section 10). At each step, the cells that no live
// change can reach any more become final: those lying forget_distance (ForgetDistance) from
// every one of the last `window` cameras and behind the newest camera (on the side it came
// from), with no vertex of a point named while one of them was the newest. A final cell is never destroyed (an
// insertion or a move that would is refused: EngineState::BlockedByFinal), toggled or weighted
// again, and its ray list is freed; a facet of dO between two final cells is final (handed out
// as a SurfacePart). A vertex whose cells are all final is deep; a deep vertex whose neighbours
// are all deep can leave the triangulation without a live cell noticing (the cells it takes
// with it, and those that fill their place, touch deep vertices only). When enough such
// vertices have gathered the triangulation is rebuilt without them: cells whose four vertices
// stay are cells of the new triangulation (Delaunay: a subset keeps them) and keep their infos;
// the others fill the place of the forgotten vertices, final and forgotten.
struct Triangle;

class Forgetting {
 public:
  Forgetting(EngineState& s, RayCaster& caster, SteinerGrid& steiner)
      : s_(s), caster_(caster), steiner_(steiner) {}

  // Whether forgetting may run: forget kOn, or kAuto outside the rays mode (whose ray lists
  // forgetting cannot free). Under kAuto the steps run from the start, and the first step that
  // finds cells to make final decides (Travelled): before it nothing differs from forget false.
  bool Armed() const {
    return s_.opt.forget == ForgetMode::kOn ||
           (s_.opt.forget == ForgetMode::kAuto && s_.opt.visibility_mode != VisibilityMode::kRays);
  }
  // The centres of the cameras an update adds (every update calls it, before its points).
  void AddUpdateCameras(std::vector<Point> centres);
  // Whether a step is due: the newest camera moved forget_step since the last step.
  bool Due() const;
  // One step: the cells that became final, the facets of dO that did (between two final
  // cells, oriented toward the cell in O), and the vertices that became deep.
  void Freeze(std::vector<Triangle>* facets, std::vector<Vertex_handle>* deep);
  // Rebuilds the triangulation without the vertices that can go when enough can (half of all:
  // a rebuild costs about what the vertices it keeps cost to insert, so its cost per frame goes
  // as (1 - x) / x of the vertices forgotten per frame; the cells kept meanwhile hold no rays).
  // Only while no ray lists are kept (between a keyframe's un-cast batch and its cast batch).
  void MaybeRebuild();
  bool Retired(uint64_t id) const { return retired_.Contains(id); }
  const RetiredIds& retired() const { return retired_; }
  // Whether an update named the point while one of the last `window` cameras was the newest
  // (a point still tracked may move; its rays come from those cameras).
  bool Live(const PointRecord& rec) const {
    return rec.named + s_.opt.window > static_cast<int64_t>(s_.cameras.size());
  }
  // Whether the newest camera is back where the cameras were forget_distance away from (a
  // place left behind: what was made there may be forgotten, and O must start again there).
  bool Returned() const;

 private:
  bool BecomesFinal(Cell_handle c) const;
  // kAuto: whether the cameras travel, so that what they leave behind is not seen again: not
  // the first update (an SfM model comes in one), the cameras one after the other along a path
  // (the median step between consecutive cameras under forget_distance / 2: an SfM model
  // replayed in an order of its own jumps), and not around an object (their centres spread no
  // more than kAroundAnObject times as far as the points: a ring's cameras spread wider than
  // the object they circle, a drive's points spread along and beside the path). Measured into
  // the stats.
  bool Travelled();
  static constexpr double kAroundAnObject = 2.0;
  bool FarBehind(const Point& p, double radius) const;
  void Rebuild(const std::vector<Vertex_handle>& gone);
  // Rebuild's steps, in order (forget.cc).
  struct Renumbering;
  Renumbering Renumber(const std::vector<Vertex_handle>& gone) const;
  bool TriangulateKept(const Renumbering& r, Dt* dt) const;
  bool MatchCells(const Renumbering& r, const Dt& dt,
                  std::vector<std::pair<Cell_handle, Cell_handle>>* matched) const;
  static void MoveCellInfos(const Renumbering& r, Dt* dt,
                            std::vector<std::pair<Cell_handle, Cell_handle>>* matched);
  void KeepRecords(const Renumbering& r, int64_t* retired_now, int64_t* freed);
  void Install(Dt* dt);

  EngineState& s_;
  RayCaster& caster_;
  SteinerGrid& steiner_;
  std::deque<std::vector<Point>> recent_;  // the updates that hold the last `window` cameras
  std::vector<Point> live_;                // recent_'s cameras at the step, thinned
  double live_radius_ = 0.0;               // each stands for those this close to it
  Point newest_, last_step_;
  bool have_camera_ = false, stepped_ = false, moving_ = false;
  double behind_[3] = {0, 0, 0};  // at the step: unit direction the cameras came from
  RetiredIds retired_;
  int64_t deep_since_rebuild_ = 0;  // vertices that became deep since the last rebuild
  // The path, one point every 2 grid steps: the recent stretch, and the places left behind as
  // voxels of that size (a few bytes a metre of the drive).
  static uint64_t Voxel(const Point& p, double size);
  std::deque<Point> path_;
  std::unordered_set<uint64_t> left_;
};

// -------------------------------------------------------------------------------------------------
// kExact moves planned ahead. A move (paper §3; exact mode: the point's vertex taken out and put
// back at its new position, and the rays of the cells that change walked again through the
// cells that replace them) changes D only, the vertex's star and the new position's conflict
// zone. What it does to D is a function of D and the cells around it: the plan computes it
// without writing anything shared (the cells that fill D, grown from its boundary by Delaunay
// wrapping; the rays each of them holds; the enclosing set for shrink), so the moves of a
// keyframe are planned on the engine's threads and committed one by one, in the keyframe's move
// order (Engine::Impl::MoveOrder), on one. A plan names the cells it read (D and its facet
// neighbours) with their serials; when an earlier commit changed one of them, the move is
// planned again at its turn. Plans never depend on when they were made, so the result is the
// same for any number of threads.
struct MovePlan {
  enum class Kind : uint8_t {
    kKeep,       // the new position is the vertex's: only cameras are added
    kDuplicate,  // another vertex sits at the new position: refused
    kInPlace,    // D is the star, reshaped: the cells stay (StarStaysDelaunay)
    kHole,       // D re-triangulated around the new position
    kSerial,     // made at its turn by ExactMovePoint (the hull, a point not in the triangulation)
  };
  // A cell that fills D (kHole), or a cell of D as reshaped (kInPlace): its vertices (>= 0: an
  // index in `verts`; -1: the moving point's vertex) and neighbours (>= 0: another such cell;
  // < 0: the facet -(n + 1) of `outer`).
  struct NewCell {
    int32_t v[4];
    int32_t n[4];
  };
  struct Listed {  // a listed ray held by a cell of D: its list loses the cell
    uint32_t point, k, cell;
  };
  struct Deferred {  // a ray the plan could not walk: walked with exact predicates at commit
    uint32_t point, k;
    uint32_t given_begin, given_count;  // the cells (indices in `cells`) it was given already
  };

  Kind kind = Kind::kSerial;
  uint32_t pt = 0;
  Vertex_handle v;
  Point p_old, p_new;
  std::vector<Cell_handle> d;      // in CellKey order
  std::vector<Facet> outer;        // D's boundary facets, seen from the cells outside D
  std::vector<uint64_t> serials;   // of d's cells, then of outer's cells
  std::vector<Vertex_handle> verts;
  // A NewCell's vertex as a point: -1 is the moved vertex at p_new, i >= 0 verts[i].
  const Point& PointOf(int32_t i) const {
    return i < 0 ? p_new : verts[static_cast<size_t>(i)]->point();
  }
  std::vector<NewCell> cells;      // kInPlace: cells[i] is d[i]
  std::vector<uint32_t> ray_begin;  // cells[i] holds rays[ray_begin[i] .. ray_begin[i + 1])
  std::vector<RayEntry> rays;
  std::vector<Listed> listed;
  std::vector<Deferred> deferred;
  std::vector<int32_t> given;
  struct Extra {  // a listed ray's new cells (EngineState::list_extra): extra_cells[begin, +count)
    uint32_t point, k, begin, count;
  };
  std::vector<Extra> extra;
  std::vector<int32_t> extra_cells;
  int64_t rays_rewalked = 0;
  bool e_planned = false;  // D met O when planned: e holds E's cells in O then
  std::vector<Cell_handle> e;  // in CellKey order (shrink peels in that order)
  std::vector<uint64_t> e_serials;
};

class MovePlanner {
 public:
  MovePlanner(EngineState& s, RayCaster& caster, Carving& carving);
  ~MovePlanner();

  // Plans moving point pt to p_new. Reads only: calls with distinct workers may run at once
  // while nothing changes the engine's state.
  void Plan(uint32_t pt, const Point& p_new, int worker, MovePlan* plan) const;
  // Whether a plan made earlier still holds (its cells unchanged since).
  bool Valid(const MovePlan& plan) const;
  // Makes a kInPlace or kHole move: shrink, then D's cells replaced or reshaped. False when D
  // could not leave O (the move is refused).
  bool Commit(MovePlan& plan);
  // Scratch for n workers (before plans are made on them).
  void Workers(int n) const;
  // Whether v can move to p keeping its cells (a move in place): its star finite, and with v at
  // p still positively oriented and Delaunay. Reads only.
  static bool StarStaysDelaunay(const Dt& dt, Vertex_handle v, const Point& p,
                                const std::vector<Cell_handle>& star);

 private:
  struct Scratch;
  // Plan's steps, in order (each says when the plan ends there).
  static void Reset(uint32_t pt, const Point& p_new, MovePlan* plan);
  bool FindRegion(MovePlan* plan, Scratch& sc) const;
  void IndexRegion(MovePlan* plan, Scratch& sc) const;
  void CollectHoleRays(MovePlan* plan, Scratch& sc) const;
  bool PlanCells(MovePlan* plan, Scratch& sc) const;
  void PlanEnclosingSet(MovePlan* plan, Scratch& sc) const;
  // fast: each open facet's apex is the point whose sphere's centre lies nearest the facet on
  // its open side, in floating point (a few flops a point instead of an exact in-sphere test);
  // the result is then only a candidate for FillIsDelaunay.
  bool FillHole(MovePlan* plan, Scratch& sc, bool fast) const;
  bool FillIsDelaunay(const MovePlan& plan, Scratch& sc) const;
  void WalkRays(MovePlan* plan, Scratch& sc) const;

  EngineState& s_;
  RayCaster& caster_;
  Carving& carving_;
  mutable std::vector<std::unique_ptr<Scratch>> scratch_;  // per worker (Workers)
  std::vector<Cell_handle> made_, given_, e_live_;          // Commit's scratch
};

// dO's facets: between a cell of O and a cell outside O, oriented toward the O cell.
struct Triangle {
  Vertex_handle v[3];
};
// live: without the facets between two final cells (forget: handed out already).
std::vector<Triangle> Boundary(const EngineState& s, bool live = false);

// -------------------------------------------------------------------------------------------------
// The invariants (Engine::CheckInvariants): O's counters, dO closed, oriented and manifold, the
// weights within what casting and transfer can make and equal to their ledger, a valid
// triangulation.
class InvariantChecker {
 public:
  explicit InvariantChecker(const EngineState& s) : s_(s) {}
  ManifoldCheckResult Check() const;
  std::string CheckRayLists() const;
  // A vertex or a cell as a user would find it: the point's id (or the Steiner point's number)
  // and where it is.
  std::string DescribeVertex(Vertex_handle v) const;
  std::string DescribeCell(Cell_handle c) const;

 private:
  void CheckWeights(const std::function<void(const std::string&)>& fail) const;
  const EngineState& s_;
};

}  // namespace imr::engine::detail

namespace imr::engine {

// The conductor of a keyframe (ApplyUpdate, engine.cc): validate, cameras and their Steiner
// points, removals, moves, insertions, the exact mode's batches, peel and grow. Its steps are
// defined in the files named for them: point_updates.cc (Validate, AddCameras, insertion and
// removal), steiner_grid.cc (PlaceSteinerPoints), moves.cc (the moves and the exact mode's
// batches around them), forget.cc (WithoutRetired, Forget), camera_path.cc, surface_export.cc
// (ToMesh, MakePart, LiveBoundary).
struct Engine::Impl {
  using Point = detail::Point;
  using Cell_handle = detail::Cell_handle;
  using Vertex_handle = detail::Vertex_handle;
  using RayEntry = detail::RayEntry;

  Impl(const EngineOptions& o, WeightTransferPolicy* p);

  Status ApplyUpdate(const KeyframeUpdate& u);
  Mesh ToMesh(const std::vector<detail::Triangle>& tris, SteinerExportRule rule) const;
  // The surface handed out in parts (SurfacePart): the triangles given as a part, its vertices
  // keyed (VertexInfo::key, the next from next_key_).
  SurfacePart MakePart(std::vector<detail::Triangle> tris);
  // The facets of dO not handed out yet: those with a cell that is not final.
  std::vector<detail::Triangle> LiveBoundary() const;
  std::vector<SurfacePart> final_parts_;  // made since the last TakeFinalParts
  int64_t next_key_ = 0;

  detail::EngineState s;
  detail::RayCaster caster;
  detail::WeightTransfer transfer;
  detail::Carving carving;
  detail::SteinerGrid steiner;
  detail::MovePlanner planner;
  detail::Forgetting forgetting;
  Status init;
  std::function<bool()> stop_requested;  // Engine::SetStopCheck

 private:
  // ApplyUpdate's own steps (engine.cc): the new cameras indexed (their centres), O peeled
  // around the points that moved or entered (regrow_radius), grow with the camera path, the
  // keyframe counted, and where the new cameras are (in O or not).
  std::vector<Point> AddNewCameras(const KeyframeUpdate& u);
  void PeelChanged(const KeyframeUpdate& u);
  void Grow();
  void EndKeyframe(double seconds);
  void CheckCameras(const std::vector<Point>& centres);
  Status Validate(const KeyframeUpdate& u) const;
  void AddCameras(detail::PointRecord& rec, const std::vector<uint64_t>& ids,
                  std::vector<uint32_t>* added);
  Vertex_handle InsertPoint(const Point& p, int64_t vertex_id, bool with_policy, bool* duplicate,
                            std::vector<RayEntry>* rays);
  void RemoveVertex(Vertex_handle v, std::vector<RayEntry>* rays);
  // The Steiner points the update's rays (and the new cameras' path) newly reach.
  void PlaceSteinerPoints(const KeyframeUpdate& update, size_t first_new_camera);
  void TimedCast(uint32_t cam, uint32_t pt, int sign);
  void TimedRecast(std::vector<RayEntry> u, int64_t skip);
  void TimedScan(uint32_t pt);
  void RemovePoint(uint32_t pt);
  void ExactRemovePoint(uint32_t pt);
  bool ShrinkMoveRegion(Vertex_handle v, const Point& p_old, const Point& p_new,
                        std::vector<Cell_handle>* d);
  void ExactMovePoint(uint32_t pt, const MovedPoint& m);
  void ExactMoves(const KeyframeUpdate& u);
  void MoveOrder(const KeyframeUpdate& u);
  const MovedPoint& MoveAsMade(const KeyframeUpdate& u, size_t i, MovedPoint* kept,
                               bool* held) const;
  void EndHeldMove(const MovedPoint& m, uint32_t pt);
  void MoveOne(const KeyframeUpdate& u, size_t i);
  void PlanMove(const KeyframeUpdate& u, size_t i, int worker, detail::MovePlan* plan);
  void CommitMove(const KeyframeUpdate& u, size_t i, detail::MovePlan& plan);
  void MovePoint(uint32_t pt, const MovedPoint& m);
  void InsertNewPoint(const NewPoint& np);
  bool Enter(uint32_t pt, bool again);
  void MoveAbsentPoint(uint32_t pt, const MovedPoint& m);
  void WindowRays(uint32_t pt, std::vector<std::pair<uint32_t, uint32_t>>* out) const;
  void FindShortMoves(const KeyframeUpdate& u);
  void UncastMoving(const KeyframeUpdate& u);
  void CastUpdated(const KeyframeUpdate& u);
  // forget: the update without the moves and removals of retired points (null: none).
  std::unique_ptr<KeyframeUpdate> WithoutRetired(const KeyframeUpdate& u);
  // forget: a step (Forgetting): what became final handed out as a part, then maybe a rebuild.
  void Forget();
  // forget: the cell holding the newest camera (null when it is outside the hull or none).
  Cell_handle CameraCell();
  // camera_path: the cells holding the last camera_path camera centres and those the segments
  // between them cross, in path order (finite cells, each once).
  std::vector<Cell_handle> CameraPathCells();
  // After grow: the path's cells (CameraPathCells, unchanged since: grow only labels) again
  // (OpenPath), then each path camera whose cell is still outside O gets O peeled within
  // camera_path_radius and grown again from its cell.
  void OpenCameraPath(const std::vector<Cell_handle>& path);

  int64_t steiner_nodes_ = 0;  // grid nodes tried, placed or refused: names the next one
  std::vector<uint32_t> entered_;  // kExact: points that entered during this update
  std::vector<uint8_t> short_move_;  // per moved point of the update: too short to make
  static constexpr size_t kMoveStrata = 16;  // moves planned together (MoveOrder)
  std::vector<size_t> move_order_;          // the keyframe's moves in the order they are made
  std::vector<detail::MovePlan> plans_;     // ExactMoves: one batch of plans
};

}  // namespace imr::engine
