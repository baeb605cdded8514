// SurfaceStream (surface_stream.h): FinishExportedMesh's fix-ups made part by part. The rules that
// make the result exactly the whole mesh's are those of SplitPinchedVertices (two triangles around
// a vertex are in one fan when they share an edge at it), FillSmallHoles (the loop walked from the
// vertex of lowest canonical index, its perimeter and centroid summed in that order) and
// CanonicalizeMesh (a vertex's canonical index follows the first face, in sorted order, that uses
// it: the lowest face key of its fan, then its place in that face).
#include "host/engine/surface_stream.h"

#include "host/engine/mesh_topology.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <memory>
#include <numeric>
#include <tuple>
#include <unordered_map>
#include <utility>
#include <vector>

namespace imr::engine {
namespace {

// A vertex's identity in CanonicalizeMesh: point id, then position.
using VertexKey = std::tuple<int64_t, double, double, double>;
using FaceKey = std::array<VertexKey, 3>;

// The small-component rule on what the fix-ups release (surface_stream.h): pieces are tracked by
// union-find over the released vertices not completed yet; a piece's triangles are held while it
// is open and under the threshold, released once it reaches it, dropped when it completes under it.
class SmallPieceGate {
 public:
  explicit SmallPieceGate(double min_area) : min_area_(min_area) {}

