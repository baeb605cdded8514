// imr-synth's ground truth: scene.json read back (and its errors named), and the road surface's
// completeness on hand-built scenes whose answer is known: a road 8 m x 20 m with one parked box,
// meshes that cover all of it, half of it, or float above it, seen by one camera.
#include "host/eval/synthetic_truth.h"
#include "host/io/testing/temp_dir.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <unistd.h>

namespace imr::eval {
namespace {

namespace fs = std::filesystem;
using synthetic::Material;
using synthetic::Rect;

// Road x in [-4, 4], y in [0, 20] at z = 0 (scene frame, z up); with_box: a box 2 m x 4 m x 1.5 m
// on it at x in [1, 3], y in [10, 14] (its top and sides, as Scene::StreetCanyon marks them).
synthetic::Scene Road(bool with_box) {
  synthetic::Scene s;
  s.AddRect({{0, 10, 0}, {1, 0, 0}, {0, 1, 0}, 4, 10, Material::kGround});
  if (with_box) {
    s.AddRect({{2, 12, 1.5}, {1, 0, 0}, {0, 1, 0}, 1, 2, Material::kBoxTop, 0});
    s.AddRect({{1, 12, 0.75}, {0, 1, 0}, {0, 0, 1}, 2, 0.75, Material::kBoxSide, 0});
    s.AddRect({{3, 12, 0.75}, {0, 0, 1}, {0, 1, 0}, 0.75, 2, Material::kBoxSide, 0});
    s.AddRect({{2, 10, 0.75}, {1, 0, 0}, {0, 0, 1}, 1, 0.75, Material::kBoxEnd, 0});
    s.AddRect({{2, 14, 0.75}, {0, 0, 1}, {1, 0, 0}, 0.75, 1, Material::kBoxEnd, 0});
  }
  return s;
}

// imr-synth's frame: world = camera 0 at frame 0 (x right, y down, z forward), the camera 1.65 m
// above the ground: x_w = x_s, y_w = 1.65 - z_s, z_w = y_s.
SyntheticTruth Truth(bool with_box) {
  SyntheticTruth t;
  t.scene = Road(with_box);
  t.rotation = {{{1, 0, 0}, {0, 0, -1}, {0, 1, 0}}};
  t.translation = {0, 1.65, 0};
  return t;
}

// The rectangle x in [x0, x1], y in [0, 20] of the scene at height z, as a world-frame mesh.
TriangleMesh Patch(const SyntheticTruth& t, double x0, double x1, double z) {
  TriangleMesh m;
  for (const io::Vec3& p : {io::Vec3{x0, 0, z}, io::Vec3{x1, 0, z}, io::Vec3{x1, 20, z},
                            io::Vec3{x0, 20, z}})
    m.vertices.push_back(t.ToWorld(p));
  m.triangles = {{0, 1, 2}, {0, 2, 3}};
  return m;
}

// The camera of frame 0 (at the world origin, looking along +z_w = +y_s), 400 x 200 pixels,
// f = 200, principal point at the centre: the road is seen from y_s = 3.3 m on.
io::CameraGeometry Camera() {
  io::CameraGeometry g;
  io::SetFromCenter(io::Identity3(), {0, 0, 0}, &g);
  g.has_intrinsics = true;
  g.intrinsics.width = 400;
  g.intrinsics.height = 200;
  g.intrinsics.fx = g.intrinsics.fy = 200;
  g.intrinsics.cx = 199.5;
  g.intrinsics.cy = 99.5;
  g.intrinsics.projectable = true;
  return g;
}

TEST(RoadSurfaceTest, CompletenessOfWholeHalfAndLiftedMeshes) {
  const SyntheticTruth t = Truth(false);
  EvaluationOptions o;
  o.taus = {0.2, 0.5};
  o.threads = 2;
  // No cameras: nothing cropped, every sample counts.
  RoadSurfaceEvaluation e = EvaluateRoadSurface(Patch(t, -4, 4, 0), t, {}, o);
  EXPECT_FALSE(e.cropped);
  EXPECT_EQ(e.samples, 16000u);
  EXPECT_EQ(e.crop.kept, 16000u);
  EXPECT_EQ(e.completeness, (std::vector<double>{1.0, 1.0}));
  EXPECT_NEAR(e.truth_to_mesh.max, 0.0, 1e-9);
  // The mesh covers x <= 0: within tau of it are the samples with x <= tau.
  e = EvaluateRoadSurface(Patch(t, -4, 0, 0), t, {}, o);
  EXPECT_NEAR(e.completeness[0], 4.2 / 8.0, 0.005);
  EXPECT_NEAR(e.completeness[1], 4.5 / 8.0, 0.005);
  // 30 cm above the road: complete at 0.5 m, not at 0.2 m.
  e = EvaluateRoadSurface(Patch(t, -4, 4, 0.3), t, {}, o);
  EXPECT_EQ(e.completeness, (std::vector<double>{0.0, 1.0}));
  EXPECT_NEAR(e.truth_to_mesh.mean, 0.3, 1e-9);
  // A mesh without area is an error, as in imr evaluate.
  EXPECT_THROW(EvaluateRoadSurface(Patch(t, 1, 1, 0), t, {}, o), std::invalid_argument);
}

TEST(RoadSurfaceTest, CroppedLikeImrEvaluateAndHiddenSamplesCounted) {
  EvaluationOptions o;
  o.taus = {0.2};
  o.threads = 2;
  const SyntheticTruth open = Truth(false);
  RoadSurfaceEvaluation e = EvaluateRoadSurface(Patch(open, -4, 4, 0), open, {Camera()}, o);
  EXPECT_TRUE(e.cropped);
  // In view: y > 200 * 1.65 / 100 = 3.3 m (v < 199.5) and |x| < y (u in [-0.5, 399.5)).
  // Area: (20 - 3.3) * 8 less the two triangles |x| > y for y < 4: 2 * (4 - 3.3)^2 / 2.
  const double in_view = (20.0 - 3.3) * 8.0 - (4.0 - 3.3) * (4.0 - 3.3);
  EXPECT_NEAR(static_cast<double>(e.crop.kept), 100.0 * in_view, 150.0);
  EXPECT_EQ(e.crop.kept + e.crop.outside_frustum + e.crop.beyond_range, e.samples);
  EXPECT_EQ(e.hidden, 0u);
  EXPECT_EQ(e.completeness, std::vector<double>{1.0});
  // Range 10 m: the road beyond sqrt(10^2 - 1.65^2) = 9.86 m is cropped.
  o.max_ray_length = 10.0;
  e = EvaluateRoadSurface(Patch(open, -4, 4, 0), open, {Camera()}, o);
  EXPECT_GT(e.crop.beyond_range, 0u);
  EXPECT_LT(static_cast<double>(e.crop.kept), 100.0 * (9.86 - 3.3) * 8.0);
  o.max_ray_length = 30.0;

  // The box hides the road behind it from the camera: those samples count (completeness over
  // all kept samples, like imr evaluate's), and are told apart.
  const SyntheticTruth boxed = Truth(true);
  e = EvaluateRoadSurface(Patch(boxed, -4, 0, 0), boxed, {Camera()}, o);
  EXPECT_GT(e.hidden, 200u);
  EXPECT_LT(e.hidden, e.crop.kept / 4);
  // The hidden samples lie at x > 1 (behind the box, seen from x = 0): none within tau of a mesh
  // that covers x <= 0, so leaving them out raises the share.
  EXPECT_GT(e.completeness_visible[0], e.completeness[0]);
  const double kept = static_cast<double>(e.crop.kept);
  EXPECT_NEAR(e.completeness_visible[0] * (kept - static_cast<double>(e.hidden)),
              e.completeness[0] * kept, 1e-6);
}

class ScratchTest : public ::testing::Test {
 protected:
  io::testing::TempDir scratch_{"imr-synthetic-truth"};
  const fs::path dir_ = scratch_.path();
};

using ReadSyntheticTruthTest = ScratchTest;

TEST_F(ReadSyntheticTruthTest, StreetAndWorldFrameReadBackErrorsNamed) {
  const fs::path p = dir_ / "scene.json";
  std::ofstream(p) << R"({"scene": "street", "length": 60, "seed": 3, "half_width": 8,
      "facade_height": 12, "world_from_scene": [[1, 0, 0, 0], [0, 0, -1, 1.65], [0, 1, 0, 0],
      [0, 0, 0, 1]]})";
  const SyntheticTruth t = ReadSyntheticTruth(p.string());
  EXPECT_EQ(t.scene.rects().size(), synthetic::Scene::StreetCanyon(60, 3).rects().size());
  const io::Vec3 w = t.ToWorld({1, 2, 3});
  EXPECT_NEAR(w[0], 1, 1e-12);
  EXPECT_NEAR(w[1], 1.65 - 3, 1e-12);
  EXPECT_NEAR(w[2], 2, 1e-12);
  const io::Vec3 s = t.ToScene(w);
  EXPECT_NEAR(s[0], 1, 1e-12);
  EXPECT_NEAR(s[1], 2, 1e-12);
  EXPECT_NEAR(s[2], 3, 1e-12);
  const std::pair<const char*, const char*> bad[] = {
      {R"({"scene": "room"})", "field 'scene'"},
      {R"({"scene": "street", "length": 60, "seed": -1})", "field 'seed'"},
      {R"({"scene": "street", "seed": 1, "half_width": 8, "facade_height": 12})",
       "field 'length'"},
      {R"({"scene": "street", "length": 60, "seed": 1, "half_width": 8, "facade_height": 12,
          "world_from_scene": [1, 2, 3]})", "field 'world_from_scene'"},
      {"{", "not valid JSON"},
  };
  for (const auto& [text, want] : bad) {
    std::ofstream(p) << text;
    try {
      ReadSyntheticTruth(p.string());
      ADD_FAILURE() << text;
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find(want), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(p.string()), std::string::npos) << e.what();
    }
  }
  EXPECT_THROW(ReadSyntheticTruth((dir_ / "missing.json").string()), std::runtime_error);
}

