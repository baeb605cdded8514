// Remesh keeps a 2-manifold with the same boundary, leaves FIXED (locked) vertices' faces alone,
// never folds, keeps creases, and does lower the dihedral angles where the triangulation cuts
// across the surface.
#include "remesh.hpp"

#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <map>
#include <random>
#include <set>

namespace imr::photometric {
namespace {

using Vec3 = Eigen::Vector3d;
using Face = std::array<uint32_t, 3>;
using Faces = std::vector<Face>;

Vec3 Normal(const std::vector<Vec3>& p, const Face& f) {
  return (p[f[1]] - p[f[0]]).cross(p[f[2]] - p[f[0]]).normalized();
}

// Empty when `faces` is an oriented 2-manifold with boundary (every directed edge once, every
// vertex's link one path or one cycle), else what is wrong.
std::string ManifoldError(std::size_t n, const Faces& faces) {
  std::set<std::pair<uint32_t, uint32_t>> directed;
  std::vector<std::map<uint32_t, uint32_t>> link(n);  // v: next -> prev around v
  for (const Face& f : faces) {
    if (f[0] == f[1] || f[1] == f[2] || f[2] == f[0]) return "a degenerate face";
    for (int k = 0; k < 3; ++k) {
      if (f[k] >= n) return "an index out of range";
      if (!directed.insert({f[k], f[(k + 1) % 3]}).second) return "a directed edge twice";
      if (!link[f[k]].emplace(f[(k + 1) % 3], f[(k + 2) % 3]).second)
        return "vertex " + std::to_string(f[k]) + " is not one fan";
    }
  }
  for (std::size_t v = 0; v < n; ++v) {
    const auto& l = link[v];
    if (l.empty()) continue;
    std::set<uint32_t> seconds;
    for (const auto& [a, b] : l)
      if (!seconds.insert(b).second) return "vertex " + std::to_string(v) + " is not one fan";
    uint32_t start = l.begin()->first;
    int starts = 0;
    for (const auto& [a, b] : l)
      if (!seconds.count(a)) start = a, ++starts;
    if (starts > 1) return "vertex " + std::to_string(v) + " is not one fan";
    std::size_t steps = 0;
    for (uint32_t cur = start; l.count(cur) && steps <= l.size();) {
      cur = l.at(cur);
      ++steps;
      if (cur == start) break;
    }
    if (steps != l.size()) return "vertex " + std::to_string(v) + " is not one fan";
  }
  return "";
}

std::set<std::pair<uint32_t, uint32_t>> BoundaryEdges(const Faces& faces) {
  std::set<std::pair<uint32_t, uint32_t>> directed, boundary;
  for (const Face& f : faces)
    for (int k = 0; k < 3; ++k) directed.insert({f[k], f[(k + 1) % 3]});
  for (const auto& [a, b] : directed)
    if (!directed.count({b, a})) boundary.insert({a, b});
  return boundary;
}

// A face up to rotation (orientation kept).
Face Canonical(Face f) {
  std::rotate(f.begin(), std::min_element(f.begin(), f.end()), f.end());
  return f;
}

std::set<Face> FacesOf(uint32_t v, const Faces& faces) {
  std::set<Face> out;
  for (const Face& f : faces)
    if (f[0] == v || f[1] == v || f[2] == v) out.insert(Canonical(f));
  return out;
}

bool HasEdge(const Faces& faces, uint32_t a, uint32_t b) {
  for (const Face& f : faces)
    for (int k = 0; k < 3; ++k)
      if ((f[k] == a && f[(k + 1) % 3] == b) || (f[k] == b && f[(k + 1) % 3] == a)) return true;
  return false;
}

// An nx x ny grid of cells: vertex (i, j) at index j * (nx + 1) + i, each cell cut along a
// random diagonal, faces counter-clockwise seen from +z. `skip(i, j)`: the cell is a hole.
template <class Skip>
Faces GridFaces(int nx, int ny, std::mt19937& rng, const Skip& skip) {
  Faces faces;
  std::bernoulli_distribution coin(0.5);
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i) {
      if (skip(i, j)) continue;
      const uint32_t a = j * (nx + 1) + i, b = a + 1, c = a + nx + 2, d = a + nx + 1;
      if (coin(rng)) {
        faces.push_back({a, b, c});
        faces.push_back({a, c, d});
      } else {
        faces.push_back({a, b, d});
        faces.push_back({b, c, d});
      }
    }
  return faces;
}

TEST(Remesh, KeepsManifoldBoundaryAndFixedVerticesOnAThousandRandomMeshes) {
  std::mt19937 rng(45);
  int64_t flips = 0, splits = 0, creases = 0, refused = 0;
  for (int trial = 0; trial < 1000; ++trial) {
    SCOPED_TRACE("trial " + std::to_string(trial));
    const int nx = std::uniform_int_distribution<int>(3, 10)(rng);
    const int ny = std::uniform_int_distribution<int>(3, 10)(rng);
    const double jitter = std::uniform_real_distribution<double>(0.0, 0.35)(rng);
    const double relief = std::uniform_real_distribution<double>(0.0, 0.8)(rng);
    std::uniform_real_distribution<double> unit(-1.0, 1.0);
    std::vector<Vec3> p;
    for (int j = 0; j <= ny; ++j)
      for (int i = 0; i <= nx; ++i)
        p.emplace_back(i + jitter * unit(rng), j + jitter * unit(rng), relief * unit(rng));
    // A hole in one inner cell now and then: a second boundary loop.
    const int hx = nx >= 3 && trial % 3 == 0 ? std::uniform_int_distribution<int>(1, nx - 2)(rng) : -1;
    const int hy = std::uniform_int_distribution<int>(1, ny - 2)(rng);
    const Faces before = GridFaces(nx, ny, rng, [&](int i, int j) { return i == hx && j == hy; });
    ASSERT_EQ(ManifoldError(p.size(), before), "");
    std::vector<uint8_t> locked(p.size(), 0);
    std::bernoulli_distribution fixed(std::uniform_real_distribution<double>(0.0, 0.3)(rng));
    for (auto& l : locked) l = fixed(rng) ? 1 : 0;
    RemeshOptions o;
    o.max_edge = trial % 2 == 0 ? 0.0 : std::uniform_real_distribution<double>(0.9, 1.6)(rng);
    o.corner_deg = std::uniform_real_distribution<double>(30.0, 120.0)(rng);
    ASSERT_TRUE(o.Check(nullptr));

    const std::vector<Vec3> p0 = p;
    const std::vector<uint8_t> locked0 = locked;
    Faces faces = before;
    std::vector<std::array<uint32_t, 2>> parents;
    const RemeshStats s = Remesh(o, {}, &p, &faces, &locked, &parents);
    flips += s.edges_flipped, splits += s.edges_split, creases += s.creases_kept, refused += s.flips_refused;

    ASSERT_EQ(ManifoldError(p.size(), faces), "");
    ASSERT_EQ(p.size(), p0.size() + parents.size());
    ASSERT_EQ(locked.size(), p.size());
    EXPECT_EQ(BoundaryEdges(faces), BoundaryEdges(before));  // the same loops, the same vertices
    for (std::size_t v = 0; v < p0.size(); ++v) {
      ASSERT_EQ(p[v], p0[v]) << "vertex " << v << " moved";
      if (locked0[v]) {
        ASSERT_EQ(FacesOf(v, faces), FacesOf(v, before)) << "locked vertex " << v;
      }
    }
    for (std::size_t i = 0; i < parents.size(); ++i)
      ASSERT_EQ(p[p0.size() + i], 0.5 * (p[parents[i][0]] + p[parents[i][1]]));  // a midpoint
    if (o.max_edge == 0.0) {
      EXPECT_LE(s.total_dihedral_after, s.total_dihedral_before + 1e-9);
    }

    // No fold: each new face's normal within 90 degrees of the old faces around its corners (a
    // midpoint stands for its edge's ends).
    std::vector<Vec3> old_around(p.size(), Vec3::Zero());
    for (const Face& f : before)
      for (uint32_t v : f) old_around[v] += Normal(p0, f);
    for (std::size_t i = 0; i < parents.size(); ++i)
      old_around[p0.size() + i] = old_around[parents[i][0]] + old_around[parents[i][1]];
    std::set<Face> old_faces;
    for (const Face& f : before) old_faces.insert(Canonical(f));
    for (const Face& f : faces) {
      if (old_faces.count(Canonical(f))) continue;  // not new
      const Vec3 around = old_around[f[0]] + old_around[f[1]] + old_around[f[2]];
      ASSERT_GT(Normal(p, f).dot(around.normalized()), 0.0)
          << "face " << f[0] << " " << f[1] << " " << f[2] << " folded";
    }
  }
  // The guards were exercised, not vacuous.
  EXPECT_GT(flips, 1000);
  EXPECT_GT(splits, 100);
  EXPECT_GT(creases, 0);
  EXPECT_GT(refused, 0);
}

// A roof whose ridge runs along x = y, every cell cut across it: the flips put the ridge back,
// and every face then lies on the roof, unless a camera that saw the cut faces' front would see
// a new face's back.
TEST(Remesh, FlipsTriangulationBackOntoARidge) {
  const int n = 8;
  std::vector<Vec3> p;
  auto roof = [](double x, double y) { return -0.25 * std::abs(x - y); };
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) p.emplace_back(i, j, roof(i, j));
  Faces faces;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const uint32_t a = j * (n + 1) + i, b = a + 1, c = a + n + 2, d = a + n + 1;
      faces.push_back({a, b, d});  // the diagonal b-d: across the ridge on cells i == j
      faces.push_back({b, c, d});
    }
  auto off_roof = [&](const Faces& fs) {
    double worst = 0;
    for (const Face& f : fs) {
      const Vec3 c = (p[f[0]] + p[f[1]] + p[f[2]]) / 3.0;
      worst = std::max(worst, std::abs(c.z() - roof(c.x(), c.y())));
    }
    return worst;
  };
  ASSERT_GT(off_roof(faces), 0.05);
  // A camera low over the ridge's side, (-1, 1, 0.2) from it: it sees both faces of each ridge
  // cell from the front, and one of the roof's planes from behind. Its view is kept.
  const Faces across = faces;
  std::vector<uint8_t> locked;
  const Vec3 centre(n / 2.0, n / 2.0, 0.0);
  const std::vector<Viewpoint> grazing = {{centre + 100 * Vec3(-1, 1, 0.2), 1e9}};
  const RemeshStats kept = Remesh(RemeshOptions{}, grazing, &p, &faces, &locked);
  EXPECT_EQ(kept.edges_flipped, 0);
  EXPECT_EQ(kept.flips_facing_away, n);
  EXPECT_EQ(faces, across);
  // Out of its range (or from above), the flips happen.
  const std::vector<Viewpoint> far = {{centre + 100 * Vec3(-1, 1, 0.2), 50.0}, {centre + Vec3(0, 0, 10), 1e9}};
  const RemeshStats s = Remesh(RemeshOptions{}, far, &p, &faces, &locked);
  EXPECT_EQ(s.edges_flipped, n);
  EXPECT_LT(off_roof(faces), 1e-12);
  EXPECT_LT(s.total_dihedral_after, 0.5 * s.total_dihedral_before);
  EXPECT_EQ(ManifoldError(p.size(), faces), "");
}