  SurfacePart Pass(SurfacePart in, SurfaceStreamStats* stats) {
    if (!(min_area_ > 0.0)) return in;
    const std::size_t nv = in.keys.size();
    std::vector<uint32_t> label(nv);
    for (std::size_t i = 0; i < nv; ++i) {
      const auto [it, fresh] = open_.try_emplace(in.keys[i], 0u);
      if (fresh) it->second = NewPiece();
      label[i] = it->second;
    }
    for (std::size_t f = 0; f + 2 < in.faces.size(); f += 3) {
      const uint32_t* t = &in.faces[f];
      const uint32_t r = Union(label[t[0]], Union(label[t[1]], label[t[2]]));
      Piece& p = pieces_.at(r);
      p.area += TriangleArea(&in.vertices[3 * size_t{t[0]}], &in.vertices[3 * size_t{t[1]}],
                             &in.vertices[3 * size_t{t[2]}]);
      ++p.faces;
    }
    constexpr uint32_t kUnknown = 0xFFFFFFFFu;  // a completion of nothing released: passed on
    std::vector<uint32_t> completed_piece(in.completed.size(), kUnknown);
    for (std::size_t i = 0; i < in.completed.size(); ++i) {
      const auto it = open_.find(in.completed[i]);
      if (it == open_.end()) continue;
      completed_piece[i] = it->second;
      --pieces_.at(Find(it->second)).open;
      open_.erase(it);
    }
    // The pieces this release touched, in the order it touched them.
    std::vector<uint32_t> touched;
    for (std::size_t f = 0; f + 2 < in.faces.size(); f += 3) touched.push_back(Find(label[in.faces[f]]));
    for (uint32_t c : completed_piece)
      if (c != kUnknown) touched.push_back(Find(c));
    {
      std::unordered_map<uint32_t, bool> seen;
      std::vector<uint32_t> unique;
      for (uint32_t r : touched)
        if (seen.emplace(r, true).second) unique.push_back(r);
      touched.swap(unique);
    }
    // Each one: reached the threshold (out), complete under it (dropped), or held.
    enum State { kOut, kDropped, kHeld };
    std::unordered_map<uint32_t, State> state;
    for (uint32_t r : touched) {
      Piece& p = pieces_.at(r);
      if (p.area >= min_area_) p.big = true;
      state[r] = p.big ? kOut : p.open == 0 ? kDropped : kHeld;
    }
    std::unordered_map<int64_t, std::array<double, 3>> position;  // this release's, by key
    std::unordered_map<int64_t, int64_t> point_id;
    for (std::size_t i = 0; i < nv; ++i) {
      position[in.keys[i]] = {in.vertices[3 * i], in.vertices[3 * i + 1], in.vertices[3 * i + 2]};
      point_id[in.keys[i]] = in.point_ids[i];
    }
    SurfacePart out;
    out.update = in.update;
    std::unordered_map<int64_t, uint32_t> out_index;
    auto emit_vertex = [&](int64_t k, const std::array<double, 3>& p, int64_t id) {
      const auto [it, fresh] = out_index.emplace(k, static_cast<uint32_t>(out.keys.size()));
      if (fresh) {
        out.vertices.insert(out.vertices.end(), p.begin(), p.end());
        out.keys.push_back(k);
        out.point_ids.push_back(id);
      }
      out.faces.push_back(it->second);
    };
    // What the pieces held first (their triangles came first): out, or dropped with the piece.
    for (uint32_t r : touched) {
      Piece& p = pieces_.at(r);
      if (state[r] == kHeld) continue;
      if (state[r] == kOut) {
        for (int64_t k : p.held) {
          const HeldVertex& v = held_vertices_.at(k);
          emit_vertex(k, v.p, v.point_id);
        }
        out.completed.insert(out.completed.end(), p.held_completed.begin(), p.held_completed.end());
      } else if (!p.counted) {  // dropped: counted once, now that it is whole
        p.counted = true;
        ++stats->dropped.components;
        stats->dropped.faces += p.faces;
        stats->dropped.vertices += p.vertices;
        stats->dropped.area += p.area;
        stats->triangles_released -= p.faces;  // released: what comes out
      }
      for (int64_t k : p.held) held_vertices_.erase(k);
      held_triangles_ -= static_cast<int64_t>(p.held.size() / 3);
      p.held.clear();
      p.held.shrink_to_fit();
      p.held_completed.clear();
      p.held_completed.shrink_to_fit();
    }
    // Then this release, in its order.
    for (std::size_t f = 0; f + 2 < in.faces.size(); f += 3) {
      const uint32_t r = Find(label[in.faces[f]]);
      const State st = state[r];
      if (st == kDropped) continue;
      for (int k = 0; k < 3; ++k) {
        const int64_t key = in.keys[in.faces[f + static_cast<std::size_t>(k)]];
        if (st == kOut) {
          emit_vertex(key, position.at(key), point_id.at(key));
        } else {
          pieces_.at(r).held.push_back(key);
          held_vertices_.try_emplace(key, HeldVertex{position.at(key), point_id.at(key)});
        }
      }
      if (st == kHeld) ++held_triangles_;
    }
    for (std::size_t i = 0; i < in.completed.size(); ++i) {
      if (completed_piece[i] == kUnknown) {
        out.completed.push_back(in.completed[i]);
        continue;
      }
      const uint32_t r = Find(completed_piece[i]);
      if (state[r] == kOut) out.completed.push_back(in.completed[i]);
      else if (state[r] == kHeld) pieces_.at(r).held_completed.push_back(in.completed[i]);
    }
    stats->held_small_triangles = held_triangles_;
    stats->peak_held_small_triangles = std::max(stats->peak_held_small_triangles, held_triangles_);
    Compact();
    return out;
  }

  // Triangles held in pieces not complete yet (0 once every vertex was completed).
  int64_t held_triangles() const { return held_triangles_; }

 private:
  struct Piece {
    uint32_t parent = 0;
    int64_t open = 0;    // its released vertices not completed yet
    int64_t faces = 0;
    int64_t vertices = 0;  // released
    double area = 0.0;
    bool big = false;    // reached min_area: released as it comes
    bool counted = false;
    std::vector<int64_t> held;            // 3 keys per held triangle
    std::vector<int64_t> held_completed;  // completions of its vertices, held with them
  };
  struct HeldVertex {
    std::array<double, 3> p{};
    int64_t point_id = -1;
  };

