// KITTI raw (host/io/image_sequence.h ReadKittiRaw): calib_cam_to_cam.txt, calib_velo_to_cam.txt,
// calib_imu_to_velo.txt, the drive's poses.txt (left out when blank: the oxts records are read
// instead), image_02/timestamps.txt and three oxts records, as one input cut by "@@@@" lines;
// beside image_02/data/0000000000..2.png.
#include <cstddef>
#include <cstdint>
#include <cstdio>

#include "host/io/image_sequence.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  const auto date = imr::fuzz::ScratchDir() / "raw" / "2011_09_26";
  const auto drive = date / "2011_09_26_drive_0001_sync";
  static const bool images = [&] {
    for (int i = 0; i < 3; ++i) {
      char name[24];
      std::snprintf(name, sizeof name, "%010d.png", i);
      imr::fuzz::WriteFile(drive / "image_02" / "data" / name, imr::fuzz::TinyPng());
    }
    return true;
  }();
  (void)images;
  const auto parts = imr::fuzz::SplitParts(data, size, 8);
  imr::fuzz::WriteFile(date / "calib_cam_to_cam.txt", parts[0]);
  imr::fuzz::WriteFile(date / "calib_velo_to_cam.txt", parts[1]);
  imr::fuzz::WriteFile(date / "calib_imu_to_velo.txt", parts[2]);
  std::error_code ec;
  if (parts[3].find_first_not_of(" \t\r\n") == std::string::npos)  // blank: use the oxts
    std::filesystem::remove(drive / "poses.txt", ec);
  else
    imr::fuzz::WriteFile(drive / "poses.txt", parts[3]);
  imr::fuzz::WriteFile(drive / "image_02" / "timestamps.txt", parts[4]);
  for (int i = 0; i < 3; ++i) {
    char name[24];
    std::snprintf(name, sizeof name, "%010d.txt", i);
    imr::fuzz::WriteFile(drive / "oxts" / "data" / name, parts[static_cast<std::size_t>(5 + i)]);
  }
  imr::fuzz::ExpectOnlyDocumentedErrors([&] {
    imr::io::ImageSequenceOptions o;
    o.frame_step = 1 + static_cast<int>(size % 2);
    (void)imr::io::ReadKittiRaw(drive.string(), o);
  });
  return 0;
}