// A plane with a 1 m step (a 90-degree crease at its foot and at its top), noisy and cut along
// random diagonals: after remeshing, the crease edges are all there and no face cuts the corner
// (spans the wall's foot and its top plane, or its top and the lower plane). At this noise (0.1 m
// on 0.5 m cells) the dihedral objective alone would cut corners: the crease rule keeps them.
TEST(Remesh, KeepsTheCornersOfANoisyStep) {
  std::mt19937 rng(7);
  std::normal_distribution<double> noise(0.0, 0.1);
  const int columns = 12, rows = 9;  // columns 0-5 on z = 0 (x 0..2.5), 6-11 on z = 1
  int64_t flips = 0;
  for (int trial = 0; trial < 20; ++trial) {
    std::vector<Vec3> p;
    for (int j = 0; j < rows; ++j)
      for (int u = 0; u < columns; ++u) {
        const double x = u <= 5 ? 0.5 * u : 2.5 + 0.5 * (u - 6);
        p.emplace_back(x + noise(rng), 0.5 * j + noise(rng), (u <= 5 ? 0.0 : 1.0) + noise(rng));
      }
    Faces faces = GridFaces(columns - 1, rows - 1, rng, [](int, int) { return false; });
    auto column = [&](uint32_t v) { return static_cast<int>(v % columns); };
    RemeshOptions o;
    o.max_edge = 0.0;
    std::vector<uint8_t> locked;
    const RemeshStats s = Remesh(o, {}, &p, &faces, &locked);
    flips += s.edges_flipped;
    ASSERT_EQ(ManifoldError(p.size(), faces), "");
    for (int j = 0; j + 1 < rows; ++j)
      for (int u : {5, 6})
        EXPECT_TRUE(HasEdge(faces, j * columns + u, (j + 1) * columns + u))
            << "trial " << trial << ": crease edge at column " << u << ", row " << j << " gone";
    for (const Face& f : faces) {
      const int lo = std::min({column(f[0]), column(f[1]), column(f[2])});
      const int hi = std::max({column(f[0]), column(f[1]), column(f[2])});
      EXPECT_FALSE((lo <= 4 && hi >= 6) || (lo <= 5 && hi >= 7))
          << "trial " << trial << ": a face across the corner, columns " << lo << "-" << hi;
    }
  }
  EXPECT_GT(flips, 0);  // the planes' noise did get flipped: the corners were not kept by idleness
}

