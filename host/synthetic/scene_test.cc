#include "host/synthetic/scene.h"

#include <gtest/gtest.h>

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

}  // namespace
}  // namespace imr::synthetic
