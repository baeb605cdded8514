// KITTI odometry text files (host/io/image_sequence.h ReadKittiOdometry): calib.txt, poses.txt and
// times.txt, given as one input cut by "@@@@" lines, beside image_0/000000..000002.png.
#include <cstddef>
#include <cstdint>
#include <cstdio>

#include "host/io/image_sequence.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  const auto dir = imr::fuzz::ScratchDir() / "kitti" / "sequences" / "00";
  static const bool images = [&] {
    for (int i = 0; i < 3; ++i) {
      char name[16];
      std::snprintf(name, sizeof name, "%06d.png", i);
      imr::fuzz::WriteFile(dir / "image_0" / name, imr::fuzz::TinyPng());
    }
    return true;
  }();
  (void)images;
  const auto parts = imr::fuzz::SplitParts(data, size, 3);
  imr::fuzz::WriteFile(dir / "calib.txt", parts[0]);
  imr::fuzz::WriteFile(dir / "poses.txt", parts[1]);
  imr::fuzz::WriteFile(dir / "times.txt", parts[2]);
  imr::fuzz::ExpectOnlyDocumentedErrors([&] {
    imr::io::ImageSequenceOptions o;
    o.frame_step = 1 + static_cast<int>(size % 2);
    (void)imr::io::ReadKittiOdometry(dir.string(), o);
  });
  return 0;
}