  uint32_t NewPiece() {
    Piece p;
    p.parent = next_;
    p.open = 1;
    p.vertices = 1;
    pieces_.emplace(next_, std::move(p));
    return next_++;
  }
  uint32_t Find(uint32_t x) {
    while (true) {
      Piece& p = pieces_.at(x);
      if (p.parent == x) return x;
      p.parent = pieces_.at(p.parent).parent;  // path halving
      x = p.parent;
    }
  }
  uint32_t Union(uint32_t a, uint32_t b) {
    a = Find(a);
    b = Find(b);
    if (a == b) return a;
    Piece& pa = pieces_.at(a);
    Piece& pb = pieces_.at(b);
    if (pa.held.size() < pb.held.size()) {
      std::swap(pa.held, pb.held);
      std::swap(pa.held_completed, pb.held_completed);
    }
    pa.held.insert(pa.held.end(), pb.held.begin(), pb.held.end());
    pa.held_completed.insert(pa.held_completed.end(), pb.held_completed.begin(), pb.held_completed.end());
    pb.held.clear();
    pb.held_completed.clear();
    pa.open += pb.open;
    pa.faces += pb.faces;
    pa.vertices += pb.vertices;
    pa.area += pb.area;
    pa.big = pa.big || pb.big;
    pb.parent = a;
    return a;
  }
  // Keeps the pieces an open vertex still names, each as its root.
  void Compact() {
    if (pieces_.size() <= 2 * open_.size() + 1024) return;
    std::unordered_map<uint32_t, Piece> kept;
    for (auto& [key, label] : open_) {
      label = Find(label);
      if (!kept.count(label)) kept.emplace(label, std::move(pieces_.at(label)));
    }
    pieces_.swap(kept);
  }

  double min_area_;
  std::unordered_map<uint32_t, Piece> pieces_;
  std::unordered_map<int64_t, uint32_t> open_;  // released, not completed: its piece
  std::unordered_map<int64_t, HeldVertex> held_vertices_;
  uint32_t next_ = 0;
  int64_t held_triangles_ = 0;
};

}  // namespace

SurfaceStreamOptions SurfaceStreamOptions::FromEngine(const EngineOptions& o) {
  SurfaceStreamOptions s;
  s.split_pinched = o.steiner_export != SteinerExportRule::kNone;
  s.fill_holes_perimeter = o.fill_holes_perimeter;
  s.smoothing_iterations = o.smoothing_iterations;
  s.min_component_area = o.MinComponentArea();
  return s;
}

std::string SurfaceStreamOptions::Check() const {
  if (!std::isfinite(fill_holes_perimeter) || fill_holes_perimeter < 0.0)
    return "fill_holes_perimeter must be >= 0";
  if (fill_holes_max_edges < 0) return "fill_holes_max_edges must be >= 0";
  if (smoothing_iterations < 0) return "smoothing_iterations must be >= 0";
  if (!std::isfinite(min_component_area) || min_component_area < 0.0)
    return "min_component_area must be >= 0";
  return "";
}

struct SurfaceStream::Impl {
  // A vertex as the engine named it (by its key), while a held triangle uses it.
  struct Vertex {
    std::array<double, 3> p{};
    int64_t point_id = -1;
    std::vector<uint64_t> triangles;  // held triangles around it (until it is split)
    int refs = 0;                     // held triangles that name it
    bool split = false;               // completed, and its fans made vertices of their own
    // Boundary edges u -> this vertex found when u was split, before this one: (u's copy, the
    // triangle with the edge), linked when this one is split.
    std::vector<std::pair<int64_t, uint64_t>> pending_in;
  };
  struct Triangle {
    std::array<int64_t, 3> v{};              // engine keys
    std::array<int64_t, 3> copy{-1, -1, -1};  // stream keys, once each vertex is split
  };
  // A vertex of the output (one fan of an engine vertex, or a hole's centre), by stream key.
  struct Copy {
    std::array<double, 3> p{};
    int64_t point_id = -1;
    int unreleased = 0;        // its triangles not released yet
    bool decided = true;       // false: on a boundary loop that may still be filled
    bool big = false;          // on a loop too long or too wide to fill
    int64_t next = -1, prev = -1;  // boundary loop neighbours (stream keys), -1: not linked
    std::pair<FaceKey, int> rank{};  // canonical order (boundary copies, filling on)
  };
  struct Hole {
    std::vector<int64_t> loop;  // from its start, in boundary order
    int64_t centre = -1;
  };

