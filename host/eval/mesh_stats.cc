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

// The packed arrays ComputeMeshStatistics reads; the indices are checked by ValidFaces.
struct MeshArrays {
  const double* xyz;
  std::size_t vertex_count;
  const uint32_t* faces;
  std::size_t face_count;
  uint32_t Corner(std::size_t f, int k) const { return faces[3 * f + static_cast<std::size_t>(k)]; }
};

// Valid faces (three distinct indices in range); counts the degenerate ones.
std::vector<uint32_t> ValidFaces(const MeshArrays& m, MeshStatistics& s) {
  std::vector<uint32_t> valid;
  valid.reserve(m.face_count);
  for (std::size_t f = 0; f < m.face_count; ++f) {
    const uint32_t a = m.Corner(f, 0), b = m.Corner(f, 1), c = m.Corner(f, 2);
    for (uint32_t v : {a, b, c})
      if (v >= m.vertex_count)
        throw std::invalid_argument("face " + std::to_string(f) + ": vertex index " +
                                    std::to_string(v) + " out of range (" +
                                    std::to_string(m.vertex_count) + " vertices)");
    if (a == b || b == c || a == c) {
      ++s.degenerate_faces;
      continue;
    }
    valid.push_back(static_cast<uint32_t>(f));
  }
  return valid;
}

// The components through shared vertices, with each used vertex's component.
struct Components {
  std::vector<char> used;
  std::vector<int64_t> of_vertex;
  std::vector<ComponentStatistics> list;
  ComponentStatistics& Of(uint32_t v) { return list[static_cast<std::size_t>(of_vertex[v])]; }
};

Components FindComponents(const MeshArrays& m, const std::vector<uint32_t>& valid,
                          MeshStatistics& s) {
  Components comps;
  DisjointSets vertex_sets(m.vertex_count);
  comps.used.assign(m.vertex_count, 0);
  for (uint32_t f : valid) {
    for (int k = 0; k < 3; ++k) comps.used[m.Corner(f, k)] = 1;
    vertex_sets.Union(m.Corner(f, 0), m.Corner(f, 1));
    vertex_sets.Union(m.Corner(f, 0), m.Corner(f, 2));
  }
  // Component index per root, numbered by smallest vertex index (reordered by size at the end).
  std::vector<int64_t> component_of_root(m.vertex_count, -1);
  comps.of_vertex.assign(m.vertex_count, -1);
  int64_t component_count = 0;
  for (std::size_t v = 0; v < m.vertex_count; ++v) {
    if (!comps.used[v]) continue;
    ++s.used_vertices;
    const std::size_t r = vertex_sets.Find(v);
    if (component_of_root[r] < 0) component_of_root[r] = component_count++;
    comps.of_vertex[v] = component_of_root[r];
  }
  s.unused_vertices = s.vertices - s.used_vertices;
  comps.list.resize(static_cast<std::size_t>(component_count));
  for (auto& c : comps.list) c.orientable = c.consistently_oriented = true;
  for (std::size_t v = 0; v < m.vertex_count; ++v)
    if (comps.used[v]) ++comps.Of(static_cast<uint32_t>(v)).vertices;
  return comps;
}

// Faces: area, counts, bounding box of the used vertices.
void AddAreasAndBounds(const MeshArrays& m, const std::vector<uint32_t>& valid,
                       Components& comps, MeshStatistics& s) {
  for (uint32_t f : valid) {
    const uint32_t a = m.Corner(f, 0), b = m.Corner(f, 1), c = m.Corner(f, 2);
    const double area = TriangleArea(m.xyz, a, b, c);
    ComponentStatistics& comp = comps.Of(a);
    ++comp.faces;
    comp.area += area;
    s.area += area;
  }
  bool any = false;
  for (std::size_t v = 0; v < m.vertex_count; ++v) {
    if (!comps.used[v]) continue;
    for (int k = 0; k < 3; ++k) {
      const double x = m.xyz[3 * v + static_cast<std::size_t>(k)];
      s.bbox_min[static_cast<std::size_t>(k)] = any ? std::min(s.bbox_min[static_cast<std::size_t>(k)], x) : x;
      s.bbox_max[static_cast<std::size_t>(k)] = any ? std::max(s.bbox_max[static_cast<std::size_t>(k)], x) : x;
    }
    any = true;
  }
}

