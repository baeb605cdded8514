// RetriangulatePlanes: folds of a flat sheet are taken out, corners and boundaries stay, and the
// surface stays a manifold with the same boundary whatever the input.
#include "host/engine/plane_retriangulation.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <random>
#include <set>
#include <utility>

#include "host/engine/mesh_topology.h"

namespace imr::engine {
namespace {

// An n x n grid of vertices, two triangles per square, oriented as (i, j) -> x, y gives +z.
// `place(i, j)` gives vertex (i, j)'s position.
template <typename Place>
Mesh Grid(int n, Place place) {
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
      m.faces.insert(m.faces.end(), {a, b, d, a, d, c});
    }
  return m;
}

std::array<double, 3> Normal(const Mesh& m, std::size_t f) {
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
double Roughness(const Mesh& m) {
  std::map<std::pair<uint32_t, uint32_t>, std::vector<std::size_t>> edges;
  for (std::size_t f = 0; f < m.faces.size() / 3; ++f)
    for (int k = 0; k < 3; ++k) {
      uint32_t a = m.faces[3 * f + k], b = m.faces[3 * f + (k + 1) % 3];
      edges[{std::min(a, b), std::max(a, b)}].push_back(f);
    }
  double sum = 0.0;
  int count = 0;
  for (const auto& [e, fs] : edges) {
    if (fs.size() != 2) continue;
    const auto n = Normal(m, fs[0]), o = Normal(m, fs[1]);
    const double d = std::clamp(n[0] * o[0] + n[1] * o[1] + n[2] * o[2], -1.0, 1.0);
    sum += std::acos(d) * 180.0 / M_PI;
    ++count;
  }
  return count ? sum / count : 0.0;
}

// The directed boundary edges (one face).
std::set<std::pair<uint32_t, uint32_t>> Boundary(const Mesh& m) {
  std::set<std::pair<uint32_t, uint32_t>> directed;
  for (std::size_t f = 0; f < m.faces.size() / 3; ++f)
    for (int k = 0; k < 3; ++k) directed.emplace(m.faces[3 * f + k], m.faces[3 * f + (k + 1) % 3]);
  std::set<std::pair<uint32_t, uint32_t>> boundary;
  for (const auto& [a, b] : directed)
    if (!directed.count({b, a})) boundary.emplace(a, b);
  return boundary;
}

// A vertex's fan folded over: it moves past its neighbour along x, so its faces overlap theirs.
void Fold(Mesh* m, int n, int i, int j, double by) { m->vertices[3 * (j * n + i)] += by; }

TEST(PlaneRetriangulationTest, FoldsOfANoisyPlaneAreTakenOut) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> noise(-0.02, 0.02);
  const int n = 12;
  Mesh m = Grid(n, [&](int i, int j) { return std::array<double, 3>{double(i), double(j), noise(rng)}; });
  for (int j = 2; j < n - 2; j += 3)
    for (int i = 2; i < n - 2; i += 4) Fold(&m, n, i, j, 1.4);
  const Mesh before = m;
  const double rough_before = Roughness(m);
  ASSERT_GT(rough_before, 10.0);  // the folds are there

  PlaneRetriangulationOptions o;
  o.tolerance = 0.15;
  const PlaneRetriangulationStats s = RetriangulatePlanes(&m, o);
  EXPECT_GE(s.regions, 1);
  EXPECT_EQ(s.regions_refused, 0);
  const ManifoldCheckResult check = CheckMesh(m, /*closed=*/false);
  ASSERT_TRUE(check.ok) << check.message;
  EXPECT_EQ(m.faces.size(), before.faces.size());
  EXPECT_EQ(m.point_ids, before.point_ids);
  EXPECT_EQ(Boundary(m), Boundary(before));
  EXPECT_LT(Roughness(m), 3.0) << "before " << rough_before;
  for (std::size_t f = 0; f < m.faces.size() / 3; ++f) EXPECT_GT(Normal(m, f)[2], 0.99) << "face " << f;
  // Boundary vertices where they were; the others moved onto the plane, by at most the noise.
  std::set<uint32_t> on_boundary;
  for (const auto& [a, b] : Boundary(before)) on_boundary.insert(a);
  for (uint32_t v = 0; v < m.point_ids.size(); ++v) {
    if (on_boundary.count(v)) {
      for (int k = 0; k < 3; ++k) EXPECT_EQ(m.vertices[3 * v + k], before.vertices[3 * v + k]);
    } else {
      for (int k = 0; k < 2; ++k)  // along the plane's normal, close to z
        EXPECT_NEAR(m.vertices[3 * v + k], before.vertices[3 * v + k], 1e-3);
      EXPECT_LE(std::abs(m.vertices[3 * v + 2] - before.vertices[3 * v + 2]), 0.05);
    }
  }
  EXPECT_LE(s.max_move, 0.05);
}

TEST(PlaneRetriangulationTest, ACornerStaysACorner) {
  // A floor (z = 0, y in 0..5) and a wall (y = 5, z in 0..5) meeting along y = 5: one strip of
  // grid bent at a right angle, normals up and toward -y (one orientation throughout).
  const int n = 11;
  Mesh m = Grid(n, [&](int i, int j) {
    return j <= 5 ? std::array<double, 3>{double(i), double(j), 0.0}
                  : std::array<double, 3>{double(i), 5.0, double(j - 5)};
  });
  const Mesh before = m;
  PlaneRetriangulationOptions o;
  o.tolerance = 0.15;
  o.min_faces = 4;
  RetriangulatePlanes(&m, o);
  ASSERT_TRUE(CheckMesh(m, false).ok);
  EXPECT_EQ(Boundary(m), Boundary(before));
  // Every face lies in the floor or in the wall: none cuts across the corner.
  for (std::size_t f = 0; f < m.faces.size() / 3; ++f) {
    const auto nn = Normal(m, f);
    EXPECT_TRUE(nn[2] > 0.999 || nn[1] < -0.999) << "face " << f << " normal " << nn[0] << " " << nn[1] << " " << nn[2];
  }
  // The vertices of the corner's line are where they were.
  for (int i = 0; i < n; ++i)
    for (int k = 0; k < 3; ++k)
      EXPECT_EQ(m.vertices[3 * (5 * n + i) + k], before.vertices[3 * (5 * n + i) + k]);
}

TEST(PlaneRetriangulationTest, APartMovesOnlyVerticesWhoseWholeFanItHolds) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> noise(-0.02, 0.02);
  const int n = 10;
  const Mesh grid = Grid(n, [&](int i, int j) { return std::array<double, 3>{double(i), double(j), noise(rng)}; });
  // The part: the squares of the lower 6 rows (the others come in a later part).
  SurfacePart part;
  part.vertices = grid.vertices;
  part.point_ids = grid.point_ids;
  for (std::size_t v = 0; v < grid.point_ids.size(); ++v) part.keys.push_back(static_cast<int64_t>(100 + v));
  const std::size_t squares_per_row = n - 1;
  part.faces.assign(grid.faces.begin(), grid.faces.begin() + 6 * 6 * squares_per_row);
  part.vertices[3 * (3 * n + 4)] += 1.4;  // a fold inside the part
  const SurfacePart before = part;

