// Ground truth for evaluation (host/eval/README.md): points on a reference mesh, KITTI Velodyne scans placed
// in the sequence's world frame, and the crop to the region the cameras saw.
#pragma once

#include "host/eval/mesh_io.h"
#include "host/io/camera_model.h"
#include "host/io/image_sequence.h"

#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <vector>

namespace imr::eval {

// `count` points uniformly distributed over the surface by area (a triangle with probability
// proportional to its area, then a uniform point in it), the same for the same seed on any
// machine (std::mt19937_64, no library distributions). Empty when the mesh has no area.
std::vector<Vec3> SampleSurface(const TriangleMesh& mesh, std::size_t count, uint64_t seed);

// One KITTI Velodyne scan (.bin): float32 x, y, z, reflectance per point, in the scanner's
// frame. Throws "<path>: ..." when the file is missing or its size is not a multiple of 16 bytes.
std::vector<Vec3> ReadVelodyneScan(const std::filesystem::path& path);

// A scan point in world coordinates, for a frame whose camera has pose x_cam = R X_w + t:
// X_w = R^T (Tr X_velo - t), Tr = velo_to_camera (3x4, Velodyne -> that camera).
Vec3 VelodyneToWorld(const io::Mat34& velo_to_camera, const io::Mat3& r, const Vec3& t,
                     const Vec3& x_velo);

// Where one scan could have measured anything: the scanner's centre and axes in world
// coordinates, and the elevations its returns span at each range. A laser scanner sees a band of
// elevations (the HDL-64E: about -24 to +3 degrees beyond 10 m), all around: a surface above that
// band in every scan (a truck's top, a bridge close by) is absent from the ground truth however
// right it is. The band is taken per range bin because close by it is wider (the lasers do not
// start from one point: the HDL-64E's upper block sits ~0.2 m above the lower one).
struct ScannerView {
  static constexpr double kFirstBin = 1.0;   // returns closer than this (the vehicle) left out
  static constexpr double kBinRatio = 1.25;  // bin k: [kFirstBin r^k, kFirstBin r^(k+1)) metres
  Vec3 origin{};                     // the scanner's centre
  std::array<Vec3, 3> axes{};        // its x (forward), y (left), z (up) axes, unit vectors
  // Per range bin, the lowest and highest elevation (radians above the x-y plane) of the returns
  // in it; a bin without returns takes the band of the next farther bin that has some.
  std::vector<std::array<double, 2>> bands;
  double max_range = 0.0;            // the farthest return's distance (0: no return)
};

// The view of a scan given in the scanner's frame (`points`), the scanner placed at `origin`
// with `axes` (world coordinates).
ScannerView ScannerViewOf(const std::vector<Vec3>& points, const Vec3& origin,
                          const std::array<Vec3, 3>& axes);

// True when some view's scanner had x within its elevations and range.
bool InScannerView(const std::vector<ScannerView>& views, const Vec3& x);

struct VelodyneTruth {
  std::vector<Vec3> points;            // world coordinates, scan after scan
  std::vector<ScannerView> views;      // one per scan read
  std::size_t scans = 0;               // scans read
  std::size_t frames_without_scan = 0; // selected frames whose scan path is empty
};

// The scans of every `scan_step`-th frame of `sequence` (which must have lidar), in world
// coordinates through each frame's camera pose.
VelodyneTruth LoadVelodyneTruth(const io::ImageSequence& sequence, int scan_step);

// What the crop did, point by point.
struct CropCounts {
  std::size_t input = 0;
  std::size_t kept = 0;
  std::size_t beyond_range = 0;     // farther than max_ray_length from every camera centre
  std::size_t outside_frustum = 0;  // within range of some camera, but in no such camera's frustum
};

// True when x projects in front of camera g (z > 0) into its image: u in [-0.5, width - 0.5),
// v in [-0.5, height - 0.5) (pixel centres at integers, top-left pixel at (0, 0); camera_model.h).
bool InFrustum(const io::CameraGeometry& g, const Vec3& x);

// Keeps (keep[i] = 1) the points inside the frustum of some camera AND within max_ray_length of
// that same camera's centre: the region the cameras saw (the paper evaluated only there). max_ray_length <= 0: no range
// limit. Every camera needs projectable intrinsics with width and height > 0 (throws
// std::invalid_argument naming the first that has not). Cameras are binned on a grid of cell
// max_ray_length, so a point is tested only against the cameras near it.
std::vector<uint8_t> CropToCameras(const std::vector<Vec3>& points,
                                   const std::vector<io::CameraGeometry>& cameras,
                                   double max_ray_length, int threads, CropCounts* counts);

}  // namespace imr::eval
