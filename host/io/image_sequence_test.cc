// Image sequence readers (KITTI odometry, KITTI raw, Middlebury) and image decoding, against
// hand-computed cases in temporary folders, every refused input (the message names the file,
// the line and what was expected), and the real samples in IMR_SHARED_DIR/data.
#include "host/io/image_io.h"
#include "host/io/image_sequence.h"
#include "host/io/input_formats.h"
#include "host/io/schema.h"
#include "host/io/testing/temp_dir.h"

#include <gtest/gtest.h>

#include <sys/stat.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <future>
#include <numbers>

namespace imr::io {
namespace {
namespace fs = std::filesystem;
using nlohmann::json;

using testing::Write;
// Scratch folders of this file's tests.
class TempDir : public testing::TempDir {
 public:
  TempDir() : testing::TempDir("imr-imageseq") {}
};

Image Gray(int w, int h) {
  Image im;
  im.width = w;
  im.height = h;
  im.channels = 1;
  im.stride_bytes = w;
  im.pixels.resize(static_cast<std::size_t>(w * h));
  for (std::size_t i = 0; i < im.pixels.size(); ++i) im.pixels[i] = static_cast<uint8_t>(i * 7);
  return im;
}

// The tiny image every reader test writes: 40x30 gray.
constexpr int kW = 40, kH = 30;
void WritePng(const fs::path& p) {
  fs::create_directories(p.parent_path());
  WriteImage(p.string(), Gray(kW, kH));
}

std::string Num(double v) {
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.17g", v);
  return buf;
}

// Runs `f`, which must throw std::runtime_error with every one of `parts` in its message.
template <class F>
void ExpectError(F&& f, const std::vector<std::string>& parts) {
  try {
    f();
    ADD_FAILURE() << "no exception; expected one naming '" << parts.front() << "'";
  } catch (const std::runtime_error& e) {
    const std::string m = e.what();
    for (const auto& p : parts)
      EXPECT_NE(m.find(p), std::string::npos) << "message: " << m << "\n  lacks: " << p;
  }
}

void ExpectVec(const Vec3& a, const Vec3& b, double tol = 1e-12) {
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(a[i], b[i], tol) << "component " << i;
}
void ExpectMat(const Mat3& a, const Mat3& b, double tol = 1e-12) {
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) EXPECT_NEAR(a[i][j], b[i][j], tol) << "element " << i << j;
}

// --- A hand-made KITTI rig -----------------------------------------------------------------------
// K: fx = fy = 700, cx = 300, cy = 200. Rectified baselines (x_cam_k = x_cam_0 + b_k), chosen
// exact in binary: b0 = 0, b1 = (-0.5, 0, 0), b2 = (0.5, 0.25, 0.125), b3 = (-0.25, 0, 0.5).
// P_k = K [I | b_k], so P_k[:, 3] = (fx bx + cx bz, fy by + cy bz, bz).
constexpr double kF = 700, kCx = 300, kCy = 200;
const Vec3 kB[4] = {{0, 0, 0}, {-0.5, 0, 0}, {0.5, 0.25, 0.125}, {-0.25, 0, 0.5}};

std::string Projection(int k) {
  const Vec3& b = kB[k];
  return Num(kF) + " 0 " + Num(kCx) + " " + Num(kF * b[0] + kCx * b[2]) + " 0 " + Num(kF) + " " +
         Num(kCy) + " " + Num(kF * b[1] + kCy * b[2]) + " 0 0 1 " + Num(b[2]);
}

// Tr (Velodyne -> camera 0): x forward, y left, z up -> x right, y down, z forward, Velodyne
// 0.27 m behind and 0.08 m above the camera.
const char* kTr = "0 -1 0 0 0 0 -1 -0.08 1 0 0 -0.27";

std::string OdometryCalib(const std::string& skip = "") {
  std::string s;
  for (int k = 0; k < 4; ++k)
    if ("P" + std::to_string(k) != skip) s += "P" + std::to_string(k) + ": " + Projection(k) + "\n";
  if (skip != "Tr") s += std::string("Tr: ") + kTr + "\n";
  return s;
}

// Frame 0: the world. Frame 1: camera i -> world T = [Ry(90 deg) | (1, 2, 3)], Ry(90) =
// [[0, 0, 1], [0, 1, 0], [-1, 0, 0]]: its centre is (1, 2, 3), its optical axis world +x;
// R (world -> camera) = Ry^T, t = -R C = -(-3, 2, 1) = (3, -2, -1).
const char* kPose0 = "1 0 0 0 0 1 0 0 0 0 1 0";
const char* kPose1 = "0 0 1 1 0 1 0 2 -1 0 0 3";
const Mat3 kR1 = {{{0, 0, -1}, {0, 1, 0}, {1, 0, 0}}};
const Vec3 kC1 = {1, 2, 3};
const Vec3 kT1 = {3, -2, -1};

// A KITTI odometry sequence folder: image_<k> for each camera, `frames` images each.
void MakeOdometry(const fs::path& root, int frames, const std::vector<int>& cameras,
                  const std::string& poses) {
  for (int k : cameras)
    for (int i = 0; i < frames; ++i) {
      char name[32];
      std::snprintf(name, sizeof name, "%06d.png", i);
      WritePng(root / ("image_" + std::to_string(k)) / name);
    }
  Write(root / "calib.txt", OdometryCalib());
  std::string times;
  for (int i = 0; i < frames; ++i) times += Num(0.1 * i) + "\n";
  Write(root / "times.txt", times);
  if (!poses.empty()) Write(root / "poses.txt", poses);
}

std::string TwoPoses() { return std::string(kPose0) + "\n" + kPose1 + "\n"; }

ImageSequenceOptions Camera(int k) {
  ImageSequenceOptions o;
  o.camera = k;
  return o;
}

// --- Options -----------------------------------------------------------------------------------

TEST(ImageSequenceOptions, SchemaIsWellFormedAndDefaultsRoundTrip) {
  const json schema = ImageSequenceOptionsSchema();
  EXPECT_TRUE(CheckSchema(schema, "schema").empty());
  for (const char* key :
       {"camera", "poses", "poses_camera", "first_frame", "frame_count", "frame_step"}) {
    ASSERT_TRUE(schema.contains(key)) << key;
    EXPECT_TRUE(schema[key].contains("description")) << key;
  }
  EXPECT_EQ(schema["poses"]["default"], "");
  const ImageSequenceOptions o = ImageSequenceOptionsFromJson(WithDefaults(schema, json::object()));
  const ImageSequenceOptions d;
  EXPECT_EQ(o.camera, d.camera);
  EXPECT_EQ(o.poses, d.poses);
  EXPECT_EQ(o.frame_count, d.frame_count);
  EXPECT_EQ(o.frame_step, 1);

  std::vector<Problem> problems;
  ValidateAgainstSchema(schema, {{"camera", 4}, {"frame_step", 0}, {"typo", 1}}, "input.options",
                        &problems);
  EXPECT_EQ(problems.size(), 3u);
  ExpectError(
      [&] {
        ImageSequenceOptionsFromJson(WithDefaults(schema, {{"frame_count", 0}}));
      },
      {"frame_count", "selects no frames"});
}

TEST(ImageSequenceOptions, FormatsAreRegisteredForImages) {
  for (const char* name : {"kitti_odometry", "kitti_raw", "middlebury"}) {
    const InputFormat* f = FindInputFormat(name);
    ASSERT_NE(f, nullptr) << name;
    EXPECT_TRUE(f->needs_front_end);
    EXPECT_TRUE(f->sequences_are_paths);
    EXPECT_FALSE(f->open);
    EXPECT_TRUE(f->open_images);
    EXPECT_EQ(f->options_schema, ImageSequenceOptionsSchema());
  }
  TempDir dir;
  MakeOdometry(dir / "00", 2, {0}, TwoPoses());
  const InputFormat* f = FindInputFormat("kitti_odometry");
  const ImageSequence s =
      f->open_images((dir / "00").string(), WithDefaults(f->options_schema, json::object()));
  EXPECT_EQ(s.frames.size(), 2u);
  EXPECT_EQ(s.layout, "kitti_odometry");
}

TEST(ImageSequenceOptions, FrameSelection) {
  ImageSequenceOptions o;
  o.first_frame = 2;
  o.frame_step = 3;
  EXPECT_EQ(SelectSourceFrames(10, o, "s"), (std::vector<int>{2, 5, 8}));
  o.frame_count = 2;
  EXPECT_EQ(SelectSourceFrames(10, o, "s"), (std::vector<int>{2, 5}));
  o.frame_count = 100;  // at most: the sequence ends first
  EXPECT_EQ(SelectSourceFrames(10, o, "s"), (std::vector<int>{2, 5, 8}));
  o.first_frame = 10;
  ExpectError([&] { SelectSourceFrames(10, o, "seq07"); }, {"seq07", "first_frame 10", "has 10"});
}

TEST(ImageSequenceOptions, NumbersNameLineAndColumn) {
  EXPECT_EQ(ParseNumbers("  1 -2.5e+01\t+3 ", "f.txt", 1), (std::vector<double>{1, -25, 3}));
  ExpectError([] { ParseNumbers("1 2 nan 4", "poses.txt", 7); },
              {"poses.txt:7", "column 5", "number 3", "'nan'", "not a finite number"});
  ExpectError([] { ParseNumbers("1 inf", "f.txt", 2); }, {"f.txt:2", "'inf'"});
  ExpectError([] { ParseNumbers("1 2x", "f.txt", 3); }, {"f.txt:3", "column 3", "'2x'"});
  ExpectError([] { ParseNumbers("1,5", "f.txt", 4); }, {"'1,5'"});
}

// --- KITTI odometry ----------------------------------------------------------------------------

TEST(KittiOdometry, PoseOfCamera0GivesRtAndCentre) {
  TempDir dir;
  MakeOdometry(dir / "00", 2, {0}, TwoPoses());
  const ImageSequence s = ReadKittiOdometry((dir / "00").string(), {});
  EXPECT_EQ(s.layout, "kitti_odometry");
  EXPECT_EQ(s.camera, 0);
  ASSERT_EQ(s.frames.size(), 2u);

  const ImageFrame& f0 = s.frames[0];
  ExpectMat(f0.camera.rotation, Identity3());
  ExpectVec(f0.camera.translation, {0, 0, 0});

  const ImageFrame& f1 = s.frames[1];
  EXPECT_EQ(f1.index, 1);
  EXPECT_EQ(f1.source_index, 1);
  EXPECT_EQ(f1.camera.id, 1u);
  EXPECT_DOUBLE_EQ(f1.timestamp, 0.1);
  EXPECT_EQ(f1.image_path, (dir / "00" / "image_0" / "000001.png").string());
  EXPECT_EQ(f1.camera.name, "000001.png");
  ExpectMat(f1.camera.rotation, kR1);
  ExpectVec(f1.camera.translation, kT1);
  ExpectVec(f1.camera.center, kC1);

  // Intrinsics from P0, size from the PNG header.
  const Intrinsics& k = f1.camera.intrinsics;
  EXPECT_TRUE(f1.camera.has_intrinsics);
  EXPECT_TRUE(k.projectable);
  EXPECT_EQ(k.source_model, "kitti_rectified");
  EXPECT_EQ(k.width, kW);
  EXPECT_EQ(k.height, kH);
  EXPECT_EQ(k.fx, kF);
  EXPECT_EQ(k.fy, kF);
  EXPECT_EQ(k.cx, kCx);
  EXPECT_EQ(k.cy, kCy);
  EXPECT_EQ(k.k1, 0.0);

  // 5 m down camera 1's optical axis (world +x from its centre) lands on the principal point.
  double u = 0, v = 0;
  ASSERT_TRUE(Project(f1.camera, {6, 2, 3}, &u, &v));
  EXPECT_NEAR(u, kCx, 1e-9);
  EXPECT_NEAR(v, kCy, 1e-9);

  EXPECT_EQ(s.summary["poses"]["chosen_by"], "poses.txt in the sequence folder");
  EXPECT_EQ(s.summary["poses"]["camera"], 0);
  EXPECT_FALSE(s.has_lidar);
}

// Camera 2 with camera-0 poses: the same rotation, the centre moved by the baseline exactly:
// t_2 = t_0 + b2, so C_2 = C_0 - R^T b2.
TEST(KittiOdometry, Camera2WithPosesOfCamera0IsOffsetByTheBaseline) {
  TempDir dir;
  MakeOdometry(dir / "00", 2, {0, 2}, TwoPoses());
  const ImageSequence s = ReadKittiOdometry((dir / "00").string(), Camera(2));
  EXPECT_EQ(s.camera, 2);
  ASSERT_EQ(s.frames.size(), 2u);
  ExpectMat(s.frames[0].camera.rotation, Identity3());
  ExpectVec(s.frames[0].camera.translation, kB[2]);
  ExpectVec(s.frames[0].camera.center, {-0.5, -0.25, -0.125});
  // Frame 1: R^T b2 = Ry(90) (0.5, 0.25, 0.125) = (0.125, 0.25, -0.5).
  ExpectMat(s.frames[1].camera.rotation, kR1);
  ExpectVec(s.frames[1].camera.translation, {3.5, -1.75, -0.875});
  ExpectVec(s.frames[1].camera.center, {0.875, 1.75, 3.5});
  EXPECT_EQ(s.frames[1].image_path, (dir / "00" / "image_2" / "000001.png").string());
  EXPECT_EQ(s.summary["baseline_applied"], json::array({0.5, 0.25, 0.125}));

  // Poses of camera 3 (option), used for camera 2: offset b2 - b3 = (0.75, 0.25, -0.375).
  ImageSequenceOptions o = Camera(2);
  o.poses_camera = 3;
  const ImageSequence s3 = ReadKittiOdometry((dir / "00").string(), o);
  ExpectVec(s3.frames[0].camera.translation, {0.75, 0.25, -0.375});
  EXPECT_EQ(s3.summary["poses"]["camera_from"], "option poses_camera");
}

TEST(KittiOdometry, LowestCameraFolderIsTheDefault) {
  TempDir dir;
  MakeOdometry(dir / "00", 2, {3, 2}, TwoPoses());
  const ImageSequence s = ReadKittiOdometry((dir / "00").string(), {});
  EXPECT_EQ(s.camera, 2);
  EXPECT_EQ(s.frames[0].camera.intrinsics.source_params.size(), 12u);
}

TEST(KittiOdometry, DevkitPosesFolderAndFrameSelection) {
  TempDir dir;
  const fs::path root = dir / "dataset" / "sequences" / "07";
  std::string poses;
  for (int i = 0; i < 6; ++i)  // camera i at (0, 0, i): straight ahead
    poses += "1 0 0 0 0 1 0 0 0 0 1 " + std::to_string(i) + "\n";
  MakeOdometry(root, 6, {0}, "");
  Write(dir / "dataset" / "poses" / "07.txt", poses);
  ImageSequenceOptions o;
  o.first_frame = 1;
  o.frame_step = 2;
  const ImageSequence s = ReadKittiOdometry(root.string() + "/", o);  // trailing slash too
  ASSERT_EQ(s.frames.size(), 3u);
  for (int j = 0; j < 3; ++j) {
    EXPECT_EQ(s.frames[j].index, j);
    EXPECT_EQ(s.frames[j].camera.id, static_cast<uint64_t>(j));
    EXPECT_EQ(s.frames[j].source_index, 1 + 2 * j);
    EXPECT_NEAR(s.frames[j].timestamp, 0.1 * (1 + 2 * j), 1e-12);
    ExpectVec(s.frames[j].camera.center, {0, 0, 1.0 + 2 * j});
  }
  EXPECT_EQ(s.frames[2].image_path, (root / "image_0" / "000005.png").string());
  EXPECT_EQ(s.summary["poses"]["chosen_by"], "the devkit layout (dataset/poses/<sequence>.txt)");
  EXPECT_EQ(s.summary["source_frames"], 6);
  EXPECT_EQ(s.summary["frames"], 3);

  o.poses = (dir / "dataset" / "poses" / "07.txt").string();  // the option wins
  EXPECT_EQ(ReadKittiOdometry(root.string(), o).summary["poses"]["chosen_by"], "option poses");
}

// Tr maps Velodyne to camera 0; camera 2's scans are offset by b2. Missing scans are "".
TEST(KittiOdometry, VelodyneScansAndTheirCalibration) {
  TempDir dir;
  MakeOdometry(dir / "00", 2, {2}, TwoPoses());
  Write(dir / "00" / "velodyne" / "000000.bin", std::string(16, '\0'));
  const ImageSequence s = ReadKittiOdometry((dir / "00").string(), {});
  ASSERT_TRUE(s.has_lidar);
  ASSERT_EQ(s.lidar.scan_paths.size(), 2u);
  EXPECT_EQ(s.lidar.scan_paths[0], (dir / "00" / "velodyne" / "000000.bin").string());
  EXPECT_EQ(s.lidar.scan_paths[1], "");
  const Mat34 expected = {{{0, -1, 0, 0.5}, {0, 0, -1, -0.08 + 0.25}, {1, 0, 0, -0.27 + 0.125}}};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 4; ++j) EXPECT_NEAR(s.lidar.velo_to_camera[i][j], expected[i][j], 1e-15);