  PlaneRetriangulationOptions o;
  o.tolerance = 0.15;
  const PlaneRetriangulationStats s = RetriangulatePlanes(&part, o);
  EXPECT_GE(s.regions, 1);
  EXPECT_EQ(part.keys, before.keys);
  EXPECT_EQ(part.point_ids, before.point_ids);
  EXPECT_EQ(part.faces.size(), before.faces.size());
  // Row 6 (the seam with the later part) and the rows above: not moved, bit for bit.
  for (std::size_t v = 6 * n; v < grid.point_ids.size(); ++v)
    for (int k = 0; k < 3; ++k) EXPECT_EQ(part.vertices[3 * v + k], before.vertices[3 * v + k]) << v;
  Mesh m;
  m.vertices = part.vertices;
  m.faces = part.faces;
  m.point_ids = part.point_ids;
  Mesh b;
  b.vertices = before.vertices;
  b.faces = before.faces;
  b.point_ids = before.point_ids;
  EXPECT_TRUE(CheckMesh(m, false).ok);
  EXPECT_EQ(Boundary(m), Boundary(b));
  EXPECT_LT(Roughness(m), 3.0);
}

// The property: on 1,000 random perturbations (noise, folds, spikes, holes, bent sheets,
// tolerances) the result is a manifold with the same boundary edges, the same vertices, and only
// inside vertices moved, each by at most the tolerance.
TEST(PlaneRetriangulationTest, AnyInputStaysAManifoldWithTheSameBoundary) {
  std::mt19937 rng(2026);
  int changed = 0;
  for (int trial = 0; trial < 1000; ++trial) {
    const int n = 4 + static_cast<int>(rng() % 7);
    std::uniform_real_distribution<double> noise(0.0, 0.2);
    const double amplitude = noise(rng);
    const double bend = (rng() % 3 == 0) ? 0.0 : std::uniform_real_distribution<double>(0.0, 1.5)(rng);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    Mesh m = Grid(n, [&](int i, int j) {
      const double x = i, y = j;
      return std::array<double, 3>{x, y, amplitude * u(rng) + (x > n / 2 ? bend * (x - n / 2) : 0.0)};
    });
    const int folds = static_cast<int>(rng() % 4);
    for (int f = 0; f < folds && n > 2; ++f) {
      const int i = 1 + static_cast<int>(rng() % (n - 2)), j = 1 + static_cast<int>(rng() % (n - 2));
      m.vertices[3 * (j * n + i)] += u(rng) * 2.0;
      m.vertices[3 * (j * n + i) + 1] += u(rng) * 2.0;
    }
    // Spikes: vertices far off the sheet, whose fans no region takes (two side by side make
    // regions whose loops touch at a vertex).
    const int spikes = static_cast<int>(rng() % 6);
    for (int k = 0; k < spikes && n > 2; ++k) {
      const int i = 1 + static_cast<int>(rng() % (n - 2)), j = 1 + static_cast<int>(rng() % (n - 2));
      m.vertices[3 * (j * n + i) + 2] += 3.0 * u(rng);
    }
    // Holes, and loops that touch at a vertex: faces taken out at random (an input that is not
    // a manifold any more is skipped).
    const int holes = static_cast<int>(rng() % 4) * (rng() % 2);
    for (int h = 0; h < holes && m.faces.size() > 6; ++h) {
      const std::size_t f = rng() % (m.faces.size() / 3);
      m.faces.erase(m.faces.begin() + 3 * f, m.faces.begin() + 3 * f + 3);
    }
    if (!CheckMesh(m, false).ok) continue;
    const Mesh before = m;
    PlaneRetriangulationOptions o;
    o.tolerance = std::uniform_real_distribution<double>(0.05, 0.6)(rng);
    o.min_faces = 1 + static_cast<int>(rng() % 10);
    const PlaneRetriangulationStats s = RetriangulatePlanes(&m, o);
    if (s.regions > 0) ++changed;
    const ManifoldCheckResult check = CheckMesh(m, false);
    ASSERT_TRUE(check.ok) << "trial " << trial << ": " << check.message;
    ASSERT_EQ(Boundary(m), Boundary(before)) << "trial " << trial;
    ASSERT_EQ(m.faces.size(), before.faces.size()) << "trial " << trial;
    ASSERT_EQ(m.point_ids, before.point_ids);
    std::set<uint32_t> on_boundary;
    for (const auto& [a, b] : Boundary(before)) on_boundary.insert(a);
    for (uint32_t v = 0; v < m.point_ids.size(); ++v) {
      double d2 = 0.0;
      for (int k = 0; k < 3; ++k) d2 += std::pow(m.vertices[3 * v + k] - before.vertices[3 * v + k], 2);
      if (on_boundary.count(v)) {
        ASSERT_EQ(d2, 0.0) << "trial " << trial << " vertex " << v;
      }
      ASSERT_LE(std::sqrt(d2), s.max_move + 1e-12);
    }
  }
  EXPECT_GT(changed, 300);  // the property is tested where the pass did something
  EXPECT_GT(changed, 300);  // the property is tested where the pass did something
}

