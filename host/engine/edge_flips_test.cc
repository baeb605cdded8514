// FlipEdges: the diagonal that lies smoother is chosen, corners stay, and the surface stays a
// manifold with the same boundary, vertices and face count whatever the input, whole or in parts.
#include "host/engine/edge_flips.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <random>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "host/engine/mesh_topology.h"
#include "host/engine/testing/surface_checks.h"

namespace imr::engine {
namespace {

using testing::Grid;
using testing::Boundary;
using testing::RandomSheet;
using testing::Roughness;
constexpr auto Normal = &testing::FaceNormal;

EdgeFlipOptions On() {
  EdgeFlipOptions o;
  o.enabled = true;
  return o;
}

// A valley along x = y (z = |x - y| / 2) triangulated across it: every square on the valley's
// floor bends the wrong way. The flips bring back the diagonal along the valley: the surface of
// the same points with the valley's own edges.
TEST(EdgeFlipsTest, TheDiagonalAlongTheValleyIsChosen) {
  const int n = 10;
  auto place = [](int i, int j) { return std::array<double, 3>{double(i), double(j), 0.5 * std::abs(i - j)}; };
  Mesh m = Grid(n, place, [](int, int) { return false; });
  const Mesh want = Grid(n, place, [](int i, int j) { return i == j; });
  const Mesh before = m;
  const double rough_before = Roughness(m), rough_want = Roughness(want);
  ASSERT_GT(rough_before, rough_want + 1.0);

  const EdgeFlipStats s = FlipEdges(&m, On());
  EXPECT_EQ(s.flips, n - 1);  // one per square on the valley's floor
  const ManifoldCheckResult check = CheckMesh(m, /*closed=*/false);
  ASSERT_TRUE(check.ok) << check.message;
  EXPECT_EQ(m.vertices, before.vertices);
  EXPECT_EQ(m.point_ids, before.point_ids);
  EXPECT_EQ(m.faces.size(), before.faces.size());
  EXPECT_EQ(Boundary(m), Boundary(before));
  EXPECT_NEAR(Roughness(m), rough_want, 1e-9) << "before " << rough_before;
  EXPECT_LT(s.degrees_sum_after, s.degrees_sum_before);
  for (std::size_t f = 0; f < m.faces.size() / 3; ++f) EXPECT_GT(Normal(m, f)[2], 0.0) << "face " << f;
}

// A floor meeting a wall at a right angle, and a roof ridge: the edges along the corner stay,
// nothing cuts across it.
TEST(EdgeFlipsTest, ACornerStaysACorner) {
  const int n = 11;
  Mesh m = Grid(
      n,
      [&](int i, int j) {
        return j <= 5 ? std::array<double, 3>{double(i), double(j), 0.0}
                      : std::array<double, 3>{double(i), 5.0, double(j - 5)};
      },
      [](int i, int j) { return (i + j) % 2 == 0; });
  const Mesh before = m;
  const EdgeFlipStats s = FlipEdges(&m, On());
  ASSERT_TRUE(CheckMesh(m, false).ok);
  EXPECT_EQ(Boundary(m), Boundary(before));
  for (std::size_t f = 0; f < m.faces.size() / 3; ++f) {
    const auto nn = Normal(m, f);
    EXPECT_TRUE(nn[2] > 0.999 || nn[1] < -0.999) << "face " << f << " normal " << nn[0] << " " << nn[1] << " " << nn[2];
  }
  // Within the floor and the wall a flip gains nothing (both diagonals lie flat).
  EXPECT_EQ(s.flips, 0);
  EXPECT_EQ(m.faces, before.faces);
}

// The property: on 1,000 random perturbations the result is a manifold with the same
// boundary edges, the same vertices bit for bit, the same number of faces, and no larger sum of
// angles between neighbouring faces.
TEST(EdgeFlipsTest, AnyInputStaysAManifoldWithTheSameBoundary) {
  std::mt19937 rng(4545);
  int changed = 0, tried = 0;
  for (int trial = 0; trial < 1000; ++trial) {
    Mesh m = RandomSheet(rng, 4 + static_cast<int>(rng() % 7));
    if (!CheckMesh(m, false).ok) continue;
    ++tried;
    const Mesh before = m;
    EdgeFlipOptions o = On();
    o.min_gain_degrees = std::uniform_real_distribution<double>(0.01, 10.0)(rng);
    o.min_angle_degrees = std::uniform_real_distribution<double>(0.0, 20.0)(rng);
    const EdgeFlipStats s = FlipEdges(&m, o);
    if (s.flips > 0) ++changed;
    const ManifoldCheckResult check = CheckMesh(m, false);
    ASSERT_TRUE(check.ok) << "trial " << trial << ": " << check.message;
    ASSERT_EQ(Boundary(m), Boundary(before)) << "trial " << trial;
    ASSERT_EQ(m.faces.size(), before.faces.size()) << "trial " << trial;
    ASSERT_EQ(m.vertices, before.vertices) << "trial " << trial;
    ASSERT_EQ(m.point_ids, before.point_ids);
    ASSERT_LE(s.degrees_sum_after, s.degrees_sum_before + 1e-9) << "trial " << trial;
  }
  EXPECT_GT(tried, 700);
  EXPECT_GT(changed, 500);  // the property is tested where the pass did something
}

// A streamed surface is flipped part by part: two parts, each done alone, still make a manifold
// with the whole's boundary (no edge made by both, none made that the other holds).
TEST(EdgeFlipsTest, PartsDoneOneByOneStillFitTogether) {
  std::mt19937 rng(46);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  int changed = 0;
  for (int trial = 0; trial < 1000; ++trial) {
    Mesh m = RandomSheet(rng, 5 + static_cast<int>(rng() % 8));
    if (!CheckMesh(m, false).ok) continue;
    // Two parts cut by a random line through the grid (faces by their first vertex).
    const int n = static_cast<int>(std::lround(std::sqrt(static_cast<double>(m.point_ids.size()))));
    const double angle = M_PI * u(rng), c = 0.5 * n * (1.0 + 0.5 * u(rng));
    std::vector<SurfacePart> parts = testing::CutInTwo(m, angle, c);
    EdgeFlipOptions o = On();
    o.min_angle_degrees = 0.0;  // as many flips as can be
    Mesh merged = m;
    merged.faces.clear();
    for (SurfacePart& p : parts) {
      if (FlipEdges(&p, o).flips > 0) ++changed;
      ASSERT_EQ(p.vertices, m.vertices);
      merged.faces.insert(merged.faces.end(), p.faces.begin(), p.faces.end());
    }
    const ManifoldCheckResult check = CheckMesh(merged, false);
    ASSERT_TRUE(check.ok) << "trial " << trial << ": " << check.message;
    ASSERT_EQ(Boundary(merged), Boundary(m)) << "trial " << trial;
  }
  EXPECT_GT(changed, 500);
}

// The real seam of imr-synth's default job (plane_retriangulation_test's fixture: releases 25
// and 26 of its stream): flipped piece by piece, every vertex that was one fan still is, and no
// directed edge repeats.
TEST(EdgeFlipsTest, TheRealSeamStaysOneFanPerVertex) {
  std::vector<SurfacePart> parts =
      testing::ReadSurfaceParts(std::string(IMR_SOURCE_DIR) + "/host/engine/testing/pinched_seam_parts.txt");
  ASSERT_EQ(parts.size(), 2u);
  int64_t flips = 0;
  const testing::FansAfterPass fans =
      testing::FansAfter(parts, [&](SurfacePart* p) { flips += FlipEdges(p, On()).flips; });
  EXPECT_GT(flips, 100);
  EXPECT_EQ(fans.error, "");
  EXPECT_EQ(fans.broken, std::vector<int64_t>{}) << "vertex keys no longer one fan";
  EXPECT_GT(fans.one_fan, 1000);
}

TEST(EdgeFlipsTest, OptionsAreChecked) {
  EdgeFlipOptions o;
  EXPECT_EQ(o.Check(), "");
  EXPECT_FALSE(o.enabled);
  Mesh m = Grid(3, [](int i, int j) { return std::array<double, 3>{double(i), double(j), double(i * j)}; },
                [](int, int) { return false; });
  const Mesh before = m;
  EXPECT_EQ(FlipEdges(&m, o).flips, 0);  // off: untouched
  EXPECT_EQ(m.faces, before.faces);
  o.min_gain_degrees = 0.0;
  EXPECT_NE(o.Check().find("min_gain_degrees"), std::string::npos);
  o.min_gain_degrees = 1.0;
  o.min_angle_degrees = 60.0;
  EXPECT_NE(o.Check().find("min_angle_degrees"), std::string::npos);
}

}  // namespace
}  // namespace imr::engine