  Write(dir / "00" / "calib.txt", OdometryCalib("Tr"));
  ExpectError([&] { ReadKittiOdometry((dir / "00").string(), {}); },
              {"calib.txt: no line 'Tr:'", "velodyne"});
}

TEST(KittiOdometry, RefusesBadInputNamingFileLineAndWhat) {
  TempDir dir;
  const fs::path root = dir / "00";
  const std::string r = root.string();
  ExpectError([&] { ReadKittiOdometry(r, {}); }, {r, "no such folder"});

  MakeOdometry(root, 2, {0, 2}, TwoPoses());
  ExpectError([&] { ReadKittiOdometry(r, Camera(3)); },
              {(root / "image_3").string(), "no such folder", "camera 3"});

  // Calibration: missing file, missing matrix, wrong count, not rectified.
  fs::remove(root / "calib.txt");
  ExpectError([&] { ReadKittiOdometry(r, {}); }, {(root / "calib.txt").string(), "no such file"});
  Write(root / "calib.txt", OdometryCalib("P2"));
  ExpectError([&] { ReadKittiOdometry(r, Camera(2)); },
              {"calib.txt: no line 'P2:'", "projection of camera 2"});
  Write(root / "calib.txt", "P0: 700 0 300 0 0 700 200 0 0 0 1\n");
  ExpectError([&] { ReadKittiOdometry(r, {}); }, {"calib.txt:1", "P0 has 11 numbers, expected 12"});
  Write(root / "calib.txt", "P0: 700 0 300 0 0 700 200 0 0 0 1 x\n");
  ExpectError([&] { ReadKittiOdometry(r, {}); }, {"calib.txt:1", "'x'", "number 12"});
  Write(root / "calib.txt", "P0: 700 0 300 0 0 700 200 0 0.5 0 1 0\n");
  ExpectError([&] { ReadKittiOdometry(r, {}); }, {"calib.txt:1", "not a rectified projection"});
  Write(root / "calib.txt", OdometryCalib());

  // Poses: count (fewer lines than images; more is a trimmed sequence, below), numbers, rotations.
  Write(root / "poses.txt", std::string(kPose0) + "\n");
  ExpectError([&] { ReadKittiOdometry(r, {}); },
              {(root / "poses.txt").string(), "1 poses (lines)", "has 2 images",
               "000001.png has no line"});
  Write(root / "poses.txt", std::string(kPose0) + "\n0 0 1 1 0 1 0 nan -1 0 0 3\n");
  ExpectError([&] { ReadKittiOdometry(r, {}); },
              {"poses.txt:2", "column 15", "number 8", "'nan'", "not a finite number"});
  Write(root / "poses.txt", std::string(kPose0) + "\n0 0 1 1 0 1 0 2 -1 0 0\n");
  ExpectError([&] { ReadKittiOdometry(r, {}); }, {"poses.txt:2", "11 numbers, expected 12"});
  Write(root / "poses.txt", std::string(kPose0) + "\n0 0 1 1 0 1.1 0 2 -1 0 0 3\n");
  ExpectError([&] { ReadKittiOdometry(r, {}); },
              {"poses.txt:2", "not a rotation", "not orthonormal"});
  Write(root / "poses.txt", std::string(kPose0) + "\n-1 0 0 1 0 1 0 2 0 0 1 3\n");
  ExpectError([&] { ReadKittiOdometry(r, {}); }, {"poses.txt:2", "not a rotation", "reflection"});
  fs::remove(root / "poses.txt");
  ExpectError([&] { ReadKittiOdometry(r, {}); },
              {r, "no poses file", (root / "poses.txt").string(), "poses/00.txt"});
  ImageSequenceOptions missing;
  missing.poses = (dir / "nowhere.txt").string();
  ExpectError([&] { ReadKittiOdometry(r, missing); },
              {(dir / "nowhere.txt").string(), "no such file", "poses file"});
  Write(root / "poses.txt", TwoPoses());

  // Times: missing, count.
  fs::remove(root / "times.txt");
  ExpectError([&] { ReadKittiOdometry(r, {}); }, {(root / "times.txt").string(), "no such file"});
  Write(root / "times.txt", "0\n");
  ExpectError([&] { ReadKittiOdometry(r, {}); },
              {(root / "times.txt").string(), "1 timestamps", "has 2 images",
               "000001.png has no line"});
  Write(root / "times.txt", "0\n0.1 0.2\n");
  ExpectError([&] { ReadKittiOdometry(r, {}); }, {"times.txt:2", "2 numbers, expected 1"});
  Write(root / "times.txt", "0\n0.1\n");

  // An image missing for a frame (the count still matches: another file stands in).
  fs::rename(root / "image_0" / "000001.png", root / "image_0" / "000002.png");
  ExpectError([&] { ReadKittiOdometry(r, {}); },
              {(root / "image_0" / "000001.png").string(), "no such file", "source frame 1"});
  fs::rename(root / "image_0" / "000002.png", root / "image_0" / "000001.png");

  ImageSequenceOptions late;
  late.first_frame = 2;
  ExpectError([&] { ReadKittiOdometry(r, late); }, {r, "first_frame 2", "has 2"});
  EXPECT_EQ(ReadKittiOdometry(r, {}).frames.size(), 2u);  // and all is well again
}