// EvaluateFiles on a sequence with a synthetic scene reports the road surface too.
std::string g_scene;
io::ImageSequence SyntheticSequence(const std::string& path, const io::ImageSequenceOptions&) {
  io::ImageSequence seq;
  seq.layout = "fake";
  seq.root = path;
  io::ImageFrame f;
  f.camera = Camera();
  seq.frames.push_back(f);
  seq.synthetic_scene = g_scene;
  return seq;
}

using RoadSurfaceFilesTest = ScratchTest;

TEST_F(RoadSurfaceFilesTest, EvaluateFilesReportsAndPrintsTheRoad) {
  g_scene = (dir_ / "scene.json").string();
  std::ofstream(g_scene) << R"({"scene": "street", "length": 30, "seed": 1, "half_width": 8,
      "facade_height": 12, "world_from_scene": [[1, 0, 0, 0], [0, 0, -1, 1.65], [0, 1, 0, 0],
      [0, 0, 0, 1]]})";
  // The street's ground (y from -40 to 70 m) as a mesh in the world frame: the whole road.
  std::ofstream(dir_ / "ground.obj") << "v -8 1.65 -40\nv 8 1.65 -40\nv 8 1.65 70\nv -8 1.65 70\n"
                                        "f 1 2 3 4\n";
  EvaluationInputs in;
  in.mesh = (dir_ / "ground.obj").string();
  in.truth = in.mesh;
  in.sequence = "synthetic-seq";
  EvaluationOptions o;
  o.taus = {0.2, 0.5};
  o.precision_samples = 1000;
  o.threads = 2;
  const nlohmann::json r = EvaluateFiles(in, o, &SyntheticSequence);
  ASSERT_TRUE(r.contains("road_surface")) << r.dump(2);
  const nlohmann::json& road = r["road_surface"];
  EXPECT_EQ(road["scene"], g_scene);
  EXPECT_GT(road["crop"]["kept"].get<int>(), 10000);
  // Everything not under a parked box is on the mesh; parked boxes hide some of it.
  EXPECT_EQ(road["completeness"], (std::vector<double>{1.0, 1.0}));
  EXPECT_GT(road["hidden"].get<int>(), 0);
  EXPECT_NE(FormatReport(r).find("road complete    1.0000   1.0000"), std::string::npos)
      << FormatReport(r);
  // A sequence without a synthetic scene: no road section.
  g_scene.clear();
  EXPECT_FALSE(EvaluateFiles(in, o, &SyntheticSequence).contains("road_surface"));
}

}  // namespace
}  // namespace imr::eval