// A streamed surface is retriangulated part by part: two parts, each done alone, still make a
// manifold with the first's boundary together (no vertex moved by both, no edge made twice).
TEST(PlaneRetriangulationTest, PartsDoneOneByOneStillFitTogether) {
  std::mt19937 rng(45);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  int changed = 0;
  for (int trial = 0; trial < 1000; ++trial) {
    const int n = 5 + static_cast<int>(rng() % 8);
    const double amplitude = 0.05 * (1.0 + u(rng));
    Mesh m = Grid(n, [&](int i, int j) { return std::array<double, 3>{double(i), double(j), amplitude * u(rng)}; });
    for (int f = 0, folds = static_cast<int>(rng() % 4); f < folds; ++f) {
      const int i = 1 + static_cast<int>(rng() % (n - 2)), j = 1 + static_cast<int>(rng() % (n - 2));
      m.vertices[3 * (j * n + i)] += 1.5 * u(rng);
      m.vertices[3 * (j * n + i) + 1] += 1.5 * u(rng);
    }
    // Spikes: holes in the regions, whose loops may touch at a vertex.
    for (int k = 0, spikes = static_cast<int>(rng() % 8); k < spikes; ++k) {
      const int i = 1 + static_cast<int>(rng() % (n - 2)), j = 1 + static_cast<int>(rng() % (n - 2));
      m.vertices[3 * (j * n + i) + 2] += 2.0 * u(rng);
    }
    // Two parts cut by a random line through the grid (faces by their first vertex).
    const double angle = M_PI * u(rng), c = 0.5 * n * (1.0 + 0.5 * u(rng));
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
    PlaneRetriangulationOptions o;
    o.tolerance = 0.1 + 0.3 * (1.0 + u(rng));
    o.min_faces = 2;
    Mesh merged = m;
    merged.faces.clear();
    for (SurfacePart& p : parts) {
      if (RetriangulatePlanes(&p, o).regions > 0) ++changed;
      merged.faces.insert(merged.faces.end(), p.faces.begin(), p.faces.end());
    }
    for (std::size_t k = 0; k < m.vertices.size(); ++k) {
      const bool moved0 = parts[0].vertices[k] != m.vertices[k], moved1 = parts[1].vertices[k] != m.vertices[k];
      ASSERT_FALSE(moved0 && moved1) << "trial " << trial << ": a vertex moved by both parts";
      merged.vertices[k] = moved0 ? parts[0].vertices[k] : parts[1].vertices[k];
    }
    const ManifoldCheckResult check = CheckMesh(merged, false);
    ASSERT_TRUE(check.ok) << "trial " << trial << ": " << check.message;
    ASSERT_EQ(Boundary(merged), Boundary(m)) << "trial " << trial;
  }
  EXPECT_GT(changed, 300);
}