// Issue 47: the usual way to cut a sequence keeps the first N images and leaves times.txt and the
// poses whole; the first N lines serve, and the cut is said (summary "trimmed"). A gap in the
// images, or fewer lines than images, is still refused, naming the file and the image.
TEST(KittiOdometry, ATrimmedSequenceUsesTheFirstLinesOfTimesAndPoses) {
  TempDir dir;
  const fs::path root = dir / "00";
  const std::string r = root.string();
  std::string poses = TwoPoses();
  for (int i = 2; i < 6; ++i) poses += std::string(kPose0) + "\n";
  MakeOdometry(root, 6, {0}, poses);  // 6 images, 6 timestamps, 6 poses
  for (int i = 4; i < 6; ++i) fs::remove(root / "image_0" / ("00000" + std::to_string(i) + ".png"));

  const ImageSequence s = ReadKittiOdometry(r, {});
  ASSERT_EQ(s.frames.size(), 4u);
  EXPECT_DOUBLE_EQ(s.frames[3].timestamp, 0.3);
  ExpectVec(s.frames[1].camera.center, kC1, 1e-12);  // line 2 of poses.txt
  ASSERT_TRUE(s.summary.contains("trimmed")) << s.summary.dump();
  ASSERT_EQ(s.summary["trimmed"].size(), 2u);  // poses.txt and times.txt
  const std::string poses_note = s.summary["trimmed"][0].get<std::string>();
  const std::string times_note = s.summary["trimmed"][1].get<std::string>();
  EXPECT_NE(poses_note.find((root / "poses.txt").string() + ": 6 poses (lines) for the 4 images of " +
                            (root / "image_0").string() + " (000000.png .. 000003.png)"),
            std::string::npos) << poses_note;
  EXPECT_NE(times_note.find((root / "times.txt").string() + ": 6 timestamps (lines) for the 4 images"),
            std::string::npos) << times_note;
  EXPECT_NE(times_note.find("a trimmed sequence; the first 4 are used"), std::string::npos) << times_note;

  // frame_count within the images, and past them (at most that many).
  ImageSequenceOptions o;
  o.frame_count = 3;
  EXPECT_EQ(ReadKittiOdometry(r, o).frames.size(), 3u);
  o.frame_count = 160;
  EXPECT_EQ(ReadKittiOdometry(r, o).frames.size(), 4u);

  // A gap (000001.png missing: the images are not the first 3): refused, naming the image.
  fs::rename(root / "image_0" / "000001.png", dir / "kept.png");
  ExpectError([&] { ReadKittiOdometry(r, {}); },
              {(root / "image_0" / "000001.png").string(), "no such file", "pose line 2",
               (root / "poses.txt").string(), "has 3 images for 6 poses (lines)"});
  fs::rename(dir / "kept.png", root / "image_0" / "000001.png");

  // Fewer timestamps than images: refused, naming the file and the images without a line.
  Write(root / "times.txt", "0\n0.1\n");
  ExpectError([&] { ReadKittiOdometry(r, {}); },
              {(root / "times.txt").string(), "2 timestamps (lines)", "has 4 images",
               "000002.png .. 000003.png have no line"});
}

