// The surface handed out in parts and the forgetting of what can no longer change
// (EngineOptions::forget, DESIGN.md section 10).
#include "host/engine/engine.h"

#include <gtest/gtest.h>

#include <map>
#include <set>

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

// A run with forgetting: every part collected, then the rest.
struct ForgetRun {
  std::vector<SurfacePart> parts;
  Mesh merged;        // the union of the parts, before FinishExportedMesh
  std::string merge;  // MergeSurfaceParts' answer
  EngineStats stats;
  EngineMemory memory;
};

ForgetRun RunForgetting(const synthetic::StreamOptions& so, EngineOptions eo) {
  synthetic::SyntheticStream stream(so);
  Engine engine(eo, nullptr);
  ForgetRun r;
  const Status s = testing::RunStream(&stream, &engine, [&](const synthetic::StreamKeyframe&) {
    for (SurfacePart& p : engine.TakeFinalParts()) r.parts.push_back(std::move(p));
    return true;
  });
  EXPECT_TRUE(s.ok()) << s.message();
  r.parts.push_back(engine.FinishSurface());
  r.merge = MergeSurfaceParts(r.parts, &r.merged);
  r.stats = engine.Stats();
  r.memory = engine.Memory();
  return r;
}

EngineOptions Forgetting(bool on) {
  EngineOptions eo;
  eo.num_threads = 1;
  eo.forget = on;
  eo.check_invariants = true;  // the full check after every keyframe (ApplyUpdate fails else)
  return eo;
}

// A drive long enough for a good part of it to be left behind: parts are handed out while it
// goes, the triangulation is rebuilt without what was forgotten, the full invariant check holds
// after every keyframe, and the union of the parts is a surface with each vertex and each
// triangle once: a 2-manifold with boundary once its pinched vertices are split.
TEST(ForgettingTest, PartsMakeOneManifoldSurface) {
  const ForgetRun r = RunForgetting(Street(450), Forgetting(true));
  ASSERT_EQ(r.merge, "");
  EXPECT_GT(r.parts.size(), 3u);
  EXPECT_GT(r.stats.forget_steps, 10);
  EXPECT_GT(r.stats.rebuilds, 0);
  EXPECT_EQ(r.stats.rebuilds_abandoned, 0);
  EXPECT_GT(r.stats.vertices_forgotten, 1000);
  EXPECT_GT(r.stats.point_records_freed, 100);
  // Each vertex once (keys at distinct positions) and each triangle once.
  std::set<std::array<double, 3>> at;
  for (size_t i = 0; i < r.merged.vertices.size(); i += 3)
    at.insert({r.merged.vertices[i], r.merged.vertices[i + 1], r.merged.vertices[i + 2]});
  EXPECT_EQ(at.size(), r.merged.vertices.size() / 3);
  std::set<std::array<uint32_t, 3>> tris;
  for (size_t i = 0; i < r.merged.faces.size(); i += 3) {
    std::array<uint32_t, 3> t = {r.merged.faces[i], r.merged.faces[i + 1], r.merged.faces[i + 2]};
    std::sort(t.begin(), t.end());
    tris.insert(t);
  }
  EXPECT_EQ(tris.size(), r.merged.faces.size() / 3);
  Mesh finished = r.merged;
  FinishExportedMesh(&finished, Forgetting(true));
  const ManifoldCheckResult m = CheckMesh(finished, /*closed=*/false);
  EXPECT_TRUE(m.ok) << m.message;
  // Every key named is completed once, by the part that names it or a later one.
  std::map<int64_t, int> completed;
  std::set<int64_t> named;
  for (const SurfacePart& p : r.parts) {
    for (int64_t k : p.keys) {
      named.insert(k);
      EXPECT_EQ(completed.count(k), 0u) << "key " << k << " named after it was completed";
    }
    for (int64_t k : p.completed) ++completed[k];
  }
  EXPECT_EQ(completed.size(), named.size());
  for (const auto& [k, n] : completed) EXPECT_EQ(n, 1) << "key " << k;
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