  SurfaceStreamOptions o;
  SurfaceStreamStats stats;
  std::unique_ptr<SmallPieceGate> gate;  // made with the first Add (o is set after construction)
  std::unordered_map<int64_t, Vertex> vertices;
  std::unordered_map<uint64_t, Triangle> triangles;
  std::unordered_map<int64_t, Copy> copies;
  uint64_t next_triangle = 0;
  int64_t next_key = 0;
  bool failed = false;

  // This Add's releases, emitted at its end (smoothed first when asked).
  std::vector<std::array<int64_t, 3>> batch;  // original triangles, stream keys
  std::vector<Hole> holes;
  std::vector<int64_t> maybe_free;  // copies to forget at the end of the Add if done
  SurfacePart out;
  std::unordered_map<int64_t, uint32_t> out_index;

  bool Filling() const { return o.fill_holes_perimeter > 0.0 && o.fill_holes_max_edges >= 3; }

  VertexKey KeyOf(int64_t engine_key) const {
    const Vertex& v = vertices.at(engine_key);
    return {v.point_id, v.p[0], v.p[1], v.p[2]};
  }

  // The face's key as CanonicalizeMesh sorts it (rotated to its smallest vertex key) and where
  // corner `c` lands in it.
  std::pair<FaceKey, int> FaceRank(const Triangle& t, int c) const {
    const FaceKey k = {KeyOf(t.v[0]), KeyOf(t.v[1]), KeyOf(t.v[2])};
    int first = 0;
    for (int i = 1; i < 3; ++i)
      if (k[i] < k[first]) first = i;
    return {{k[first], k[(first + 1) % 3], k[(first + 2) % 3]}, (c - first + 3) % 3};
  }

  static int CornerOf(const Triangle& t, int64_t engine_key) {
    for (int k = 0; k < 3; ++k)
      if (t.v[k] == engine_key) return k;
    return -1;
  }

  int64_t NewCopy(const std::array<double, 3>& p, int64_t point_id) {
    Copy c;
    c.p = p;
    c.point_id = point_id;
    copies.emplace(next_key, c);
    return next_key++;
  }

