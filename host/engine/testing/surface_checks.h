// Test support for the passes that change an exported surface (plane_retriangulation,
// edge_flips, normal_filter): grids, random sheets, face normals, roughness, the directed
// boundary, and the real seam fixture (pinched_seam_parts.txt: two released pieces of
// imr-synth's default job) with each vertex's fan shape across the pieces, before and after a
// pass.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <fstream>
#include <map>
#include <random>
#include <set>
#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "host/engine/engine.h"
#include "host/engine/mesh_topology.h"

namespace imr::engine::testing {

// An n x n grid of vertices placed by `place(i, j)` (point id j * n + i), two triangles per
// square, oriented +z for a flat grid; `along(i, j)`: the square's diagonal from (i, j) to
// (i + 1, j + 1), else the other.
template <typename Place, typename Along>
Mesh Grid(int n, Place place, Along along) {
  Mesh m;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const std::array<double, 3> p = place(i, j);
      m.vertices.insert(m.vertices.end(), p.begin(), p.end());
      m.point_ids.push_back(j * n + i);
    }
  for (int j = 0; j + 1 < n; ++j)
    for (int i = 0; i + 1 < n; ++i) {
      const uint32_t a = j * n + i, b = a + 1, c = a + n, d = c + 1;
      if (along(i, j))
        m.faces.insert(m.faces.end(), {a, b, d, a, d, c});
      else
        m.faces.insert(m.faces.end(), {a, b, c, b, d, c});
    }
  return m;
}
template <typename Place>
Mesh Grid(int n, Place place) {
  return Grid(n, place, [](int, int) { return true; });
}

// A random n x n sheet: noise, spikes, folds, holes, bends; not always a manifold (callers skip
// those: CheckMesh).
inline Mesh RandomSheet(std::mt19937& rng, int n) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const double amplitude = 0.2 * (1.0 + u(rng));
  const double bend = (rng() % 3 == 0) ? 0.0 : 0.75 * (1.0 + u(rng));
  Mesh m = Grid(
      n,
      [&](int i, int j) {
        const double x = i, y = j;
        return std::array<double, 3>{x, y, amplitude * u(rng) + (x > n / 2 ? bend * (x - n / 2) : 0.0)};
      },
      [&](int, int) { return rng() % 2 == 0; });
  for (int f = 0, folds = static_cast<int>(rng() % 4); f < folds; ++f) {
    const int i = 1 + static_cast<int>(rng() % (n - 2)), j = 1 + static_cast<int>(rng() % (n - 2));
    m.vertices[3 * (j * n + i)] += u(rng) * 2.0;
    m.vertices[3 * (j * n + i) + 1] += u(rng) * 2.0;
  }
  for (int k = 0, spikes = static_cast<int>(rng() % 6); k < spikes; ++k) {
    const int i = 1 + static_cast<int>(rng() % (n - 2)), j = 1 + static_cast<int>(rng() % (n - 2));
    m.vertices[3 * (j * n + i) + 2] += 3.0 * u(rng);
  }
  for (int h = 0, holes = static_cast<int>(rng() % 4) * static_cast<int>(rng() % 2); h < holes && m.faces.size() > 6; ++h) {
    const std::size_t f = rng() % (m.faces.size() / 3);
    m.faces.erase(m.faces.begin() + 3 * static_cast<std::ptrdiff_t>(f), m.faces.begin() + 3 * static_cast<std::ptrdiff_t>(f) + 3);
  }
  return m;
}

// The unit normal of face f (counter-clockwise).
inline std::array<double, 3> FaceNormal(const Mesh& m, std::size_t f) {
  const double* a = &m.vertices[3 * m.faces[3 * f]];
  const double* b = &m.vertices[3 * m.faces[3 * f + 1]];
  const double* c = &m.vertices[3 * m.faces[3 * f + 2]];
  const double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
  const double w[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
  std::array<double, 3> n = {u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]};
  const double l = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
  for (double& x : n) x /= l;
  return n;
}

// Mean angle (degrees) between the normals of faces sharing an edge.
inline double Roughness(const Mesh& m) {
  std::map<std::pair<uint32_t, uint32_t>, std::vector<std::size_t>> edges;
  for (std::size_t f = 0; f < m.faces.size() / 3; ++f)
    for (int k = 0; k < 3; ++k) {
      const uint32_t a = m.faces[3 * f + k], b = m.faces[3 * f + (k + 1) % 3];
      edges[{std::min(a, b), std::max(a, b)}].push_back(f);
    }
  double sum = 0.0;
  int count = 0;
  for (const auto& [e, fs] : edges) {
    if (fs.size() != 2) continue;
    const auto n = FaceNormal(m, fs[0]), o = FaceNormal(m, fs[1]);
    sum += std::acos(std::clamp(n[0] * o[0] + n[1] * o[1] + n[2] * o[2], -1.0, 1.0)) * 180.0 / M_PI;
    ++count;
  }
  return count ? sum / count : 0.0;
}

// The directed boundary edges (those of one face).
inline std::set<std::pair<uint32_t, uint32_t>> Boundary(const Mesh& m) {
  std::set<std::pair<uint32_t, uint32_t>> directed;
  for (std::size_t f = 0; f < m.faces.size() / 3; ++f)
    for (int k = 0; k < 3; ++k) directed.emplace(m.faces[3 * f + k], m.faces[3 * f + (k + 1) % 3]);
  std::set<std::pair<uint32_t, uint32_t>> boundary;
  for (const auto& [a, b] : directed)
    if (!directed.count({b, a})) boundary.emplace(a, b);
  return boundary;
}

