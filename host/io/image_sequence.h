// Image sequences with known camera poses (docs/interop.md, KITTI and Middlebury): what the image front end reads. Each
// layout reader (KITTI odometry, KITTI raw, Middlebury) converts to ONE convention, the one of
// camera_model.h:
//
//   x_cam = R * X_world + t,  camera looking down +z, x right, y down (KITTI's and OpenCV's);
//   pixels (u, v) = K * x_cam / z with the centre of the top-left pixel at (0, 0);
//   images are rectified / undistorted (distortion zero), K = [fx 0 cx; 0 fy cy; 0 0 1] (the
//   readers refuse a skewed K: Intrinsics has no skew);
//   world = the frame of the sequence's poses (KITTI: the camera of source frame 0, also when
//   first_frame > 0, so frame 0 has R = I, t = 0 for the camera whose poses were given; other
//   cameras of the rig are offset by their rectified baseline b_k = K^-1 P_k[:, 3]).
//
// Errors are std::runtime_error naming the file, the line when there is one, and what was
// expected, e.g. "<root>/calib.txt: no line 'P2:' (the rectified projection of camera 2, ...)".
//
// Readers only read text files and check that the images exist; the pixels are decoded later,
// one frame at a time (image_io.h), so a 5000-frame sequence costs nothing up front.
#pragma once

#include "host/io/camera_model.h"
#include "host/io/image_io.h"
#include "host/util/geodesy.h"

#include <nlohmann/json.hpp>

#include <array>
#include <optional>
#include <string>
#include <vector>

namespace imr::io {

using Mat34 = std::array<std::array<double, 4>, 3>;  // row-major 3x4 [R | t]

struct ImageFrame {
  int index = 0;           // frame number in the sequence (after first/step selection), from 0
  int source_index = 0;    // line / file number in the source layout
  double timestamp = 0.0;  // seconds (times.txt); the source index when the layout has none
  std::string image_path;  // path of the image file (absolute, or as the job's path made it)
  CameraGeometry camera;   // id = index; has_intrinsics = true, zero distortion
};

// Ground truth that comes with a layout (KITTI: Velodyne scans), for evaluation (issue 6).
struct LidarGroundTruth {
  std::vector<std::string> scan_paths;  // one per frame (same order as frames), "" when missing
  Mat34 velo_to_camera{};               // Tr: Velodyne -> the frames' camera coordinates
};

struct ImageSequence {
  std::string layout;  // "kitti_odometry", "kitti_raw", "middlebury"
  std::string root;    // the folder (or _par.txt file) the job named
  int camera = 0;      // KITTI camera index used (0..3); 0 for Middlebury
  std::vector<ImageFrame> frames;
  bool has_lidar = false;
  LidarGroundTruth lidar;
  // Ground truth of a sequence made by the synthetic generator (tools/): the path of its scene
  // description (ground_truth/scene.json), "" otherwise.
  std::string synthetic_scene;
  // Figures for the report: files read, frames selected, what was inferred (e.g. which poses file).
  nlohmann::json summary = nlohmann::json::object();
  // What every frame's image must be (checked from its header before decoding): the size of
  // frame 0, within the options' max_image_megapixels.
  ImageLimits image_limits;
  // Where the sequence's frame stands on the Earth, when the input says (KITTI raw with poses
  // from oxts: the GNSS/IMU of source frame 0); geo-references the tiles without an origin.
  std::optional<geo::GeoAnchor> geo;
};

// Options every layout takes (job "input.options"); checked against ImageSequenceOptionsSchema.
// The readers set the sequence's image_limits from them (ImageLimitsFor).
struct ImageSequenceOptions {
  int camera = -1;        // KITTI camera 0..3; -1: the lowest-numbered image_0X folder present
  std::string poses;      // poses file; "" = the layout's default (see the readers)
  int poses_camera = -1;  // which camera the poses file gives; -1 = inferred ("poses_cam2*"
                          // -> 2), else 0 (KITTI odometry ground truth is camera 0)
  int first_frame = 0;    // first source frame used
  int frame_count = -1;   // at most this many frames; -1 = all to the end
  int frame_step = 1;     // use every n-th source frame
  int keyframe_every = 5; // the front end makes every n-th selected frame a keyframe (paper: 5)
  // Larger images are refused from their header, before decoding (memory: about 3 bytes a
  // pixel, several times over in the features plugin's pyramids).
  double max_image_megapixels = 50.0;