// --- KITTI raw -----------------------------------------------------------------------------------
// Date folder: calib_cam_to_cam.txt (P_rect_00..03 as above, R_rect_00), calib_velo_to_cam.txt,
// calib_imu_to_velo.txt. The chain IMU -> rectified camera 0 is built to be
//   x_cam = Pm x_imu + (0, 0, -1),   Pm = [[0, -1, 0], [0, 0, -1], [1, 0, 0]]
// (IMU x forward, y left, z up; the camera 1 m ahead of the IMU), split over the three files so
// that each must be applied, in the right order:
//   imu -> velo: R = I, T = (0.5, 0, 0);
//   R_rect_00 = Rz_cam(90 deg) = [[0, -1, 0], [1, 0, 0], [0, 0, 1]];
//   velo -> cam: R = R_rect^T Pm = [[0, 0, -1], [0, 1, 0], [1, 0, 0]], T = R_rect^T (0, 0, -1.5)
//   = (0, 0, -1.5);  so R_rect (R_v (x + (0.5, 0, 0)) + T) = Pm x + (0, 0, 0.5) + (0, 0, -1.5).
const char* kRrect = "0 -1 0 1 0 0 0 0 1";
const char* kVeloToCamR = "0 0 -1 0 1 0 1 0 0";

std::string CamToCam(const std::string& skip = "") {
  std::string s = "calib_time: 09-Jan-2012 13:57:47\ncorner_dist: 9.950000e-02\n";
  s += std::string("R_rect_00: ") + kRrect + "\n";
  for (int k = 0; k < 4; ++k) {
    const std::string key = "P_rect_0" + std::to_string(k);
    if (key != skip) s += key + ": " + Projection(k) + "\n";
  }
  return s;
}

// oxts: 30 numbers, lat lon alt roll pitch yaw and 24 more (velocities etc., unused here).
std::string Oxts(double lat, double lon, double alt, double roll, double pitch, double yaw) {
  std::string s = Num(lat) + " " + Num(lon) + " " + Num(alt) + " " + Num(roll) + " " + Num(pitch) +
                  " " + Num(yaw);
  for (int i = 0; i < 24; ++i) s += " 0";
  return s + "\n";
}

struct RawDrive {
  fs::path date, drive;
};

RawDrive MakeRawDrive(const TempDir& dir, int frames, const std::vector<int>& cameras) {
  RawDrive d{dir / "2011_09_26", dir / "2011_09_26" / "2011_09_26_drive_0001_sync"};
  for (int k : cameras)
    for (int i = 0; i < frames; ++i) {
      char name[32];
      std::snprintf(name, sizeof name, "%010d.png", i);
      WritePng(d.drive / ("image_0" + std::to_string(k)) / "data" / name);
    }
  Write(d.date / "calib_cam_to_cam.txt", CamToCam());
  Write(d.date / "calib_velo_to_cam.txt",
        std::string("calib_time: 15-Mar-2012 11:37:16\nR: ") + kVeloToCamR + "\nT: 0 0 -1.5\n");
  Write(d.date / "calib_imu_to_velo.txt", "R: 1 0 0 0 1 0 0 0 1\nT: 0.5 0 0\n");
  return d;
}

// Three oxts records (hand-computed result below). Earth radius 6378137 m; Mercator scale
// s = cos(lat0); east = s * lon * pi * er / 180, north = s * er * ln(tan((90 + lat) pi / 360)).
//   0: lat0 = 49, lon0 = 8.4, alt 110, heading (yaw) 30 deg.
//   1: 10 m along the heading of frame 0 (east 10 cos 30, north 10 sin 30), yaw 120 deg.
//   2: 2 m above frame 0, roll 90 deg, yaw 30 deg.
void WriteOxts(const RawDrive& d) {
  const double pi = std::numbers::pi, er = 6378137.0, lat0 = 49.0, lon0 = 8.4;
  const double s = std::cos(lat0 * pi / 180.0);
  const double north0 = s * er * std::log(std::tan((90.0 + lat0) * pi / 360.0));
  const double lon1 = lon0 + 10.0 * std::cos(pi / 6) * 180.0 / (s * pi * er);
  const double lat1 =
      std::atan(std::exp((north0 + 10.0 * std::sin(pi / 6)) / (s * er))) * 360.0 / pi - 90.0;
  const fs::path oxts = d.drive / "oxts" / "data";
  Write(oxts / "0000000000.txt", Oxts(lat0, lon0, 110, 0, 0, pi / 6));
  Write(oxts / "0000000001.txt", Oxts(lat1, lon1, 110, 0, 0, 2 * pi / 3));
  Write(oxts / "0000000002.txt", Oxts(lat0, lon0, 112, pi / 2, 0, pi / 6));
}

// Camera 0, world = camera 0 at frame 0 (IMU_0 coordinates X -> Pm X + (0, 0, -1)):
//   frame 1: the IMU is 10 m ahead of where it was and turned 90 deg left; the camera, 1 m
//     ahead of the IMU, is at IMU_0 (10, 1, 0) -> world (-1, 0, 9), looking along world -x:
//     R rows (its x, y, z axes in world) = (0, 0, 1), (0, 1, 0), (-1, 0, 0).
//   frame 2: the IMU 2 m up and rolled 90 deg about its forward axis (a yaw-first product
//     Rz Ry Rx; any other order gives another rotation, as the heading is 30 deg): the camera is
//     at IMU_0 (1, 0, 2) -> world (0, -2, 0); its x axis points world down (0, 1, 0), its y axis
//     world left (-1, 0, 0), its z still forward.
const Mat3 kRawR1 = {{{0, 0, 1}, {0, 1, 0}, {-1, 0, 0}}};
const Mat3 kRawR2 = {{{0, 1, 0}, {-1, 0, 0}, {0, 0, 1}}};

