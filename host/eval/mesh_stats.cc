#include "host/eval/mesh_stats.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <stdexcept>
#include <string>

namespace imr::eval {
namespace {

// Union-find with path halving and union by size.
class DisjointSets {
 public:
  explicit DisjointSets(std::size_t n) : parent_(n), size_(n, 1) {
    std::iota(parent_.begin(), parent_.end(), std::size_t{0});
  }
  std::size_t Find(std::size_t x) {
    while (parent_[x] != x) {
      parent_[x] = parent_[parent_[x]];
      x = parent_[x];
    }
    return x;
  }
  void Union(std::size_t a, std::size_t b) {
    a = Find(a);
    b = Find(b);
    if (a == b) return;
    if (size_[a] < size_[b]) std::swap(a, b);
    parent_[b] = a;
    size_[a] += size_[b];
  }

 private:
  std::vector<std::size_t> parent_;
  std::vector<std::size_t> size_;
};

// One directed edge of a valid face: from corner k of `face` to corner k + 1.
struct HalfEdge {
  uint64_t key;      // min(a, b) << 32 | max(a, b): the undirected edge
  uint32_t face;
  uint8_t corner;    // k: the edge starts at face[k]
  bool ascending;    // a < b
};

double TriangleArea(const double* xyz, uint32_t a, uint32_t b, uint32_t c) {
  const double* p = xyz + 3 * static_cast<std::size_t>(a);
  const double* q = xyz + 3 * static_cast<std::size_t>(b);
  const double* r = xyz + 3 * static_cast<std::size_t>(c);
  const double u[3] = {q[0] - p[0], q[1] - p[1], q[2] - p[2]};
  const double v[3] = {r[0] - p[0], r[1] - p[1], r[2] - p[2]};
  const double n[3] = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2],
                       u[0] * v[1] - u[1] * v[0]};
  return 0.5 * std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
}

}  // namespace

