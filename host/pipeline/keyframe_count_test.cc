// Keyframes of an image sequence (front_end.h): how many keyframe_every gives, and what a job
// that did not choose it gets for a short image set.
#include "host/pipeline/front_end.h"

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

}  // namespace
}  // namespace imr::pipeline