TEST(KittiRaw, OxtsPosesAsTheDevkitConvertsThem) {
  TempDir dir;
  const RawDrive d = MakeRawDrive(dir, 3, {0, 2});
  WriteOxts(d);
  const ImageSequence s = ReadKittiRaw(d.drive.string(), {});
  EXPECT_EQ(s.layout, "kitti_raw");
  EXPECT_EQ(s.camera, 0);
  ASSERT_EQ(s.frames.size(), 3u);
  ExpectMat(s.frames[0].camera.rotation, Identity3(), 1e-12);
  ExpectVec(s.frames[0].camera.center, {0, 0, 0}, 1e-9);
  ExpectMat(s.frames[1].camera.rotation, kRawR1, 1e-12);
  ExpectVec(s.frames[1].camera.center, {-1, 0, 9}, 1e-6);  // Mercator round trip: ~1e-9 m
  ExpectMat(s.frames[2].camera.rotation, kRawR2, 1e-12);
  ExpectVec(s.frames[2].camera.center, {0, -2, 0}, 1e-6);
  EXPECT_NEAR(s.summary["poses"]["mercator_scale"].get<double>(),
              std::cos(49.0 * std::numbers::pi / 180.0), 1e-15);
  // No timestamps.txt, no times.txt: 10 Hz.
  EXPECT_DOUBLE_EQ(s.frames[2].timestamp, 0.2);

  // Where the world stands on the Earth (issue 46, geo-referenced tiles): camera 0 of frame 0,
  // 1 m ahead of the IMU along the yaw of 30 deg (counter-clockwise from east), its axes to ENU:
  // forward (world +z) to (cos 30, sin 30, 0), up (world -y) to up.
  ASSERT_TRUE(s.geo.has_value());
  const double pi = std::numbers::pi;
  auto ahead = [](double lat, double lon, double alt, double yaw, double metres) {
    std::array<double, 3> x = geo::EcefFromGeodetic({lat, lon, alt});
    const std::array<double, 9> enu = geo::EnuAxes(lat, lon);
    for (int k = 0; k < 3; ++k) x[k] += metres * (std::cos(yaw) * enu[k] + std::sin(yaw) * enu[3 + k]);
    return x;
  };
  const std::array<double, 3> at = geo::EcefFromGeodetic(s.geo->origin);
  const std::array<double, 3> want = ahead(49.0, 8.4, 110.0, pi / 6, 1.0);
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(at[k], want[k], 1e-6);
  const std::array<double, 9>& r = s.geo->enu_from_world;
  ExpectVec({r[2], r[5], r[8]}, {std::cos(pi / 6), std::sin(pi / 6), 0}, 1e-12);
  ExpectVec({-r[1], -r[4], -r[7]}, {0, 0, 1}, 1e-12);
  EXPECT_NE(s.geo->source.find("0000000000.txt"), std::string::npos);
  EXPECT_EQ(s.summary["geo_anchor"]["latitude"], s.geo->origin.latitude);
  // Frame 1's camera, put on the Earth through the anchor, is where its own oxts record and the
  // calibration say: 1 m ahead of that record's position along its yaw (120 deg). The poses are
  // the devkit's Mercator: within a few centimetres of the ellipsoid over these 10 m.
  {
    const Vec3 c = s.frames[1].camera.center;
    std::array<double, 3> ecef = at;
    const std::array<double, 9> enu = geo::EnuAxes(s.geo->origin.latitude, s.geo->origin.longitude);
    for (int k = 0; k < 3; ++k)
      for (int j = 0; j < 3; ++j) ecef[k] += enu[3 * j + k] * (r[3 * j] * c[0] + r[3 * j + 1] * c[1] + r[3 * j + 2] * c[2]);
    const double s0 = std::cos(49.0 * pi / 180.0), er = 6378137.0;
    const double north0 = s0 * er * std::log(std::tan((90.0 + 49.0) * pi / 360.0));
    const double lon1 = 8.4 + 10.0 * std::cos(pi / 6) * 180.0 / (s0 * pi * er);
    const double lat1 = std::atan(std::exp((north0 + 10.0 * std::sin(pi / 6)) / (s0 * er))) * 360.0 / pi - 90.0;
    const std::array<double, 3> want1 = ahead(lat1, lon1, 110.0, 2 * pi / 3, 1.0);
    EXPECT_LT(std::hypot(ecef[0] - want1[0], ecef[1] - want1[1], ecef[2] - want1[2]), 0.05);
  }

  // Camera 2 (x_cam2 = x_cam0 + b2, world = camera 2 at frame 0): the same rotations;
  // C = C_0 - R^T b2 + b2. Frame 1: R^T b2 = (-0.125, 0.25, 0.5), C = (-0.375, 0, 8.625).
  const ImageSequence s2 = ReadKittiRaw(d.drive.string(), Camera(2));
  ExpectVec(s2.frames[0].camera.center, {0, 0, 0}, 1e-9);
  ExpectMat(s2.frames[1].camera.rotation, kRawR1, 1e-12);
  ExpectVec(s2.frames[1].camera.center, {-0.375, 0, 8.625}, 1e-6);
  EXPECT_EQ(s2.frames[1].image_path, (d.drive / "image_02" / "data" / "0000000001.png").string());
}

TEST(KittiRaw, PosesFileTimestampsAndVelodyne) {
  TempDir dir;
  const RawDrive d = MakeRawDrive(dir, 2, {2});
  Write(d.drive / "poses_cam0_gt.txt", TwoPoses());  // camera inferred from the name
  Write(d.drive / "image_02" / "timestamps.txt",
        "2011-09-26 23:59:59.950000000\n2011-09-27 00:00:00.050000001\n");
  Write(d.drive / "velodyne_points" / "data" / "0000000001.bin", std::string(16, '\0'));
  const ImageSequence s = ReadKittiRaw(d.drive.string(), {});
  EXPECT_EQ(s.camera, 2);
  EXPECT_EQ(s.summary["poses"]["camera"], 0);
  EXPECT_EQ(s.summary["poses"]["camera_from"], "the file name");
  EXPECT_EQ(s.summary["poses"]["chosen_by"], "the only poses*.txt in the drive folder");
  EXPECT_FALSE(s.geo.has_value());  // a poses file's frame is not placed on the Earth
  ExpectVec(s.frames[0].camera.translation, kB[2]);  // camera-0 poses, camera 2 images
  ExpectVec(s.frames[1].camera.center, {0.875, 1.75, 3.5});
  EXPECT_DOUBLE_EQ(s.frames[0].timestamp, 0.0);
  EXPECT_NEAR(s.frames[1].timestamp, 0.100000001, 1e-10);  // across midnight
  EXPECT_EQ(s.frames[0].camera.intrinsics.width, kW);

  // Velodyne -> camera 2: [I | b2] R_rect_00 T_velo_to_cam = Pm x + (0, 0, -1.5) + b2.
  ASSERT_TRUE(s.has_lidar);
  EXPECT_EQ(s.lidar.scan_paths[0], "");
  EXPECT_EQ(s.lidar.scan_paths[1],
            (d.drive / "velodyne_points" / "data" / "0000000001.bin").string());
  const Mat34 expected = {{{0, -1, 0, 0.5}, {0, 0, -1, 0.25}, {1, 0, 0, -1.5 + 0.125}}};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 4; ++j) EXPECT_NEAR(s.lidar.velo_to_camera[i][j], expected[i][j], 1e-15);

  // A second poses file: the one named for the chosen camera wins; two such are refused.
  Write(d.drive / "poses_cam2_lidar.txt", std::string(kPose0) + "\n" + kPose0 + "\n");
  const ImageSequence s2 = ReadKittiRaw(d.drive.string(), {});
  EXPECT_EQ(s2.summary["poses"]["file"], (d.drive / "poses_cam2_lidar.txt").string());
  ExpectVec(s2.frames[0].camera.translation, {0, 0, 0});
  Write(d.drive / "poses_cam2_other.txt", TwoPoses());
  ExpectError([&] { ReadKittiRaw(d.drive.string(), {}); },
              {"several poses files", "poses_cam0_gt.txt", "poses_cam2_other.txt", "option poses"});
}

// The open rule (issue 44): each file of a KITTI raw drive that is a FIFO is refused at once,
// naming it (an optional one, timestamps or a poses file, is not taken for absent).
TEST(KittiRaw, AFifoWhereAFileGoesIsRefusedAtOnceNamingIt) {
  const auto fifo_refused = [](const RawDrive& d, const fs::path& fifo) {
    fs::remove(fifo);
    ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0) << fifo;
    auto done = std::async(std::launch::async, [&] {
      try {
        ReadKittiRaw(d.drive.string(), {});
      } catch (const std::runtime_error& e) {
        return std::string(e.what());
      }
      return std::string("(no error)");
    });
    if (done.wait_for(std::chrono::seconds(5)) != std::future_status::ready) {
      ADD_FAILURE() << fifo << ": the reader still waits on the FIFO after 5 s";
      std::_Exit(1);  // the blocked thread cannot be joined
    }
    const std::string m = done.get();
    EXPECT_NE(m.find(fifo.string() + ": is not a regular file (a FIFO)"), std::string::npos) << m;
  };
  for (const char* which : {"calib", "oxts", "timestamps", "poses"}) {
    SCOPED_TRACE(which);
    TempDir dir;
    const RawDrive d = MakeRawDrive(dir, 3, {2});
    WriteOxts(d);
    const std::string w = which;
    if (w == "calib") fifo_refused(d, d.date / "calib_cam_to_cam.txt");
    if (w == "oxts") fifo_refused(d, d.drive / "oxts" / "data" / "0000000001.txt");
    if (w == "timestamps") fifo_refused(d, d.drive / "image_02" / "timestamps.txt");
    if (w == "poses") fifo_refused(d, d.drive / "poses.txt");
  }
}

