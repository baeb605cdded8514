// io::UpdateCheck: the readers' checks of cameras, positions and ids, for updates no reader
// built (the Python module's keyframes), in the readers' words.
#include "host/io/update_check.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

namespace imr::io {
namespace {

engine::Camera Cam(uint64_t id, std::array<double, 9> r = {1, 0, 0, 0, 1, 0, 0, 0, 1},
                   std::array<double, 4> k = {}) {
  engine::Camera c;
  c.id = id;
  c.rotation = r;
  c.intrinsics = k;
  return c;
}

void ExpectProblem(engine::Camera c, const std::string& part) {
  const std::string p = CameraProblem(&c);
  EXPECT_NE(p.find(part), std::string::npos) << "'" << p << "' lacks '" << part << "'";
}

TEST(UpdateCheck, RotationsThatAreNotRotationsAreRefusedInTheReadersWords) {
  ExpectProblem(Cam(3, {1, 1, 1, 1, 1, 1, 1, 1, 1}), "camera 3: the rotation is not a rotation: not orthonormal");
  ExpectProblem(Cam(3, {0, 0, 0, 0, 0, 0, 0, 0, 0}), "not orthonormal");
  ExpectProblem(Cam(3, {2, 0, 0, 0, 2, 0, 0, 0, 2}), "more than the 0.0001 imr re-orthonormalises");
  ExpectProblem(Cam(3, {1, 0, 0, 0, 1, 0, 0, 0, -1}), "is not a rotation: determinant -1 (a reflection)");
  const double nan = std::numeric_limits<double>::quiet_NaN();
  ExpectProblem(Cam(3, {nan, 0, 0, 0, 1, 0, 0, 0, 1}), "has a non-finite entry");
  // 1.4e-6 from orthonormal (six digits in a file): accepted and made orthonormal to rounding.
  engine::Camera near = Cam(4, {1.0000014, 0, 0, 0, 1, 0, 0, 0, 1});
  EXPECT_EQ(CameraProblem(&near), "");
  EXPECT_NEAR(near.rotation[0], 1.0, 1e-12);
}

TEST(UpdateCheck, IntrinsicsAreUnknownOrFiniteAndPositive) {
  engine::Camera unknown = Cam(1);
  EXPECT_EQ(CameraProblem(&unknown), "");
  engine::Camera good = Cam(1, {1, 0, 0, 0, 1, 0, 0, 0, 1}, {500, 500, 320, 240});
  EXPECT_EQ(CameraProblem(&good), "");
  const double nan = std::numeric_limits<double>::quiet_NaN();
  ExpectProblem(Cam(1, {1, 0, 0, 0, 1, 0, 0, 0, 1}, {nan, 500, 320, 240}),
                "camera 1: intrinsics: expected focal lengths fx, fy finite and > 0 (pixels), got fx nan");
  ExpectProblem(Cam(1, {1, 0, 0, 0, 1, 0, 0, 0, 1}, {0, 500, 320, 240}), "got fx 0, fy 500");
  ExpectProblem(Cam(1, {1, 0, 0, 0, 1, 0, 0, 0, 1}, {-500, -500, 320, 240}), "got fx -500");
  ExpectProblem(Cam(1, {1, 0, 0, 0, 1, 0, 0, 0, 1}, {500, 500, INFINITY, 240}),
                "expected a finite principal point cx, cy (pixels), got cx inf");
  EXPECT_EQ(IntrinsicsProblem(800, 800, 320, 240), "");
}

TEST(UpdateCheck, CoordinatesBeyondTheReadersBoundAreRefused) {
  engine::Camera far = Cam(2);
  far.center = {0, 1e13, 0};
  ExpectProblem(far, "camera 2: center y: expected a coordinate within +-1e12 (scene units), got 1e+13");
  UpdateCheck check;
  engine::KeyframeUpdate u;
  u.cameras = {Cam(0)};
  u.new_points = {{1, {0, 0, 5}, {0}}, {2, {0, 0, 1e300}, {0}}};
  EXPECT_EQ(check.Check(&u, 0),
            "new_points: point 2: z: expected a coordinate within +-1e12 (scene units), got 1e+300");
  u.new_points[1].position = {0, 0, 1e12};  // the bound itself is in
  EXPECT_EQ(check.Check(&u, 0), "");
  engine::KeyframeUpdate m;
  m.moved_points = {{1, {-1e13, 0, 0}, {}}};
  EXPECT_EQ(check.Check(&m, 1),
            "moved_points: point 1: x: expected a coordinate within +-1e12 (scene units), got -1e+13");
}

TEST(UpdateCheck, IdsAreKnownAndRemovedOnceAsTheSlamJsonReaderSaysIt) {
  UpdateCheck check;
  engine::KeyframeUpdate first;
  first.cameras = {Cam(0)};
  first.new_points = {{1, {0, 0, 5}, {0}}, {2, {1, 0, 5}, {0}}};
  ASSERT_EQ(check.Check(&first, 0), "");
  engine::KeyframeUpdate remove;
  remove.removed_points = {1};
  ASSERT_EQ(check.Check(&remove, 1), "");
  EXPECT_EQ(check.Check(&remove, 2), "removed_points: " + PointNotInStream(1, 2));
  EXPECT_EQ(PointNotInStream(1, 2), "point 1 is not in the stream at keyframe 2");
  engine::KeyframeUpdate twice;  // twice in one update
  twice.removed_points = {2, 2};
  EXPECT_EQ(check.Check(&twice, 2), "removed_points: point 2 is not in the stream at keyframe 2");
  engine::KeyframeUpdate unknown;
  unknown.removed_points = {77};
  EXPECT_EQ(check.Check(&unknown, 2), "removed_points: point 77 is not in the stream at keyframe 2");
  engine::KeyframeUpdate move_removed;
  move_removed.moved_points = {{1, {0, 0, 6}, {}}};
  EXPECT_EQ(check.Check(&move_removed, 2), "moved_points: point 1 is observed after it was removed");
  engine::KeyframeUpdate move_unknown;
  move_unknown.moved_points = {{78, {0, 0, 6}, {}}};
  EXPECT_EQ(check.Check(&move_unknown, 2), "moved_points: point 78 is not in the stream at keyframe 2");
  engine::KeyframeUpdate reuse;
  reuse.new_points = {{1, {0, 0, 5}, {0}}};
  EXPECT_EQ(check.Check(&reuse, 2),
            "new_points: point 1 uses the id of a point removed at keyframe 1: ids must not be reused");
  reuse.new_points = {{2, {0, 0, 5}, {0}}};
  EXPECT_EQ(check.Check(&reuse, 2), "new_points: point 2 uses an id that is already known");
  // A refused update records nothing: point 2 is still in the stream.
  engine::KeyframeUpdate remove_and_move;
  remove_and_move.removed_points = {2};
  remove_and_move.moved_points = {{2, {0, 0, 6}, {}}};
  EXPECT_EQ(check.Check(&remove_and_move, 3), "moved_points: point 2 is observed after it was removed");
  engine::KeyframeUpdate move2;
  move2.moved_points = {{2, {0, 0, 6}, {}}};
  EXPECT_EQ(check.Check(&move2, 3), "");
}

}  // namespace
}  // namespace imr::io
