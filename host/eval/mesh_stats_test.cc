// Mesh statistics on meshes built by hand, each figure counted by hand: a tetrahedron (closed,
// genus 0), a torus (genus 1), two disjoint triangles, an open square, and the ill cases (a
// bowtie vertex, an edge in three faces, a Moebius strip, a flipped face, degenerate faces).
#include "host/eval/mesh_stats.h"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <stdexcept>

namespace imr::eval {
namespace {

struct Mesh {
  std::vector<double> xyz;
  std::vector<uint32_t> faces;
};

MeshStatistics Stats(const Mesh& m) { return ComputeMeshStatistics(m.xyz, m.faces); }

// Unit right-angled tetrahedron, outward normals.
Mesh Tetrahedron() {
  return {{0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1}, {0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3}};
}

// A torus of n x m quads (each split in two triangles), radii R and r.
Mesh Torus(int n, int m, double big_r = 3.0, double small_r = 1.0) {
  Mesh t;
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < m; ++j) {
      const double u = 2 * std::numbers::pi * i / n, v = 2 * std::numbers::pi * j / m;
      t.xyz.insert(t.xyz.end(), {(big_r + small_r * std::cos(v)) * std::cos(u),
                                 (big_r + small_r * std::cos(v)) * std::sin(u),
                                 small_r * std::sin(v)});
    }
  }
  auto id = [&](int i, int j) { return static_cast<uint32_t>((i % n) * m + (j % m)); };
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < m; ++j) {
      t.faces.insert(t.faces.end(), {id(i, j), id(i + 1, j), id(i + 1, j + 1)});
      t.faces.insert(t.faces.end(), {id(i, j), id(i + 1, j + 1), id(i, j + 1)});
    }
  }
  return t;
}

TEST(MeshStats, TetrahedronIsAClosedGenusZeroSurface) {
  const MeshStatistics s = Stats(Tetrahedron());
  EXPECT_EQ(s.vertices, 4);
  EXPECT_EQ(s.used_vertices, 4);
  EXPECT_EQ(s.faces, 4);
  EXPECT_EQ(s.edges, 6);
  EXPECT_EQ(s.euler_characteristic, 2);
  EXPECT_EQ(s.components, 1);
  EXPECT_EQ(s.boundary_edges, 0);
  EXPECT_EQ(s.boundary_loops, 0);
  EXPECT_EQ(s.nonmanifold_edges, 0);
  EXPECT_EQ(s.nonmanifold_vertices, 0);
  EXPECT_TRUE(s.manifold);
  EXPECT_TRUE(s.closed);
  EXPECT_TRUE(s.orientable);
  EXPECT_TRUE(s.consistently_oriented);
  EXPECT_EQ(s.genus, 0);
  // Three right triangles of area 1/2 and one equilateral of side sqrt(2).
  EXPECT_NEAR(s.area, 1.5 + std::sqrt(3.0) / 2.0, 1e-12);
  EXPECT_EQ(s.bbox_min, (std::array<double, 3>{0, 0, 0}));
  EXPECT_EQ(s.bbox_max, (std::array<double, 3>{1, 1, 1}));
  ASSERT_EQ(s.component_list.size(), 1u);
  EXPECT_EQ(s.component_list[0].genus, 0);
  EXPECT_EQ(s.component_list[0].euler_characteristic, 2);
}

TEST(MeshStats, TorusHasGenusOne) {
  const MeshStatistics s = Stats(Torus(8, 6));
  EXPECT_EQ(s.used_vertices, 48);
  EXPECT_EQ(s.faces, 96);
  EXPECT_EQ(s.edges, 144);  // 3 per quad
  EXPECT_EQ(s.euler_characteristic, 0);
  EXPECT_EQ(s.components, 1);
  EXPECT_TRUE(s.closed);
  EXPECT_TRUE(s.manifold);
  EXPECT_TRUE(s.consistently_oriented);
  EXPECT_EQ(s.genus, 1);
}

