// What the export does to dO's exported part after the Steiner rule (no CGAL here): open_steiner's
// regions, filling small holes and smoothing, both keeping the mesh a 2-manifold (with the same
// boundary, for smoothing), dropping faces and small components.
#include <algorithm>
#include <array>
#include <cmath>
#include <numeric>
#include <stdexcept>
#include <unordered_map>
#include <vector>

#include "host/engine/engine.h"
#include "host/engine/mesh_topology.h"

namespace imr::engine {
namespace {

double Distance(const Mesh& m, uint32_t a, uint32_t b) {
  double s = 0.0;
  for (int k = 0; k < 3; ++k) {
    const double d = m.vertices[3 * a + k] - m.vertices[3 * b + k];
    s += d * d;
  }
  return std::sqrt(s);
}

// Boundary half-edges: those whose reverse no face has, as `next[a] = b` (one per boundary vertex
// on a manifold with boundary). Vertices without one map to kNone.
constexpr uint32_t kNone = 0xFFFFFFFFu;
std::vector<uint32_t> BoundaryNext(const Mesh& m) {
  const size_t nv = m.vertices.size() / 3;
  std::vector<uint64_t> directed;  // a << 32 | b
  directed.reserve(m.faces.size());
  for (size_t t = 0; t + 2 < m.faces.size(); t += 3)
    for (int k = 0; k < 3; ++k) {
      const uint64_t a = m.faces[t + k], b = m.faces[t + (k + 1) % 3];
      directed.push_back(a << 32 | b);
    }
  std::sort(directed.begin(), directed.end());
  std::vector<uint32_t> next(nv, kNone);
  for (const uint64_t key : directed) {
    const uint32_t a = static_cast<uint32_t>(key >> 32), b = static_cast<uint32_t>(key);
    const uint64_t reverse = static_cast<uint64_t>(b) << 32 | a;
    if (!std::binary_search(directed.begin(), directed.end(), reverse)) next[a] = b;
  }
  return next;
}

}  // namespace

int FillSmallHoles(Mesh* m, double max_perimeter, int max_edges) {
  if (max_perimeter <= 0.0 || max_edges < 3) return 0;
  const std::vector<uint32_t> next = BoundaryNext(*m);
  std::vector<uint8_t> seen(next.size(), 0);
  int filled = 0;
  std::vector<uint32_t> loop;
  for (uint32_t start = 0; start < next.size(); ++start) {
    if (next[start] == kNone || seen[start]) continue;
    loop.clear();
    double perimeter = 0.0;
    bool closed = false;
    for (uint32_t v = start; loop.size() <= static_cast<size_t>(max_edges);) {
      if (seen[v]) {
        closed = v == start;
        break;
      }
      seen[v] = 1;
      loop.push_back(v);
      const uint32_t w = next[v];
      if (w == kNone) break;
      perimeter += Distance(*m, v, w);
      v = w;
    }
    // Mark the rest of a long loop so it is walked once.
    for (uint32_t v = loop.empty() ? start : next[loop.back()]; v != kNone && !seen[v]; v = next[v])
      seen[v] = 1;
    if (!closed || loop.size() < 3 || loop.size() > static_cast<size_t>(max_edges) ||
        perimeter > max_perimeter)
      continue;
    // A fan around the loop's centroid: each boundary edge a -> b gets the face (b, a, centre),
    // oriented like the face the edge already has.
    std::array<double, 3> c{0.0, 0.0, 0.0};
    for (uint32_t v : loop)
      for (int k = 0; k < 3; ++k) c[k] += m->vertices[3 * v + k] / static_cast<double>(loop.size());
    const uint32_t centre = static_cast<uint32_t>(m->vertices.size() / 3);
    m->vertices.insert(m->vertices.end(), c.begin(), c.end());
    if (!m->point_ids.empty()) m->point_ids.push_back(-1);
    for (uint32_t a : loop) m->faces.insert(m->faces.end(), {next[a], a, centre});
    ++filled;
  }
  return filled;
}

void SmoothTaubin(Mesh* m, int iterations, double lambda, double mu) {
  if (iterations <= 0) return;
  const size_t nv = m->vertices.size() / 3;
  const std::vector<uint32_t> next = BoundaryNext(*m);
  // Neighbours by edges (each edge once per direction).
  std::vector<std::vector<uint32_t>> around(nv);
  for (size_t t = 0; t + 2 < m->faces.size(); t += 3)
    for (int k = 0; k < 3; ++k) {
      const uint32_t a = m->faces[t + k], b = m->faces[t + (k + 1) % 3];
      around[a].push_back(b);
      around[b].push_back(a);
    }
  for (auto& n : around) {
    std::sort(n.begin(), n.end());
    n.erase(std::unique(n.begin(), n.end()), n.end());
  }
  std::vector<double> delta(3 * nv);
  auto step = [&](double factor) {
    for (size_t v = 0; v < nv; ++v) {
      for (int k = 0; k < 3; ++k) delta[3 * v + k] = 0.0;
      if (next[v] != kNone || around[v].empty()) continue;  // boundary vertices stay
      for (uint32_t w : around[v])
        for (int k = 0; k < 3; ++k) delta[3 * v + k] += m->vertices[3 * w + k];
      for (int k = 0; k < 3; ++k)
        delta[3 * v + k] = delta[3 * v + k] / static_cast<double>(around[v].size()) -
                           m->vertices[3 * v + k];
    }
    for (size_t i = 0; i < 3 * nv; ++i) m->vertices[i] += factor * delta[i];
  };
  for (int i = 0; i < iterations; ++i) {
    step(lambda);
    step(mu);
  }
}

double TriangleArea(const double* a, const double* b, const double* c) {
  const double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
  const double w[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
  const double n[3] = {u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]};
  return 0.5 * std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
}

namespace {

// `faces` (indices into m's vertices) become m's faces; the vertices no face names go, the others
// keep their order, renumbered.
void KeepFaces(Mesh* m, std::vector<uint32_t> faces) {
  std::vector<uint32_t> new_index(m->point_ids.size(), kNone);
  for (uint32_t v : faces) new_index[v] = 0;
  Mesh out;
  for (size_t v = 0; v < new_index.size(); ++v) {
    if (new_index[v] == kNone) continue;
    new_index[v] = static_cast<uint32_t>(out.point_ids.size());
    out.vertices.insert(out.vertices.end(), &m->vertices[3 * v], &m->vertices[3 * v] + 3);
    out.point_ids.push_back(m->point_ids[v]);
  }
  for (uint32_t& i : faces) i = new_index[i];
  out.faces = std::move(faces);
  *m = std::move(out);
}

}  // namespace

void DropSmallComponents(Mesh* m, double min_area, DroppedComponents* dropped) {
  const size_t nv = m->point_ids.size(), nf = m->faces.size() / 3;
  if (!(min_area > 0.0) || nf == 0) return;
  // Union-find over vertices: a face joins its three.
  std::vector<uint32_t> parent(nv);
  std::iota(parent.begin(), parent.end(), 0u);
  auto find = [&](uint32_t v) {
    while (parent[v] != v) v = parent[v] = parent[parent[v]];
    return v;
  };
  for (size_t f = 0; f < nf; ++f) {
    const uint32_t a = find(m->faces[3 * f]);
    for (int k = 1; k < 3; ++k) {
      const uint32_t b = find(m->faces[3 * f + static_cast<size_t>(k)]);
      if (a != b) parent[b] = a;
    }
  }
  std::vector<double> area(nv, 0.0);  // per root
  std::vector<int64_t> faces(nv, 0), vertices(nv, 0);
  for (size_t v = 0; v < nv; ++v) ++vertices[find(static_cast<uint32_t>(v))];
  for (size_t f = 0; f < nf; ++f) {
    const uint32_t* t = &m->faces[3 * f];
    const uint32_t r = find(t[0]);
    area[r] += TriangleArea(&m->vertices[3 * size_t{t[0]}], &m->vertices[3 * size_t{t[1]}],
                            &m->vertices[3 * size_t{t[2]}]);
    ++faces[r];
  }
  DroppedComponents d;
  for (size_t v = 0; v < nv; ++v)
    if (faces[v] > 0 && area[v] < min_area) {
      ++d.components;
      d.faces += faces[v];
      d.vertices += vertices[v];
      d.area += area[v];
    }
  if (d.components == 0) return;
  // What stays, in its order.
  std::vector<uint32_t> kept;
  kept.reserve(m->faces.size());
  for (size_t f = 0; f < nf; ++f) {
    const uint32_t* t = &m->faces[3 * f];
    if (area[find(t[0])] >= min_area) kept.insert(kept.end(), t, t + 3);
  }
  KeepFaces(m, std::move(kept));
  if (dropped != nullptr) {
    dropped->components += d.components;
    dropped->faces += d.faces;
    dropped->vertices += d.vertices;
    dropped->area += d.area;
  }
}

int64_t DropFaces(Mesh* m, const std::vector<uint8_t>& drop, double min_area, DroppedComponents* dropped) {
  const size_t nf = m->faces.size() / 3;
  if (drop.size() != nf) throw std::invalid_argument("DropFaces: one flag per face expected");
  std::vector<uint32_t> kept;
  kept.reserve(m->faces.size());
  int64_t gone = 0;
  for (size_t f = 0; f < nf; ++f) {
    if (drop[f]) {
      ++gone;
      continue;
    }
    kept.insert(kept.end(), &m->faces[3 * f], &m->faces[3 * f] + 3);
  }
  if (gone == 0) return 0;
  m->faces = std::move(kept);
  SplitPinchedVertices(m);
  KeepFaces(m, std::move(m->faces));
  DropSmallComponents(m, min_area, dropped);
  return gone;
}

// open_steiner: where the points are sparse, dO closes over the views through triangles with a
// Steiner vertex. Those between point triangles fill gaps (the road between its few points);
// those that mostly border nothing span into where no point was seen (a sheet over the sky). A
// region's rim is counted edge by edge, not by length: its open edges run along the long grid
// edges, its closing ones along the short point edges. Split at creases (crease_deg < 180), a
// sheet that meets a truck's side at an angle is weighed on its own rim, not on the truck's.
int64_t DropOpenSteinerRegions(Mesh* m, double crease_deg) {
  const size_t nf = m->faces.size() / 3;
  std::vector<uint8_t> steiner(nf, 0);
  for (size_t f = 0; f < nf; ++f)
    for (int k = 0; k < 3; ++k) steiner[f] |= m->point_ids[m->faces[3 * f + k]] < 0 ? 1 : 0;
  // Each face's edges, grouped by their two vertices (dO can name an edge with four faces).
  struct HalfEdge {
    uint64_t key;
    uint32_t face;
  };
  std::vector<HalfEdge> edges;
  edges.reserve(3 * nf);
  for (size_t f = 0; f < nf; ++f)
    for (int k = 0; k < 3; ++k) {
      const uint64_t a = m->faces[3 * f + k], b = m->faces[3 * f + (k + 1) % 3];
      edges.push_back({std::min(a, b) << 32 | std::max(a, b), static_cast<uint32_t>(f)});
    }
  std::sort(edges.begin(), edges.end(), [](const HalfEdge& x, const HalfEdge& y) {
    return x.key != y.key ? x.key < y.key : x.face < y.face;
  });
  std::vector<uint32_t> region(nf);
  std::iota(region.begin(), region.end(), 0u);
  auto find = [&](uint32_t f) {
    while (region[f] != f) f = region[f] = region[region[f]];
    return f;
  };
  auto for_each_edge = [&](auto&& visit) {
    for (size_t b = 0, e = 0; b < edges.size(); b = e) {
      for (e = b + 1; e < edges.size() && edges[e].key == edges[b].key;) ++e;
      visit(b, e);
    }
  };
  // Unit normals of the Steiner faces, for the crease test (below 180 degrees only).
  const bool creases = crease_deg < 180.0;
  const double min_cos = std::cos(crease_deg * M_PI / 180.0);
  std::vector<Vec3> normal(creases ? nf : 0);
  auto corner = [&](size_t f, int k) {
    const double* p = &m->vertices[3 * static_cast<size_t>(m->faces[3 * f + k])];
    return Vec3{p[0], p[1], p[2]};
  };
  for (size_t f = 0; creases && f < nf; ++f) {
    if (!steiner[f]) continue;
    const Vec3 n = Cross(Sub(corner(f, 1), corner(f, 0)), Sub(corner(f, 2), corner(f, 0)));
    const double len = Norm(n);
    normal[f] = len > 0.0 ? Scale(n, 1.0 / len) : n;
  }
  auto joined = [&](uint32_t f, uint32_t g) { return !creases || Dot(normal[f], normal[g]) >= min_cos; };
  for_each_edge([&](size_t b, size_t e) {
    uint32_t first = nf;  // the group's first Steiner face
    for (size_t i = b; i < e; ++i) {
      const uint32_t f = edges[i].face;
      if (!steiner[f]) continue;
      if (first == nf) first = f;
      else if (joined(f, first)) region[find(f)] = find(first);
    }
  });
  // Per region: rim edges shared with a point triangle minus those bordering nothing or another
  // region.
  std::vector<int64_t> closing_minus_open(nf, 0);
  for_each_edge([&](size_t b, size_t e) {
    int steiner_faces = 0;
    for (size_t i = b; i < e; ++i) steiner_faces += steiner[edges[i].face];
    const bool point_face = steiner_faces < static_cast<int>(e - b);
    // A rim edge has one face of its region (an edge with two is inside it); split at a crease,
    // two regions can share an edge, each on its rim there.
    for (size_t i = b; i < e; ++i) {
      if (!steiner[edges[i].face]) continue;
      const uint32_t r = find(edges[i].face);
      int in_region = 0;
      for (size_t j = b; j < e; ++j) in_region += steiner[edges[j].face] && find(edges[j].face) == r;
      if (in_region == 1) closing_minus_open[r] += point_face ? 1 : -1;
    }
  });
  std::vector<uint32_t> kept;
  kept.reserve(m->faces.size());
  int64_t gone = 0;
  for (size_t f = 0; f < nf; ++f) {
    if (steiner[f] && closing_minus_open[find(static_cast<uint32_t>(f))] < 0) {
      ++gone;
      continue;
    }
    kept.insert(kept.end(), &m->faces[3 * f], &m->faces[3 * f] + 3);
  }
  if (gone > 0) KeepFaces(m, std::move(kept));
  return gone;
}

}  // namespace imr::engine