TEST(KittiRaw, RefusesBadInputNamingFileLineAndWhat) {
  TempDir dir;
  const RawDrive d = MakeRawDrive(dir, 2, {2});
  const std::string r = d.drive.string();
  ExpectError([&] { ReadKittiRaw(r, {}); }, {r, "no poses", "oxts"});
  WriteOxts(d);  // 3 records for 2 images: a trimmed drive (issue 47), the first 2 serve
  {
    const ImageSequence t = ReadKittiRaw(r, {});
    EXPECT_EQ(t.frames.size(), 2u);
    ASSERT_EQ(t.summary["trimmed"].size(), 1u) << t.summary.dump();
    EXPECT_NE(t.summary["trimmed"][0].get<std::string>().find(
                  (d.drive / "oxts" / "data").string() + ": 3 oxts records (.txt) for the 2 images"),
              std::string::npos) << t.summary["trimmed"][0];
    // Dates for 3 images, 2 kept: the same cut.
    Write(d.drive / "image_02" / "timestamps.txt",
          "2011-09-26 13:02:25.5\n2011-09-26 13:02:25.6\n2011-09-26 13:02:25.7\n");
    const ImageSequence u = ReadKittiRaw(r, {});
    EXPECT_EQ(u.summary["trimmed"].size(), 2u) << u.summary.dump();
    EXPECT_NEAR(u.frames[1].timestamp, 0.1, 1e-9);
    fs::remove(d.drive / "image_02" / "timestamps.txt");
  }
  fs::remove(d.drive / "image_02" / "data" / "0000000001.png");  // now a gap: 0 and (not) 1
  Write(d.drive / "image_02" / "data" / "0000000005.png", "");
  ExpectError([&] { ReadKittiRaw(r, {}); },
              {(d.drive / "image_02" / "data" / "0000000001.png").string(), "no such file",
               "line 2 of " + (d.drive / "oxts" / "data").string()});
  fs::remove(d.drive / "image_02" / "data" / "0000000005.png");
  WritePng(d.drive / "image_02" / "data" / "0000000001.png");
  fs::remove(d.drive / "oxts" / "data" / "0000000002.txt");
  Write(d.drive / "oxts" / "data" / "0000000001.txt", "49 8.4 110 0 0 0\n");
  ExpectError([&] { ReadKittiRaw(r, {}); },
              {"0000000001.txt:1", "6 numbers, expected 30", "lat lon alt roll pitch yaw"});
  fs::remove(d.date / "calib_imu_to_velo.txt");
  ExpectError([&] { ReadKittiRaw(r, {}); },
              {(d.date / "calib_imu_to_velo.txt").string(), "no such file", "oxts"});
  fs::remove_all(d.drive / "oxts");

  Write(d.drive / "poses.txt", TwoPoses());
  EXPECT_EQ(ReadKittiRaw(r, {}).frames.size(), 2u);

  Write(d.date / "calib_cam_to_cam.txt", CamToCam("P_rect_02"));
  ExpectError([&] { ReadKittiRaw(r, {}); },
              {"calib_cam_to_cam.txt: no line 'P_rect_02:'", "projection of camera 2"});
  fs::remove(d.date / "calib_cam_to_cam.txt");
  ExpectError([&] { ReadKittiRaw(r, {}); },
              {(d.date / "calib_cam_to_cam.txt").string(), "no such file", "date folder"});
  Write(d.date / "calib_cam_to_cam.txt", CamToCam());

  Write(d.drive / "image_02" / "timestamps.txt", "2011-09-26 13:02:25.96\n2011-09-26 13:02\n");
  ExpectError([&] { ReadKittiRaw(r, {}); },
              {"timestamps.txt:2", "'2011-09-26 13:02'", "YYYY-MM-DD hh:mm:ss"});
  Write(d.drive / "image_02" / "timestamps.txt", "2011-09-26 13:02:25.96\n");
  ExpectError([&] { ReadKittiRaw(r, {}); }, {"timestamps.txt", "1 timestamps", "has 2 images"});
  fs::remove(d.drive / "image_02" / "timestamps.txt");
  Write(d.drive / "times.txt", "0\n");
  ExpectError([&] { ReadKittiRaw(r, {}); }, {"times.txt", "1 timestamps", "has 2 images"});
  fs::remove(d.drive / "times.txt");

  // Velodyne scans need calib_velo_to_cam.txt.
  Write(d.drive / "velodyne_points" / "data" / "0000000000.bin", std::string(16, '\0'));
  Write(d.date / "calib_velo_to_cam.txt", "R: 1 0 0 0 1 0 0 0 1\n");
  ExpectError([&] { ReadKittiRaw(r, {}); },
              {"calib_velo_to_cam.txt: no line 'T:'", "velodyne -> camera 0"});
  Write(d.date / "calib_velo_to_cam.txt", "R: 1 0 0 0 1 0 0 0 2\nT: 0 0 0\n");
  ExpectError([&] { ReadKittiRaw(r, {}); }, {"calib_velo_to_cam.txt:1", "R is not a rotation"});
  ExpectError([&] { ReadKittiRaw(r, Camera(1)); },
              {(d.drive / "image_01").string(), "no such folder"});
  ExpectError([&] { ReadKittiRaw((dir / "nothing").string(), {}); }, {"nothing", "no such folder"});
}

// --- Middlebury ----------------------------------------------------------------------------------
// View a: K = [[1500, 0, 300], [0, 1510, 240], [0, 0, 1]], R = Ry(90)^T (see kR1), t = (3, -2,
// -1): C = (1, 2, 3). View b: R = I, t = (0, 0, 2): C = (0, 0, -2).
std::string ParLine(const std::string& name, const std::string& r, const std::string& t) {
  return name + " 1500 0 300 0 1510 240 0 0 1 " + r + " " + t + "\n";
}

void MakeMiddlebury(const fs::path& folder, const std::string& count = "2") {
  WritePng(folder / "a.png");
  WritePng(folder / "b.png");
  Write(folder / "obj_par.txt", count + "\n" + ParLine("a.png", "0 0 -1 0 1 0 1 0 0", "3 -2 -1") +
                                    ParLine("b.png", "1 0 0 0 1 0 0 0 1", "0 0 2"));
}

TEST(Middlebury, ParLineGivesKRt) {
  TempDir dir;
  MakeMiddlebury(dir / "obj");
  const ImageSequence s = ReadMiddlebury((dir / "obj").string(), {});  // the folder
  EXPECT_EQ(s.layout, "middlebury");
  ASSERT_EQ(s.frames.size(), 2u);
  const CameraGeometry& a = s.frames[0].camera;
  EXPECT_EQ(a.name, "a.png");
  EXPECT_EQ(s.frames[0].image_path, (dir / "obj" / "a.png").string());
  ExpectMat(a.rotation, kR1);
  ExpectVec(a.translation, kT1);
  ExpectVec(a.center, kC1);
  EXPECT_EQ(a.intrinsics.fx, 1500);
  EXPECT_EQ(a.intrinsics.fy, 1510);
  EXPECT_EQ(a.intrinsics.cx, 300);
  EXPECT_EQ(a.intrinsics.cy, 240);
  EXPECT_EQ(a.intrinsics.width, kW);
  EXPECT_TRUE(a.intrinsics.projectable);
  // The world origin: camera b sees it 2 m ahead on its axis; camera a sees it at
  // x_cam = t = (3, -2, -1)... behind it (z < 0), so it does not project.
  double u = 0, v = 0;
  ASSERT_TRUE(Project(s.frames[1].camera, {0, 0, 0}, &u, &v));
  EXPECT_NEAR(u, 300, 1e-12);
  EXPECT_NEAR(v, 240, 1e-12);
  EXPECT_FALSE(Project(a, {0, 0, 0}, &u, &v));
  // (1.5, 2, 3): 0.5 m ahead of a's centre along world +x, a's axis.
  ASSERT_TRUE(Project(a, {1.5, 2, 3}, &u, &v));
  EXPECT_NEAR(u, 300, 1e-12);
  EXPECT_EQ(s.frames[1].camera.id, 1u);
  EXPECT_EQ(s.frames[1].timestamp, 1.0);

  ImageSequenceOptions o;
  o.first_frame = 1;
  const ImageSequence one = ReadMiddlebury((dir / "obj" / "obj_par.txt").string(), o);
  ASSERT_EQ(one.frames.size(), 1u);
  EXPECT_EQ(one.frames[0].camera.id, 0u);
  EXPECT_EQ(one.frames[0].source_index, 1);
  EXPECT_EQ(one.frames[0].camera.name, "b.png");
}