TEST(MeshStats, TwoDisjointTrianglesAreTwoComponentsWithABoundaryLoopEach) {
  const Mesh m{{0, 0, 0, 1, 0, 0, 0, 1, 0, 5, 0, 0, 6, 0, 0, 5, 2, 0}, {0, 1, 2, 3, 4, 5}};
  const MeshStatistics s = Stats(m);
  EXPECT_EQ(s.components, 2);
  EXPECT_EQ(s.edges, 6);
  EXPECT_EQ(s.euler_characteristic, 2);  // 1 per disc
  EXPECT_EQ(s.boundary_edges, 6);
  EXPECT_EQ(s.boundary_loops, 2);
  EXPECT_FALSE(s.closed);
  EXPECT_TRUE(s.manifold);
  EXPECT_EQ(s.genus, 0);
  EXPECT_NEAR(s.area, 0.5 + 1.0, 1e-12);
  ASSERT_EQ(s.component_list.size(), 2u);
  for (const auto& c : s.component_list) {
    EXPECT_EQ(c.vertices, 3);
    EXPECT_EQ(c.edges, 3);
    EXPECT_EQ(c.faces, 1);
    EXPECT_EQ(c.euler_characteristic, 1);
    EXPECT_EQ(c.boundary_loops, 1);
    EXPECT_EQ(c.genus, 0);
  }
  // Equal face counts: listed in vertex order.
  EXPECT_NEAR(s.component_list[0].area, 0.5, 1e-12);
  EXPECT_NEAR(s.component_list[1].area, 1.0, 1e-12);
}

TEST(MeshStats, OpenSquareIsADiscWithOneBoundaryLoop) {
  const Mesh m{{0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0}, {0, 1, 2, 0, 2, 3}};
  const MeshStatistics s = Stats(m);
  EXPECT_EQ(s.used_vertices, 4);
  EXPECT_EQ(s.edges, 5);
  EXPECT_EQ(s.euler_characteristic, 1);
  EXPECT_EQ(s.boundary_edges, 4);
  EXPECT_EQ(s.boundary_loops, 1);
  EXPECT_FALSE(s.closed);
  EXPECT_TRUE(s.manifold);
  EXPECT_TRUE(s.consistently_oriented);
  EXPECT_EQ(s.genus, 0);
  EXPECT_NEAR(s.area, 1.0, 1e-12);
}

TEST(MeshStats, CylinderHasTwoBoundaryLoopsAndGenusZero) {
  // A torus grid without its closing ring of quads in j is a tube: chi = 0, two loops.
  Mesh t = Torus(8, 6);
  Mesh tube{t.xyz, {}};
  for (std::size_t f = 0; f < t.faces.size(); f += 3) {
    // Drop the quads between j = 5 and j = 0 (vertex index % 6 == 5 next to % 6 == 0).
    bool wraps = false;
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b)
        wraps = wraps || (t.faces[f + a] % 6 == 5 && t.faces[f + b] % 6 == 0);
    if (!wraps) tube.faces.insert(tube.faces.end(), t.faces.begin() + f, t.faces.begin() + f + 3);
  }
  const MeshStatistics s = Stats(tube);
  EXPECT_EQ(s.euler_characteristic, 0);
  EXPECT_EQ(s.boundary_loops, 2);
  EXPECT_EQ(s.boundary_edges, 16);
  EXPECT_EQ(s.genus, 0);
}

TEST(MeshStats, BowtieVertexIsNonManifold) {
  // Two triangles sharing only vertex 0.
  const Mesh m{{0, 0, 0, 1, 0, 0, 1, 1, 0, -1, 0, 0, -1, -1, 0}, {0, 1, 2, 0, 3, 4}};
  const MeshStatistics s = Stats(m);
  EXPECT_EQ(s.components, 1);  // connected through the shared vertex
  EXPECT_EQ(s.nonmanifold_vertices, 1);
  EXPECT_EQ(s.nonmanifold_edges, 0);
  EXPECT_EQ(s.boundary_loops, 1);  // the two triangles' boundaries touch at vertex 0
  EXPECT_FALSE(s.manifold);
  EXPECT_EQ(s.genus, -1);
  EXPECT_EQ(s.ToJson()["genus"], nullptr);
}

TEST(MeshStats, EdgeInThreeFacesIsNonManifold) {
  const Mesh m{{0, 0, 0, 1, 0, 0, 0, 1, 0, 0, -1, 0, 0, 0, 1}, {0, 1, 2, 1, 0, 3, 0, 1, 4}};
  const MeshStatistics s = Stats(m);
  EXPECT_EQ(s.nonmanifold_edges, 1);
  EXPECT_EQ(s.nonmanifold_vertices, 2);  // the edge's two ends
  EXPECT_FALSE(s.manifold);
  EXPECT_EQ(s.genus, -1);
}