MeshStatistics ComputeMeshStatistics(const double* xyz, std::size_t vertex_count,
                                     const uint32_t* faces, std::size_t face_count) {
  MeshStatistics s;
  s.vertices = static_cast<int64_t>(vertex_count);
  s.faces = static_cast<int64_t>(face_count);
  auto corner_vertex = [&](std::size_t f, int k) { return faces[3 * f + static_cast<std::size_t>(k)]; };

  // Valid faces (three distinct indices in range).
  std::vector<uint32_t> valid;
  valid.reserve(face_count);
  for (std::size_t f = 0; f < face_count; ++f) {
    const uint32_t a = corner_vertex(f, 0), b = corner_vertex(f, 1), c = corner_vertex(f, 2);
    for (uint32_t v : {a, b, c})
      if (v >= vertex_count)
        throw std::invalid_argument("face " + std::to_string(f) + ": vertex index " +
                                    std::to_string(v) + " out of range (" +
                                    std::to_string(vertex_count) + " vertices)");
    if (a == b || b == c || a == c) {
      ++s.degenerate_faces;
      continue;
    }
    valid.push_back(static_cast<uint32_t>(f));
  }

  // Components through shared vertices; used vertices.
  DisjointSets vertex_sets(vertex_count);
  std::vector<char> used(vertex_count, 0);
  for (uint32_t f : valid) {
    for (int k = 0; k < 3; ++k) used[corner_vertex(f, k)] = 1;
    vertex_sets.Union(corner_vertex(f, 0), corner_vertex(f, 1));
    vertex_sets.Union(corner_vertex(f, 0), corner_vertex(f, 2));
  }
  // Component index per root, numbered by smallest vertex index (reordered by size at the end).
  std::vector<int64_t> component_of_root(vertex_count, -1);
  std::vector<int64_t> vertex_component(vertex_count, -1);
  int64_t component_count = 0;
  for (std::size_t v = 0; v < vertex_count; ++v) {
    if (!used[v]) continue;
    ++s.used_vertices;
    const std::size_t r = vertex_sets.Find(v);
    if (component_of_root[r] < 0) component_of_root[r] = component_count++;
    vertex_component[v] = component_of_root[r];
  }
  s.unused_vertices = s.vertices - s.used_vertices;
  std::vector<ComponentStatistics> comps(static_cast<std::size_t>(component_count));
  for (auto& c : comps) c.orientable = c.consistently_oriented = true;
  auto comp_of = [&](uint32_t v) -> ComponentStatistics& {
    return comps[static_cast<std::size_t>(vertex_component[v])];
  };
  for (std::size_t v = 0; v < vertex_count; ++v)
    if (used[v]) ++comp_of(static_cast<uint32_t>(v)).vertices;

  // Faces: area, counts, bounding box.
  bool any = false;
  for (uint32_t f : valid) {
    const uint32_t a = corner_vertex(f, 0), b = corner_vertex(f, 1), c = corner_vertex(f, 2);
    const double area = TriangleArea(xyz, a, b, c);
    ComponentStatistics& comp = comp_of(a);
    ++comp.faces;
    comp.area += area;
    s.area += area;
  }
  for (std::size_t v = 0; v < vertex_count; ++v) {
    if (!used[v]) continue;
    for (int k = 0; k < 3; ++k) {
      const double x = xyz[3 * v + static_cast<std::size_t>(k)];
      s.bbox_min[static_cast<std::size_t>(k)] = any ? std::min(s.bbox_min[static_cast<std::size_t>(k)], x) : x;
      s.bbox_max[static_cast<std::size_t>(k)] = any ? std::max(s.bbox_max[static_cast<std::size_t>(k)], x) : x;
    }
    any = true;
  }

  // Edges: the half-edges sorted by undirected edge.
  std::vector<HalfEdge> half;
  half.reserve(3 * valid.size());
  for (uint32_t f : valid) {
    for (int k = 0; k < 3; ++k) {
      const uint32_t a = corner_vertex(f, k), b = corner_vertex(f, (k + 1) % 3);
      const uint64_t lo = std::min(a, b), hi = std::max(a, b);
      half.push_back({lo << 32 | hi, f, static_cast<uint8_t>(k), a < b});
    }
  }
  std::sort(half.begin(), half.end(), [](const HalfEdge& x, const HalfEdge& y) {
    return x.key != y.key ? x.key < y.key : x.face < y.face;
  });

  // Corners (face, k) joined across manifold edges: the fans around each vertex.
  DisjointSets corner_sets(3 * face_count);
  auto corner_of = [&](uint32_t f, uint32_t v) {
    for (int k = 0; k < 3; ++k)
      if (corner_vertex(f, k) == v) return 3 * static_cast<std::size_t>(f) + static_cast<std::size_t>(k);
    return std::size_t{0};  // not reached: v is a vertex of f
  };
  DisjointSets boundary_sets(vertex_count);
  std::vector<char> on_boundary(vertex_count, 0), on_nonmanifold_edge(vertex_count, 0);
  // Face adjacency across manifold edges, with whether both faces run the edge the same way.
  struct Neighbour {
    uint32_t face;
    bool same_direction;
  };
  std::vector<std::vector<Neighbour>> adjacency(face_count);
  for (std::size_t i = 0; i < half.size();) {
    std::size_t j = i;
    while (j < half.size() && half[j].key == half[i].key) ++j;
    const std::size_t n = j - i;
    const uint32_t a = static_cast<uint32_t>(half[i].key >> 32);
    const uint32_t b = static_cast<uint32_t>(half[i].key & 0xffffffffu);
    ComponentStatistics& comp = comp_of(a);
    ++s.edges;
    ++comp.edges;
    if (n == 1) {
      ++s.boundary_edges;
      ++comp.boundary_edges;
      boundary_sets.Union(a, b);
      on_boundary[a] = on_boundary[b] = 1;
    } else if (n == 2) {
      const HalfEdge& x = half[i];
      const HalfEdge& y = half[i + 1];
      corner_sets.Union(corner_of(x.face, a), corner_of(y.face, a));
      corner_sets.Union(corner_of(x.face, b), corner_of(y.face, b));
      const bool same = x.ascending == y.ascending;
      adjacency[x.face].push_back({y.face, same});
      adjacency[y.face].push_back({x.face, same});
    } else {
      ++s.nonmanifold_edges;
      ++comp.nonmanifold_edges;
      on_nonmanifold_edge[a] = on_nonmanifold_edge[b] = 1;
    }
    i = j;
  }

  // Boundary loops: one per component of the boundary-edge graph.
  std::vector<char> loop_counted(vertex_count, 0);
  for (std::size_t v = 0; v < vertex_count; ++v) {
    if (!on_boundary[v]) continue;
    const std::size_t r = boundary_sets.Find(v);
    if (loop_counted[r]) continue;
    loop_counted[r] = 1;
    ++s.boundary_loops;
    ++comp_of(static_cast<uint32_t>(v)).boundary_loops;
  }

  // Non-manifold vertices: on a non-manifold edge, or with two or more fans.
  std::vector<std::pair<uint32_t, std::size_t>> vertex_fans;
  vertex_fans.reserve(3 * valid.size());
  for (uint32_t f : valid)
    for (int k = 0; k < 3; ++k)
      vertex_fans.emplace_back(corner_vertex(f, k),
                               corner_sets.Find(3 * static_cast<std::size_t>(f) + static_cast<std::size_t>(k)));
  std::sort(vertex_fans.begin(), vertex_fans.end());
  vertex_fans.erase(std::unique(vertex_fans.begin(), vertex_fans.end()), vertex_fans.end());
  for (std::size_t i = 0; i < vertex_fans.size();) {
    std::size_t j = i;
    while (j < vertex_fans.size() && vertex_fans[j].first == vertex_fans[i].first) ++j;
    const uint32_t v = vertex_fans[i].first;
    if (j - i > 1 || on_nonmanifold_edge[v]) {
      ++s.nonmanifold_vertices;
      ++comp_of(v).nonmanifold_vertices;
    }
    i = j;
  }

  // Orientation: propagate flips over the manifold edges; a contradiction = non-orientable.
  std::vector<int8_t> flip(face_count, -1);
  std::vector<uint32_t> queue;
  for (uint32_t start : valid) {
    if (flip[start] >= 0) continue;
    flip[start] = 0;
    queue.assign(1, start);
    while (!queue.empty()) {
      const uint32_t f = queue.back();
      queue.pop_back();
      ComponentStatistics& comp = comp_of(corner_vertex(f, 0));
      for (const Neighbour& nb : adjacency[f]) {
        if (nb.same_direction) comp.consistently_oriented = false;
        // Across an edge both faces run the same way, exactly one of them must flip.
        const int8_t want = static_cast<int8_t>(flip[f] ^ (nb.same_direction ? 1 : 0));
        if (flip[nb.face] < 0) {
          flip[nb.face] = want;
          queue.push_back(nb.face);
        } else if (flip[nb.face] != want) {
          comp.orientable = false;
        }
      }
    }
  }

  // Per component: chi, manifoldness, genus; then the totals.
  s.manifold = s.closed = s.orientable = s.consistently_oriented = true;
  s.genus = 0;
  for (ComponentStatistics& c : comps) {
    c.euler_characteristic = c.vertices - c.edges + c.faces;
    c.manifold = c.nonmanifold_edges == 0 && c.nonmanifold_vertices == 0;
    c.closed = c.boundary_edges == 0;
    if (!c.orientable) c.consistently_oriented = false;
    const int64_t twice_genus = 2 - c.euler_characteristic - c.boundary_loops;
    c.genus = c.manifold && c.orientable && twice_genus >= 0 && twice_genus % 2 == 0
                  ? twice_genus / 2 : -1;
    s.manifold = s.manifold && c.manifold;
    s.closed = s.closed && c.closed;
    s.orientable = s.orientable && c.orientable;
    s.consistently_oriented = s.consistently_oriented && c.consistently_oriented;
    s.genus = (s.genus < 0 || c.genus < 0) ? -1 : s.genus + c.genus;
  }
  s.components = component_count;
  s.euler_characteristic = s.used_vertices - s.edges + static_cast<int64_t>(valid.size());
  // Largest first; ties keep the order of the smallest vertex index (stable sort).
  std::stable_sort(comps.begin(), comps.end(),
                   [](const ComponentStatistics& x, const ComponentStatistics& y) {
                     return x.faces > y.faces;
                   });
  s.component_list = std::move(comps);
  return s;
}