TEST(Middlebury, RefusesBadInputNamingFileLineAndWhat) {
  TempDir dir;
  const fs::path par = dir / "obj" / "obj_par.txt";
  MakeMiddlebury(dir / "obj", "3");
  ExpectError([&] { ReadMiddlebury(par.string(), {}); },
              {"obj_par.txt:1", "says 3 views", "has 2 view lines"});
  MakeMiddlebury(dir / "obj", "two");
  ExpectError([&] { ReadMiddlebury(par.string(), {}); }, {"obj_par.txt:1", "'two'"});
  Write(par, "2\n" + ParLine("a.png", "0 0 -1 0 1 0 1 0 0", "3 -2 -1") +
                 ParLine("b.png", "1 0 0 0 1 0 0 0 1", "0 0"));
  ExpectError([&] { ReadMiddlebury(par.string(), {}); },
              {"obj_par.txt:3", "20 numbers", "expected 21"});
  Write(par, "2\n" + ParLine("a.png", "0 0 -1 0 1 0 1 0 0", "3 -2 -1") +
                 ParLine("b.png", "1 0 0 0 1 0 0 0.5 1", "0 0 2"));
  ExpectError([&] { ReadMiddlebury(par.string(), {}); },
              {"obj_par.txt:3", "R (numbers 10-18) is not a rotation"});
  Write(par, "1\nc.png 1500 2 300 0 1510 240 0 0 1 1 0 0 0 1 0 0 0 1 0 0 2\n");
  ExpectError([&] { ReadMiddlebury(par.string(), {}); }, {"obj_par.txt:2", "K is not"});
  Write(par, "1\n" + ParLine("c.png", "1 0 0 0 1 0 0 0 1", "0 0 2"));
  ExpectError([&] { ReadMiddlebury(par.string(), {}); },
              {(dir / "obj" / "c.png").string(), "no such file", "obj_par.txt:2"});
  ImageSequenceOptions o = Camera(2);
  ExpectError([&] { ReadMiddlebury(par.string(), o); }, {"camera, poses and poses_camera"});
  ExpectError([&] { ReadMiddlebury((dir / "empty").string(), {}); }, {"no such file or folder"});
  fs::create_directories(dir / "empty");
  ExpectError([&] { ReadMiddlebury((dir / "empty").string(), {}); }, {"no *_par.txt"});
}

// --- image_io ----------------------------------------------------------------------------------

// A PNG written by hand (stored deflate blocks), for the bit depths and channel layouts
// WriteImage does not write: 16-bit gray, gray + alpha, RGBA.
uint32_t Crc32(const std::string& bytes) {
  uint32_t c = 0xffffffffu;
  for (unsigned char b : bytes) {
    c ^= b;
    for (int k = 0; k < 8; ++k) c = (c >> 1) ^ (0xedb88320u & (0u - (c & 1u)));
  }
  return c ^ 0xffffffffu;
}
std::string Be32(uint32_t v) {
  return {static_cast<char>(v >> 24), static_cast<char>(v >> 16), static_cast<char>(v >> 8),
          static_cast<char>(v)};
}
std::string Chunk(const std::string& type, const std::string& data) {
  return Be32(static_cast<uint32_t>(data.size())) + type + data + Be32(Crc32(type + data));
}
// `rows`: raw bytes of each row (without the filter byte).
std::string HandPng(int w, int h, int bit_depth, int color_type,
                    const std::vector<std::string>& rows) {
  std::string raw;
  for (const auto& r : rows) raw += '\0' + r;
  uint32_t a = 1, b = 0;  // Adler-32
  for (unsigned char c : raw) {
    a = (a + c) % 65521;
    b = (b + a) % 65521;
  }
  const auto n = static_cast<uint16_t>(raw.size());
  std::string z = "\x78\x01";
  z += '\x01';  // final stored block
  z += static_cast<char>(n & 0xff);
  z += static_cast<char>(n >> 8);
  z += static_cast<char>(~n & 0xff);
  z += static_cast<char>((~n >> 8) & 0xff);
  z += raw + Be32((b << 16) | a);
  std::string ihdr = Be32(static_cast<uint32_t>(w)) + Be32(static_cast<uint32_t>(h));
  ihdr += static_cast<char>(bit_depth);
  ihdr += static_cast<char>(color_type);
  ihdr += std::string(3, '\0');
  return std::string("\x89PNG\r\n\x1a\n", 8) + Chunk("IHDR", ihdr) + Chunk("IDAT", z) +
         Chunk("IEND", "");
}

TEST(ImageIo, RoundTripGrayAndColour) {
  TempDir dir;
  const Image g = Gray(5, 3);
  WriteImage((dir / "g.png").string(), g);
  const Image g2 = ReadImage((dir / "g.png").string());
  EXPECT_EQ(g2.width, 5);
  EXPECT_EQ(g2.height, 3);
  EXPECT_EQ(g2.channels, 1);
  EXPECT_EQ(g2.stride_bytes, 5);
  EXPECT_EQ(g2.pixels, g.pixels);

  Image c;
  c.width = 2;
  c.height = 2;
  c.channels = 3;
  c.stride_bytes = 6;
  c.pixels = {255, 0, 0, 0, 255, 0, 0, 0, 255, 10, 20, 30};  // BGR
  WriteImage((dir / "c.png").string(), c);
  const Image c2 = ReadImage((dir / "c.png").string());
  EXPECT_EQ(c2.channels, 3);
  EXPECT_EQ(c2.pixels, c.pixels);
  const ImageSize size = ReadImageSize((dir / "c.png").string());
  EXPECT_EQ(size.width, 2);
  EXPECT_EQ(size.height, 2);

  WriteImage((dir / "g.jpg").string(), Gray(33, 17));  // size from the JPEG frame header
  const ImageSize js = ReadImageSize((dir / "g.jpg").string());
  EXPECT_EQ(js.width, 33);
  EXPECT_EQ(js.height, 17);
  EXPECT_EQ(ReadImage((dir / "g.jpg").string()).width, 33);
}

TEST(ImageIo, SixteenBitAndAlphaBecomeEightBitGrayOrBgr) {
  TempDir dir;
  // 16-bit gray, 2x1: 0xffff and 0x8080 -> 255 and 128.
  Write(dir / "g16.png", HandPng(2, 1, 16, 0, {std::string("\xff\xff\x80\x80", 4)}));
  const Image g = ReadImage((dir / "g16.png").string());
  EXPECT_EQ(g.channels, 1);
  EXPECT_EQ(g.pixels, (std::vector<uint8_t>{255, 128}));
  // Gray + alpha: OpenCV's PNG decoder expands it to BGRA; the gray stays, alpha is dropped.
  Write(dir / "ga.png", HandPng(2, 1, 8, 4, {std::string("\x10\x80\x20\xff", 4)}));
  const Image ga = ReadImage((dir / "ga.png").string());
  EXPECT_EQ(ga.channels, 3);
  EXPECT_EQ(ga.pixels, (std::vector<uint8_t>{0x10, 0x10, 0x10, 0x20, 0x20, 0x20}));
  // RGBA: BGR, alpha dropped.
  Write(dir / "rgba.png", HandPng(1, 1, 8, 6, {std::string("\x01\x02\x03\x04", 4)}));
  const Image rgba = ReadImage((dir / "rgba.png").string());
  EXPECT_EQ(rgba.channels, 3);
  EXPECT_EQ(rgba.stride_bytes, 3);
  EXPECT_EQ(rgba.pixels, (std::vector<uint8_t>{3, 2, 1}));
  EXPECT_EQ(ReadImageSize((dir / "rgba.png").string()).width, 1);
}

TEST(ImageIo, MissingAndCorruptFilesAreNamed) {
  TempDir dir;
  const std::string missing = (dir / "none.png").string();
  ExpectError([&] { ReadImage(missing); }, {missing, "no such file"});
  ExpectError([&] { ReadImageSize(missing); }, {missing, "no such file"});
  Write(dir / "text.png", "this is not an image");
  ExpectError([&] { ReadImage((dir / "text.png").string()); },
              {"cannot decode", (dir / "text.png").string(), "not a PNG/JPEG, or truncated"});
  ExpectError([&] { ReadImageSize((dir / "text.png").string()); }, {"cannot decode"});
  // A real PNG cut after its header: the size is readable, the pixels are not.
  const std::string png = HandPng(4, 4, 8, 0, std::vector<std::string>(4, std::string(4, 'x')));
  Write(dir / "cut.png", png.substr(0, 40));
  EXPECT_EQ(ReadImageSize((dir / "cut.png").string()).width, 4);
  ExpectError([&] { ReadImage((dir / "cut.png").string()); },
              {"cannot decode", (dir / "cut.png").string()});
  Write(dir / "short.png", png.substr(0, 12));
  ExpectError([&] { ReadImageSize((dir / "short.png").string()); }, {"cannot decode", "IHDR"});
  ExpectError([&] { ReadImage(dir.path().string()); }, {"is a folder"});
}