TEST(MeshStats, MoebiusStripIsNotOrientable) {
  // A strip of 5 quads whose ends are glued with a half twist: (top_5, bottom_5) = (bottom_0, top_0).
  const int n = 5;
  Mesh m;
  for (int i = 0; i < n; ++i) {
    const double a = 2 * std::numbers::pi * i / n;
    m.xyz.insert(m.xyz.end(), {std::cos(a), std::sin(a), 0.3});
    m.xyz.insert(m.xyz.end(), {std::cos(a), std::sin(a), -0.3});
  }
  auto top = [&](int i) { return static_cast<uint32_t>(i == n ? 1 : 2 * i); };
  auto bottom = [&](int i) { return static_cast<uint32_t>(i == n ? 0 : 2 * i + 1); };
  for (int i = 0; i < n; ++i) {
    m.faces.insert(m.faces.end(), {top(i), bottom(i), bottom(i + 1)});
    m.faces.insert(m.faces.end(), {top(i), bottom(i + 1), top(i + 1)});
  }
  const MeshStatistics s = Stats(m);
  EXPECT_EQ(s.components, 1);
  EXPECT_TRUE(s.manifold);
  EXPECT_EQ(s.boundary_loops, 1);  // a Moebius strip has one boundary curve
  EXPECT_EQ(s.euler_characteristic, 0);
  EXPECT_FALSE(s.orientable);
  EXPECT_FALSE(s.consistently_oriented);
  EXPECT_EQ(s.genus, -1);
}

TEST(MeshStats, FlippedFaceIsOrientableButNotConsistentlyOriented) {
  Mesh m = Tetrahedron();
  std::swap(m.faces[1], m.faces[2]);
  const MeshStatistics s = Stats(m);
  EXPECT_TRUE(s.orientable);
  EXPECT_FALSE(s.consistently_oriented);
  EXPECT_EQ(s.genus, 0);
}

TEST(MeshStats, DegenerateFacesAndUnusedVerticesAreSetAside) {
  Mesh m = Tetrahedron();
  m.xyz.insert(m.xyz.end(), {9, 9, 9});  // vertex 4: unused
  m.faces.insert(m.faces.end(), {0, 0, 1});
  const MeshStatistics s = Stats(m);
  EXPECT_EQ(s.vertices, 5);
  EXPECT_EQ(s.used_vertices, 4);
  EXPECT_EQ(s.unused_vertices, 1);
  EXPECT_EQ(s.faces, 5);
  EXPECT_EQ(s.degenerate_faces, 1);
  EXPECT_EQ(s.euler_characteristic, 2);
  EXPECT_EQ(s.genus, 0);
  EXPECT_EQ(s.bbox_max, (std::array<double, 3>{1, 1, 1}));  // the unused vertex is not in it
}

TEST(MeshStats, ComponentsAreListedLargestFirstAndCappedInJson) {
  Mesh m = Tetrahedron();
  const Mesh t = Torus(4, 3);
  for (double x : t.xyz) m.xyz.push_back(x + 10);
  for (uint32_t f : t.faces) m.faces.push_back(f + 4);
  const MeshStatistics s = Stats(m);
  ASSERT_EQ(s.components, 2);
  EXPECT_EQ(s.component_list[0].faces, 24);
  EXPECT_EQ(s.component_list[0].genus, 1);
  EXPECT_EQ(s.component_list[1].genus, 0);
  EXPECT_EQ(s.genus, 1);
  EXPECT_EQ(s.euler_characteristic, 2);
  const auto j = s.ToJson(1);
  EXPECT_EQ(j["components"], 2);
  EXPECT_EQ(j["components_listed"], 1);
  EXPECT_EQ(j["component_list"].size(), 1u);
  EXPECT_EQ(j["components_connected_by"], "shared vertices");
}

TEST(MeshStats, BadInputThrows) {
  EXPECT_THROW(ComputeMeshStatistics(std::vector<double>{0, 0}, {}), std::invalid_argument);
  EXPECT_THROW(ComputeMeshStatistics(std::vector<double>{0, 0, 0}, {0, 0}), std::invalid_argument);
  try {
    ComputeMeshStatistics(Tetrahedron().xyz, {0, 1, 7});
    FAIL() << "no throw";
  } catch (const std::invalid_argument& e) {
    EXPECT_STREQ(e.what(), "face 0: vertex index 7 out of range (4 vertices)");
  }
}

TEST(MeshStats, EmptyMesh) {
  const MeshStatistics s = Stats({});
  EXPECT_EQ(s.components, 0);
  EXPECT_EQ(s.edges, 0);
  EXPECT_EQ(s.area, 0.0);
}

}  // namespace
}  // namespace imr::eval
