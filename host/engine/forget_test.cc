// The surface handed out in parts and the forgetting of what can no longer change
// (EngineOptions::forget, DESIGN.md section 10).
#include "host/engine/engine.h"

#include <gtest/gtest.h>

#include "host/engine/testing/run_stream.h"

namespace imr::engine {
namespace {

synthetic::StreamOptions Street(int frames) {
  synthetic::StreamOptions so;
  so.scene = synthetic::SceneKind::kStreet;
  so.frames = frames;
  so.points_per_keyframe = 150;
  return so;
}

// Without forgetting, the run's one part is its whole exported surface: merged and finished as
// ExtractMesh finishes dO, it is the same mesh.
TEST(SurfacePartsTest, FinishSurfaceWithoutForgettingIsTheExportedMesh) {
  synthetic::SyntheticStream stream(Street(60));
  EngineOptions eo;
  eo.num_threads = 1;
  Engine engine(eo, nullptr);
  ASSERT_TRUE(testing::RunStream(&stream, &engine).ok());
  EXPECT_TRUE(engine.TakeFinalParts().empty());
  const Mesh whole = engine.ExtractMesh();
  ASSERT_GT(whole.faces.size(), 300u);

  const SurfacePart part = engine.FinishSurface();
  EXPECT_EQ(part.keys.size(), part.point_ids.size());
  EXPECT_EQ(part.completed.size(), part.keys.size());  // every vertex is complete at the end
  Mesh merged;
  ASSERT_EQ(MergeSurfaceParts({part}, &merged), "");
  FinishExportedMesh(&merged, eo);
  EXPECT_EQ(merged.vertices, whole.vertices);
  EXPECT_EQ(merged.faces, whole.faces);
  EXPECT_EQ(merged.point_ids, whole.point_ids);
}

TEST(SurfacePartsTest, MergeRefusesAKeyAtTwoPositions) {
  SurfacePart a, b;
  a.vertices = {0, 0, 0, 1, 0, 0, 0, 1, 0};
  a.keys = {0, 1, 2};
  a.point_ids = {10, 11, 12};
  a.faces = {0, 1, 2};
  b = a;
  b.vertices[0] = 0.5;  // key 0 moved
  Mesh m;
  EXPECT_EQ(MergeSurfaceParts({a, a}, &m), "");
  EXPECT_EQ(m.vertices.size(), 9u);  // shared by key
  EXPECT_EQ(m.faces.size(), 6u);
  EXPECT_NE(MergeSurfaceParts({a, b}, &m).find("vertex key 0"), std::string::npos);
  b = a;
  b.faces = {0, 1, 3};
  EXPECT_NE(MergeSurfaceParts({b}, &m).find("out of range"), std::string::npos);
}

}  // namespace
}  // namespace imr::engine