  // A vertex completed: its triangles around it, grouped into fans (SplitPinchedVertices), each
  // fan a copy; boundary edges out of each fan linked to their far end when it is split too.
  void Split(int64_t key) {
    Vertex& v = vertices.at(key);
    const std::vector<uint64_t> around = std::move(v.triangles);
    v.triangles.clear();
    const std::size_t n = around.size();
    // Union-find over the triangles: joined when they share another vertex (an edge at v).
    std::vector<std::size_t> parent(n);
    std::iota(parent.begin(), parent.end(), 0);
    auto root = [&](std::size_t i) {
      while (parent[i] != i) i = parent[i] = parent[parent[i]];
      return i;
    };
    std::vector<int> corner(n);
    std::unordered_map<int64_t, std::size_t> by_other;
    for (std::size_t i = 0; i < n; ++i) {
      const Triangle& t = triangles.at(around[i]);
      corner[i] = CornerOf(t, key);
      if (!o.split_pinched) {
        parent[i] = 0;
        continue;
      }
      for (int s = 1; s <= 2; ++s) {
        const auto [it, fresh] = by_other.emplace(t.v[(corner[i] + s) % 3], i);
        if (!fresh) parent[root(i)] = root(it->second);
      }
    }
    // One copy per fan, in the order of the fans' first triangles.
    std::unordered_map<std::size_t, int64_t> copy_of_root;
    for (std::size_t i = 0; i < n; ++i) {
      const std::size_t r = root(i);
      auto it = copy_of_root.find(r);
      if (it == copy_of_root.end()) {
        it = copy_of_root.emplace(r, NewCopy(v.p, v.point_id)).first;
        if (copy_of_root.size() > 1) ++stats.vertices_split;
      }
      triangles.at(around[i]).copy[corner[i]] = it->second;
      ++copies.at(it->second).unreleased;
    }
    // Boundary edges: v -> a (a triangle's next corner) is one when no triangle of the same fan
    // has a -> v (a as its previous corner); likewise b -> v.
    std::unordered_map<int64_t, std::vector<int64_t>> ins, outs;  // copy -> far ends
    for (std::size_t i = 0; i < n; ++i) {
      const Triangle& t = triangles.at(around[i]);
      ins[t.copy[corner[i]]].push_back(t.v[(corner[i] + 2) % 3]);
      outs[t.copy[corner[i]]].push_back(t.v[(corner[i] + 1) % 3]);
    }
    auto holds = [](const std::vector<int64_t>& list, int64_t k) {
      return std::find(list.begin(), list.end(), k) != list.end();
    };
    // Boundary copies wait for their loop (filling on): first all of them, with their rank, then
    // the links, which may decide them.
    std::vector<std::size_t> out_edges;  // triangles with a boundary edge out of v
    for (std::size_t i = 0; i < n && Filling(); ++i) {
      const Triangle& t = triangles.at(around[i]);
      const int64_t c = t.copy[corner[i]];
      const int64_t a = t.v[(corner[i] + 1) % 3], b = t.v[(corner[i] + 2) % 3];
      const bool out_edge = !holds(ins[c], a), in_edge = !holds(outs[c], b);
      if (out_edge) out_edges.push_back(i);
      Copy& cc = copies.at(c);
      if ((!out_edge && !in_edge) || !cc.decided) continue;
      cc.decided = false;
      cc.rank = FaceRank(t, corner[i]);
      for (std::size_t j = 0; j < n; ++j)
        if (root(j) == root(i)) cc.rank = std::min(cc.rank, FaceRank(triangles.at(around[j]), corner[j]));
    }
    for (std::size_t i : out_edges) {
      const uint64_t tid = around[i];
      const Triangle& t = triangles.at(tid);
      const int64_t c = t.copy[corner[i]];
      const int64_t a = t.v[(corner[i] + 1) % 3];
      Vertex& w = vertices.at(a);
      if (w.split)
        Link(c, t.copy[CornerOf(t, a)]);
      else
        w.pending_in.push_back({c, tid});
    }
    for (const auto& [from, tid] : v.pending_in) {
      const Triangle& t = triangles.at(tid);
      Link(from, t.copy[CornerOf(t, key)]);
    }
    v.pending_in.clear();
    v.pending_in.shrink_to_fit();
    v.split = true;
    if (n == 0) vertices.erase(key);  // named without a triangle
    for (uint64_t tid : around) {
      const Triangle& t = triangles.at(tid);
      if (t.copy[0] >= 0 && t.copy[1] >= 0 && t.copy[2] >= 0) Release(tid);
    }
  }

  void Release(uint64_t tid) {
    const Triangle t = triangles.at(tid);
    triangles.erase(tid);
    batch.push_back(t.copy);
    for (int k = 0; k < 3; ++k) {
      --copies.at(t.copy[k]).unreleased;
      maybe_free.push_back(t.copy[k]);
      Vertex& v = vertices.at(t.v[k]);
      if (--v.refs == 0 && v.split) vertices.erase(t.v[k]);
    }
  }

  double Distance(int64_t a, int64_t b) const {
    const Copy &ca = copies.at(a), &cb = copies.at(b);
    double s = 0.0;
    for (int k = 0; k < 3; ++k) {
      const double d = ca.p[k] - cb.p[k];
      s += d * d;
    }
    return std::sqrt(s);
  }

  void MarkBig(const std::vector<int64_t>& chain) {
    for (int64_t k : chain) {
      Copy& c = copies.at(k);
      c.big = true;
      c.decided = true;
      maybe_free.push_back(k);
    }
  }

