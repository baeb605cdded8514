#include "tools/bench/common/surface_figures.h"

#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>

namespace imr::bench {
namespace {

// Two triangles making the unit square on z = 0 (normals +z), and a third folded up along the
// square's edge x = 1 by `fold` degrees.
void FoldedSquare(double fold_degrees, std::vector<double>* xyz, std::vector<uint32_t>* faces) {
  const double a = fold_degrees * M_PI / 180.0;
  *xyz = {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0, 1 + std::cos(a), 0.5, std::sin(a)};
  *faces = {0, 1, 2, 0, 2, 3, 1, 4, 2};
}

TEST(Roughness, FlatIsZeroAndAFoldIsItsAngle) {
  std::vector<double> xyz;
  std::vector<uint32_t> faces;
  FoldedSquare(0.0, &xyz, &faces);
  EXPECT_NEAR(Roughness(xyz, faces), 0.0, 1e-9);
  FoldedSquare(90.0, &xyz, &faces);
  // Edges with two faces: the diagonal (0°) and x = 1 (the fold: 90°).
  EXPECT_NEAR(Roughness(xyz, faces), 45.0, 1e-9);
}

eval::SyntheticTruth GroundWithBox() {
  eval::SyntheticTruth t;
  t.scene = synthetic::Scene::Plane(10.0);
  t.scene.AddRect({{20.0, 0.0, 0.0}, {1, 0, 0}, {0, 1, 0}, 5.0, 5.0});  // coplanar with the ground
  t.scene.AddBox({2.0, 2.0, 0.0}, {4.0, 4.0, 1.5}, /*with_bottom=*/false);
  return t;
}

TEST(SyntheticPlanes, OnePlaneCountsAnEdgeOfTheTruthDoesNot) {
  const PlaneOf plane_of = SyntheticPlanes(GroundWithBox(), 0.2);
  const int ground = plane_of({-5.0, -5.0, 0.05});
  EXPECT_GE(ground, 0);
  EXPECT_EQ(plane_of({20.0, 3.0, -0.1}), ground);  // the coplanar rect: the same plane
  EXPECT_EQ(plane_of({-5.0, -5.0, 0.5}), -1);      // off every plane
  EXPECT_EQ(plane_of({2.05, 3.0, 0.05}), -1);      // where the box meets the ground
  const int side = plane_of({2.05, 3.0, 0.8});
  EXPECT_GE(side, 0);
  EXPECT_NE(side, ground);
  EXPECT_EQ(plane_of({3.0, 3.0, 1.6}), plane_of({3.5, 2.5, 1.45}));  // the box's top
}

TEST(RoughnessOnPlanes, CountsOnlyTheEdgesOnOneTruePlane) {
  std::vector<double> xyz;
  std::vector<uint32_t> faces;
  FoldedSquare(90.0, &xyz, &faces);  // the fold's vertex 4 at (1, 0.5, 1): off the ground
  for (std::size_t i = 0; i < xyz.size(); i += 3) xyz[i] -= 5.0, xyz[i + 1] -= 5.0;
  const PlaneRoughness r = RoughnessOnPlanes(xyz, faces, SyntheticPlanes(GroundWithBox(), 0.2));
  EXPECT_EQ(r.edges, 1);  // the diagonal; the fold's edge has a face off the plane
  EXPECT_NEAR(r.degrees, 0.0, 1e-9);
  EXPECT_NEAR(r.face_share, 2.0 / 3.0, 1e-12);
  // A crumpled ground: the square's far corner 0.1 m up, still within the tolerance.
  FoldedSquare(0.0, &xyz, &faces);
  xyz[8] = 0.1;
  for (std::size_t i = 0; i < xyz.size(); i += 3) xyz[i] -= 5.0, xyz[i + 1] -= 5.0;
  const PlaneRoughness c = RoughnessOnPlanes(xyz, faces, SyntheticPlanes(GroundWithBox(), 0.2));
  EXPECT_EQ(c.edges, 2);
  EXPECT_GT(c.degrees, 1.0);
  EXPECT_NEAR(c.face_share, 1.0, 1e-12);
}

TEST(SmallComponents, ASpeckBesideASquare) {
  // A 10 x 10 square (area 100) and a triangle of area 0.125 far away.
  const std::vector<double> xyz = {0, 0, 0, 10, 0, 0, 10, 10, 0, 0, 10, 0,
                                   50, 50, 0, 50.5, 50, 0, 50, 50.5, 0};
  const std::vector<uint32_t> faces = {0, 1, 2, 0, 2, 3, 4, 5, 6};
  const SmallComponents s = SmallComponentsOf(eval::ComputeMeshStatistics(xyz, faces));
  EXPECT_EQ(s.components, 2);
  EXPECT_EQ(s.small, 1);
  EXPECT_NEAR(s.area_share, 0.125 / 100.125, 1e-12);
  // At 0.1 % the speck (0.12 %) is no longer small.
  EXPECT_EQ(SmallComponentsOf(eval::ComputeMeshStatistics(xyz, faces), 0.001).small, 0);
  EXPECT_THROW(SmallComponentsOf(eval::ComputeMeshStatistics(xyz, faces), 0.0), std::invalid_argument);
}

io::ColmapModel Model(int images, const std::string& camera_model) {
  io::ColmapModel m;
  io::ColmapModel::Camera c;
  c.id = 1, c.model = camera_model, c.width = 64, c.height = 48;
  c.params = camera_model == "SIMPLE_PINHOLE" ? std::vector<double>{50, 32, 24}
                                              : std::vector<double>{50, 50, 32, 24, 0.1};
  m.cameras.push_back(c);
  for (int i = images - 1; i >= 0; --i) {  // out of order: the ranks go by id
    io::ColmapModel::Image im;
    im.id = static_cast<uint32_t>(i), im.camera_id = 1, im.name = std::to_string(i) + ".png";
    im.tvec = {0.0, 0.0, -static_cast<double>(i)};  // camera i at z = i, looking down +z
    m.images.push_back(im);
  }
  return m;
}

TEST(KeyframeViews, EveryTenthKeyframeOfTheExport) {
  const std::vector<render::Camera> v = KeyframeViews(Model(101, "SIMPLE_PINHOLE"), 5, 10);
  ASSERT_EQ(v.size(), 3u);  // images 0, 50, 100
  EXPECT_NEAR(v[1].Center()[2], 50.0, 1e-12);
  EXPECT_NEAR(v[2].Center()[2], 100.0, 1e-12);
  EXPECT_EQ(v[0].fx, 50.0);
  EXPECT_EQ(v[0].cy, 24.0);
  try {
    KeyframeViews(Model(3, "SIMPLE_RADIAL"), 5, 10);
    FAIL() << "a distorted camera was accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("camera 1 is SIMPLE_RADIAL"), std::string::npos) << e.what();
  }
}

TEST(SeenFromBehind, ASheetFacingAwayAndOneFacingTheCamera) {
  const std::vector<render::Camera> cameras = KeyframeViews(Model(1, "SIMPLE_PINHOLE"), 5, 10);
  // A sheet across the view at z = 5; this order's normal is +z, away from the camera at z = 0.
  const std::vector<double> xyz = {-9, -9, 5, 9, -9, 5, 9, 9, 5, -9, 9, 5};
  const std::vector<uint32_t> away = {0, 1, 2, 0, 2, 3};
  const std::vector<uint32_t> toward = {0, 2, 1, 0, 3, 2};
  const render::BackFacing b = SeenFromBehind(xyz, away, cameras, 1.0);
  EXPECT_EQ(b.views, 1);
  EXPECT_EQ(b.pixels, 64 * 48);
  EXPECT_NEAR(b.Share(), 1.0, 1e-12);
  EXPECT_NEAR(SeenFromBehind(xyz, toward, cameras, 1.0).Share(), 0.0, 1e-12);
  // Half of each: the left half facing away.
  const std::vector<double> two = {-9, -9, 5, 0, -9, 5, 0, 9, 5, -9, 9, 5,
                                   0, -9, 5, 9, -9, 5, 9, 9, 5, 0, 9, 5};
  const std::vector<uint32_t> half = {0, 1, 2, 0, 2, 3, 4, 6, 5, 4, 7, 6};
  EXPECT_NEAR(SeenFromBehind(two, half, cameras, 1.0).Share(), 0.5, 0.03);
}

}  // namespace
}  // namespace imr::bench