// A fold: a flat grid where one vertex was pushed across an edge of its link (as a noisy point
// between its neighbours leaves the carving's sheet turned back on itself): the face of its fan
// on that edge faces down, overlapping the face beyond. With fold_deg below their angle the flips take the
// fold out (no face down, a manifold with the same boundary); without (180) the folds are
// creases and stay.
TEST(Remesh, FlipsAFoldOutOfAFlatSheet) {
  const int n = 6;
  auto make = [&](std::vector<Vec3>* p, Faces* faces) {
    p->clear();
    for (int j = 0; j <= n; ++j)
      for (int i = 0; i <= n; ++i) p->emplace_back(i, j, 0.0);
    faces->clear();
    for (int j = 0; j < n; ++j)  // every cell split along (i, j)-(i+1, j+1)
      for (int i = 0; i < n; ++i) {
        const uint32_t a = j * (n + 1) + i, b = a + 1, c = a + n + 2, d = a + n + 1;
        faces->push_back({a, b, c});
        faces->push_back({a, c, d});
      }
    // Vertex (3, 3) pushed across its link's edge (4, 3)-(4, 4), into the face beyond, 1 cm up:
    // its face on that edge turns over onto that face.
    (*p)[3 * (n + 1) + 3] = Vec3(4.2, 3.5, 0.01);
  };
  auto down = [](const std::vector<Vec3>& p, const Faces& fs) {
    int count = 0;
    for (const Face& f : fs) count += Normal(p, f).z() < 0 ? 1 : 0;
    return count;
  };
  const std::vector<Viewpoint> above = {{Vec3(n / 2.0, n / 2.0, 10.0), 1e9}};
  std::vector<Vec3> p;
  Faces faces;
  make(&p, &faces);
  const int folded = down(p, faces);
  ASSERT_GT(folded, 0);
  const auto boundary = BoundaryEdges(faces);
  std::vector<uint8_t> locked;

  RemeshOptions creases;  // fold_deg 180: a fold is a crease
  Faces kept = faces;
  const RemeshStats k = Remesh(creases, above, &p, &kept, &locked);
  EXPECT_EQ(k.folds_flipped, 0);
  EXPECT_EQ(down(p, kept), folded);

  RemeshOptions folds;
  folds.fold_deg = 150.0;
  const RemeshStats s = Remesh(folds, above, &p, &faces, &locked);
  EXPECT_GT(s.folds_flipped, 0) << s.creases_kept << " creases kept, " << s.flips_refused << " refused, " << s.flips_facing_away << " facing away, " << s.edges_flipped << " flipped";
  EXPECT_EQ(down(p, faces), 0) << "of " << folded << " faces down";
  EXPECT_EQ(ManifoldError(p.size(), faces), "");
  EXPECT_EQ(BoundaryEdges(faces), boundary);
  EXPECT_LT(s.total_dihedral_after, 0.5 * s.total_dihedral_before);
}

TEST(Remesh, OptionsCheckNamesTheField) {
  RemeshOptions o;
  std::string error;
  EXPECT_TRUE(o.Check(&error));
  o.max_turn_deg = 95;
  EXPECT_FALSE(o.Check(&error));
  EXPECT_NE(error.find("max_turn_deg"), std::string::npos);
  o = RemeshOptions{};
  o.max_edge = -1;
  EXPECT_FALSE(o.Check(&error));
  EXPECT_NE(error.find("max_edge"), std::string::npos);
}

}  // namespace
}  // namespace imr::photometric
