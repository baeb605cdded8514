#include "host/synthetic/scene.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <tuple>

#include "host/synthetic/evaluation.h"

namespace imr::synthetic {
namespace {

TEST(SceneTest, RoomDistanceAndIntersection) {
  const Scene room = Scene::ClosedRoom({-5, -4, 0}, {5, 4, 3});
  EXPECT_EQ(room.rects().size(), 6u);
  EXPECT_NEAR(room.Distance({0, 0, 1.5}), 1.5, 1e-12);
  EXPECT_NEAR(room.Distance({4.5, 0, 1.5}), 0.5, 1e-12);
  EXPECT_NEAR(room.Distance({7, 0, 1.5}), 2.0, 1e-12);  // Outside, facing the wall.
  double t = 0;
  ASSERT_TRUE(room.Intersect({0, 0, 1.5}, {1, 0, 0}, 100, &t));
  EXPECT_NEAR(t, 5.0, 1e-12);
  ASSERT_TRUE(room.Intersect({0, 0, 1.5}, {0, 0, -1}, 100, &t));
  EXPECT_NEAR(t, 1.5, 1e-12);
  EXPECT_FALSE(room.Intersect({0, 0, 1.5}, {1, 0, 0}, 4.0, &t));  // Beyond t_max.
  EXPECT_TRUE(room.Visible({0, 0, 1.5}, {4, 3, 2}));
  EXPECT_FALSE(room.Visible({0, 0, 1.5}, {6, 0, 1.5}));
}

TEST(SceneTest, StreetHasGroundFacadesAndBoxes) {
  const Scene street = Scene::StreetCanyon(200, 3);
  EXPECT_GT(street.rects().size(), 3u + 5u * 20u);  // Ground, two facades, dozens of boxes.
  EXPECT_NEAR(street.Distance({0, 100, 1.0}), 1.0, 1e-9);  // Mid-street: the ground.
  double t = 0;
  ASSERT_TRUE(street.Intersect({0, 100, 1.65}, {1, 0, 0}, 100, &t));
  EXPECT_LE(t, 8.0);  // A box or the facade at x = 8.
  ASSERT_TRUE(street.Intersect({0, 100, 5.0}, {1, 0, 0}, 100, &t));
  EXPECT_NEAR(t, 8.0, 1e-9);  // Above the boxes: the facade.
  EXPECT_FALSE(street.Intersect({0, 100, 5.0}, {0, 0, 1}, 100, &t));  // The sky.
  // Same seed, same scene.
  EXPECT_EQ(Scene::StreetCanyon(200, 3).rects().size(), street.rects().size());
}

// A query's cost follows what is near it, not the street's length: the street's ground and
// facades (as long as the street) are tried by every query, the boxes only where they are; and
// the index answers as trying every rect does.
TEST(SceneTest, QueriesNearAPointCostTheSameOnAnyLengthOfStreet) {
  const Scene shortish = Scene::StreetCanyon(2000, 5), km20 = Scene::StreetCanyon(20000, 5);
  EXPECT_GT(km20.rects().size(), 9u * shortish.rects().size());  // boxes all along: linear
  EXPECT_LT(km20.rects().size(), 30000u);                          // ~21,000 rects for 20 km
  const auto near_short = shortish.RectsNear(-40, 1500, 40, 1580);
  const auto near_long = km20.RectsNear(-40, 19500, 40, 19580);
  EXPECT_LT(near_long.size(), 140u);  // ~100 m of street in the box's bins: ~20 boxes
  EXPECT_LT(near_long.size(), near_short.size() + 15);
  EXPECT_TRUE(std::is_sorted(near_long.begin(), near_long.end()));
  EXPECT_EQ(std::adjacent_find(near_long.begin(), near_long.end()), near_long.end());
  // Every rect whose bounding box meets the query box is among them.
  for (int i = 0; i < static_cast<int>(km20.rects().size()); ++i) {
    const Rect& r = km20.rects()[i];
    const double ey = std::abs(r.u[1]) * r.half_u + std::abs(r.v[1]) * r.half_v;
    if (r.center[1] + ey >= 19500 && r.center[1] - ey <= 19580) {
      EXPECT_TRUE(std::binary_search(near_long.begin(), near_long.end(), i)) << i;
    }
  }
  // Index and brute force agree on hits and distances.
  std::mt19937_64 rng(2);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int k = 0; k < 500; ++k) {
    const Vec3 o{6.0 * u(rng), 19000.0 + 900.0 * u(rng), 2.0 + 1.5 * u(rng)};
    const Vec3 d = Normalized({u(rng), u(rng), 0.5 * u(rng)});
    double best = std::numeric_limits<double>::infinity(), nearest = best;
    for (const Rect& r : km20.rects()) {
      const Vec3 n = Cross(r.u, r.v);
      const double den = Dot(d, n);
      if (std::abs(den) >= 1e-12) {
        const double t = Dot(Sub(r.center, o), n) / den;
        const Vec3 q = Sub(Add(o, Scale(d, t)), r.center);
        if (t > 1e-9 && t <= 40.0 && std::abs(Dot(q, r.u)) <= r.half_u &&
            std::abs(Dot(q, r.v)) <= r.half_v)
          best = std::min(best, t);
      }
      const Vec3 q = Sub(o, r.center);
      const double ds = std::max(std::abs(Dot(q, r.u)) - r.half_u, 0.0);
      const double dt = std::max(std::abs(Dot(q, r.v)) - r.half_v, 0.0);
      nearest = std::min(nearest, std::sqrt(Dot(q, n) * Dot(q, n) + ds * ds + dt * dt));
    }
    double t = -1.0;
    const bool hit = km20.Intersect(o, d, 40.0, &t);
    EXPECT_EQ(hit, best < std::numeric_limits<double>::infinity());
    if (hit) {
      EXPECT_EQ(t, best);
    }
    EXPECT_EQ(km20.Visible(o, Add(o, Scale(d, 40.0)), 0.0), !hit);
    EXPECT_EQ(km20.Distance(o), nearest);
  }
}

TEST(EvaluationTest, PointTriangleDistanceAndMeshAccuracy) {
  EXPECT_NEAR(PointTriangleDistance({0.2, 0.2, 1}, {0, 0, 0}, {1, 0, 0}, {0, 1, 0}), 1.0, 1e-12);
  EXPECT_NEAR(PointTriangleDistance({2, 0, 0}, {0, 0, 0}, {1, 0, 0}, {0, 1, 0}), 1.0, 1e-12);
  const Scene plane = Scene::Plane(10.0);
  // A square at z = 0.1 over the plane: 0.1 m from the scene, covers the true points under it.
  const std::vector<double> v = {-1, -1, 0.1, 1, -1, 0.1, 1, 1, 0.1, -1, 1, 0.1};
  const std::vector<uint32_t> f = {0, 1, 2, 0, 2, 3};
  const MeshAccuracy a = EvaluateMesh(plane, v, f, {{0, 0, 0}, {0.5, 0.5, 0}, {5, 5, 0}}, 0.2);
  EXPECT_NEAR(a.mean_mesh_to_scene, 0.1, 1e-9);
  EXPECT_NEAR(a.area, 4.0, 1e-9);
  EXPECT_NEAR(a.precision, 1.0, 1e-12);
  EXPECT_NEAR(a.completeness, 2.0 / 3.0, 1e-12);
}

// The grid search is exact: the same distances, bit for bit, as trying every triangle, for the
// cell sizes EvaluateMesh (the cap) and the benchmarks (2 m) use.
TEST(EvaluationTest, TruthToMeshDistancesAreTheBruteForceMinimum) {
  std::mt19937_64 g(7);
  std::uniform_real_distribution<double> u(-30.0, 30.0), small(-1.5, 1.5);
  std::vector<double> v;
  std::vector<uint32_t> f;
  for (uint32_t t = 0; t < 300; ++t) {
    const Vec3 c = {u(g), u(g), u(g) / 6};
    for (int k = 0; k < 3; ++k)
      v.insert(v.end(), {c[0] + small(g), c[1] + small(g), c[2] + small(g)});
    f.insert(f.end(), {3 * t, 3 * t + 1, 3 * t + 2});
  }
  std::vector<Vec3> truth;
  for (int i = 0; i < 2000; ++i) truth.push_back({u(g), u(g), u(g) / 6});
  for (const auto& [cap, cell, span] :
       {std::tuple{5.0, 5.0, int64_t{64}}, {20.0, 2.0, int64_t{200}}}) {
    const std::vector<double> d = TruthToMeshDistances(v, f, truth, cap, cell, span);
    ASSERT_EQ(d.size(), truth.size());
    int capped = 0;
    for (std::size_t i = 0; i < truth.size(); ++i) {
      double best = cap;
      for (std::size_t t = 0; t < f.size() / 3; ++t)
        best =
            std::min(best, PointTriangleDistance(truth[i], {v[9 * t], v[9 * t + 1], v[9 * t + 2]},
                                                 {v[9 * t + 3], v[9 * t + 4], v[9 * t + 5]},
                                                 {v[9 * t + 6], v[9 * t + 7], v[9 * t + 8]}));
      ASSERT_EQ(d[i], best) << "point " << i << ", cap " << cap;
      capped += best == cap;
    }
    EXPECT_LT(capped, static_cast<int>(truth.size())) << "some points are within the cap";
  }
}

// A road x in [-4, 4], y in [0, 20] with a box 2 m x 4 m x 1.5 m standing on it at x in [1, 3],
// y in [10, 14] (its top marked as Scene::StreetCanyon marks box tops).
// EvaluateMesh runs on every core it may use; its figures are the bits one thread gives
// (the sums in triangle and point order), recomputed here serially.
TEST(EvaluationTest, MeshAccuracyIsTheSerialSumOnAnyNumberOfThreads) {
  const Scene street = Scene::StreetCanyon(100, 3);
  std::mt19937_64 g(11);
  std::uniform_real_distribution<double> x(-9.0, 9.0), y(0.0, 100.0), z(0.0, 6.0), small(-0.8, 0.8);
  std::vector<double> v;
  std::vector<uint32_t> f;
  for (uint32_t t = 0; t < 3000; ++t) {  // several chunks of triangles
    const Vec3 c = {x(g), y(g), z(g)};
    for (int k = 0; k < 3; ++k)
      v.insert(v.end(), {c[0] + small(g), c[1] + small(g), c[2] + small(g)});
    f.insert(f.end(), {3 * t, 3 * t + 1, 3 * t + 2});
  }
  std::vector<Vec3> truth;
  for (int i = 0; i < 3000; ++i) truth.push_back({x(g), y(g), z(g)});
  const double tau = 0.2, cap = 5.0;
  const MeshAccuracy a = EvaluateMesh(street, v, f, truth, tau, cap);
  double sum = 0.0, within = 0.0, area = 0.0;
  for (size_t t = 0; t < f.size() / 3; ++t) {
    auto p = [&](int k) {
      return Vec3{v[3 * f[3 * t + k]], v[3 * f[3 * t + k] + 1], v[3 * f[3 * t + k] + 2]};
    };
    const Vec3 a0 = p(0), b0 = p(1), c0 = p(2);
    const double ar = 0.5 * Norm(Cross(Sub(b0, a0), Sub(c0, a0)));
    if (ar <= 0.0) continue;
    const Vec3 q[4] = {Scale(Add(a0, Add(b0, c0)), 1.0 / 3.0),
                       Scale(Add(Scale(a0, 4), Add(b0, c0)), 1.0 / 6.0),
                       Scale(Add(Scale(b0, 4), Add(a0, c0)), 1.0 / 6.0),
                       Scale(Add(Scale(c0, 4), Add(a0, b0)), 1.0 / 6.0)};
    for (const Vec3& s : q) {
      const double d = street.Distance(s);
      sum += 0.25 * ar * d;
      if (d <= tau) within += 0.25 * ar;
    }
    area += ar;
  }
  EXPECT_EQ(a.area, area);
  EXPECT_EQ(a.mean_mesh_to_scene, sum / area);
  EXPECT_EQ(a.precision, within / area);
  double tsum = 0.0;
  size_t near = 0;
  for (const double d : TruthToMeshDistances(v, f, truth, cap, cap, 64)) {
    tsum += d;
    near += d <= tau ? 1 : 0;
  }
  EXPECT_EQ(a.mean_truth_to_mesh, tsum / truth.size());
  EXPECT_EQ(a.completeness, static_cast<double>(near) / truth.size());
  EXPECT_GT(a.completeness, 0.0);
  EXPECT_GT(a.precision, 0.0);

  // The same mesh in blocks of uneven size, each with its own vertices (as a long drive's mesh
  // is read back from disk): the same mesh -> scene figures, bit for bit.
  MeshToScene blocks(street, tau);
  for (size_t first = 0, n = 1; first < f.size() / 3; first += n, n = 2 * n + 1) {
    const size_t count = std::min(n, f.size() / 3 - first);
    std::vector<double> bv(v.begin() + static_cast<std::ptrdiff_t>(9 * first),
                           v.begin() + static_cast<std::ptrdiff_t>(9 * (first + count)));
    std::vector<uint32_t> bf;
    for (uint32_t i = 0; i < 3 * count; ++i) bf.push_back(i);
    blocks.AddTriangles(bv, bf);
  }
  const MeshAccuracy b = blocks.Result();
  EXPECT_EQ(b.triangles, a.triangles);
  EXPECT_EQ(b.area, a.area);
  EXPECT_EQ(b.mean_mesh_to_scene, a.mean_mesh_to_scene);
  EXPECT_EQ(b.precision, a.precision);
}

// Both directions in blocks (a long drive's mesh read back from disk, the truth -> mesh distances
// a running minimum per true point): EvaluateMesh's figures bit for bit, for blocks that each
// cover a stretch of the street (most true points beyond a block's reach) or all of it.
TEST(EvaluationTest, MeshAccuracyInBlocksIsTheWholeMeshFigures) {
  const Scene street = Scene::StreetCanyon(100, 3);
  std::mt19937_64 g(13);
  std::uniform_real_distribution<double> x(-9.0, 9.0), y(0.0, 100.0), z(0.0, 6.0), small(-0.8, 0.8);
  std::vector<Vec3> centres;
  for (int t = 0; t < 4000; ++t) centres.push_back({x(g), y(g), z(g)});
  std::vector<Vec3> truth;
  for (int i = 0; i < 3000; ++i) truth.push_back({x(g), y(g), z(g)});
  const double tau = 0.2, cap = 5.0;
  for (const bool along_the_street : {true, false}) {
    std::vector<Vec3> c = centres;
    if (along_the_street)
      std::sort(c.begin(), c.end(), [](const Vec3& a, const Vec3& b) { return a[1] < b[1]; });
    std::vector<double> v;
    std::vector<uint32_t> f;
    for (uint32_t t = 0; t < c.size(); ++t) {
      for (int k = 0; k < 3; ++k)
        v.insert(v.end(), {c[t][0] + small(g), c[t][1] + small(g), c[t][2] + small(g)});
      f.insert(f.end(), {3 * t, 3 * t + 1, 3 * t + 2});
    }
    const MeshAccuracy a = EvaluateMesh(street, v, f, truth, tau, cap);
    MeshAccuracyInBlocks blocks(street, truth, tau, cap);
    int count = 0;
    for (size_t first = 0, n = 7; first < f.size() / 3; first += n, n = n * 3 / 2 + 5, ++count) {
      const size_t m = std::min(n, f.size() / 3 - first);
      // Each block with its own vertices, numbered from 0, and one unused vertex first.
      std::vector<double> bv = {1e6, 1e6, 1e6};
      bv.insert(bv.end(), v.begin() + static_cast<std::ptrdiff_t>(9 * first),
                v.begin() + static_cast<std::ptrdiff_t>(9 * (first + m)));
      std::vector<uint32_t> bf;
      for (uint32_t i = 0; i < 3 * m; ++i) bf.push_back(i + 1);
      blocks.AddTriangles(bv, bf);
    }
    ASSERT_GT(count, 5);
    const MeshAccuracy b = blocks.Result();
    EXPECT_EQ(b.triangles, a.triangles);
    EXPECT_EQ(b.area, a.area);
    EXPECT_EQ(b.mean_mesh_to_scene, a.mean_mesh_to_scene);
    EXPECT_EQ(b.precision, a.precision);
    EXPECT_EQ(b.mean_truth_to_mesh, a.mean_truth_to_mesh) << along_the_street;
    EXPECT_EQ(b.completeness, a.completeness) << along_the_street;
    EXPECT_GT(a.completeness, 0.0);
    EXPECT_LT(a.mean_truth_to_mesh, cap);
  }
  // No truth: mesh -> scene alone, as EvaluateMesh without true points.
  MeshAccuracyInBlocks none(street, {}, tau, cap);
  none.AddTriangles({0, 10, 0, 1, 10, 0, 0, 11, 0}, {0, 1, 2});
  EXPECT_EQ(none.Result().completeness, 0.0);
  EXPECT_EQ(none.Result().triangles, 1u);
}

TEST(SampleRoadSurfaceTest, GroundOnlyNotUnderBoxesDenseAndDeterministic) {
  Scene s;
  s.AddRect({{0, 10, 0}, {1, 0, 0}, {0, 1, 0}, 4, 10, Material::kGround});
  const Scene open = s;
  s.AddRect({{2, 12, 1.5}, {1, 0, 0}, {0, 1, 0}, 1, 2, Material::kBoxTop, 0});
  const std::vector<Vec3> a = SampleRoadSurface(s, 100.0, 7);
  // 160 m^2 of road less the box's 8 m^2 at 100 per m^2: one point in each 10 cm square, and the
  // squares tile the road and the footprint exactly.
  EXPECT_EQ(a.size(), 15200u);
  for (const Vec3& p : a) {
    ASSERT_EQ(p[2], 0.0);
    ASSERT_TRUE(std::abs(p[0]) <= 4.0 && p[1] >= 0.0 && p[1] <= 20.0);
    ASSERT_FALSE(p[0] >= 1.0 && p[0] <= 3.0 && p[1] >= 10.0 && p[1] <= 14.0) << p[0] << " " << p[1];
  }
  std::size_t in_square = 0;  // a 1 m square away from the box
  for (const Vec3& p : a) in_square += p[0] >= -3 && p[0] < -2 && p[1] >= 5 && p[1] < 6;
  EXPECT_EQ(in_square, 100u);
  EXPECT_EQ(SampleRoadSurface(s, 100.0, 7), a);
  EXPECT_NE(SampleRoadSurface(s, 100.0, 8), a);
  EXPECT_EQ(SampleRoadSurface(open, 100.0, 7).size(), 16000u);
  EXPECT_EQ(SampleRoadSurface(s, 25.0, 7).size(), 3800u);
  EXPECT_TRUE(SampleRoadSurface(Scene::Plane(5.0), 100.0, 7).empty());  // no ground material
  EXPECT_TRUE(SampleRoadSurface(s, 0.0, 7).empty());
  // The street: its ground, less every parked box.
  const Scene street = Scene::StreetCanyon(100, 3);
  double boxes = 0.0;
  for (const Rect& r : street.rects())
    if (r.material == Material::kBoxTop) boxes += 4.0 * r.half_u * r.half_v;
  const double ground = 16.0 * 180.0;  // x in [-8, 8], y in [-40, 140]
  EXPECT_NEAR(static_cast<double>(SampleRoadSurface(street, 4.0, 1).size()), 4.0 * (ground - boxes),
              0.01 * 4.0 * ground);
}

}  // namespace
}  // namespace imr::synthetic
