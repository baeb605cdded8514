// Keyframes of an image sequence (front_end.h): how many keyframe_every gives, and what a job
// that did not choose it gets for a short image set; the keyframes a level of detail's texture
// takes (mesh_export.h).
#include "host/pipeline/front_end.h"
#include "host/pipeline/mesh_export.h"

#include <gtest/gtest.h>

namespace imr::pipeline {
namespace {

TEST(KeyframeCount, EveryKthFrameAndTheLast) {
  EXPECT_EQ(KeyframeCount(16, 5), 4);   // 0, 5, 10, 15
  EXPECT_EQ(KeyframeCount(17, 5), 5);   // 0, 5, 10, 15, 16
  EXPECT_EQ(KeyframeCount(60, 5), 13);  // 0..55, 59
  EXPECT_EQ(KeyframeCount(1, 5), 1);
  EXPECT_EQ(KeyframeCount(16, 1), 16);
  EXPECT_EQ(KeyframeCount(0, 5), 0);
}

TEST(KeyframeCount, ShortSetsGetEnoughKeyframes) {
  // The Middlebury rings: 16 images at the default 5 would be 4 keyframes; every image instead.
  EXPECT_EQ(ShortSequenceKeyframeEvery(16, 5), 1);
  EXPECT_EQ(ShortSequenceKeyframeEvery(30, 5), 2);  // 16 keyframes (3: 11)
  // Long enough already: unchanged (imr-synth's 60 and 500, the KITTI sample's 78).
  EXPECT_EQ(ShortSequenceKeyframeEvery(60, 5), 5);
  EXPECT_EQ(ShortSequenceKeyframeEvery(78, 5), 5);
  EXPECT_EQ(ShortSequenceKeyframeEvery(500, 5), 5);
  // Fewer frames than kMinKeyframes: every frame, no lower.
  EXPECT_EQ(ShortSequenceKeyframeEvery(3, 5), 1);
  EXPECT_GE(KeyframeCount(30, ShortSequenceKeyframeEvery(30, 5)), kMinKeyframes);
}

// A level of detail takes every n-th keyframe that may see it, the last too, with its image.
TEST(KeyframeCount, EveryNthKeyframeKeepsTheFirstTheLastAndTheirImages) {
  ExportContext c;
  for (int i = 0; i < 10; ++i) {
    imr_camera cam{};
    cam.t[0] = i;
    c.keyframes.push_back(cam);
    c.image_paths.push_back("image" + std::to_string(i) + ".png");
  }
  auto kept = [](const ExportContext& e) {
    std::vector<int> t;
    for (std::size_t i = 0; i < e.keyframes.size(); ++i) {
      t.push_back(static_cast<int>(e.keyframes[i].t[0]));
      EXPECT_EQ(e.image_paths[i], "image" + std::to_string(t.back()) + ".png");
    }
    return t;
  };
  EXPECT_EQ(kept(EveryNthKeyframe(c, 1)), std::vector<int>({0, 1, 2, 3, 4, 5, 6, 7, 8, 9}));
  EXPECT_EQ(kept(EveryNthKeyframe(c, 4)), std::vector<int>({0, 4, 8, 9}));
  EXPECT_EQ(kept(EveryNthKeyframe(c, 3)), std::vector<int>({0, 3, 6, 9}));
  EXPECT_EQ(kept(EveryNthKeyframe(c, 64)), std::vector<int>({0, 9}));
  c.image_paths.clear();  // engine-only inputs: no images
  EXPECT_TRUE(EveryNthKeyframe(c, 2).image_paths.empty());
  EXPECT_EQ(EveryNthKeyframe(c, 2).keyframes.size(), 6u);
}

}  // namespace
}  // namespace imr::pipeline
