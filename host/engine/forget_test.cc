// The surface handed out in parts and the forgetting of what can no longer change
// (EngineOptions::forget, DESIGN.md section 10).
#include "host/engine/engine.h"

#include <gtest/gtest.h>

#include <cmath>
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
  eo.forget = ForgetMode::kOff;
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

// The full invariant check (dO closed and manifold where it is live, every weight against its
// rays and the ledger, a valid triangulation) after every `check_every`-th keyframe.
ForgetRun RunForgetting(const synthetic::StreamOptions& so, EngineOptions eo, int check_every = 0) {
  synthetic::SyntheticStream stream(so);
  Engine engine(eo, nullptr);
  ForgetRun r;
  const Status s = testing::RunStream(&stream, &engine, [&](const synthetic::StreamKeyframe& kf) {
    for (SurfacePart& p : engine.TakeFinalParts()) r.parts.push_back(std::move(p));
    if (check_every > 0 && kf.index % check_every == 0) {
      const ManifoldCheckResult c = engine.CheckInvariants();
      EXPECT_TRUE(c.ok) << "keyframe " << kf.index << ": " << c.message;
      return c.ok;
    }
    return true;
  });
  EXPECT_TRUE(s.ok()) << s.message();
  r.parts.push_back(engine.FinishSurface());
  r.merge = MergeSurfaceParts(r.parts, &r.merged);
  r.stats = engine.Stats();
  r.memory = engine.Memory();
  return r;
}

EngineOptions Forgetting(ForgetMode mode) {
  EngineOptions eo;
  eo.num_threads = 1;
  eo.forget = mode;
  return eo;
}
EngineOptions Forgetting(bool on) { return Forgetting(on ? ForgetMode::kOn : ForgetMode::kOff); }

