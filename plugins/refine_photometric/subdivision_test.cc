// SubdivideLongEdges keeps a manifold a manifold: every edge in one or two faces, each interior
// edge used once in each direction (orientation kept), the same boundary, the same area.
#include "subdivision.hpp"

#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include <map>

namespace imr::photometric {
namespace {

using Faces = std::vector<std::array<uint32_t, 3>>;

struct Check {
  bool manifold = true;   // no edge in more than two faces, none twice in one direction
  int boundary_edges = 0;
  double area = 0.0;
  double longest = 0.0;
};

Check Inspect(const std::vector<Eigen::Vector3d>& p, const Faces& faces) {
  Check c;
  std::map<std::pair<uint32_t, uint32_t>, int> directed;
  for (const auto& f : faces) {
    c.area += 0.5 * (p[f[1]] - p[f[0]]).cross(p[f[2]] - p[f[0]]).norm();
    for (int k = 0; k < 3; ++k) {
      c.longest = std::max(c.longest, (p[f[k]] - p[f[(k + 1) % 3]]).norm());
      if (++directed[{f[k], f[(k + 1) % 3]}] > 1) c.manifold = false;
    }
  }
  for (const auto& [e, n] : directed)
    if (!directed.count({e.second, e.first})) ++c.boundary_edges;
  return c;
}

// An open 4 x 4 grid of a plane, 1 m cells, with one long sliver fan in a corner.
void Grid(std::vector<Eigen::Vector3d>* p, Faces* faces) {
  for (int y = 0; y <= 4; ++y)
    for (int x = 0; x <= 4; ++x) p->emplace_back(x, y, 0.0);
  for (int y = 0; y < 4; ++y)
    for (int x = 0; x < 4; ++x) {
      const uint32_t a = 5 * y + x, b = a + 1, c = a + 6, d = a + 5;
      faces->push_back({a, b, c});
      faces->push_back({a, c, d});
    }
}

TEST(Subdivision, KeepsTheManifoldItsBoundaryAndArea) {
  std::vector<Eigen::Vector3d> p;
  Faces faces;
  Grid(&p, &faces);
  const Check before = Inspect(p, faces);
  std::vector<uint8_t> eligible;
  const SubdivisionStats s = SubdivideLongEdges(0.9, 2, &p, &faces, &eligible);
  const Check after = Inspect(p, faces);
  EXPECT_TRUE(after.manifold);
  EXPECT_NEAR(after.area, before.area, 1e-9);
  EXPECT_LE(after.longest, 0.9);
  EXPECT_EQ(faces.size(), 4 * 32u);  // every edge was long: each face in four, once
  EXPECT_GT(s.edges_split, 0);
  EXPECT_EQ(s.faces_after, static_cast<int64_t>(faces.size()));
  EXPECT_EQ(eligible.size(), p.size());
  // The border is split too: twice as many boundary edges (each one in two), one loop still.
  EXPECT_EQ(after.boundary_edges, 2 * before.boundary_edges);
}

TEST(Subdivision, OnlyEdgesBetweenEligibleVertices) {
  std::vector<Eigen::Vector3d> p;
  Faces faces;
  Grid(&p, &faces);
  std::vector<uint8_t> eligible(p.size(), 0);
  eligible[0] = eligible[1] = eligible[6] = 1;  // one face's corners
  const std::size_t n = p.size();
  SubdivideLongEdges(0.9, 1, &p, &faces, &eligible);
  // Its three edges split (its diagonal 0-6, and 0-1, 1-6), nothing else.
  EXPECT_EQ(p.size(), n + 3);
  EXPECT_TRUE(Inspect(p, faces).manifold);
}

TEST(Subdivision, ShortEdgesChangeNothing) {
  std::vector<Eigen::Vector3d> p;
  Faces faces;
  Grid(&p, &faces);
  const Faces copy = faces;
  std::vector<uint8_t> eligible;
  const SubdivisionStats s = SubdivideLongEdges(2.0, 3, &p, &faces, &eligible);
  EXPECT_EQ(s.edges_split, 0);
  EXPECT_EQ(faces, copy);
}

}  // namespace
}  // namespace imr::photometric
