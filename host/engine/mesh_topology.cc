// The engine's mesh topology helpers (no CGAL here): SplitPinchedVertices for the exported
// surface and CheckMesh, the 2-manifold test of a mesh.
#include "host/engine/mesh_topology.h"

#include <algorithm>
#include <cstdint>
#include <map>
#include <string>
#include <unordered_map>
#include <unordered_set>
#include <utility>
#include <vector>

namespace imr::engine {

// After dropping triangles from a closed 2-manifold, a vertex may keep several separate fans;
// give each extra fan its own copy of the vertex so the result is a 2-manifold with boundary.
void SplitPinchedVertices(Mesh* m) {
  const size_t nv = m->vertices.size() / 3;
  const size_t nt = m->faces.size() / 3;
  std::vector<std::vector<uint32_t>> around(nv);
  for (size_t t = 0; t < nt; ++t)
    for (int k = 0; k < 3; ++k) around[m->faces[3 * t + k]].push_back(static_cast<uint32_t>(t));
  for (size_t v = 0; v < nv; ++v) {
    const auto& tris = around[v];
    if (tris.size() < 2) continue;
    // Union-find over the triangles around v: two are joined when they share an edge at v.
    std::vector<int> parent(tris.size());
    for (size_t i = 0; i < tris.size(); ++i) parent[i] = static_cast<int>(i);
    auto root = [&](int i) {
      while (parent[i] != i) i = parent[i] = parent[parent[i]];
      return i;
    };
    auto others = [&](uint32_t t, uint32_t out[2]) {
      int n = 0;
      for (int k = 0; k < 3; ++k)
        if (m->faces[3 * t + k] != v) out[n++] = m->faces[3 * t + k];
    };
    for (size_t i = 0; i < tris.size(); ++i) {
      uint32_t a[2];
      others(tris[i], a);
      for (size_t j = i + 1; j < tris.size(); ++j) {
        uint32_t b[2];
        others(tris[j], b);
        if (a[0] == b[0] || a[0] == b[1] || a[1] == b[0] || a[1] == b[1])
          parent[root(static_cast<int>(i))] = root(static_cast<int>(j));
      }
    }
    std::map<int, uint32_t> copy;  // Component root -> vertex index.
    copy[root(0)] = static_cast<uint32_t>(v);
    for (size_t i = 0; i < tris.size(); ++i) {
      const int r = root(static_cast<int>(i));
      auto it = copy.find(r);
      if (it == copy.end()) {
        const uint32_t nvtx = static_cast<uint32_t>(m->vertices.size() / 3);
        m->vertices.insert(m->vertices.end(), {m->vertices[3 * v], m->vertices[3 * v + 1],
                                               m->vertices[3 * v + 2]});
        m->point_ids.push_back(m->point_ids[v]);
        it = copy.emplace(r, nvtx).first;
      }
      if (it->second == v) continue;
      for (int k = 0; k < 3; ++k)
        if (m->faces[3 * tris[i] + k] == v) m->faces[3 * tris[i] + k] = it->second;
    }
  }
}

// The check as first written, node-based maps and all (~60 bytes per directed edge and a
// vector per vertex: 0.6 GB for a 3 M-face drive's mesh): CheckMesh runs it only on a mesh
// its lean pass found wrong, for the same first message and counts.
ManifoldCheckResult CheckMeshReference(const Mesh& mesh, bool closed) {
  ManifoldCheckResult r;
  auto fail = [&](const std::string& s) {
    if (r.ok) r.message = s;
    r.ok = false;
  };
  const size_t nv = mesh.vertices.size() / 3;
  std::map<std::pair<uint32_t, uint32_t>, int> directed;
  std::vector<std::vector<std::pair<uint32_t, uint32_t>>> links(nv);
  for (size_t t = 0; t + 2 < mesh.faces.size(); t += 3) {
    const uint32_t f[3] = {mesh.faces[t], mesh.faces[t + 1], mesh.faces[t + 2]};
    for (int k = 0; k < 3; ++k)
      if (f[k] >= nv) {
        fail("a face index is out of range");
        return r;
      }
    if (f[0] == f[1] || f[1] == f[2] || f[0] == f[2]) fail("a degenerate face");
    for (int k = 0; k < 3; ++k) {
      if (++directed[{f[k], f[(k + 1) % 3]}] > 1) fail("a directed edge repeats");
      links[f[k]].push_back({f[(k + 1) % 3], f[(k + 2) % 3]});
    }
  }
  r.boundary_triangles = static_cast<int64_t>(mesh.faces.size() / 3);
  for (const auto& [e, n] : directed) {
    (void)n;
    if (!directed.count({e.second, e.first}) && closed) {
      fail("an edge is in only one triangle of a mesh required closed");
      break;
    }
  }
  // Each vertex: its link edges (a -> b, consistently oriented) form one cycle or one path.
  for (size_t v = 0; v < nv; ++v) {
    const auto& l = links[v];
    if (l.empty()) continue;
    ++r.boundary_vertices;
    std::unordered_map<uint32_t, uint32_t> next;
    std::unordered_set<uint32_t> has_prev;
    bool bad = false;
    for (const auto& e : l) {
      if (!next.emplace(e.first, e.second).second || !has_prev.insert(e.second).second) bad = true;
    }
    uint32_t start = l[0].first;
    int starts = 0;
    for (const auto& e : l)
      if (!has_prev.count(e.first)) {
        start = e.first;
        ++starts;
      }
    if (!bad && starts <= 1 && !(closed && starts == 1)) {
      size_t steps = 0;
      uint32_t cur = start;
      while (next.count(cur) && steps <= l.size()) {
        cur = next[cur];
        ++steps;
        if (cur == start) break;
      }
      bad = steps != l.size();
    } else {
      bad = true;
    }
    if (bad) {
      fail("vertex " + std::to_string(v) + " is not one fan");
      break;
    }
  }
  return r;
}

// The lean pass: the directed edges as sorted 64-bit keys (a repeat is two equal neighbours, a
// missing twin a failed search) and the vertices' links in one array by vertex (12 bytes per
// corner), each link checked in a few small sorted arrays. It decides only ok or not; anything
// wrong is examined again by the reference for its message.
ManifoldCheckResult CheckMesh(const Mesh& mesh, bool closed) {
  const size_t nv = mesh.vertices.size() / 3;
  const size_t nf = mesh.faces.size() / 3;
  auto reference = [&] { return CheckMeshReference(mesh, closed); };
  std::vector<uint64_t> edges;
  edges.reserve(3 * nf);
  std::vector<uint32_t> offset(nv + 1, 0);
  for (size_t t = 0; t < nf; ++t) {
    const uint32_t* f = &mesh.faces[3 * t];
    for (int k = 0; k < 3; ++k)
      if (f[k] >= nv) return reference();
    if (f[0] == f[1] || f[1] == f[2] || f[0] == f[2]) return reference();
    for (int k = 0; k < 3; ++k) {
      edges.push_back(uint64_t{f[k]} << 32 | f[(k + 1) % 3]);
      ++offset[f[k] + 1];
    }
  }
  std::sort(edges.begin(), edges.end());
  if (std::adjacent_find(edges.begin(), edges.end()) != edges.end()) return reference();
  if (closed)
    for (uint64_t e : edges)
      if (!std::binary_search(edges.begin(), edges.end(), e << 32 | e >> 32)) return reference();
  edges = {};

  // Each vertex's link edges (b, c) in face order, then one cycle or one path per vertex.
  for (size_t v = 0; v < nv; ++v) offset[v + 1] += offset[v];
  std::vector<std::pair<uint32_t, uint32_t>> links(3 * nf);
  {
    std::vector<uint32_t> fill(offset.begin(), offset.end() - 1);
    for (size_t t = 0; t < nf; ++t) {
      const uint32_t* f = &mesh.faces[3 * t];
      for (int k = 0; k < 3; ++k) links[fill[f[k]]++] = {f[(k + 1) % 3], f[(k + 2) % 3]};
    }
  }
  ManifoldCheckResult r;
  r.boundary_triangles = static_cast<int64_t>(nf);
  std::vector<std::pair<uint32_t, uint32_t>> by_first;
  std::vector<uint32_t> seconds;
  for (size_t v = 0; v < nv; ++v) {
    const size_t n = offset[v + 1] - offset[v];
    if (n == 0) continue;
    ++r.boundary_vertices;
    const LinkShape shape = CheckLink(links.data() + offset[v], n, &by_first, &seconds);
    if (shape == LinkShape::kNotOneFan || (closed && shape == LinkShape::kPath)) return reference();
  }
  return r;
}

LinkShape CheckLink(const std::pair<uint32_t, uint32_t>* l, std::size_t n,
                    std::vector<std::pair<uint32_t, uint32_t>>* by_first_scratch,
                    std::vector<uint32_t>* seconds_scratch) {
  auto& by_first = *by_first_scratch;
  auto& seconds = *seconds_scratch;
  by_first.assign(l, l + n);
  std::sort(by_first.begin(), by_first.end());
  seconds.clear();
  for (size_t i = 0; i < n; ++i) seconds.push_back(l[i].second);
  std::sort(seconds.begin(), seconds.end());
  bool bad = std::adjacent_find(seconds.begin(), seconds.end()) != seconds.end();
  for (size_t i = 1; i < n && !bad; ++i) bad = by_first[i].first == by_first[i - 1].first;
  // As the reference: the last link edge (in face order) whose first has no predecessor.
  uint32_t start = l[0].first;
  int starts = 0;
  for (size_t i = 0; i < n; ++i)
    if (!std::binary_search(seconds.begin(), seconds.end(), l[i].first)) {
      start = l[i].first;
      ++starts;
    }
  if (bad || starts > 1) return LinkShape::kNotOneFan;
  auto next = [&](uint32_t a, uint32_t* b) {
    const auto it = std::lower_bound(by_first.begin(), by_first.end(), std::make_pair(a, uint32_t{0}));
    if (it == by_first.end() || it->first != a) return false;
    *b = it->second;
    return true;
  };
  size_t steps = 0;
  uint32_t cur = start;
  while (steps <= n && next(cur, &cur)) {
    ++steps;
    if (cur == start) break;
  }
  if (steps != n) return LinkShape::kNotOneFan;
  return starts == 1 ? LinkShape::kPath : LinkShape::kCycle;
}

namespace {

// A vertex's link as its open paths (first, last) in order and its count of cycles; false when a
// neighbour comes twice as a first or as a second (not a union of paths and cycles).
bool LinkPaths(std::vector<std::pair<uint32_t, uint32_t>>& link,
               std::vector<std::pair<uint32_t, uint32_t>>* paths, int* cycles) {
  std::sort(link.begin(), link.end());
  std::vector<uint32_t> seconds;
  for (const auto& e : link) seconds.push_back(e.second);
  std::sort(seconds.begin(), seconds.end());
  if (std::adjacent_find(seconds.begin(), seconds.end()) != seconds.end()) return false;
  for (std::size_t i = 1; i < link.size(); ++i)
    if (link[i].first == link[i - 1].first) return false;
  std::vector<uint8_t> seen(link.size(), 0);
  auto at = [&](uint32_t a) -> std::ptrdiff_t {
    const auto it = std::lower_bound(link.begin(), link.end(), std::make_pair(a, uint32_t{0}));
    return it != link.end() && it->first == a ? it - link.begin() : -1;
  };
  paths->clear();
  *cycles = 0;
  for (std::size_t i = 0; i < link.size(); ++i) {
    if (std::binary_search(seconds.begin(), seconds.end(), link[i].first)) continue;  // not a start
    std::ptrdiff_t j = static_cast<std::ptrdiff_t>(i);
    uint32_t last = link[i].first;
    while (j >= 0 && !seen[static_cast<std::size_t>(j)]) {
      seen[static_cast<std::size_t>(j)] = 1;
      last = link[static_cast<std::size_t>(j)].second;
      j = at(last);
    }
    paths->emplace_back(link[i].first, last);
  }
  for (std::size_t i = 0; i < link.size(); ++i) {
    if (seen[i]) continue;
    ++*cycles;
    for (std::ptrdiff_t j = static_cast<std::ptrdiff_t>(i); j >= 0 && !seen[static_cast<std::size_t>(j)];
         j = at(link[static_cast<std::size_t>(j)].second))
      seen[static_cast<std::size_t>(j)] = 1;
  }
  std::sort(paths->begin(), paths->end());
  return true;
}

std::vector<std::vector<std::pair<uint32_t, uint32_t>>> Links(const std::vector<uint32_t>& faces,
                                                              std::size_t vertex_count) {
  std::vector<std::vector<std::pair<uint32_t, uint32_t>>> links(vertex_count);
  for (std::size_t f = 0; f + 2 < faces.size(); f += 3)
    for (std::size_t k = 0; k < 3; ++k)
      if (faces[f + k] < vertex_count)
        links[faces[f + k]].emplace_back(faces[f + (k + 1) % 3], faces[f + (k + 2) % 3]);
  return links;
}

}  // namespace

std::string SameVertexLinks(const std::vector<uint32_t>& before, const std::vector<uint32_t>& after,
                            std::size_t vertex_count) {
  for (const uint32_t v : after)
    if (v >= vertex_count) return "a face names vertex " + std::to_string(v) + " of " + std::to_string(vertex_count);
  auto a = Links(before, vertex_count), b = Links(after, vertex_count);
  std::vector<std::pair<uint32_t, uint32_t>> pa, pb;
  int ca = 0, cb = 0;
  for (std::size_t v = 0; v < vertex_count; ++v) {
    if (!LinkPaths(b[v], &pb, &cb))
      return "vertex " + std::to_string(v) + ": a neighbour twice in its faces";
    if (!LinkPaths(a[v], &pa, &ca)) continue;  // it was not a union of fans before either
    if (pa != pb || ca != cb)
      return "vertex " + std::to_string(v) + ": its fans changed (" + std::to_string(pa.size()) + " open, " +
             std::to_string(ca) + " closed -> " + std::to_string(pb.size()) + " open, " + std::to_string(cb) +
             " closed, or other ends)";
  }
  return {};
}

void VertexFans(const std::vector<uint32_t>& faces, std::size_t vertex_count, std::vector<uint32_t>* start,
                std::vector<uint32_t>* fan) {
  start->assign(vertex_count + 1, 0);
  for (uint32_t v : faces) ++(*start)[v + 1];
  for (std::size_t v = 0; v < vertex_count; ++v) (*start)[v + 1] += (*start)[v];
  fan->resize(faces.size());
  std::vector<uint32_t> fill(start->begin(), start->end() - 1);
  for (std::size_t f = 0; 3 * f + 2 < faces.size(); ++f)
    for (int k = 0; k < 3; ++k) (*fan)[fill[faces[3 * f + static_cast<std::size_t>(k)]]++] = static_cast<uint32_t>(f);
}

std::vector<uint8_t> ClosedFans(const std::vector<uint32_t>& faces, const std::vector<uint32_t>& start,
                                const std::vector<uint32_t>& fan) {
  const std::size_t nv = start.empty() ? 0 : start.size() - 1;
  std::vector<uint8_t> closed(nv, 0);
  std::vector<std::pair<uint32_t, uint32_t>> link, by_first;
  std::vector<uint32_t> seconds;
  for (uint32_t v = 0; v < nv; ++v) {
    link.clear();
    for (uint32_t i = start[v]; i < start[v + 1]; ++i) {
      const uint32_t* t = &faces[3 * std::size_t{fan[i]}];
      const int at = t[0] == v ? 0 : t[1] == v ? 1 : 2;
      link.emplace_back(t[(at + 1) % 3], t[(at + 2) % 3]);
    }
    closed[v] = !link.empty() &&
                CheckLink(link.data(), link.size(), &by_first, &seconds) == LinkShape::kCycle;
  }
  return closed;
}

}  // namespace imr::engine