// A drive long enough for a good part of it to be left behind: parts are handed out while it
// goes, the triangulation is rebuilt without what was forgotten, the full invariant check holds
// (every third keyframe), and the union of the parts is a surface with each vertex and each
// triangle once: a 2-manifold with boundary once its pinched vertices are split.
TEST(ForgettingTest, PartsMakeOneManifoldSurface) {
  const ForgetRun r = RunForgetting(Street(450), Forgetting(true), /*check_every=*/3);
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

// Forgetting changes what is kept, not what is made: on a drive where nothing needs a cell made
// final (no late move, no return), the parts merged and finished are the very mesh of the run
// without forgetting, rebuilds included.
TEST(ForgettingTest, TheSurfaceIsTheOneWithoutForgetting) {
  const EngineOptions off = Forgetting(false), on = Forgetting(true);
  ForgetRun without = RunForgetting(Street(450), off);
  ForgetRun with = RunForgetting(Street(450), on);
  ASSERT_EQ(with.merge, "");
  EXPECT_GT(with.stats.rebuilds, 0);
  EXPECT_EQ(with.stats.changes_refused_final, 0);
  EXPECT_EQ(with.stats.points_dropped, without.stats.points_dropped);
  EXPECT_EQ(with.stats.moves_skipped, without.stats.moves_skipped);
  FinishExportedMesh(&without.merged, off);
  FinishExportedMesh(&with.merged, on);
  EXPECT_EQ(with.merged.vertices, without.merged.vertices);
  EXPECT_EQ(with.merged.faces, without.merged.faces);
  EXPECT_EQ(with.merged.point_ids, without.merged.point_ids);
  // And what it keeps is less: the cells' ray lists of what was left behind, its cells, its
  // point records.
  EXPECT_LT(with.memory.Total(), without.memory.Total() * 3 / 4);
  EXPECT_LT(with.stats.cells, without.stats.cells);
}

// engine.forget "auto" (the default) decides on the camera path. On a drive it turns on at the
// first step that has something to make final, so the run is the very run with forget true:
// the same parts, the same surface.
TEST(ForgettingTest, AutoForgetsOnADriveAsForgetTrueDoes) {
  EXPECT_EQ(EngineOptions{}.forget, ForgetMode::kAuto);
  ForgetRun on = RunForgetting(Street(450), Forgetting(true));
  ForgetRun automatic = RunForgetting(Street(450), Forgetting(ForgetMode::kAuto));
  ASSERT_EQ(automatic.merge, "");
  EXPECT_GT(automatic.stats.forget_on_update, 1);  // decided on the way, not at the start
  EXPECT_EQ(automatic.stats.forget_steps_held, 0);
  EXPECT_GT(automatic.stats.forget_point_spread, 0.0);
  EXPECT_LE(automatic.stats.forget_camera_spread, 2.0 * automatic.stats.forget_point_spread);
  EXPECT_GT(automatic.stats.points_forgotten, 100);
  EXPECT_EQ(automatic.parts.size(), on.parts.size());
  EXPECT_EQ(automatic.stats.cells_finalized, on.stats.cells_finalized);
  EXPECT_EQ(automatic.merged.vertices, on.merged.vertices);
  EXPECT_EQ(automatic.merged.faces, on.merged.faces);
  EXPECT_EQ(automatic.merged.point_ids, on.merged.point_ids);
  EXPECT_EQ(automatic.memory.Total(), on.memory.Total());
}

// An object ring: cameras on a circle of radius 40 m around a sphere of radius 8 m, looking at
// it; each point enters with the first camera that sees it and gains the later ones (a move
// in place). The ring is wider than forget_distance (56 m by default), so forget true makes
// cells on its far side final; what the cameras come back to is then lost.
class RingStream {
 public:
  explicit RingStream(int cameras) : cameras_(cameras) {
    const int n = 1500;
    const double golden = M_PI * (3.0 - std::sqrt(5.0));
    for (int i = 0; i < n; ++i) {  // a Fibonacci sphere: evenly spread
      const double y = 1.0 - 2.0 * (i + 0.5) / n, r = std::sqrt(1.0 - y * y), a = golden * i;
      points_.push_back({8.0 * r * std::cos(a), 8.0 * y, 8.0 * r * std::sin(a)});
    }
    seen_.assign(n, false);
  }
  bool Next(KeyframeUpdate* u) {
    if (next_ >= cameras_) return false;
    *u = KeyframeUpdate{};
    const double a = 2.0 * M_PI * next_ / cameras_;
    Camera c;
    c.id = static_cast<uint64_t>(next_);
    c.center = {40.0 * std::cos(a), 2.0, 40.0 * std::sin(a)};
    u->cameras.push_back(c);
    for (size_t i = 0; i < points_.size(); ++i) {
      const Vec3& p = points_[i];
      // Seen where the sphere faces the camera (its outward normal is p / 8).
      const double facing = (p[0] * (c.center[0] - p[0]) + p[1] * (c.center[1] - p[1]) +
                             p[2] * (c.center[2] - p[2])) / 8.0;
      if (facing <= 0.3 * 32.0) continue;
      if (!seen_[i]) {
        u->new_points.push_back({i + 1000, p, {c.id}});
        seen_[i] = true;
      } else {
        u->moved_points.push_back({i + 1000, p, {c.id}});
      }
    }
    ++next_;
    return true;
  }

 private:
  int cameras_, next_ = 0;
  std::vector<Vec3> points_;
  std::vector<bool> seen_;
};

struct RingRun {
  Mesh mesh;
  EngineStats stats;
  size_t parts = 0;
};
RingRun RunRing(ForgetMode mode) {
  RingStream ring(72);
  Engine engine(Forgetting(mode), nullptr);
  RingRun r;
  KeyframeUpdate u;
  while (ring.Next(&u)) {
    const Status s = engine.ApplyUpdate(u);
    EXPECT_TRUE(s.ok()) << s.message();
    if (!s.ok()) break;
    r.parts += engine.TakeFinalParts().size();
  }
  r.mesh = engine.ExtractMesh();
  r.stats = engine.Stats();
  return r;
}

// On the ring auto stays off: the rule looked (steps that found cells to make final held them),
// the cameras spread wider than the sphere they circle, and the surface is the one without
// forgetting, to the byte; forget true on the same ring does make cells final.
TEST(ForgettingTest, AutoStaysOffOnAnObjectRing) {
  const RingRun off = RunRing(ForgetMode::kOff);
  const RingRun automatic = RunRing(ForgetMode::kAuto);
  const RingRun on = RunRing(ForgetMode::kOn);
  ASSERT_GT(off.mesh.faces.size(), 300u);
  EXPECT_GT(on.stats.cells_finalized, 0) << "the ring must be wide enough for forget true to act";
  EXPECT_EQ(automatic.stats.forget_on_update, 0);
  EXPECT_GT(automatic.stats.forget_steps_held, 0);
  EXPECT_GT(automatic.stats.forget_camera_spread, 2.0 * automatic.stats.forget_point_spread);
  EXPECT_EQ(automatic.stats.cells_finalized, 0);
  EXPECT_EQ(automatic.parts, 0u);
  EXPECT_EQ(automatic.mesh.vertices, off.mesh.vertices);
  EXPECT_EQ(automatic.mesh.faces, off.mesh.faces);
  EXPECT_EQ(automatic.mesh.point_ids, off.mesh.point_ids);
}

// A model in one update (an SfM batch) never turns forgetting on, whatever its cameras do.
TEST(ForgettingTest, AutoStaysOffForOneUpdate) {
  synthetic::SyntheticStream stream(Street(200));
  KeyframeUpdate all;
  synthetic::StreamKeyframe kf;
  std::map<uint64_t, size_t> at;
  while (stream.Next(&kf)) {
    const KeyframeUpdate u = testing::ToUpdate(kf);
    all.cameras.insert(all.cameras.end(), u.cameras.begin(), u.cameras.end());
    for (const NewPoint& p : u.new_points) {
      at[p.id] = all.new_points.size();
      all.new_points.push_back(p);
    }
    for (const MovedPoint& m : u.moved_points) {  // the final position, every camera
      NewPoint& p = all.new_points[at.at(m.id)];
      p.position = m.position;
      p.camera_ids.insert(p.camera_ids.end(), m.camera_ids.begin(), m.camera_ids.end());
    }
    for (uint64_t id : u.removed_points) all.new_points[at.at(id)].camera_ids.clear();
  }
  std::vector<NewPoint> kept;
  for (NewPoint& p : all.new_points)
    if (!p.camera_ids.empty()) kept.push_back(std::move(p));
  all.new_points = std::move(kept);
  all.last = true;
  Engine engine(Forgetting(ForgetMode::kAuto), nullptr);
  const Status s = engine.ApplyUpdate(all);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_FALSE(engine.forgetting());
  EXPECT_TRUE(engine.TakeFinalParts().empty());
  EXPECT_EQ(engine.Stats().cells_finalized, 0);
}

// Points far behind can still be named: a late move of a forgotten point (a SLAM system
// refining an old landmark) is ignored and counted, a removal too; a new point may not reuse a
// forgotten id; a point the engine never saw is still an error.
TEST(ForgettingTest, UpdatesOfForgottenPointsAreIgnored) {
  synthetic::SyntheticStream stream(Street(450));
  Engine engine(Forgetting(true), nullptr);
  ASSERT_TRUE(testing::RunStream(&stream, &engine).ok());
  ASSERT_GT(engine.Stats().points_forgotten, 0);
  Vec3 at;
  ASSERT_FALSE(engine.PointPosition(1, &at));  // the stream's first point: forgotten
  KeyframeUpdate late;
  late.moved_points.push_back({1, {0.0, 1.0, 0.0}, {}});
  late.removed_points.push_back(2);
  const Status s = engine.ApplyUpdate(late);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_EQ(engine.Stats().updates_of_forgotten_points, 2);
  KeyframeUpdate reuse;
  reuse.new_points.push_back({1, {0.0, 1.0, 0.0}, {0}});
  const Status r = engine.ApplyUpdate(reuse);
  EXPECT_FALSE(r.ok());
  EXPECT_NE(r.message().find("forgotten"), std::string::npos) << r.message();
  KeyframeUpdate unknown;
  unknown.moved_points.push_back({99999999, {0.0, 1.0, 0.0}, {}});
  EXPECT_NE(engine.ApplyUpdate(unknown).message().find("unknown"), std::string::npos);
}

// The car comes back: the first stretch of the street is driven again (new cameras, new points
// with new ids) after it was forgotten. What was handed out stays as it was (a change that would
// touch its surface is refused), and the second pass makes a surface of its own there; the full
// invariant check holds (every third keyframe) and the parts still make one manifold.
TEST(ForgettingTest, DrivingBackIntoWhatWasForgotten) {
  const EngineOptions eo = Forgetting(true);
  Engine engine(eo, nullptr);
  std::vector<SurfacePart> parts;
  int keyframes = 0;
  auto take = [&] {
    for (SurfacePart& p : engine.TakeFinalParts()) parts.push_back(std::move(p));
    if (keyframes % 3 == 0) {
      const ManifoldCheckResult c = engine.CheckInvariants();
      EXPECT_TRUE(c.ok) << "keyframe " << keyframes << ": " << c.message;
    }
  };
  synthetic::SyntheticStream first(Street(400));
  synthetic::StreamKeyframe kf;
  while (first.Next(&kf)) {
    const Status s = engine.ApplyUpdate(testing::ToUpdate(kf));
    ASSERT_TRUE(s.ok()) << "keyframe " << keyframes << ": " << s.message();
    take();
    ++keyframes;
  }
  ASSERT_GT(engine.Stats().rebuilds, 0);
  // The same street from its start, the ids moved past the first drive's.
  synthetic::StreamOptions again_options = Street(120);
  again_options.seed = 7;
  synthetic::SyntheticStream again(again_options);
  constexpr uint64_t kOffset = 1000000;
  while (again.Next(&kf)) {
    KeyframeUpdate u = testing::ToUpdate(kf);
    for (Camera& c : u.cameras) c.id += kOffset;
    for (NewPoint& p : u.new_points) {
      p.id += kOffset;
      for (uint64_t& c : p.camera_ids) c += kOffset;
    }
    for (MovedPoint& p : u.moved_points) {
      p.id += kOffset;
      for (uint64_t& c : p.camera_ids) c += kOffset;
    }
    const Status s = engine.ApplyUpdate(u);
    ASSERT_TRUE(s.ok()) << "keyframe " << keyframes << ": " << s.message();
    take();
    ++keyframes;
  }
  parts.push_back(engine.FinishSurface());
  Mesh merged;
  ASSERT_EQ(MergeSurfaceParts(parts, &merged), "");
  // Both passes made surface where the street starts.
  int64_t first_pass = 0, second_pass = 0;
  for (size_t f = 0; f < merged.faces.size(); ++f) {
    const uint32_t v = merged.faces[f];
    if (merged.vertices[3 * v + 1] > 100.0 || merged.point_ids[v] < 0) continue;
    ++(static_cast<uint64_t>(merged.point_ids[v]) >= kOffset ? second_pass : first_pass);
  }
  EXPECT_GT(first_pass, 1000);
  EXPECT_GT(second_pass, 1000);
  FinishExportedMesh(&merged, eo);
  const ManifoldCheckResult m = CheckMesh(merged, /*closed=*/false);
  EXPECT_TRUE(m.ok) << m.message;
}

// The cameras jump 1 km aside after keyframe 30 (a SLAM system relocalising): the cameras, the
// new points and the later estimates of the points still tracked all move by 1 km. A tracked
// point's move next to a final cell of O fails where it would have succeeded without
// forgetting: the mesh differs, and that is counted (shrinks_blocked_final), not silent (issue
// 44: 18,931 faces against 18,789 with nothing counted).
TEST(ForgettingTest, WhatAJumpCostsIsCounted) {
  auto run = [](bool forget, Mesh* mesh, EngineStats* stats) {
    synthetic::SyntheticStream stream(Street(300));
    Engine engine(Forgetting(forget), nullptr);
    std::vector<SurfacePart> parts;
    synthetic::StreamKeyframe kf;
    for (int k = 0; stream.Next(&kf); ++k) {
      KeyframeUpdate u = testing::ToUpdate(kf);
      if (k >= 30) {
        for (Camera& c : u.cameras) c.center[0] += 1000.0;
        for (NewPoint& p : u.new_points) p.position[0] += 1000.0;
        for (MovedPoint& p : u.moved_points) p.position[0] += 1000.0;
      }
      const Status s = engine.ApplyUpdate(u);
      ASSERT_TRUE(s.ok()) << "keyframe " << k << ": " << s.message();
      for (SurfacePart& p : engine.TakeFinalParts()) parts.push_back(std::move(p));
    }
    if (forget) {
      parts.push_back(engine.FinishSurface());
      ASSERT_EQ(MergeSurfaceParts(parts, mesh), "");
      FinishExportedMesh(mesh, Forgetting(true));
    } else {
      *mesh = engine.ExtractMesh();
    }
    *stats = engine.Stats();
  };
  Mesh without, with;
  EngineStats off, on;
  run(false, &without, &off);
  run(true, &with, &on);
  ASSERT_NE(with.faces.size(), without.faces.size());  // the case: forgetting changed the mesh
  EXPECT_GT(on.shrinks_blocked_final, 0);
  EXPECT_GE(on.moves_skipped + on.points_dropped, off.moves_skipped + off.points_dropped);
  EXPECT_EQ(off.shrinks_blocked_final, 0);  // counted only when forgetting
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