// Two pieces of imr-synth's default job's surface stream (releases 25 and 26, cut around the
// vertex in question): a region's loop passed a seam vertex twice, and in the plane the order of
// its edges paired its wedges otherwise than the surface: each piece a manifold, the two together
// not ("vertex 40321 is not one fan"). The random cuts above never made that shape (30,000 of
// them tried without the rule).
TEST(PlaneRetriangulationTest, ALoopThatPassesASeamVertexTwiceIsNotTriangulatedAcrossIt) {
  std::ifstream in(std::string(IMR_SOURCE_DIR) + "/host/engine/testing/pinched_seam_parts.txt");
  ASSERT_TRUE(in) << "host/engine/testing/pinched_seam_parts.txt";
  std::vector<SurfacePart> parts;
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream head(line);
    std::string word;
    std::size_t nv = 0, nf = 0;
    head >> word >> nv >> nf;
    ASSERT_EQ(word, "part");
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
    std::getline(in, line);
    parts.push_back(std::move(p));
  }
  ASSERT_EQ(parts.size(), 2u);
  // The two pieces alone are not a closed-up surface (their neighbours are missing), so the test
  // is per vertex: every vertex whose faces in the two make one fan still does, and no directed
  // edge repeats.
  auto shapes = [](const std::vector<SurfacePart>& ps) {
    Mesh m;
    EXPECT_EQ(MergeSurfaceParts(ps, &m), "");
    std::vector<std::vector<std::pair<uint32_t, uint32_t>>> links(m.point_ids.size());
    std::set<std::pair<uint32_t, uint32_t>> directed;
    for (std::size_t f = 0; f < m.faces.size(); f += 3)
      for (int k = 0; k < 3; ++k) {
        links[m.faces[f + k]].emplace_back(m.faces[f + (k + 1) % 3], m.faces[f + (k + 2) % 3]);
        EXPECT_TRUE(directed.emplace(m.faces[f + k], m.faces[f + (k + 1) % 3]).second);
      }
    std::vector<std::pair<uint32_t, uint32_t>> by_first;
    std::vector<uint32_t> seconds;
    std::map<int64_t, LinkShape> shape;  // by key
    std::map<int64_t, uint32_t> index;
    for (const SurfacePart& p : ps)
      for (std::size_t i = 0; i < p.keys.size(); ++i) index.emplace(p.keys[i], static_cast<uint32_t>(index.size()));
    for (const auto& [key, v] : index)
      if (!links[v].empty()) shape[key] = CheckLink(links[v].data(), links[v].size(), &by_first, &seconds);
    return shape;
  };
  const std::map<int64_t, LinkShape> before = shapes(parts);
  PlaneRetriangulationOptions o;
  o.tolerance = 0.1;  // the default job's
  int64_t regions = 0;
  for (SurfacePart& p : parts) regions += RetriangulatePlanes(&p, o).regions;
  EXPECT_GT(regions, 0);
  const std::map<int64_t, LinkShape> after = shapes(parts);
  int64_t one_fan = 0;
  for (const auto& [key, shape] : before) {
    if (shape == LinkShape::kNotOneFan) continue;
    ++one_fan;
    EXPECT_NE(after.at(key), LinkShape::kNotOneFan) << "vertex key " << key;
  }
  EXPECT_GT(one_fan, 1000);
}

TEST(PlaneRetriangulationTest, OptionsAreChecked) {
  PlaneRetriangulationOptions o;
  EXPECT_EQ(o.Check(), "");
  EXPECT_FALSE(o.enabled());
  o.tolerance = -1.0;
  EXPECT_NE(o.Check().find("tolerance"), std::string::npos);
  o.tolerance = 0.1;
  o.min_faces = 0;
  EXPECT_NE(o.Check().find("min_faces"), std::string::npos);
}

}  // namespace
}  // namespace imr::engine
