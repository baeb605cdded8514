#include "host/engine/mesh_passes.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdint>
#include <random>
#include <set>
#include <stdexcept>
#include <string>
#include <vector>

#include "host/engine/testing/surface_checks.h"

namespace imr::engine {
namespace {

// A grid of n x n quads over a ridge along x = y (z = -|x - y|), each quad split by the diagonal
// across it: the quads on the ridge fold the wrong way, which the flips pass mends.
Mesh RidgeSplitAcross(int n) {
  Mesh m;
  for (int y = 0; y <= n; ++y)
    for (int x = 0; x <= n; ++x) {
      m.vertices.insert(m.vertices.end(), {double(x), double(y), -std::abs(double(x - y))});
      m.point_ids.push_back(y * (n + 1) + x);
    }
  auto at = [n](int x, int y) { return static_cast<uint32_t>(y * (n + 1) + x); };
  for (int y = 0; y < n; ++y)
    for (int x = 0; x < n; ++x) {
      const uint32_t a = at(x, y), b = at(x + 1, y), c = at(x + 1, y + 1), d = at(x, y + 1);
      m.faces.insert(m.faces.end(), {a, b, d, b, c, d});
    }
  return m;
}

// The passes the options ask for, in the order the export runs them.
TEST(MeshPasses, TheOptionsPassesInOrder) {
  EngineOptions o;
  MeshPassesStats stats;
  EXPECT_TRUE(MeshPasses(o, &stats).empty());
  o.retriangulate_planes = 0.1;
  o.flip_edges = true;
  o.filter_normals = 2;
  const std::vector<MeshPass> passes = MeshPasses(o, &stats);
  ASSERT_EQ(passes.size(), 3u);
  EXPECT_EQ(passes[0].name, "engine.retriangulate_planes");
  EXPECT_EQ(passes[1].name, "engine.flip_edges");
  EXPECT_FALSE(passes[1].moves_vertices);
  EXPECT_EQ(passes[2].name, "engine.filter_normals");
  EXPECT_FALSE(passes[2].changes_faces);
}

// mesh_pass_rounds: the list again after the first, its later entries named by round; the
// figures of the rounds add up, the angles those before the first and after the last.
TEST(MeshPasses, RoundsRepeatTheListAndAddTheirFigures) {
  EngineOptions o;
  o.retriangulate_planes = 0.1;
  o.flip_edges = true;
  o.filter_normals = 5;
  o.mesh_pass_rounds = 2;
  MeshPassesStats stats;
  const std::vector<MeshPass> passes = MeshPasses(o, &stats);
  ASSERT_EQ(passes.size(), 6u);
  EXPECT_EQ(passes[2].name, "engine.filter_normals");
  EXPECT_EQ(passes[3].name, "engine.retriangulate_planes (round 2)");
  EXPECT_EQ(passes[5].name, "engine.filter_normals (round 2)");

  EdgeFlipStats total, round;
  round.flips = 3;
  round.edges = 10;
  round.degrees_sum_before = 200.0;
  round.degrees_sum_after = 150.0;
  AddRound(&total, round);
  round.flips = 2;
  round.degrees_sum_before = 120.0;
  round.degrees_sum_after = 100.0;
  AddRound(&total, round);
  EXPECT_EQ(total.flips, 5);
  EXPECT_EQ(total.edges, 10);
  EXPECT_DOUBLE_EQ(total.degrees_sum_before, 200.0);
  EXPECT_DOUBLE_EQ(total.degrees_sum_after, 100.0);
}

// A plane whose vertices are off it by more than the planes' tolerance, with folds in it: the
// first round's planes pass finds no region, the normal filter flattens the noise but cannot open
// a fold; the second round's planes pass can: fewer faces turned off the plane, half the roughness.
TEST(MeshPasses, ASecondRoundTakesOutFoldsTheFilterFlattened) {
  const int n = 14;
  const auto noisy_folded = [n] {
    std::mt19937 rng(45);
    std::uniform_real_distribution<double> noise(-0.3, 0.3);
    const auto inside = [n](int i, int j) { return i > 0 && j > 0 && i + 1 < n && j + 1 < n; };
    Mesh m = testing::Grid(n, [&](int i, int j) {
      return std::array<double, 3>{double(i), double(j), inside(i, j) ? noise(rng) : 0.0};
    });
    for (int j = 3; j < n - 3; j += 4)
      for (int i = 3; i < n - 3; i += 4) m.vertices[3 * (j * n + i)] += 1.4;  // its fan folded over
    return m;
  };
  EngineOptions o;
  o.retriangulate_planes = 0.1;
  o.flip_edges = true;
  o.filter_normals = 5;
  double rough[2] = {0.0, 0.0};
  int64_t regions[2] = {0, 0}, turned[2] = {0, 0};  // turned: faces more than 30 degrees off the plane
  for (int rounds = 1; rounds <= 2; ++rounds) {
    Mesh m = noisy_folded();
    const Mesh before = m;
    o.mesh_pass_rounds = rounds;
    MeshPassesStats stats;
    ManifoldCheckResult check = CheckMesh(m, /*closed=*/false);
    ASSERT_TRUE(check.ok) << check.message;
    RunMeshPasses(MeshPasses(o, &stats), &m, &stats, &check);
    EXPECT_EQ(stats.undone, 0) << stats.undone_why;
    ASSERT_TRUE(CheckMesh(m, /*closed=*/false).ok);
    EXPECT_EQ(testing::Boundary(m), testing::Boundary(before));
    EXPECT_EQ(m.faces.size(), before.faces.size());
    rough[rounds - 1] = testing::Roughness(m);
    regions[rounds - 1] = stats.planes.regions;
    for (std::size_t f = 0; f < m.faces.size() / 3; ++f) turned[rounds - 1] += testing::FaceNormal(m, f)[2] < 0.87;
  }
  EXPECT_EQ(regions[0], 0);  // the noise is above the tolerance
  EXPECT_GE(regions[1], 1);
  EXPECT_LT(turned[1], turned[0]);  // 7 -> 3
  EXPECT_LT(rough[1], 0.6 * rough[0]) << "one round " << rough[0] << ", two " << rough[1];  // 6.1 -> 2.7
}

// DropFaces (engine.drop_back_faces' step): whatever faces go, the rest is a 2-manifold with
// boundary, every vertex named by a face, point ids kept with their positions, the pieces under
// the area gone; a vertex left with two fans is split.
TEST(MeshPasses, DroppingAnyFacesLeavesAManifold) {
  std::mt19937 rng(46);
  int64_t split = 0, sheets = 0;
  for (int trial = 0; trial < 1000; ++trial) {
    Mesh m = testing::RandomSheet(rng, 4 + static_cast<int>(rng() % 6));
    for (std::size_t v = 0; v < m.point_ids.size(); ++v) m.point_ids[v] = static_cast<int64_t>(1000 + v);
    if (!CheckMesh(m, /*closed=*/false).ok) continue;  // RandomSheet's holes may pinch
    ++sheets;
    const Mesh before = m;
    const std::size_t nf = m.faces.size() / 3;
    std::vector<uint8_t> drop(nf, 0);
    const int share = 1 + static_cast<int>(rng() % 40);  // percent of the faces
    int64_t asked = 0;
    for (auto& d : drop) asked += d = static_cast<int>(rng() % 100) < share ? 1 : 0;
    DroppedComponents dropped;
    const double min_area = trial % 2 == 0 ? 0.0 : 0.5;
    EXPECT_EQ(DropFaces(&m, drop, min_area, &dropped), asked);
    const ManifoldCheckResult check = CheckMesh(m, /*closed=*/false);
    ASSERT_TRUE(check.ok) << "trial " << trial << ": " << check.message;
    EXPECT_EQ(m.faces.size() / 3 + static_cast<std::size_t>(asked + dropped.faces), nf) << "trial " << trial;
    std::vector<uint8_t> named(m.point_ids.size(), 0);
    for (uint32_t v : m.faces) named[v] = 1;
    for (std::size_t v = 0; v < named.size(); ++v) {
      if (asked > 0) {
        ASSERT_TRUE(named[v]) << "trial " << trial << ": vertex " << v << " named by no face";
      }
      const auto id = static_cast<std::size_t>(m.point_ids[v] - 1000);
      for (int k = 0; k < 3; ++k) EXPECT_EQ(m.vertices[3 * v + k], before.vertices[3 * id + k]);
    }
    std::vector<int> copies(before.point_ids.size(), 0);
    for (int64_t id : m.point_ids) ++copies[static_cast<std::size_t>(id - 1000)];
    for (int c : copies) split += c > 1 ? c - 1 : 0;
    if (min_area > 0.0) {  // every piece left weighs at least min_area
      Mesh again = m;
      DroppedComponents none;
      DropSmallComponents(&again, min_area, &none);
      EXPECT_EQ(none.components, 0) << "trial " << trial;
    }
  }
  EXPECT_GT(sheets, 500);
  EXPECT_GT(split, 0);  // some drops pinched a vertex, and it was split
  Mesh m = testing::RandomSheet(rng, 5);
  EXPECT_THROW(DropFaces(&m, std::vector<uint8_t>(3, 0), 0.0), std::invalid_argument);
}

// steiner_export open_steiner's step on a flat 6 x 6 grid: a Steiner vertex inside (its fan
// closes a gap between point triangles) and one on the border (rim: three edges on points, two
// open) stay; the top row of Steiner vertices (its strip borders points on 5 edges, nothing on 7)
// and a loose triangle with a Steiner corner (nothing on 3) go.
TEST(SteinerRegions, GapsBetweenPointsStaySheetsIntoNothingGo) {
  const int n = 6;
  Mesh m = testing::Grid(n, [](int i, int j) { return std::array<double, 3>{1.0 * i, 1.0 * j, 0.0}; });
  m.point_ids[2 * n + 2] = -1;  // inside
  m.point_ids[0 * n + 3] = -1;  // on the border
  for (int i = 0; i < n; ++i) m.point_ids[(n - 1) * n + i] = -1;  // the top row
  const uint32_t loose = static_cast<uint32_t>(m.point_ids.size());
  m.vertices.insert(m.vertices.end(), {10, 0, 0, 11, 0, 0, 10, 1, 0});
  m.point_ids.insert(m.point_ids.end(), {-1, 100, 101});
  m.faces.insert(m.faces.end(), {loose, loose + 1, loose + 2});
  const std::size_t faces = m.faces.size() / 3;
  EXPECT_EQ(DropOpenSteinerRegions(&m), 2 * (n - 1) + 1);
  EXPECT_EQ(m.faces.size() / 3, faces - 2 * (n - 1) - 1);
  EXPECT_EQ(m.point_ids.size(), static_cast<std::size_t>(n * (n - 1)));  // the top row, the loose corners gone
  std::set<int64_t> steiner_faces_left;
  for (std::size_t f = 0; f < m.faces.size() / 3; ++f)
    for (int k = 0; k < 3; ++k)
      if (m.point_ids[m.faces[3 * f + k]] < 0) steiner_faces_left.insert(static_cast<int64_t>(f));
  EXPECT_EQ(steiner_faces_left.size(), 6u + 3u);  // the inside fan, the border fan
  EXPECT_TRUE(CheckMesh(m, /*closed=*/false).ok) << CheckMesh(m, false).message;
  EXPECT_EQ(DropOpenSteinerRegions(&m), 0);
}

// open_steiner_crease: a gap strip on a floor (row 4 Steiner, points on both sides) meets, at a
// right angle, a wall of Steiner vertices rising into nothing (columns 6-8). Joined across the
// crease (180 degrees) their rims balance and both stay; split at it (45), the strip keeps its
// rim on points and stays, the wall's rim borders mostly nothing and goes, whole.
TEST(SteinerRegions, ACreaseSplitsASheetFromTheGapItRisesFrom) {
  const int n = 9;
  auto floor_and_wall = [&] {
    Mesh m = testing::Grid(n, [](int i, int j) {
      return i <= 5 ? std::array<double, 3>{1.0 * i, 1.0 * j, 0.0}
                    : std::array<double, 3>{5.0, 1.0 * j, 1.0 * (i - 5)};
    });
    for (int i = 0; i <= 5; ++i) m.point_ids[4 * n + i] = -1;  // the strip
    for (int j = 0; j < n; ++j)
      for (int i = 6; i < n; ++i) m.point_ids[j * n + i] = -1;  // the wall
    return m;
  };
  Mesh joined = floor_and_wall();
  const std::size_t faces = joined.faces.size() / 3;
  EXPECT_EQ(DropOpenSteinerRegions(&joined, 180.0), 0);
  EXPECT_EQ(DropOpenSteinerRegions(&joined), 0);  // 180 is the default
  Mesh split = floor_and_wall();
  const int64_t wall_faces = 2 * (n - 1) * 3;  // columns 5-8
  EXPECT_EQ(DropOpenSteinerRegions(&split, 45.0), wall_faces);
  ASSERT_EQ(split.faces.size() / 3, faces - static_cast<std::size_t>(wall_faces));
  for (std::size_t v = 0; v < split.point_ids.size(); ++v)
    EXPECT_LE(split.vertices[3 * v], 5.0 + 1e-12);  // nothing of the wall is left above the floor
  for (std::size_t f = 0; f < split.faces.size() / 3; ++f)
    for (int k = 0; k < 3; ++k) EXPECT_EQ(split.vertices[3 * split.faces[3 * f + k] + 2], 0.0);
  EXPECT_TRUE(CheckMesh(split, /*closed=*/false).ok) << CheckMesh(split, false).message;
  EXPECT_EQ(DropOpenSteinerRegions(&split, 45.0), 0);
}

// On random sheets with random Steiner vertices, through FinishExportedMesh: a 2-manifold, every
// triangle between points kept, and nothing more to drop (a kept region's rim borders points or
// nothing, never another region).
TEST(SteinerRegions, RandomSheetsKeepTheirPointTrianglesAndAManifold) {
  std::mt19937 rng(61);
  EngineOptions o;
  o.steiner_export = SteinerExportRule::kOpenSteiner;
  o.fill_holes_perimeter = 0.0;
  o.min_component_area = 0.0;
  int64_t sheets = 0, dropped = 0, kept_steiner = 0;
  auto point_faces = [](const Mesh& m) {
    int64_t count = 0;
    for (std::size_t f = 0; f < m.faces.size() / 3; ++f)
      count += m.point_ids[m.faces[3 * f]] >= 0 && m.point_ids[m.faces[3 * f + 1]] >= 0 &&
               m.point_ids[m.faces[3 * f + 2]] >= 0;
    return count;
  };
  for (int trial = 0; trial < 1000; ++trial) {
    Mesh m = testing::RandomSheet(rng, 4 + static_cast<int>(rng() % 6));
    if (!CheckMesh(m, /*closed=*/false).ok) continue;
    ++sheets;
    const int share = 5 + static_cast<int>(rng() % 45);  // percent of the vertices
    for (int64_t& id : m.point_ids) id = static_cast<int>(rng() % 100) < share ? -1 : id;
    const std::size_t nf = m.faces.size() / 3;
    const int64_t points = point_faces(m);
    FinishExportedMesh(&m, o);
    const ManifoldCheckResult check = CheckMesh(m, /*closed=*/false);
    ASSERT_TRUE(check.ok) << "trial " << trial << ": " << check.message;
    EXPECT_EQ(point_faces(m), points) << "trial " << trial;
    dropped += static_cast<int64_t>(nf - m.faces.size() / 3);
    kept_steiner += static_cast<int64_t>(m.faces.size() / 3) - points;
    EXPECT_EQ(DropOpenSteinerRegions(&m), 0) << "trial " << trial;
  }
  EXPECT_GT(sheets, 500);
  EXPECT_GT(dropped, 0);       // both outcomes happen
  EXPECT_GT(kept_steiner, 0);
}

// A pass that breaks the manifold is undone (the mesh as the pass before it left it, its figures
// forgotten, a warning naming it); the passes before and after it keep their work.
TEST(MeshPasses, APassThatBreaksTheManifoldIsUndone) {
  Mesh mesh = RidgeSplitAcross(6);
  EngineOptions o;
  o.flip_edges = true;
  MeshPassesStats stats;
  std::vector<MeshPass> passes = MeshPasses(o, &stats);
  ASSERT_EQ(passes.size(), 1u);
  bool broke_ran = false;
  passes.push_back({"a pass that repeats a face", false, true,
                    [&](Mesh* m) {
                      broke_ran = true;
                      m->faces.insert(m->faces.end(), m->faces.begin(), m->faces.begin() + 3);
                      return true;
                    },
                    {}});
  passes.push_back({"a pass that lifts a corner", true, false,
                    [](Mesh* m) {
                      m->vertices[2] += 0.5;
                      return true;
                    },
                    {}});
  std::vector<std::string> warnings;
  ManifoldCheckResult check = CheckMesh(mesh, /*closed=*/false);
  ASSERT_TRUE(check.ok) << check.message;
  RunMeshPasses(passes, &mesh, &stats, &check,
                [&](const std::string& w) { warnings.push_back(w); });
  EXPECT_TRUE(broke_ran);
  EXPECT_GT(stats.flips.flips, 0);  // the flips kept
  EXPECT_EQ(stats.undone, 1);
  EXPECT_EQ(stats.undone_why.rfind("a pass that repeats a face: ", 0), 0u) << stats.undone_why;
  ASSERT_EQ(warnings.size(), 1u);
  EXPECT_EQ(warnings[0].rfind("a pass that repeats a face undone: the mesh was no manifold", 0), 0u)
      << warnings[0];
  EXPECT_EQ(mesh.faces.size(), 6u * 6u * 6u);  // the repeated face gone
  EXPECT_DOUBLE_EQ(mesh.vertices[2], 0.5);     // the last pass ran after the undo
  EXPECT_TRUE(check.ok) << check.message;
  EXPECT_TRUE(CheckMesh(mesh, /*closed=*/false).ok);

  // The flips' own figures go when they are the pass undone.
  Mesh again = RidgeSplitAcross(6);
  MeshPassesStats stats2;
  std::vector<MeshPass> flips_then_break = MeshPasses(o, &stats2);
  const std::vector<uint32_t> before = again.faces;
  flips_then_break[0].run = [&, inner = flips_then_break[0].run](Mesh* m) {
    inner(m);
    m->faces.insert(m->faces.end(), m->faces.begin(), m->faces.begin() + 3);
    return true;
  };
  ManifoldCheckResult check2 = CheckMesh(again, /*closed=*/false);
  RunMeshPasses(flips_then_break, &again, &stats2, &check2);
  EXPECT_EQ(stats2.undone, 1);
  EXPECT_EQ(stats2.flips.flips, 0);
  EXPECT_EQ(again.faces, before);
}

}  // namespace
}  // namespace imr::engine