// --- Real data (IMR_SHARED_DIR/data) -----------------------------------------------------------

fs::path SharedData(const std::string& relative) {
  const char* shared = std::getenv("IMR_SHARED_DIR");
  if (shared == nullptr) return {};
  const fs::path p = fs::path(shared) / "data" / relative;
  return fs::exists(p) ? p : fs::path();
}

const char* kKittiDrive = "kitti-raw-2011_09_26-traffic/2011_09_26/2011_09_26_drive_unknown_sync";

double Distance(const Vec3& a, const Vec3& b) {
  return std::sqrt((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) +
                   (a[2] - b[2]) * (a[2] - b[2]));
}

// The KITTI raw sample: colour camera 2, camera-2 poses from LiDAR registration (README: about
// 8.1 m over frames 0-53, then standing). Measured here: 8.02 m at frame 53, 8.01 m at 77.
TEST(RealData, KittiRawTrafficSample) {
  const fs::path drive = SharedData(kKittiDrive);
  if (drive.empty())
    GTEST_SKIP() << "KITTI raw sample not found (IMR_SHARED_DIR/data/" << kKittiDrive << ")";
  const ImageSequence s = ReadKittiRaw(drive.string(), {});
  EXPECT_EQ(s.camera, 2);
  ASSERT_EQ(s.frames.size(), 78u);
  EXPECT_EQ(s.summary["poses"]["file"], (drive / "poses_cam2_lidar.txt").string());
  EXPECT_EQ(s.summary["poses"]["camera"], 2);
  const Intrinsics& k = s.frames[0].camera.intrinsics;
  EXPECT_EQ(k.width, 1242);
  EXPECT_EQ(k.height, 375);
  EXPECT_DOUBLE_EQ(k.fx, 721.5377);
  EXPECT_DOUBLE_EQ(k.fy, 721.5377);
  EXPECT_DOUBLE_EQ(k.cx, 609.5593);
  EXPECT_DOUBLE_EQ(k.cy, 172.854);
  ExpectMat(s.frames[0].camera.rotation, Identity3(), 1e-8);
  ExpectVec(s.frames[0].camera.center, {0, 0, 0}, 1e-8);
  for (std::size_t i = 0; i < s.frames.size(); ++i) {
    EXPECT_EQ(s.frames[i].camera.id, i);
    EXPECT_NEAR(s.frames[i].timestamp, 0.1 * static_cast<double>(i), 1e-9);
    EXPECT_TRUE(RotationProblem(s.frames[i].camera.rotation, 1e-6).empty()) << i;
  }
  const double travelled = Distance(s.frames[53].camera.center, s.frames[0].camera.center);
  EXPECT_GT(travelled, 7.8);
  EXPECT_LT(travelled, 8.4);
  // Forward is +z; the stationary tail stays within a few cm.
  EXPECT_GT(s.frames[53].camera.center[2], 7.8);
  EXPECT_LT(Distance(s.frames[77].camera.center, s.frames[54].camera.center), 0.05);

  ASSERT_TRUE(s.has_lidar);
  ASSERT_EQ(s.lidar.scan_paths.size(), 78u);
  for (const auto& p : s.lidar.scan_paths) EXPECT_TRUE(fs::is_regular_file(p)) << p;
  EXPECT_EQ(fs::file_size(s.lidar.scan_paths[0]) % 16, 0u);  // float32 x, y, z, reflectance

  // The first image decodes to what the header said.
  const Image image = ReadImage(s.frames[0].image_path);
  EXPECT_EQ(image.width, 1242);
  EXPECT_EQ(image.height, 375);
  EXPECT_EQ(image.channels, 3);
}

// calib_cam_to_cam.txt (date folder) and the drive's odometry-style calib.txt agree: P2 and
// Tr = velodyne -> rectified camera 0 (= R_rect_00 T_velo_to_cam).
TEST(RealData, KittiRawCalibrationAgreesWithCalibTxt) {
  const fs::path drive = SharedData(kKittiDrive);
  if (drive.empty())
    GTEST_SKIP() << "KITTI raw sample not found (IMR_SHARED_DIR/data/" << kKittiDrive << ")";
  const ImageSequence s = ReadKittiRaw(drive.string(), {});
  std::vector<double> p2, tr;
  const std::string calib = (drive / "calib.txt").string();
  const std::vector<std::string> lines = ReadTextLines(calib, "test");
  for (std::size_t i = 0; i < lines.size(); ++i) {
    if (lines[i].rfind("P2:", 0) == 0) p2 = ParseNumbers(lines[i].substr(3), calib, 1);
    if (lines[i].rfind("Tr:", 0) == 0) tr = ParseNumbers(lines[i].substr(3), calib, 1);
  }
  ASSERT_EQ(p2.size(), 12u);
  ASSERT_EQ(tr.size(), 12u);
  const Intrinsics& k = s.frames[0].camera.intrinsics;
  EXPECT_EQ(k.source_params, p2);
  EXPECT_EQ(k.fx, p2[0]);
  EXPECT_EQ(k.cx, p2[2]);
  EXPECT_EQ(k.cy, p2[6]);
  // b2 = K^-1 P2[:, 3]: camera 2 is 6 cm left of camera 0 (x_cam2 = x_cam0 + b2).
  const double bz = p2[11], by = (p2[7] - p2[6] * bz) / p2[5], bx = (p2[3] - p2[2] * bz) / p2[0];
  EXPECT_NEAR(bx, 0.0599, 1e-3);
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) EXPECT_NEAR(s.lidar.velo_to_camera[i][j], tr[i * 4 + j], 1e-6);
    EXPECT_NEAR(s.lidar.velo_to_camera[i][3],
                tr[i * 4 + 3] + (i == 0   ? bx
                                 : i == 1 ? by
                                          : bz),
                1e-6);
  }
}

// Middlebury sparse rings: the centre of the published bounding box projects inside every view.
void CheckMiddlebury(const std::string& name, const Vec3& box_min, const Vec3& box_max) {
  const fs::path folder = SharedData("middlebury/" + name);
  if (folder.empty()) GTEST_SKIP() << "Middlebury " << name << " not found (IMR_SHARED_DIR/data)";
  const ImageSequence s = ReadMiddlebury(folder.string(), {});
  ASSERT_EQ(s.frames.size(), 16u);
  const Vec3 centre = {(box_min[0] + box_max[0]) / 2, (box_min[1] + box_max[1]) / 2,
                       (box_min[2] + box_max[2]) / 2};
  for (const ImageFrame& f : s.frames) {
    const Intrinsics& k = f.camera.intrinsics;
    EXPECT_EQ(k.width, 640);
    EXPECT_EQ(k.height, 480);
    double u = 0, v = 0;
    ASSERT_TRUE(Project(f.camera, centre, &u, &v)) << f.camera.name;
    EXPECT_GT(u, 0);
    EXPECT_LT(u, 640);
    EXPECT_GT(v, 0);
    EXPECT_LT(v, 480);
    // Cameras on a ring about 0.5-0.7 m from the object.
    const double d = Distance(f.camera.center, centre);
    EXPECT_GT(d, 0.4) << f.camera.name;
    EXPECT_LT(d, 0.8) << f.camera.name;
  }
}

TEST(RealData, MiddleburyTempleSparseRing) {
  CheckMiddlebury("templeSparseRing", {-0.073568, 0.021728, -0.012445},
                  {0.028855, 0.181892, 0.062736});
}

TEST(RealData, MiddleburyDinoSparseRing) {
  CheckMiddlebury("dinoSparseRing", {-0.061897, -0.018874, -0.057845},
                  {0.010897, 0.068227, 0.015495});
}

}  // namespace
}  // namespace imr::io
