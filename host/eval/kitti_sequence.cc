#include "host/eval/evaluate.h"

#include <filesystem>
#include <stdexcept>

namespace imr::eval {

io::ImageSequence ReadKittiSequence(const std::string& path,
                                    const io::ImageSequenceOptions& options) {
  namespace fs = std::filesystem;
  const fs::path root(path);
  std::error_code ec;
  if (!fs::is_directory(root, ec))
    throw std::runtime_error(path + ": not a folder (expected a KITTI odometry sequence or a KITTI "
                                    "raw drive)");
  // A raw drive has image_0X/data/ and velodyne_points/ (and may also hold an odometry-style
  // calib.txt); an odometry sequence has image_0X/ with the images directly, and calib.txt.
  bool raw = fs::is_directory(root / "velodyne_points", ec);
  for (const char* cam : {"image_00", "image_01", "image_02", "image_03"})
    raw = raw || fs::is_directory(root / cam / "data", ec);
  if (!raw && fs::exists(root / "calib.txt", ec)) return io::ReadKittiOdometry(path, options);
  return io::ReadKittiRaw(path, options);
}

}  // namespace imr::eval