  // A boundary edge a -> b whose ends are both split: the loop through it, as far as it is known,
  // is filled when it is closed and small, or given up when it cannot be.
  void Link(int64_t a, int64_t b) {
    copies.at(a).next = b;
    copies.at(b).prev = a;
    const std::size_t max_edges = static_cast<std::size_t>(o.fill_holes_max_edges);
    // A copy forgotten already was decided: on a big loop (a filled loop has no edge out).
    auto big_or_gone = [&](int64_t k) {
      const auto it = copies.find(k);
      return it == copies.end() || it->second.big;
    };
    std::vector<int64_t> forward;  // b, b.next, ... (up to a when closed)
    bool closed = false, big = false;
    for (int64_t x = b;;) {
      if (x == a) {
        closed = true;
        break;
      }
      if (big_or_gone(x)) {
        big = true;
        break;
      }
      forward.push_back(x);
      if (forward.size() > max_edges) {
        big = true;
        break;
      }
      x = copies.at(x).next;
      if (x < 0) break;
    }
    if (closed) {
      std::vector<int64_t> loop = forward;
      loop.push_back(a);
      const bool small = loop.size() >= 3 && loop.size() <= max_edges;
      if (small && TryFill(loop)) return;
      MarkBig(loop);
      return;
    }
    // Backward too when the forward walk met a big copy: a and the copies before it are on the
    // same big loop.
    std::vector<int64_t> backward;  // a, a.prev, ...
    for (int64_t x = a;;) {
      if (big_or_gone(x)) {
        big = true;
        break;
      }
      backward.push_back(x);
      if (backward.size() > max_edges) {
        big = true;
        break;
      }
      x = copies.at(x).prev;
      if (x < 0) break;
    }
    std::vector<int64_t> chain(backward.rbegin(), backward.rend());
    chain.insert(chain.end(), forward.begin(), forward.end());
    // A chain of E edges closes into a loop of at least E + 1: too many once E >= max_edges.
    if (!big && chain.size() >= max_edges + 1) big = true;
    if (!big) {
      double perimeter = 0.0;
      for (std::size_t i = 0; i + 1 < chain.size(); ++i) perimeter += Distance(chain[i], chain[i + 1]);
      // A margin for the loop's own sum, taken in another order.
      big = perimeter > o.fill_holes_perimeter * (1.0 + 1e-9);
    }
    if (big) {
      // The copies beyond a big neighbour are big already.
      std::vector<int64_t> mark;
      for (int64_t k : chain)
        if (!big_or_gone(k)) mark.push_back(k);
      MarkBig(mark);
    }
  }

  // FillSmallHoles on one closed loop: from the copy of lowest canonical index, the perimeter
  // and the centroid summed in loop order; the fan (next, a, centre) for each a.
  bool TryFill(std::vector<int64_t> loop) {
    std::size_t start = 0;
    for (std::size_t i = 1; i < loop.size(); ++i)
      if (copies.at(loop[i]).rank < copies.at(loop[start]).rank) start = i;
    std::rotate(loop.begin(), loop.begin() + static_cast<std::ptrdiff_t>(start), loop.end());
    double perimeter = 0.0;
    for (std::size_t i = 0; i < loop.size(); ++i)
      perimeter += Distance(loop[i], loop[(i + 1) % loop.size()]);
    if (perimeter > o.fill_holes_perimeter) return false;
    std::array<double, 3> c{0.0, 0.0, 0.0};
    for (int64_t k : loop)
      for (int d = 0; d < 3; ++d) c[d] += copies.at(k).p[d] / static_cast<double>(loop.size());
    Hole h;
    h.centre = NewCopy(c, -1);
    for (int64_t k : loop) {
      Copy& cc = copies.at(k);
      cc.decided = true;
      maybe_free.push_back(k);
    }
    maybe_free.push_back(h.centre);
    h.loop = std::move(loop);
    holes.push_back(std::move(h));
    ++stats.holes_filled;
    return true;
  }

