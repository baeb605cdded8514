// FilterNormals: a noisy plane gets flat, a corner stays a corner, and whatever the input the
// faces, the boundary and the seam vertices stay and no face turns over, whole or in parts.
#include "host/engine/normal_filter.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <map>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "host/engine/mesh_topology.h"
#include "host/engine/testing/surface_checks.h"

namespace imr::engine {
namespace {

using testing::Boundary;
using testing::Grid;
using testing::RandomSheet;
using testing::Roughness;
constexpr auto Normal = &testing::FaceNormal;

NormalFilterOptions On(int iterations = 5) {
  NormalFilterOptions o;
  o.iterations = iterations;
  return o;
}

double Dot(const std::array<double, 3>& a, const std::array<double, 3>& b) {
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}
double AngleDegrees(const std::array<double, 3>& a, const std::array<double, 3>& b) {
  return std::acos(std::clamp(Dot(a, b), -1.0, 1.0)) * 180.0 / M_PI;
}

// Vertices whose fan is one closed cycle in `faces` (those the pass may move).
std::vector<bool> Closed(const std::vector<uint32_t>& faces, std::size_t nv) {
  std::vector<std::vector<std::pair<uint32_t, uint32_t>>> links(nv);
  for (std::size_t f = 0; f < faces.size(); f += 3)
    for (int k = 0; k < 3; ++k) links[faces[f + k]].emplace_back(faces[f + (k + 1) % 3], faces[f + (k + 2) % 3]);
  std::vector<bool> closed(nv, false);
  std::vector<std::pair<uint32_t, uint32_t>> by_first;
  std::vector<uint32_t> seconds;
  for (std::size_t v = 0; v < nv; ++v)
    closed[v] = !links[v].empty() &&
                CheckLink(links[v].data(), links[v].size(), &by_first, &seconds) == LinkShape::kCycle;
  return closed;
}

// Whether vertex v has the same position in both (bit for bit).
bool Same(const std::vector<double>& a, const std::vector<double>& b, std::size_t v) {
  return a[3 * v] == b[3 * v] && a[3 * v + 1] == b[3 * v + 1] && a[3 * v + 2] == b[3 * v + 2];
}

// A 20 x 20 plane (edges 1) with its vertices off the boundary moved up or down by up to 0.2
// (the boundary stays where it is, so noise there would stay): neighbouring faces meet at 12.5
// degrees; after the pass at under 1.
TEST(NormalFilterTest, ANoisyPlaneGetsFlat) {
  const int n = 20;
  std::mt19937 rng(45);
  std::uniform_real_distribution<double> u(-0.2, 0.2);
  const auto inside = [&](int i, int j) { return i > 0 && j > 0 && i + 1 < n && j + 1 < n; };
  Mesh m = Grid(
      n, [&](int i, int j) { return std::array<double, 3>{double(i), double(j), inside(i, j) ? u(rng) : 0.0}; },
      [](int i, int j) { return (i + j) % 2 == 0; });
  const Mesh before = m;
  const double rough_before = Roughness(m);
  ASSERT_GT(rough_before, 10.0);
  const NormalFilterStats s = FilterNormals(&m, On());
  const double rough_after = Roughness(m);
  EXPECT_LT(rough_after, 1.0) << "before " << rough_before;  // 12.5 -> 0.27 degrees
  EXPECT_EQ(s.iterations, 5);
  EXPECT_EQ(s.vertices_moved, (n - 2) * (n - 2));  // every vertex off the boundary
  EXPECT_EQ(s.moves_reverted, 0);
  EXPECT_NEAR(s.degrees_sum_before / static_cast<double>(s.edges), rough_before, 1e-9);
  EXPECT_NEAR(s.degrees_sum_after / static_cast<double>(s.edges), rough_after, 1e-9);
  EXPECT_EQ(m.faces, before.faces);
  EXPECT_EQ(m.point_ids, before.point_ids);
  const std::vector<bool> closed = Closed(m.faces, m.point_ids.size());
  for (std::size_t v = 0; v < m.point_ids.size(); ++v) {
    if (closed[v]) continue;
    EXPECT_TRUE(Same(m.vertices, before.vertices, v)) << "boundary vertex " << v;
  }
  for (std::size_t f = 0; f < m.faces.size() / 3; ++f) EXPECT_GT(Normal(m, f)[2], 0.999) << "face " << f;
}

// A floor (z = 0) meeting a wall (y = 7) at a right angle, every vertex off the boundary moved
// by up to 0.15 along its plane's normal (the corner's row along both). The faces end within a few degrees of
// their plane, the corner's edge within a fraction of an edge of its line: the two sides are
// filtered apart, where Taubin's smoothing rounds the corner off.
TEST(NormalFilterTest, ANoisyCornerStaysACorner) {
  const int n = 16, corner = 7;
  std::mt19937 rng(90);
  std::uniform_real_distribution<double> noise(-0.15, 0.15);
  int i_now = 0, j_now = 0;
  const auto u = [&](std::mt19937&) {
    return i_now > 0 && j_now > 0 && i_now + 1 < n && j_now + 1 < n ? noise(rng) : 0.0;
  };
  Mesh m = Grid(
      n,
      [&](int i, int j) {
        i_now = i, j_now = j;
        if (j < corner) return std::array<double, 3>{double(i), double(j), u(rng)};
        if (j > corner) return std::array<double, 3>{double(i), corner + u(rng), double(j - corner)};
        return std::array<double, 3>{double(i), corner + u(rng), u(rng)};
      },
      [](int i, int j) { return (i + j) % 2 == 0; });
  const Mesh before = m;
  const std::array<double, 3> floor = {0, 0, 1}, wall = {0, -1, 0};
  // Off the corner's row, each face's plane is known by its vertices' rows.
  const auto side = [&](std::size_t f) {
    int lo = n, hi = -1;
    for (int k = 0; k < 3; ++k) {
      const int j = static_cast<int>(m.faces[3 * f + k] / n);
      lo = std::min(lo, j), hi = std::max(hi, j);
    }
    return hi <= corner ? 0 : lo >= corner ? 1 : -1;
  };
  double worst_before = 0.0;
  for (std::size_t f = 0; f < m.faces.size() / 3; ++f)
    if (side(f) >= 0) worst_before = std::max(worst_before, AngleDegrees(Normal(m, f), side(f) == 0 ? floor : wall));
  ASSERT_GT(worst_before, 10.0);

  Mesh taubin = m;
  SmoothTaubin(&taubin, 10);
  const NormalFilterStats s = FilterNormals(&m, On());
  EXPECT_GT(s.vertices_moved, 0);
  double worst = 0.0, worst_edge = 0.0, mean = 0.0;
  int counted = 0;
  for (std::size_t f = 0; f < m.faces.size() / 3; ++f) {
    if (side(f) < 0) continue;
    const double a = AngleDegrees(Normal(m, f), side(f) == 0 ? floor : wall);
    worst = std::max(worst, a), mean += a, ++counted;
  }
  mean /= counted;
  // The corner's row: its distance from the line y = 7, z = 0.
  for (int i = 1; i + 1 < n; ++i) {
    const double* p = &m.vertices[3 * (corner * n + i)];
    worst_edge = std::max(worst_edge, std::hypot(p[1] - corner, p[2]));
  }
  EXPECT_LT(worst, 5.0) << "before " << worst_before;  // 2.2 degrees
  EXPECT_LT(mean, 1.5);                               // 0.56
  EXPECT_LT(worst_edge, 0.15);                        // 0.07 edge lengths
  // Taubin's smoothing (10 rounds) on the same input, for contrast: the corner rounded off.
  double taubin_worst = 0.0, taubin_edge = 0.0;
  for (std::size_t f = 0; f < taubin.faces.size() / 3; ++f)
    if (side(f) >= 0) taubin_worst = std::max(taubin_worst, AngleDegrees(Normal(taubin, f), side(f) == 0 ? floor : wall));
  for (int i = 1; i + 1 < n; ++i) {
    const double* p = &taubin.vertices[3 * (corner * n + i)];
    taubin_edge = std::max(taubin_edge, std::hypot(p[1] - corner, p[2]));
  }
  EXPECT_GT(taubin_worst, 15.0);
  EXPECT_GT(taubin_edge, 0.3);
  EXPECT_EQ(m.faces, before.faces);
}

// The property: on 1,000 random sheets (noise, spikes, folds, holes, bends) the faces,
// the point ids and the boundary stay, the boundary's vertices bit for bit, and no face turns
// more than max_turn_degrees from where it was or becomes degenerate.
TEST(NormalFilterTest, AnyInputStaysAManifoldWithTheSameBoundary) {
  std::mt19937 rng(4545);
  int changed = 0, tried = 0;
  int64_t reverted = 0;
  for (int trial = 0; trial < 1000; ++trial) {
    Mesh m = RandomSheet(rng, 4 + static_cast<int>(rng() % 7));
    if (!CheckMesh(m, false).ok) continue;
    ++tried;
    const Mesh before = m;
    NormalFilterOptions o = On(1 + static_cast<int>(rng() % 6));
    o.sigma_range = std::uniform_real_distribution<double>(0.1, 1.0)(rng);
    o.sigma_spatial = std::uniform_real_distribution<double>(0.3, 3.0)(rng);
    o.max_turn_degrees = std::uniform_real_distribution<double>(20.0, 90.0)(rng);
    const NormalFilterStats s = FilterNormals(&m, o);
    if (s.vertices_moved > 0) ++changed;
    reverted += s.moves_reverted;
    const ManifoldCheckResult check = CheckMesh(m, false);
    ASSERT_TRUE(check.ok) << "trial " << trial << ": " << check.message;
    ASSERT_EQ(m.faces, before.faces) << "trial " << trial;
    ASSERT_EQ(m.point_ids, before.point_ids);
    ASSERT_EQ(Boundary(m), Boundary(before)) << "trial " << trial;
    const std::vector<bool> closed = Closed(m.faces, m.point_ids.size());
    for (std::size_t v = 0; v < m.point_ids.size(); ++v) {
      if (closed[v]) continue;
      ASSERT_TRUE(Same(m.vertices, before.vertices, v)) << "trial " << trial << " vertex " << v;
    }
    for (std::size_t f = 0; f < m.faces.size() / 3; ++f) {
      const auto was = Normal(before, f), now = Normal(m, f);
      if (!std::isfinite(was[0])) continue;  // degenerate before
      ASSERT_TRUE(std::isfinite(now[0])) << "trial " << trial << ": face " << f << " became degenerate";
      ASSERT_LT(AngleDegrees(was, now), o.max_turn_degrees) << "trial " << trial << ": face " << f;
    }
  }
  EXPECT_GT(tried, 700);
  EXPECT_GT(changed, 600);  // the property is tested where the pass did something
  EXPECT_GT(reverted, 0);   // ... and where the guard held a face back
}

// A streamed surface is filtered part by part: in each of two parts cut from a random sheet,
// the seam vertices (whose fan is open in the part) keep their positions bit for bit, so the
// parts still meet; a vertex moves in one part at most.
TEST(NormalFilterTest, SeamVerticesOfAPartDoNotMove) {
  std::mt19937 rng(46);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  int moved_somewhere = 0, seams = 0;
  for (int trial = 0; trial < 300; ++trial) {
    Mesh m = RandomSheet(rng, 5 + static_cast<int>(rng() % 8));
    if (!CheckMesh(m, false).ok) continue;
    const int n = static_cast<int>(std::lround(std::sqrt(static_cast<double>(m.point_ids.size()))));
    const double angle = M_PI * u(rng), c = 0.5 * n * (1.0 + 0.5 * u(rng));
    std::vector<SurfacePart> parts = testing::CutInTwo(m, angle, c);
    std::vector<int> moved_in(m.point_ids.size(), 0);
    for (SurfacePart& p : parts) {
      const std::vector<double> was = p.vertices;
      const std::vector<uint32_t> faces = p.faces;
      const std::vector<bool> closed = Closed(p.faces, p.keys.size());
      const NormalFilterStats s = FilterNormals(&p, On(3));
      ASSERT_EQ(p.faces, faces);
      for (std::size_t v = 0; v < p.keys.size(); ++v) {
        if (!Same(p.vertices, was, v)) {
          ++moved_in[v];
          ASSERT_TRUE(closed[v]) << "trial " << trial << ": vertex " << v << " moved, its fan open in the part";
        } else if (!closed[v]) {
          ++seams;
        }
      }
      if (s.vertices_moved > 0) ++moved_somewhere;
    }
    for (std::size_t v = 0; v < moved_in.size(); ++v) ASSERT_LE(moved_in[v], 1) << "trial " << trial;
  }
  EXPECT_GT(moved_somewhere, 300);
  EXPECT_GT(seams, 1000);
}

// The real seam of imr-synth's default job (plane_retriangulation_test's fixture: releases 25
// and 26 of its stream): each piece filtered alone, every vertex both pieces name stays where
// both have it, and the pieces get smoother.
TEST(NormalFilterTest, TheRealSeamStaysWhereBothPiecesHaveIt) {
  std::vector<SurfacePart> parts =
      testing::ReadSurfaceParts(std::string(IMR_SOURCE_DIR) + "/host/engine/testing/pinched_seam_parts.txt");
  ASSERT_EQ(parts.size(), 2u);
  std::map<int64_t, int> named;
  for (const SurfacePart& p : parts)
    for (int64_t key : p.keys) ++named[key];
  int64_t moved = 0, shared = 0;
  for (SurfacePart& p : parts) {
    const std::vector<double> was = p.vertices;
    const NormalFilterStats s = FilterNormals(&p, On());
    moved += s.vertices_moved;
    EXPECT_LT(s.degrees_sum_after, s.degrees_sum_before);
    for (std::size_t v = 0; v < p.keys.size(); ++v) {
      if (named[p.keys[v]] < 2) continue;
      ++shared;
      EXPECT_TRUE(Same(p.vertices, was, v)) << "key " << p.keys[v];
    }
  }
  EXPECT_GT(moved, 1000);
  EXPECT_GT(shared, 10);
  std::string error;
  testing::LinkShapesByKey(parts, &error);
  EXPECT_EQ(error, "");
}

TEST(NormalFilterTest, OptionsAreChecked) {
  NormalFilterOptions o;
  EXPECT_EQ(o.Check(), "");
  EXPECT_FALSE(o.enabled());
  Mesh m = Grid(4, [](int i, int j) { return std::array<double, 3>{double(i), double(j), double(i * j % 3)}; });
  const Mesh before = m;
  EXPECT_EQ(FilterNormals(&m, o).vertices_moved, 0);  // off: untouched
  EXPECT_EQ(m.vertices, before.vertices);
  o.iterations = -1;
  EXPECT_NE(o.Check().find("iterations"), std::string::npos);
  o.iterations = 1;
  o.sigma_range = 0.0;
  EXPECT_NE(o.Check().find("sigma_range"), std::string::npos);
  o.sigma_range = 0.35;
  o.sigma_spatial = -1.0;
  EXPECT_NE(o.Check().find("sigma_spatial"), std::string::npos);
  o.sigma_spatial = 1.0;
  o.max_turn_degrees = 0.0;
  EXPECT_NE(o.Check().find("max_turn_degrees"), std::string::npos);
  EngineOptions e;
  e.filter_normals = 3;
  e.filter_normals_range = 0.5;
  e.filter_normals_spatial = 2.0;
  const NormalFilterOptions f = NormalFilterOptions::FromEngine(e);
  EXPECT_EQ(f.iterations, 3);
  EXPECT_EQ(f.sigma_range, 0.5);
  EXPECT_EQ(f.sigma_spatial, 2.0);
}

}  // namespace
}  // namespace imr::engine
