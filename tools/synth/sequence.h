// imr-synth's job: render the synthetic street (host/synthetic: Scene::StreetCanyon, the street
// camera path StreetCameraCenter) into a KITTI odometry sequence folder:
//
//   OUT/image_0/NNNNNN.png       gray (image_2/ instead with color: BGR, seen from camera 2)
//   OUT/calib.txt                P0..P3 (KITTI sequence 00, scaled to the size), Tr (velo->cam 0)
//   OUT/times.txt                0.1 s per frame
//   OUT/poses.txt                camera 0 of frame i -> camera 0 of frame 0, 12 numbers a line
//   OUT/velodyne/NNNNNN.bin      float32 x, y, z, reflectance (unless lidar is off)
//   OUT/ground_truth/scene.ply   the exact scene mesh (2 triangles per rect) in the poses' frame
//   OUT/ground_truth/scene.json  what rebuilds the analytic scene, and world_from_scene
//
// Every file is written atomically, and the folder as a whole: it is built as
// OUT.partial-<pid> and renamed to OUT at the end, so a killed run never leaves a sequence that
// looks whole (only the .partial folder, which can be deleted).
#pragma once

#include <atomic>
#include <cstdint>
#include <iosfwd>
#include <stdexcept>
#include <string>

#include "host/synthetic/scene.h"
#include "tools/synth/rig.h"

namespace imr::synth {

struct SynthOptions {
  std::string out;    // Output folder; must not exist unless force.
  int frames = 500;   // Frames rendered.
  uint64_t seed = 1;  // Scene (parked boxes, buildings, markings) and image noise.
  int width = 1242;   // Image size; intrinsics scale from KITTI's 1242 x 375.
  int height = 375;
  double speed = 1.0;           // Metres per frame along the street (0.1 s per frame).
  double noise = 2.0;           // Gaussian image noise, grey levels (standard deviation).
  bool color = false;           // image_2 (BGR, camera 2) instead of image_0 (gray, camera 0).
  bool lidar = true;            // Write velodyne/ scans.
  double lidar_step = 0.2;      // Horizontal step of the scan, degrees.
  bool force = false;           // Replace an existing output folder.
  int threads = 0;              // Worker threads; 0: one per core.
  bool progress = true;         // Print [i/N] lines while rendering.
  bool id_colors = false;       // Debug/test: pixels hold rect index + 1 (see RenderOptions).
  double half_width = 8.0;      // Street half width (Scene::StreetCanyon).
  double facade_height = 12.0;  // Facade height (Scene::StreetCanyon).

  // Empty when valid, else a message naming the bad option and its value.
  std::string Check() const;
};

struct SynthResult {
  std::string out;  // The folder written.
  int frames = 0;
  int width = 0, height = 0;
  double seconds = 0.0;  // Wall time of the whole run.
  uint64_t lidar_points = 0;
};

// The output folder exists and force is off (nothing was written).
struct OutputExistsError : std::runtime_error {
  using std::runtime_error::runtime_error;
};
// `cancel` became true during the run (the partial folder was removed).
struct CancelledError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// Renders the sequence. Progress lines go to `log`. Throws std::invalid_argument (bad options),
// OutputExistsError, CancelledError, or std::runtime_error naming the file that failed.
SynthResult GenerateSequence(const SynthOptions& options, std::ostream& log,
                             const std::atomic<bool>* cancel = nullptr);

// The scene an options set renders, and where its poses' world frame sits in it.
synthetic::Scene StreetScene(const SynthOptions& options);
Mat44 StreetWorldFromScene(const SynthOptions& options);

// Ground-truth files: the mesh (ASCII PLY, double coordinates, faces 2i and 2i+1 = rect i, with
// a per-face material code = synthetic::Material) and the scene description (JSON).
std::string SceneMeshPly(const synthetic::Scene& scene, const Mat44& world_from_scene);
std::string SceneJson(const SynthOptions& options);

}  // namespace imr::synth