  // The faces released by this Add, smoothed when asked, into `out`; then what is done is
  // forgotten.
  void Emit() {
    std::vector<std::array<int64_t, 3>> faces = std::move(batch);
    batch.clear();
    // Holes in canonical order of their start (FillSmallHoles' order of centres).
    std::sort(holes.begin(), holes.end(), [&](const Hole& x, const Hole& y) {
      return copies.at(x.loop[0]).rank < copies.at(y.loop[0]).rank;
    });
    if (o.smoothing_iterations > 0 && !(faces.empty() && holes.empty())) Smooth(faces);
    for (const Hole& h : holes)
      for (std::size_t i = 0; i < h.loop.size(); ++i)
        faces.push_back({h.loop[(i + 1) % h.loop.size()], h.loop[i], h.centre});
    holes.clear();
    for (const auto& f : faces)
      for (int64_t k : f) {
        const auto [it, fresh] = out_index.emplace(k, static_cast<uint32_t>(out.keys.size()));
        if (fresh) {
          const Copy& c = copies.at(k);
          out.vertices.insert(out.vertices.end(), c.p.begin(), c.p.end());
          out.keys.push_back(k);
          out.point_ids.push_back(c.point_id);
        }
        out.faces.push_back(it->second);
      }
    stats.triangles_released += static_cast<int64_t>(faces.size());
    std::sort(maybe_free.begin(), maybe_free.end());
    maybe_free.erase(std::unique(maybe_free.begin(), maybe_free.end()), maybe_free.end());
    for (int64_t k : maybe_free) {
      const auto it = copies.find(k);
      if (it == copies.end() || it->second.unreleased > 0 || !it->second.decided) continue;
      // A boundary copy stays while a neighbour still points at it (a later link walks to it).
      copies.erase(it);
      out.completed.push_back(k);
    }
    maybe_free.clear();
  }

  // SmoothTaubin on this Add's faces as one mesh: in canonical order, centres after, as
  // FinishExportedMesh has them when this is the whole surface.
  void Smooth(const std::vector<std::array<int64_t, 3>>& faces) {
    Mesh m;
    std::unordered_map<int64_t, uint32_t> index;
    std::vector<int64_t> key_of;
    auto add = [&](int64_t k) {
      const auto [it, fresh] = index.emplace(k, static_cast<uint32_t>(key_of.size()));
      if (fresh) {
        const Copy& c = copies.at(k);
        m.vertices.insert(m.vertices.end(), c.p.begin(), c.p.end());
        m.point_ids.push_back(c.point_id);
        key_of.push_back(k);
      }
      return it->second;
    };
    for (const auto& f : faces)
      for (int64_t k : f) m.faces.push_back(add(k));
    std::vector<uint32_t> new_index;
    CanonicalizeMesh(&m, &new_index);
    std::vector<int64_t> canonical_key(key_of.size());
    for (std::size_t i = 0; i < key_of.size(); ++i) canonical_key[new_index[i]] = key_of[i];
    index.clear();
    for (std::size_t i = 0; i < canonical_key.size(); ++i)
      index.emplace(canonical_key[i], static_cast<uint32_t>(i));
    key_of = std::move(canonical_key);
    for (const Hole& h : holes) {
      for (int64_t k : h.loop) add(k);
      const uint32_t centre = add(h.centre);
      for (std::size_t i = 0; i < h.loop.size(); ++i)
        m.faces.insert(m.faces.end(), {index.at(h.loop[(i + 1) % h.loop.size()]), index.at(h.loop[i]), centre});
    }
    SmoothTaubin(&m, o.smoothing_iterations);
    for (std::size_t i = 0; i < key_of.size(); ++i)
      std::copy_n(&m.vertices[3 * i], 3, copies.at(key_of[i]).p.begin());
  }

