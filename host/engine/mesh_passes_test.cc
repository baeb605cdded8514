#include "host/engine/mesh_passes.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

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