  // Empty when usable, else which field and why.
  std::string Check() const;
};

// The schema of those options (job "input.options" of kitti_odometry, kitti_raw, middlebury).
nlohmann::json ImageSequenceOptionsSchema();
// From options with defaults filled in (WithDefaults); throws std::runtime_error when Check fails.
ImageSequenceOptions ImageSequenceOptionsFromJson(const nlohmann::json& options);

// The limits of a sequence whose frame 0 is `first` (the readers check frame 0 with them).
ImageLimits ImageLimitsFor(const ImageSequenceOptions& options, const ImageSize& first);

// KITTI odometry: <root>/image_0 (gray) .. image_3 (colour), <root>/calib.txt (P0..P3, Tr),
// <root>/times.txt, poses: options.poses, else <root>/poses.txt, else
// <root>/../../poses/<basename(root)>.txt (the devkit's dataset/poses/NN.txt). Velodyne scans:
// <root>/velodyne/NNNNNN.bin when that folder exists (velo_to_camera = Tr offset by b_camera).
ImageSequence ReadKittiOdometry(const std::string& root, const ImageSequenceOptions& options);

// KITTI raw: <root> = a drive folder (<date>/<date>_drive_NNNN_sync) with image_0X/data/*.png,
// calibration in <root>/.. (calib_cam_to_cam.txt: P_rect_0X, R_rect_00; calib_velo_to_cam.txt;
// calib_imu_to_velo.txt for oxts). Poses: options.poses, else a KITTI-odometry-style poses file in
// <root> (poses*.txt; of several, the one named poses_camK* for the chosen camera K), else
// <root>/oxts/data/*.txt converted as the KITTI devkit does (convertOxtsToPose: Mercator with
// the scale of the first latitude, R = Rz(yaw) Ry(pitch) Rx(roll), relative to the first record;
// IMU -> camera X by [I | b_X] R_rect_00 T_velo_to_cam T_imu_to_velo; world = camera X at source
// frame 0). Timestamps: image_0X/timestamps.txt (dates, as seconds since the first), else
// times.txt, else 0.1 s steps. Velodyne scans: <root>/velodyne_points/data/NNNNNNNNNN.bin
// (velo_to_camera = [I | b_X] R_rect_00 T_velo_to_cam).
ImageSequence ReadKittiRaw(const std::string& root, const ImageSequenceOptions& options);

// Middlebury multi-view: <file>_par.txt (first line: count; then per line: image name, K (9),
// R (9), t (3), P = K [R | t]); images beside it. `path` is the _par.txt file or its folder
// (which must hold exactly one). Only the frame options apply: camera, poses and poses_camera
// set to anything but their defaults are refused.
ImageSequence ReadMiddlebury(const std::string& path, const ImageSequenceOptions& options);

// --- Text helpers the layout readers share (image_sequence.cc) ---------------------------------

// "<file>:<line>" (1-based), the prefix of every message about one line of a file.
std::string FileLine(const std::string& file, int line);
// True for a line of only blanks, tabs and a carriage return.
bool IsBlankLine(const std::string& line);

// Empty when `path` is a regular file (or a link to one); else what it is: "no such file", "is a
// folder, expected <expected>", ... (a folder named 000003.png is not missing).
std::string FileProblem(const std::string& path, const std::string& expected);
// Removes a UTF-8 byte order mark (EF BB BF, as Windows editors save) from the start of a file's
// first line: it would hide the first key or number.
void SkipByteOrderMark(std::string* first_line);
// The lines of a text file, without line ends or a byte order mark. Throws "<path>: no such file
// (<what>)" when it is absent, e.g. what = "the poses file".
std::vector<std::string> ReadTextLines(const std::string& path, const std::string& what);
// The blank-separated numbers of line `line` (1-based) of `file`. Throws
// "<file>:<line>: column <c> (number <k>): 'x' is not a finite number" for text, NaN or inf.
std::vector<double> ParseNumbers(const std::string& text, const std::string& file, int line);
// "FIRST[:COUNT[:STEP]]" (command lines) -> first_frame, frame_count, frame_step of `options`;
// false (and `options` untouched) when malformed.
bool ParseFrameSelection(const std::string& text, ImageSequenceOptions* options);
// The source frames chosen by first_frame, frame_step and frame_count (at most that many) among
// `source_count`. Throws, naming `sequence`, when none is left.
std::vector<int> SelectSourceFrames(int source_count, const ImageSequenceOptions& options,
                                    const std::string& sequence);

}  // namespace imr::io