// The half-edges sorted by undirected edge.
std::vector<HalfEdge> SortedHalfEdges(const MeshArrays& m, const std::vector<uint32_t>& valid) {
  std::vector<HalfEdge> half;
  half.reserve(3 * valid.size());
  for (uint32_t f : valid) {
    for (int k = 0; k < 3; ++k) {
      const uint32_t a = m.Corner(f, k), b = m.Corner(f, (k + 1) % 3);
      const uint64_t lo = std::min(a, b), hi = std::max(a, b);
      half.push_back({lo << 32 | hi, f, static_cast<uint8_t>(k), a < b});
    }
  }
  std::sort(half.begin(), half.end(), [](const HalfEdge& x, const HalfEdge& y) {
    return x.key != y.key ? x.key < y.key : x.face < y.face;
  });
  return half;
}

// Face adjacency across a manifold edge, with whether both faces run the edge the same way.
struct Neighbour {
  uint32_t face;
  bool same_direction;
};

// What the edges tell: corners (face, k) joined across manifold edges (the fans around each
// vertex), the boundary-edge graph, the vertices on boundary / non-manifold edges, adjacency.
struct EdgeTopology {
  DisjointSets corner_sets;
  DisjointSets boundary_sets;
  std::vector<char> on_boundary, on_nonmanifold_edge;
  std::vector<std::vector<Neighbour>> adjacency;
  explicit EdgeTopology(const MeshArrays& m)
      : corner_sets(3 * m.face_count), boundary_sets(m.vertex_count),
        on_boundary(m.vertex_count, 0), on_nonmanifold_edge(m.vertex_count, 0),
        adjacency(m.face_count) {}
};

// Counts edges by how many faces share them and joins what they connect.
EdgeTopology ClassifyEdges(const MeshArrays& m, const std::vector<HalfEdge>& half,
                           Components& comps, MeshStatistics& s) {
  EdgeTopology t(m);
  auto corner_of = [&](uint32_t f, uint32_t v) {
    for (int k = 0; k < 3; ++k)
      if (m.Corner(f, k) == v) return 3 * static_cast<std::size_t>(f) + static_cast<std::size_t>(k);
    return std::size_t{0};  // not reached: v is a vertex of f
  };
  for (std::size_t i = 0; i < half.size();) {
    std::size_t j = i;
    while (j < half.size() && half[j].key == half[i].key) ++j;
    const std::size_t n = j - i;
    const uint32_t a = static_cast<uint32_t>(half[i].key >> 32);
    const uint32_t b = static_cast<uint32_t>(half[i].key & 0xffffffffu);
    ComponentStatistics& comp = comps.Of(a);
    ++s.edges;
    ++comp.edges;
    if (n == 1) {
      ++s.boundary_edges;
      ++comp.boundary_edges;
      t.boundary_sets.Union(a, b);
      t.on_boundary[a] = t.on_boundary[b] = 1;
    } else if (n == 2) {
      const HalfEdge& x = half[i];
      const HalfEdge& y = half[i + 1];
      t.corner_sets.Union(corner_of(x.face, a), corner_of(y.face, a));
      t.corner_sets.Union(corner_of(x.face, b), corner_of(y.face, b));
      const bool same = x.ascending == y.ascending;
      t.adjacency[x.face].push_back({y.face, same});
      t.adjacency[y.face].push_back({x.face, same});
    } else {
      ++s.nonmanifold_edges;
      ++comp.nonmanifold_edges;
      t.on_nonmanifold_edge[a] = t.on_nonmanifold_edge[b] = 1;
    }
    i = j;
  }
  return t;
}

