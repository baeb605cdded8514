// Planar regions triangulated again (plane_retriangulation.h). CGAL's 2D constrained Delaunay
// triangulation stays in this file.
#include "host/engine/plane_retriangulation.h"

#include <CGAL/Constrained_Delaunay_triangulation_2.h>
#include <CGAL/Constrained_triangulation_face_base_2.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Triangulation_face_base_with_info_2.h>
#include <CGAL/Triangulation_vertex_base_with_info_2.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <deque>
#include <numeric>
#include <sstream>
#include <unordered_map>
#include <unordered_set>
#include <tuple>
#include <utility>

#include "host/engine/mesh_topology.h"

namespace imr::engine {

namespace {

using K = CGAL::Exact_predicates_inexact_constructions_kernel;
using Vb = CGAL::Triangulation_vertex_base_with_info_2<uint32_t, K>;
struct FaceInfo {
  int nesting = -1;  // constrained loops crossed from the infinite face; odd: inside the region
};
using Fbi = CGAL::Triangulation_face_base_with_info_2<FaceInfo, K>;
using Fb = CGAL::Constrained_triangulation_face_base_2<K, Fbi>;
using Tds = CGAL::Triangulation_data_structure_2<Vb, Fb>;
// Constraints that cross (or pass through a vertex) throw: the region's loops would not be
// simple in its plane, and the region stays as it was.
using Cdt = CGAL::Constrained_Delaunay_triangulation_2<K, Tds, CGAL::No_constraint_intersection_tag>;

using Vec3 = std::array<double, 3>;

double Dot(const Vec3& a, const Vec3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
Vec3 Cross(const Vec3& a, const Vec3& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
Vec3 Sub(const double* a, const Vec3& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
Vec3 Normalized(Vec3 v) {
  const double n = std::sqrt(Dot(v, v));
  if (n > 0.0)
    for (double& x : v) x /= n;
  return v;
}

uint64_t EdgeKey(uint32_t a, uint32_t b) {
  if (a > b) std::swap(a, b);
  return (uint64_t{a} << 32) | b;
}

struct Plane {
  Vec3 centre{};
  Vec3 normal{};  // unit
};

// The least-squares plane through `ids` (the eigenvector of the smallest eigenvalue of their
// scatter, by Jacobi rotations: 3x3, symmetric) and the largest distance of a point from it.
std::pair<Plane, double> FitPlane(const std::vector<double>& xyz, const std::vector<uint32_t>& ids) {
  Plane pl;
  for (uint32_t v : ids)
    for (int k = 0; k < 3; ++k) pl.centre[k] += xyz[3 * size_t{v} + k];
  for (double& c : pl.centre) c /= static_cast<double>(ids.size());
  double a[3][3] = {};
  for (uint32_t v : ids) {
    const Vec3 d = Sub(&xyz[3 * size_t{v}], pl.centre);
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) a[i][j] += d[i] * d[j];
  }
  double e[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  for (int sweep = 0; sweep < 32; ++sweep) {
    const double off = a[0][1] * a[0][1] + a[0][2] * a[0][2] + a[1][2] * a[1][2];
    const double diag = a[0][0] * a[0][0] + a[1][1] * a[1][1] + a[2][2] * a[2][2];
    if (off <= 1e-30 * diag || off == 0.0) break;
    for (int p = 0; p < 2; ++p)
      for (int q = p + 1; q < 3; ++q) {
        if (a[p][q] == 0.0) continue;
        const double theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
        const double t = (theta >= 0 ? 1.0 : -1.0) / (std::abs(theta) + std::sqrt(theta * theta + 1.0));
        const double c = 1.0 / std::sqrt(t * t + 1.0);
        const double s = t * c;
        for (int k = 0; k < 3; ++k) {  // A <- A J (columns p, q)
          const double akp = a[k][p], akq = a[k][q];
          a[k][p] = c * akp - s * akq;
          a[k][q] = s * akp + c * akq;
        }
        for (int k = 0; k < 3; ++k) {  // A <- J^T A (rows p, q)
          const double apk = a[p][k], aqk = a[q][k];
          a[p][k] = c * apk - s * aqk;
          a[q][k] = s * apk + c * aqk;
        }
        for (int k = 0; k < 3; ++k) {  // E <- E J
          const double ekp = e[k][p], ekq = e[k][q];
          e[k][p] = c * ekp - s * ekq;
          e[k][q] = s * ekp + c * ekq;
        }
      }
  }
  int smallest = 0;
  for (int i = 1; i < 3; ++i)
    if (a[i][i] < a[smallest][smallest]) smallest = i;
  pl.normal = Normalized({e[0][smallest], e[1][smallest], e[2][smallest]});
  double worst = 0.0;
  for (uint32_t v : ids)
    worst = std::max(worst, std::abs(Dot(Sub(&xyz[3 * size_t{v}], pl.centre), pl.normal)));
  return {pl, worst};
}

// Loops crossed from the infinite face, per face: an odd count is inside the region's loops.
void MarkNesting(Cdt& cdt) {
  for (auto f = cdt.all_faces_begin(); f != cdt.all_faces_end(); ++f) f->info().nesting = -1;
  std::deque<Cdt::Edge> border;
  auto flood = [&](Cdt::Face_handle start, int level) {
    std::deque<Cdt::Face_handle> queue{start};
    while (!queue.empty()) {
      const Cdt::Face_handle f = queue.front();
      queue.pop_front();
      if (f->info().nesting != -1) continue;
      f->info().nesting = level;
      for (int i = 0; i < 3; ++i) {
        const Cdt::Face_handle n = f->neighbor(i);
        if (n->info().nesting != -1) continue;
        if (cdt.is_constrained(Cdt::Edge(f, i)))
          border.emplace_back(f, i);
        else
          queue.push_back(n);
      }
    }
  };
  flood(cdt.infinite_face(), 0);
  while (!border.empty()) {
    const Cdt::Edge e = border.front();
    border.pop_front();
    const Cdt::Face_handle n = e.first->neighbor(e.second);
    if (n->info().nesting == -1) flood(n, e.first->info().nesting + 1);
  }
}

class Retriangulator {
 public:
  // `seams`: a vertex whose fan is open may have faces in other parts (a SurfacePart), so its
  // edges stay and no edge joins two such vertices anew; else the mesh is whole.
  Retriangulator(std::vector<double>* xyz, std::vector<uint32_t>* faces,
                 const PlaneRetriangulationOptions& o, bool seams)
      : xyz_(*xyz), faces_(*faces), o_(o), seams_(seams) {}

  PlaneRetriangulationStats Run() {
    const std::size_t nf = faces_.size() / 3;
    const std::size_t nv = xyz_.size() / 3;
    if (nf == 0) return stats_;
    BuildTopology(nv, nf);
    tol_ = o_.tolerance * MedianEdgeLength();
    if (!(tol_ > 0.0)) return stats_;

    // Seeds: faces whose neighbourhood (every face at one of its vertices) is flat, flattest
    // first, so that a region starts where the plane is surest.
    struct Seed {
      double worst;  // the largest distance of its neighbourhood from the plane
      uint32_t face;
      Plane plane;
    };
    std::vector<Seed> seeds;
    std::vector<uint32_t> ids;
    for (uint32_t f = 0; f < nf; ++f) {
      ids.clear();
      for (int k = 0; k < 3; ++k) {
        const uint32_t v = faces_[3 * size_t{f} + k];
        for (uint32_t i = fan_start_[v]; i < fan_start_[v + 1]; ++i)
          for (int j = 0; j < 3; ++j) ids.push_back(faces_[3 * size_t{fan_[i]} + j]);
      }
      std::sort(ids.begin(), ids.end());
      ids.erase(std::unique(ids.begin(), ids.end()), ids.end());
      const auto [plane, worst] = FitPlane(xyz_, ids);
      if (worst <= tol_) seeds.push_back({worst, f, plane});
    }
    std::sort(seeds.begin(), seeds.end(), [](const Seed& a, const Seed& b) {
      return a.worst < b.worst || (a.worst == b.worst && a.face < b.face);
    });

    taken_.assign(nf, 0);
    tested_.assign(nf, 0);
    uint32_t stamp = 0;
    std::vector<uint32_t> region;
    for (const Seed& s : seeds) {
      const uint32_t seed = s.face;
      if (taken_[seed]) continue;
      const Plane& plane = s.plane;
      ++stamp;
      region.assign(1, seed);
      tested_[seed] = stamp;
      for (std::size_t r = 0; r < region.size() && region.size() < std::size_t(o_.max_faces); ++r) {
        const uint32_t f = region[r];
        for (int k = 0; k < 3; ++k) {
          const int64_t g = Across(f, k);
          if (g < 0 || taken_[g] || tested_[g] == stamp) continue;
          tested_[g] = stamp;
          if (Within(static_cast<uint32_t>(g), plane)) region.push_back(static_cast<uint32_t>(g));
          if (region.size() >= std::size_t(o_.max_faces)) break;
        }
      }
      // A region refused is tried again without the faces at the vertices that made it fail
      // (a fold over its edge), up to kRetries times.
      const std::vector<uint32_t> grown = region;
      bool replaced = false;
      std::vector<uint32_t> trouble;
      for (int retry = 0; retry <= kRetries; ++retry) {
        if (region.size() < std::size_t(std::max(o_.min_faces, 1))) break;
        if ((replaced = Replace(region, plane, &trouble)) || trouble.empty()) break;
        DropFacesAt(trouble, &region);
      }
      if (replaced) {
        ++stats_.regions;
        stats_.faces += static_cast<int64_t>(region.size());
      } else if (grown.size() >= std::size_t(std::max(o_.min_faces, 1))) {
        ++stats_.regions_refused;
      }
      // Its faces, replaced or not, are no seeds any more, nor taken by a later region.
      for (uint32_t f : grown) taken_[f] = 1;
    }
    return stats_;
  }

 private:
  static constexpr int kRetries = 8;

  // The region without its faces at the vertices `at`.
  void DropFacesAt(const std::vector<uint32_t>& at, std::vector<uint32_t>* region) const {
    const std::unordered_set<uint32_t> drop(at.begin(), at.end());
    std::vector<uint32_t> kept;
    for (uint32_t f : *region) {
      const uint32_t* t = &faces_[3 * size_t{f}];
      if (!drop.count(t[0]) && !drop.count(t[1]) && !drop.count(t[2])) kept.push_back(f);
    }
    region->swap(kept);
  }

  void BuildTopology(std::size_t nv, std::size_t nf) {
    VertexFans(faces_, nv, &fan_start_, &fan_);
    edges_.reserve(faces_.size());
    for (uint32_t f = 0; f < nf; ++f)
      for (int k = 0; k < 3; ++k) AddEdge(f, k);
    // A vertex may move when its fan is one closed cycle of consistently oriented faces.
    closed_ = ClosedFans(faces_, fan_start_, fan_);
  }

  void AddEdge(uint32_t f, int k) {
    const uint64_t key = EdgeKey(faces_[3 * size_t{f} + k], faces_[3 * size_t{f} + (k + 1) % 3]);
    auto& e = edges_[key];
    if (e.count < 2) e.face[e.count] = f;
    ++e.count;
  }
  void RemoveEdge(uint32_t f, int k) {
    const uint64_t key = EdgeKey(faces_[3 * size_t{f} + k], faces_[3 * size_t{f} + (k + 1) % 3]);
    const auto it = edges_.find(key);
    if (it == edges_.end()) return;
    auto& e = it->second;
    if (e.count == 2 && e.face[0] == f) e.face[0] = e.face[1];
    if (--e.count == 0) edges_.erase(it);
  }

  // The face across edge k (vertices k, k+1) of face f; -1 at a boundary or a non-manifold edge.
  int64_t Across(uint32_t f, int k) const {
    const auto it =
        edges_.find(EdgeKey(faces_[3 * size_t{f} + k], faces_[3 * size_t{f} + (k + 1) % 3]));
    if (it == edges_.end() || it->second.count != 2) return -1;
    return it->second.face[0] == f ? it->second.face[1] : it->second.face[0];
  }

  Vec3 Point(uint32_t v) const { return {xyz_[3 * size_t{v}], xyz_[3 * size_t{v} + 1], xyz_[3 * size_t{v} + 2]}; }

  bool Within(uint32_t f, const Plane& plane) const {
    for (int k = 0; k < 3; ++k)
      if (std::abs(Dot(Sub(&xyz_[3 * size_t{faces_[3 * size_t{f} + k]}], plane.centre), plane.normal)) > tol_)
        return false;
    return true;
  }

  double MedianEdgeLength() const {
    std::vector<double> lengths;
    lengths.reserve(edges_.size());
    for (const auto& [key, e] : edges_) {
      const double* a = &xyz_[3 * (key >> 32)];
      const double* b = &xyz_[3 * (key & 0xffffffffu)];
      lengths.push_back(std::sqrt((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) +
                                  (a[2] - b[2]) * (a[2] - b[2])));
    }
    if (lengths.empty()) return 0.0;
    std::nth_element(lengths.begin(), lengths.begin() + lengths.size() / 2, lengths.end());
    return lengths[lengths.size() / 2];
  }

  // The region's faces replaced by the constrained Delaunay triangulation of its vertices,
  // projected onto its plane, inside its boundary loops; false (nothing changed) when that would
  // not give a manifold with the same boundary.
  bool Replace(const std::vector<uint32_t>& region, Plane plane, std::vector<uint32_t>* trouble) {
    trouble->clear();
    std::unordered_map<uint32_t, uint32_t> local;  // mesh vertex -> region vertex
    std::vector<uint32_t> verts;
    for (uint32_t f : region)
      for (int k = 0; k < 3; ++k)
        if (local.emplace(faces_[3 * size_t{f} + k], static_cast<uint32_t>(verts.size())).second)
          verts.push_back(faces_[3 * size_t{f} + k]);
    // The plane of the whole region when it holds every vertex as well as the seed's did.
    if (const auto [fitted, worst] = FitPlane(xyz_, verts); worst <= tol_) plane = fitted;

    std::unordered_set<uint32_t> in_region(region.begin(), region.end());
    std::vector<std::pair<uint32_t, uint32_t>> boundary;  // directed, as the region's faces have them
    std::unordered_set<uint64_t> old_edges;
    std::vector<uint8_t> on_boundary(verts.size(), 0);
    double orientation = 0.0;
    for (uint32_t f : region) {
      const uint32_t* t = &faces_[3 * size_t{f}];
      const Vec3 origin = Point(t[0]);
      orientation += Dot(Cross(Sub(&xyz_[3 * size_t{t[1]}], origin), Sub(&xyz_[3 * size_t{t[2]}], origin)),
                         plane.normal);
      for (int k = 0; k < 3; ++k) {
        const uint32_t u = t[k], w = t[(k + 1) % 3];
        old_edges.insert(EdgeKey(u, w));
        const int64_t g = Across(f, k);
        if (g < 0 || !in_region.count(static_cast<uint32_t>(g))) {
          boundary.emplace_back(u, w);
          on_boundary[local.at(u)] = on_boundary[local.at(w)] = 1;
        }
      }
    }
    // The region's loops pass each vertex once: where they touch at a vertex, the plane's order
    // of its edges may pair its wedges otherwise than the surface does (its fan would not be one
    // fan any more: seen on imr-synth's default job, across two parts), so the faces at that
    // vertex leave the region.
    {
      std::unordered_map<uint32_t, int> leaving;
      for (const auto& edge : boundary)
        if (++leaving[edge.first] == 2) trouble->push_back(edge.first);
      if (!trouble->empty()) return false;
    }
    // A vertex inside the region moves onto the plane: its whole fan must be in the region.
    for (std::size_t i = 0; i < verts.size(); ++i) {
      if (on_boundary[i]) continue;
      const uint32_t v = verts[i];
      if (!closed_[v]) return false;
      for (uint32_t j = fan_start_[v]; j < fan_start_[v + 1]; ++j)
        if (!in_region.count(fan_[j])) return false;
    }

    // The plane's frame: (u, w, normal) right-handed, so counter-clockwise in (u, w) is a face
    // whose normal is +normal.
    const Vec3& n = plane.normal;
    const Vec3 seed_axis = std::abs(n[0]) < 0.6 ? Vec3{1, 0, 0} : Vec3{0, 1, 0};
    const Vec3 u = Normalized(Cross(seed_axis, n));
    const Vec3 w = Cross(n, u);
    Cdt cdt;
    std::vector<Cdt::Vertex_handle> handle(verts.size());
    for (std::size_t i = 0; i < verts.size(); ++i) {
      const Vec3 d = Sub(&xyz_[3 * size_t{verts[i]}], plane.centre);
      handle[i] = cdt.insert(K::Point_2(Dot(d, u), Dot(d, w)));
      if (cdt.number_of_vertices() != i + 1) {  // two vertices at one place in the plane
        trouble->insert(trouble->end(), {verts[i], verts[handle[i]->info()]});
        return false;
      }
      handle[i]->info() = static_cast<uint32_t>(i);
    }
    // The loops, and in a part the edges at its seam vertices, as constraints; one that crosses
    // another (a fold over the region's edge) is trouble at its two ends.
    uint32_t a = 0, b = 0;
    try {
      for (const auto& edge : boundary) {
        std::tie(a, b) = edge;
        cdt.insert_constraint(handle[local.at(a)], handle[local.at(b)]);
      }
      if (seams_)
        for (uint64_t key : old_edges) {
          a = static_cast<uint32_t>(key >> 32);
          b = static_cast<uint32_t>(key & 0xffffffffu);
          if ((!closed_[a] || !closed_[b]) && !cdt.is_edge(handle[local.at(a)], handle[local.at(b)]))
            cdt.insert_constraint(handle[local.at(a)], handle[local.at(b)]);
        }
    } catch (const Cdt::Intersection_of_constraints_exception&) {
      trouble->insert(trouble->end(), {a, b});
      return false;
    }
    if (cdt.number_of_vertices() != verts.size()) return false;
    MarkNesting(cdt);

    const bool flip = orientation < 0.0;
    std::vector<uint32_t> next;
    next.reserve(3 * region.size());
    std::vector<uint8_t> used(verts.size(), 0);
    for (auto f = cdt.finite_faces_begin(); f != cdt.finite_faces_end(); ++f) {
      if (f->info().nesting % 2 != 1) continue;
      uint32_t t[3];
      for (int k = 0; k < 3; ++k) {
        t[k] = f->vertex(k)->info();
        used[t[k]] = 1;
      }
      if (flip) std::swap(t[1], t[2]);
      for (uint32_t x : t) next.push_back(verts[x]);
    }
    // Every vertex in a face inside the loops, as many faces as before; a vertex left out (a
    // fold over the region's edge put it outside its loops) is trouble.
    for (std::size_t i = 0; i < verts.size(); ++i)
      if (!used[i]) trouble->push_back(verts[i]);
    if (!trouble->empty() || next.size() != 3 * region.size()) return false;
    // The boundary kept as it was, each edge in its direction; no new edge that the mesh has
    // elsewhere (two faces of it across the region would make it non-manifold), nor, in a part,
    // one between two vertices on its boundary: their other faces come in other parts, which
    // may hold that edge.
    std::unordered_map<uint64_t, int> directed;  // uses of each directed edge
    for (std::size_t i = 0; i < next.size(); i += 3)
      for (int k = 0; k < 3; ++k) ++directed[(uint64_t{next[i + k]} << 32) | next[i + (k + 1) % 3]];
    for (const auto& [from, to] : boundary)
      if (!directed.count((uint64_t{from} << 32) | to)) {
        trouble->insert(trouble->end(), {from, to});
        return false;
      }
    // ... and the new faces a surface with that boundary: each boundary edge once and never the
    // other way, every other edge once each way. A loop folded over in the plane can give both
    // sides of one of its edges a face (seen on imr-synth's default job with max_ray_length 60:
    // a part's edge, whose other face is in the next part, got a second face here).
    std::unordered_set<uint64_t> boundary_directed;
    for (const auto& [from, to] : boundary) boundary_directed.insert((uint64_t{from} << 32) | to);
    for (const auto& [edge, uses] : directed) {
      const uint64_t reverse = (edge << 32) | (edge >> 32);
      const bool ok = uses == 1 && (boundary_directed.count(edge) ? !directed.count(reverse)
                                                                  : !boundary_directed.count(reverse) &&
                                                                        directed.count(reverse));
      if (!ok) {
        trouble->insert(trouble->end(), {static_cast<uint32_t>(edge >> 32), static_cast<uint32_t>(edge)});
        return false;
      }
    }
    for (std::size_t i = 0; i < next.size(); i += 3)
      for (int k = 0; k < 3; ++k) {
        const uint64_t key = EdgeKey(next[i + k], next[i + (k + 1) % 3]);
        if (old_edges.count(key)) continue;
        if (edges_.count(key) || (seams_ && !closed_[next[i + k]] && !closed_[next[i + (k + 1) % 3]])) {
          trouble->insert(trouble->end(), {next[i + k], next[i + (k + 1) % 3]});
          return false;
        }
      }

    for (uint32_t f : region)
      for (int k = 0; k < 3; ++k) RemoveEdge(f, k);
    // The new faces take the region's slots. The vertices' face lists (fan_) are not updated:
    // they are read only for a vertex inside a later region, and such a vertex has no face in a
    // region replaced before (it would be on the later region's boundary).
    for (std::size_t r = 0; r < region.size(); ++r) {
      std::copy_n(&next[3 * r], 3, &faces_[3 * size_t{region[r]}]);
      for (int k = 0; k < 3; ++k) AddEdge(region[r], k);
    }
    for (std::size_t i = 0; i < verts.size(); ++i) {
      if (on_boundary[i]) continue;
      double* p = &xyz_[3 * size_t{verts[i]}];
      const double d = Dot(Sub(p, plane.centre), n);
      for (int k = 0; k < 3; ++k) p[k] -= d * n[k];
      stats_.max_move = std::max(stats_.max_move, std::abs(d));
      ++stats_.vertices_moved;
    }
    return true;
  }

  std::vector<double>& xyz_;
  std::vector<uint32_t>& faces_;
  const PlaneRetriangulationOptions& o_;
  const bool seams_;
  PlaneRetriangulationStats stats_;
  double tol_ = 0.0;
  struct EdgeFaces {
    uint32_t face[2] = {0, 0};
    uint32_t count = 0;
  };
  std::unordered_map<uint64_t, EdgeFaces> edges_;
  std::vector<uint32_t> fan_start_, fan_;  // faces at each vertex (CSR)
  std::vector<uint8_t> closed_;
  std::vector<uint8_t> taken_;  // per face: in a region already (replaced or refused)
  std::vector<uint32_t> tested_;
};

}  // namespace

PlaneRetriangulationOptions PlaneRetriangulationOptions::FromEngine(const EngineOptions& options) {
  PlaneRetriangulationOptions o;
  o.tolerance = options.retriangulate_planes;
  return o;
}

std::string PlaneRetriangulationOptions::Check() const {
  std::ostringstream e;
  if (!std::isfinite(tolerance) || tolerance < 0.0)
    e << "tolerance must be >= 0 (median edge lengths; 0: off); ";
  if (min_faces < 1) e << "min_faces must be >= 1; ";
  if (max_faces < min_faces) e << "max_faces must be >= min_faces; ";
  return e.str();
}

PlaneRetriangulationStats& PlaneRetriangulationStats::operator+=(const PlaneRetriangulationStats& o) {
  regions += o.regions;
  faces += o.faces;
  vertices_moved += o.vertices_moved;
  regions_refused += o.regions_refused;
  max_move = std::max(max_move, o.max_move);
  return *this;
}

PlaneRetriangulationStats RetriangulatePlanes(Mesh* mesh, const PlaneRetriangulationOptions& options) {
  if (!options.enabled()) return {};
  return Retriangulator(&mesh->vertices, &mesh->faces, options, /*seams=*/false).Run();
}

PlaneRetriangulationStats RetriangulatePlanes(SurfacePart* part,
                                              const PlaneRetriangulationOptions& options) {
  if (!options.enabled()) return {};
  return Retriangulator(&part->vertices, &part->faces, options, /*seams=*/true).Run();
}

}  // namespace imr::engine