  std::string Add(const SurfacePart& part) {
    const std::size_t nv = part.keys.size();
    if (part.vertices.size() != 3 * nv || part.point_ids.size() != nv)
      return "vertices, keys and point ids differ in number";
    if (part.faces.size() % 3 != 0) return "faces: not a multiple of 3 indices";
    for (std::size_t i = 0; i < nv; ++i) {
      const std::array<double, 3> p = {part.vertices[3 * i], part.vertices[3 * i + 1], part.vertices[3 * i + 2]};
      const auto [it, fresh] = vertices.try_emplace(part.keys[i]);
      if (fresh) {
        it->second.p = p;
        it->second.point_id = part.point_ids[i];
      } else if (it->second.p != p || it->second.point_id != part.point_ids[i]) {
        return "vertex key " + std::to_string(part.keys[i]) + " is not where an earlier part put it";
      } else if (it->second.split) {
        return "vertex key " + std::to_string(part.keys[i]) + " was completed by an earlier part";
      }
    }
    for (std::size_t f = 0; f < part.faces.size(); f += 3) {
      Triangle t;
      for (int k = 0; k < 3; ++k) {
        if (part.faces[f + k] >= nv) return "a face index is out of range";
        t.v[k] = part.keys[part.faces[f + k]];
      }
      if (t.v[0] == t.v[1] || t.v[1] == t.v[2] || t.v[0] == t.v[2]) return "a degenerate face";
      const uint64_t id = next_triangle++;
      for (int k = 0; k < 3; ++k) {
        Vertex& v = vertices.at(t.v[k]);
        v.triangles.push_back(id);
        ++v.refs;
      }
      triangles.emplace(id, t);
    }
    stats.triangles_in += static_cast<int64_t>(part.faces.size() / 3);
    for (int64_t k : part.completed) {
      const auto it = vertices.find(k);
      if (it == vertices.end()) return "completed key " + std::to_string(k) + " was named by no part";
      if (it->second.split) return "completed key " + std::to_string(k) + " is completed twice";
    }
    for (int64_t k : part.completed) Split(k);
    Emit();
    ++stats.parts;
    stats.vertices_released = next_key - stats.dropped.vertices;
    stats.held_triangles = static_cast<int64_t>(triangles.size());
    stats.held_vertices = static_cast<int64_t>(vertices.size() + copies.size());
    stats.peak_held_triangles = std::max(stats.peak_held_triangles, stats.held_triangles);
    stats.peak_held_vertices = std::max(stats.peak_held_vertices, stats.held_vertices);
    return "";
  }
};

SurfaceStream::SurfaceStream(const SurfaceStreamOptions& options) : impl_(std::make_unique<Impl>()) {
  impl_->o = options;
}

SurfaceStream::~SurfaceStream() = default;

std::string SurfaceStream::Add(const SurfacePart& part) {
  if (impl_->failed) return "the stream failed before";
  if (const std::string e = impl_->o.Check(); !e.empty()) {
    impl_->failed = true;
    return e;
  }
  std::string e = impl_->Add(part);
  if (!e.empty()) {
    impl_->failed = true;
    e = "part " + std::to_string(impl_->stats.parts) + ": " + e;
  }
  return e;
}

SurfacePart SurfaceStream::TakeReleased() {
  SurfacePart p = std::move(impl_->out);
  impl_->out = SurfacePart();
  impl_->out_index.clear();
  p.update = impl_->stats.parts;
  if (!impl_->gate) impl_->gate = std::make_unique<SmallPieceGate>(impl_->o.min_component_area);
  p = impl_->gate->Pass(std::move(p), &impl_->stats);
  impl_->stats.vertices_released = impl_->next_key - impl_->stats.dropped.vertices;
  return p;
}

std::string SurfaceStream::Finish() const {
  const Impl& s = *impl_;
  if (s.gate && s.gate->held_triangles() > 0)
    return std::to_string(s.gate->held_triangles()) +
           " triangles of small pieces still held: a vertex was never completed";
  if (s.triangles.empty() && s.vertices.empty() && s.copies.empty()) return "";
  return std::to_string(s.triangles.size()) + " triangles and " +
         std::to_string(s.vertices.size() + s.copies.size()) +
         " vertices still held: a vertex was never completed";
}

const SurfaceStreamStats& SurfaceStream::stats() const { return impl_->stats; }

}  // namespace imr::engine