// Boundary loops: one per component of the boundary-edge graph.
void CountBoundaryLoops(const MeshArrays& m, EdgeTopology& t, Components& comps,
                        MeshStatistics& s) {
  std::vector<char> loop_counted(m.vertex_count, 0);
  for (std::size_t v = 0; v < m.vertex_count; ++v) {
    if (!t.on_boundary[v]) continue;
    const std::size_t r = t.boundary_sets.Find(v);
    if (loop_counted[r]) continue;
    loop_counted[r] = 1;
    ++s.boundary_loops;
    ++comps.Of(static_cast<uint32_t>(v)).boundary_loops;
  }
}

// Non-manifold vertices: on a non-manifold edge, or with two or more fans.
void CountNonmanifoldVertices(const MeshArrays& m, const std::vector<uint32_t>& valid,
                              EdgeTopology& t, Components& comps, MeshStatistics& s) {
  std::vector<std::pair<uint32_t, std::size_t>> vertex_fans;
  vertex_fans.reserve(3 * valid.size());
  for (uint32_t f : valid)
    for (int k = 0; k < 3; ++k)
      vertex_fans.emplace_back(m.Corner(f, k),
                               t.corner_sets.Find(3 * static_cast<std::size_t>(f) + static_cast<std::size_t>(k)));
  std::sort(vertex_fans.begin(), vertex_fans.end());
  vertex_fans.erase(std::unique(vertex_fans.begin(), vertex_fans.end()), vertex_fans.end());
  for (std::size_t i = 0; i < vertex_fans.size();) {
    std::size_t j = i;
    while (j < vertex_fans.size() && vertex_fans[j].first == vertex_fans[i].first) ++j;
    const uint32_t v = vertex_fans[i].first;
    if (j - i > 1 || t.on_nonmanifold_edge[v]) {
      ++s.nonmanifold_vertices;
      ++comps.Of(v).nonmanifold_vertices;
    }
    i = j;
  }
}

// Orientation: propagate flips over the manifold edges; a contradiction = non-orientable.
void CheckOrientation(const MeshArrays& m, const std::vector<uint32_t>& valid,
                      const EdgeTopology& t, Components& comps) {
  std::vector<int8_t> flip(m.face_count, -1);
  std::vector<uint32_t> queue;
  for (uint32_t start : valid) {
    if (flip[start] >= 0) continue;
    flip[start] = 0;
    queue.assign(1, start);
    while (!queue.empty()) {
      const uint32_t f = queue.back();
      queue.pop_back();
      ComponentStatistics& comp = comps.Of(m.Corner(f, 0));
      for (const Neighbour& nb : t.adjacency[f]) {
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
}

// Per component: chi, manifoldness, genus; then the totals, the components largest first.
void Summarise(std::vector<ComponentStatistics> comps, std::size_t valid_faces,
               MeshStatistics& s) {
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
  s.components = static_cast<int64_t>(comps.size());
  s.euler_characteristic = s.used_vertices - s.edges + static_cast<int64_t>(valid_faces);
  // Largest first; ties keep the order of the smallest vertex index (stable sort).
  std::stable_sort(comps.begin(), comps.end(),
                   [](const ComponentStatistics& x, const ComponentStatistics& y) {
                     return x.faces > y.faces;
                   });
  s.component_list = std::move(comps);
}

}  // namespace

MeshStatistics ComputeMeshStatistics(const double* xyz, std::size_t vertex_count,
                                     const uint32_t* faces, std::size_t face_count) {
  const MeshArrays m{xyz, vertex_count, faces, face_count};
  MeshStatistics s;
  s.vertices = static_cast<int64_t>(vertex_count);
  s.faces = static_cast<int64_t>(face_count);
  const std::vector<uint32_t> valid = ValidFaces(m, s);
  Components comps = FindComponents(m, valid, s);
  AddAreasAndBounds(m, valid, comps, s);
  EdgeTopology edges = ClassifyEdges(m, SortedHalfEdges(m, valid), comps, s);
  CountBoundaryLoops(m, edges, comps, s);
  CountNonmanifoldVertices(m, valid, edges, comps, s);
  CheckOrientation(m, valid, edges, comps);
  Summarise(std::move(comps.list), valid.size(), s);
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