MeshStatistics ComputeMeshStatistics(const std::vector<double>& xyz,
                                     const std::vector<uint32_t>& faces) {
  if (xyz.size() % 3 != 0)
    throw std::invalid_argument("vertex array of " + std::to_string(xyz.size()) +
                                " numbers is not packed xyz (not a multiple of 3)");
  if (faces.size() % 3 != 0)
    throw std::invalid_argument("face array of " + std::to_string(faces.size()) +
                                " indices is not packed triangles (not a multiple of 3)");
  return ComputeMeshStatistics(xyz.data(), xyz.size() / 3, faces.data(), faces.size() / 3);
}

namespace {

nlohmann::json ComponentJson(const ComponentStatistics& c) {
  return {{"vertices", c.vertices},
          {"edges", c.edges},
          {"faces", c.faces},
          {"euler_characteristic", c.euler_characteristic},
          {"boundary_edges", c.boundary_edges},
          {"boundary_loops", c.boundary_loops},
          {"nonmanifold_edges", c.nonmanifold_edges},
          {"nonmanifold_vertices", c.nonmanifold_vertices},
          {"manifold", c.manifold},
          {"closed", c.closed},
          {"orientable", c.orientable},
          {"consistently_oriented", c.consistently_oriented},
          {"genus", c.genus >= 0 ? nlohmann::json(c.genus) : nlohmann::json(nullptr)},
          {"area", c.area}};
}

}  // namespace

nlohmann::json MeshStatistics::ToJson(std::size_t max_components) const {
  nlohmann::json list = nlohmann::json::array();
  for (std::size_t i = 0; i < component_list.size() && i < max_components; ++i)
    list.push_back(ComponentJson(component_list[i]));
  return {{"vertices", vertices},
          {"used_vertices", used_vertices},
          {"unused_vertices", unused_vertices},
          {"faces", faces},
          {"degenerate_faces", degenerate_faces},
          {"edges", edges},
          {"euler_characteristic", euler_characteristic},
          {"components", components},
          {"components_connected_by", "shared vertices"},
          {"boundary_edges", boundary_edges},
          {"boundary_loops", boundary_loops},
          {"nonmanifold_edges", nonmanifold_edges},
          {"nonmanifold_vertices", nonmanifold_vertices},
          {"manifold", manifold},
          {"closed", closed},
          {"orientable", orientable},
          {"consistently_oriented", consistently_oriented},
          {"genus", genus >= 0 ? nlohmann::json(genus) : nlohmann::json(nullptr)},
          {"area", area},
          {"bbox", {{"min", bbox_min}, {"max", bbox_max}}},
          {"components_listed", list.size()},
          {"component_list", list}};
}

}  // namespace imr::eval