// `m` in two parts cut by the line x cos(angle) + y sin(angle) = c (a face by its first vertex),
// each with every vertex of `m`, keyed by index: as a SurfaceStream may release a grid.
inline std::vector<SurfacePart> CutInTwo(const Mesh& m, double angle, double c) {
  std::vector<SurfacePart> parts(2);
  for (SurfacePart& p : parts) {
    p.vertices = m.vertices;
    p.point_ids = m.point_ids;
    for (std::size_t v = 0; v < m.point_ids.size(); ++v) p.keys.push_back(static_cast<int64_t>(v));
  }
  for (std::size_t f = 0; f < m.faces.size() / 3; ++f) {
    const double* a = &m.vertices[3 * m.faces[3 * f]];
    const int side = a[0] * std::cos(angle) + a[1] * std::sin(angle) < c ? 0 : 1;
    parts[side].faces.insert(parts[side].faces.end(), &m.faces[3 * f], &m.faces[3 * f] + 3);
  }
  return parts;
}

// The parts of a fixture file: "part NV NF" lines, then NV lines "key id x y z", then 3 NF
// vertex indices; '#' lines are comments. Throws std::runtime_error naming the file.
inline std::vector<SurfacePart> ReadSurfaceParts(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path + ": cannot open");
  std::vector<SurfacePart> parts;
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream head(line);
    std::string word;
    std::size_t nv = 0, nf = 0;
    head >> word >> nv >> nf;
    if (word != "part") throw std::runtime_error(path + ": expected 'part NV NF', got '" + line + "'");
    SurfacePart p;
    for (std::size_t i = 0; i < nv; ++i) {
      int64_t key = 0, id = 0;
      double x = 0, y = 0, z = 0;
      in >> key >> id >> x >> y >> z;
      p.keys.push_back(key);
      p.point_ids.push_back(id);
      p.vertices.insert(p.vertices.end(), {x, y, z});
    }
    for (std::size_t i = 0; i < 3 * nf; ++i) {
      uint32_t v = 0;
      in >> v;
      p.faces.push_back(v);
    }
    if (!in) throw std::runtime_error(path + ": a part cut short");
    std::getline(in, line);
    parts.push_back(std::move(p));
  }
  return parts;
}

// The parts merged by key: per vertex key, the shape of its faces' link across them; `error`
// gets MergeSurfaceParts's message, or a directed edge that repeats.
inline std::map<int64_t, LinkShape> LinkShapesByKey(const std::vector<SurfacePart>& parts, std::string* error) {
  Mesh m;
  *error = MergeSurfaceParts(parts, &m);
  std::vector<std::vector<std::pair<uint32_t, uint32_t>>> links(m.point_ids.size());
  std::set<std::pair<uint32_t, uint32_t>> directed;
  for (std::size_t f = 0; f < m.faces.size(); f += 3)
    for (int k = 0; k < 3; ++k) {
      links[m.faces[f + k]].emplace_back(m.faces[f + (k + 1) % 3], m.faces[f + (k + 2) % 3]);
      if (!directed.emplace(m.faces[f + k], m.faces[f + (k + 1) % 3]).second && error->empty())
        *error = "a directed edge repeats";
    }
  std::vector<std::pair<uint32_t, uint32_t>> by_first;
  std::vector<uint32_t> seconds;
  std::map<int64_t, uint32_t> index;  // MergeSurfaceParts numbers keys in order of appearance
  for (const SurfacePart& p : parts)
    for (std::size_t i = 0; i < p.keys.size(); ++i) index.emplace(p.keys[i], static_cast<uint32_t>(index.size()));
  std::map<int64_t, LinkShape> shape;
  for (const auto& [key, v] : index)
    if (v < links.size() && !links[v].empty()) shape[key] = CheckLink(links[v].data(), links[v].size(), &by_first, &seconds);
  return shape;
}

// Parts of a stream cut around a vertex, each put through `pass` alone (fn(SurfacePart*)): the
// vertex keys whose faces made one fan across the parts before and do not after, how many made
// one fan before, and LinkShapesByKey's message before or after. (The pieces alone are not a
// closed-up surface, their neighbours are missing: so the check is per vertex.)
struct FansAfterPass {
  int64_t one_fan = 0;
  std::vector<int64_t> broken;
  std::string error;
};
template <typename Pass>
FansAfterPass FansAfter(std::vector<SurfacePart>& parts, Pass pass) {
  FansAfterPass out;
  std::string error;
  const std::map<int64_t, LinkShape> before = LinkShapesByKey(parts, &error);
  if (!error.empty()) out.error = "before: " + error;
  for (SurfacePart& p : parts) pass(&p);
  const std::map<int64_t, LinkShape> after = LinkShapesByKey(parts, &error);
  if (!error.empty() && out.error.empty()) out.error = "after: " + error;
  for (const auto& [key, shape] : before) {
    if (shape == LinkShape::kNotOneFan) continue;
    ++out.one_fan;
    if (after.at(key) == LinkShape::kNotOneFan) out.broken.push_back(key);
  }
  return out;
}

}  // namespace imr::engine::testing
