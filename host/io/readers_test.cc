// The SfM/SLAM readers against hand-computed cases: one convention for every format (the same
// world point projects to the same pixel through each), exact export/re-import round trips, and
// bad files (dangling ids, missing fields, non-rotations, truncation) refused with the id or field.
#include "host/io/colmap_model.h"
#include "host/io/input_formats.h"
#include "host/io/openmvg_reader.h"
#include "host/io/schema.h"
#include "host/io/slam_json.h"
#include "host/io/stream_recorder.h"
#include "host/io/testing/temp_dir.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <random>
#include <set>

namespace imr::io {
namespace {
namespace fs = std::filesystem;
using nlohmann::json;

// --- The hand-computed scene -------------------------------------------------------------------
// K: f = 800, principal point (320, 240), no distortion.
// Camera 1: C1 = (1, 2, 3), R1 = [[0, 1, 0], [-1, 0, 0], [0, 0, 1]] (world -> camera), so
//   t1 = -R1 C1 = (-2, 1, -3); as a quaternion (scalar first) R1 is a -90 degree turn about z:
//   q1 = (sqrt(1/2), 0, 0, -sqrt(1/2)).
// Camera 2: C2 = (3, 2, 3), R2 = I, t2 = (-3, -2, -3), q2 = (1, 0, 0, 0).
// Point X = (2, 2.5, 7):
//   camera 1: R1 (X - C1) = R1 (1, 0.5, 4) = (0.5, -1, 4) -> u = 800 * 0.125 + 320 = 420,
//             v = 800 * -0.25 + 240 = 40;
//   camera 2: X - C2 = (-1, 0.5, 4) -> u = 800 * -0.25 + 320 = 120, v = 800 * 0.125 + 240 = 340.
constexpr double kF = 800, kCx = 320, kCy = 240;
const Vec3 kX = {2, 2.5, 7};
const Vec3 kC1 = {1, 2, 3}, kC2 = {3, 2, 3};
constexpr double kU1 = 420, kV1 = 40, kU2 = 120, kV2 = 340;
const char* kR1 = "[[0, 1, 0], [-1, 0, 0], [0, 0, 1]]";
const char* kR2 = "[[1, 0, 0], [0, 1, 0], [0, 0, 1]]";
const char* kQ1 = "0.70710678118654757 0 0 -0.70710678118654757";

using testing::Write;
// Scratch folders of this file's tests.
class TempDir : public testing::TempDir {
 public:
  TempDir() : testing::TempDir("imr-readers") {}
};

std::string Read(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

// The scene as an OpenMVG sfm_data (cereal layout: ptr_wrapper ids with the high bit on first
// use, the intrinsic type named once).
json OpenMvgScene() {
  return json::parse(std::string(R"({
    "sfm_data_version": "0.3", "root_path": "/images",
    "views": [
      {"key": 1, "value": {"ptr_wrapper": {"id": 2147483649, "data": {"local_path": "", "filename": "a.png",
        "width": 640, "height": 480, "id_view": 1, "id_intrinsic": 0, "id_pose": 1}}}},
      {"key": 2, "value": {"ptr_wrapper": {"id": 2147483650, "data": {"local_path": "", "filename": "b.png",
        "width": 640, "height": 480, "id_view": 2, "id_intrinsic": 0, "id_pose": 2}}}},
      {"key": 3, "value": {"ptr_wrapper": {"id": 2147483651, "data": {"local_path": "", "filename": "c.png",
        "width": 640, "height": 480, "id_view": 3, "id_intrinsic": 0, "id_pose": 4294967295}}}},
      {"key": 4, "value": {"ptr_wrapper": {"id": 2147483652, "data": {"local_path": "", "filename": "d.png",
        "width": 640, "height": 480, "id_view": 4, "id_intrinsic": 0, "id_pose": 4}}}}],
    "intrinsics": [{"key": 0, "value": {"polymorphic_id": 2147483649, "polymorphic_name": "pinhole",
        "ptr_wrapper": {"id": 2147483653, "data": {"width": 640, "height": 480, "focal_length": 800,
        "principal_point": [320, 240]}}}}],
    "extrinsics": [
      {"key": 1, "value": {"rotation": )") + kR1 + R"(, "center": [1, 2, 3]}},
      {"key": 2, "value": {"rotation": )" + kR2 + R"(, "center": [3, 2, 3]}},
      {"key": 4, "value": {"rotation": )" + kR2 + R"(, "center": [5, 2, 3]}}],
    "structure": [{"key": 7, "value": {"X": [2, 2.5, 7], "observations": [
      {"key": 1, "value": {"id_feat": 0, "x": [420, 40]}},
      {"key": 2, "value": {"id_feat": 0, "x": [120, 340]}},
      {"key": 3, "value": {"id_feat": 0, "x": [1, 1]}}]}}],
    "control_points": []})");
}

void WriteColmapTextScene(const fs::path& dir) {
  Write(dir / "cameras.txt", "# Camera list\n1 SIMPLE_PINHOLE 640 480 800 320 240\n");
  Write(dir / "images.txt",
        std::string("# Image list\n1 ") + kQ1 + " -2 1 -3 1 a.png\n420 40 7 10 10 -1\n" +
            "2 1 0 0 0 -3 -2 -3 1 b.png\n\n"  // an image with no 2D points: an empty line
            "3 1 0 0 0 -3 -2 -3 1 c.png\n5 5 -1 120 340 7\n");
  Write(dir / "points3D.txt", "# 3D points\n7 2 2.5 7 255 0 0 0.5 1 0 3 1\n");
}

// COLMAP's binary layout, little-endian (scene/reconstruction_io.cc).
class Bytes {
 public:
  template <typename T>
  Bytes& Put(T v) {
    unsigned char b[sizeof(T)];
    std::memcpy(b, &v, sizeof(T));  // this test runs on little-endian machines
    s_.append(reinterpret_cast<const char*>(b), sizeof(T));
    return *this;
  }
  Bytes& Name(const std::string& n) {
    s_ += n;
    s_.push_back('\0');
    return *this;
  }
  const std::string& str() const { return s_; }

 private:
  std::string s_;
};

void WriteColmapBinaryScene(const fs::path& dir) {
  Write(dir / "cameras.bin", Bytes().Put<uint64_t>(1).Put<int32_t>(1).Put<int32_t>(0)
                                 .Put<uint64_t>(640).Put<uint64_t>(480)
                                 .Put(kF).Put(kCx).Put(kCy).str());
  const double h = std::sqrt(0.5);
  Bytes images;
  images.Put<uint64_t>(3);
  images.Put<int32_t>(1).Put(h).Put(0.0).Put(0.0).Put(-h).Put(-2.0).Put(1.0).Put(-3.0)
      .Put<int32_t>(1).Name("a.png").Put<uint64_t>(2)
      .Put(420.0).Put(40.0).Put<int64_t>(7).Put(10.0).Put(10.0).Put<int64_t>(-1);
  images.Put<int32_t>(2).Put(1.0).Put(0.0).Put(0.0).Put(0.0).Put(-3.0).Put(-2.0).Put(-3.0)
      .Put<int32_t>(1).Name("b.png").Put<uint64_t>(0);
  images.Put<int32_t>(3).Put(1.0).Put(0.0).Put(0.0).Put(0.0).Put(-3.0).Put(-2.0).Put(-3.0)
      .Put<int32_t>(1).Name("c.png").Put<uint64_t>(2)
      .Put(5.0).Put(5.0).Put<int64_t>(-1).Put(120.0).Put(340.0).Put<int64_t>(7);
  Write(dir / "images.bin", images.str());
  Write(dir / "points3D.bin", Bytes().Put<uint64_t>(1).Put<uint64_t>(7).Put(2.0).Put(2.5).Put(7.0)
                                  .Put<uint8_t>(255).Put<uint8_t>(0).Put<uint8_t>(0).Put(0.5)
                                  .Put<uint64_t>(2).Put<int32_t>(1).Put<int32_t>(0)
                                  .Put<int32_t>(3).Put<int32_t>(1).str());
}

json SlamScene() {
  return json::parse(std::string(R"({
    "slam_data_version": "0.3", "root_path": "",
    "intrinsics": [{"intrinsicId": 0, "value": {"polymorphic_id": 0, "polymorphic_name": "pinhole",
      "ptr_wrapper": {"data": {"width": 640, "height": 480, "focal_length": 800, "principal_point": [320, 240]}}}}],
    "views": [
      {"viewId": 1, "local_path": "/", "filename": "a.png", "width": 640, "height": 480, "id_intrinsic": 0,
       "extrinsic": {"rotation": )") + kR1 + R"(, "center": [1, 2, 3]},
       "observations": [{"pointId": 7, "X": [2, 2.5, 7.5], "x": [420, 40]}]},
      {"viewId": 2, "local_path": "/", "filename": "b.png", "width": 640, "height": 480, "id_intrinsic": 0,
       "extrinsic": {"rotation": )" + kR2 + R"(, "center": [3, 2, 3]},
       "observations": [{"pointId": 7, "X": [2, 2.5, 7], "x": [120, 340]}]}]})");
}

std::unique_ptr<KeyframeSource> Open(const std::string& format, const fs::path& path,
                                     json options = json::object()) {
  const InputFormat* f = FindInputFormat(format);
  EXPECT_NE(f, nullptr) << format;
  std::vector<Problem> problems;
  ValidateAgainstSchema(f->options_schema, options, "input.options", &problems);
  EXPECT_TRUE(problems.empty()) << problems[0].ToString();
  return f->open(path.string(), WithDefaults(f->options_schema, options));
}

std::vector<engine::KeyframeUpdate> All(KeyframeSource* s) {
  std::vector<engine::KeyframeUpdate> out;
  engine::KeyframeUpdate u;
  KeyframeInfo info;
  while (s->Next(&u, &info)) out.push_back(u);
  return out;
}

// Every reader: camera 1 and 2 have the hand-computed centres, and X projects to the
// hand-computed pixels; the batch update holds both cameras and the point seen by both.
void ExpectScene(KeyframeSource* s, const std::string& what) {
  SCOPED_TRACE(what);
  const CameraGeometry* g1 = s->Camera(1);
  const CameraGeometry* g2 = s->Camera(2);
  ASSERT_NE(g1, nullptr);
  ASSERT_NE(g2, nullptr);
  for (int i = 0; i < 3; ++i) {
    EXPECT_NEAR(g1->center[i], kC1[i], 1e-12);
    EXPECT_NEAR(g2->center[i], kC2[i], 1e-12);
  }
  double u = 0, v = 0;
  ASSERT_TRUE(Project(*g1, kX, &u, &v));
  EXPECT_NEAR(u, kU1, 1e-9);
  EXPECT_NEAR(v, kV1, 1e-9);
  ASSERT_TRUE(Project(*g2, kX, &u, &v));
  EXPECT_NEAR(u, kU2, 1e-9);
  EXPECT_NEAR(v, kV2, 1e-9);
  EXPECT_EQ(g1->name, "a.png");
}

TEST(Conventions, TheSamePointProjectsToTheSamePixelThroughEveryReader) {
  TempDir dir;
  Write(dir / "sfm_data.json", OpenMvgScene().dump());
  auto mvg = Open("openmvg", dir / "sfm_data.json");
  ExpectScene(mvg.get(), "openmvg");
  auto mu = All(mvg.get());
  ASSERT_EQ(mu.size(), 1u);
  ASSERT_EQ(mu[0].cameras.size(), 3u);  // view 3 has no pose: skipped
  ASSERT_EQ(mu[0].new_points.size(), 1u);
  EXPECT_EQ(mu[0].new_points[0].id, 7u);
  EXPECT_EQ(mu[0].new_points[0].position, kX);
  EXPECT_EQ(mu[0].new_points[0].camera_ids, (std::vector<uint64_t>{1, 2}));
  EXPECT_EQ(mvg->Summary()["observations_skipped_unposed_view"], 1);

  WriteColmapTextScene(dir / "text");
  WriteColmapBinaryScene(dir / "bin");
  for (const char* sub : {"text", "bin"}) {
    auto colmap = Open("colmap", dir / sub);
    ExpectScene(colmap.get(), std::string("colmap ") + sub);
    auto cu = All(colmap.get());
    ASSERT_EQ(cu.size(), 1u);
    ASSERT_EQ(cu[0].cameras.size(), 3u);
    ASSERT_EQ(cu[0].new_points.size(), 1u);
    EXPECT_EQ(cu[0].new_points[0].position, kX);
    EXPECT_EQ(cu[0].new_points[0].camera_ids, (std::vector<uint64_t>{1, 3}));
  }
  // Text and binary give the same model.
  const ColmapModel t = ReadColmapText(dir / "text"), b = ReadColmapBinary(dir / "bin");
  ASSERT_EQ(t.images.size(), b.images.size());
  for (std::size_t i = 0; i < t.images.size(); ++i) {
    for (int k = 0; k < 4; ++k) EXPECT_NEAR(t.images[i].qvec[k], b.images[i].qvec[k], 1e-16);
    EXPECT_EQ(t.images[i].points2d.size(), b.images[i].points2d.size());
  }
  // Binary wins when both are there: a broken text model beside a good binary one is not read.
  fs::copy(dir / "bin", dir / "both");
  Write(dir / "both" / "cameras.txt", "garbage\n");
  Write(dir / "both" / "images.txt", "garbage\n");
  Write(dir / "both" / "points3D.txt", "garbage\n");
  EXPECT_NO_THROW(Open("colmap", dir / "both"));

  Write(dir / "slam.json", SlamScene().dump());
  // By default five views make a keyframe: both views in one update, the point with both.
  auto five = Open("slam_json", dir / "slam.json");
  auto fu = All(five.get());
  ASSERT_EQ(fu.size(), 1u);
  ASSERT_EQ(fu[0].new_points.size(), 1u);
  EXPECT_EQ(fu[0].new_points[0].camera_ids, (std::vector<uint64_t>{1, 2}));
  auto slam = Open("slam_json", dir / "slam.json", {{"views_per_keyframe", 1}});
  ExpectScene(slam.get(), "slam_json");
  auto su = All(slam.get());
  ASSERT_EQ(su.size(), 2u);  // one view per keyframe
  EXPECT_TRUE(su[0].new_points.empty());  // seen by one view only
  ASSERT_EQ(su[1].new_points.size(), 1u);  // enters with the second view, at its latest X
  EXPECT_EQ(su[1].new_points[0].position, kX);
  EXPECT_EQ(su[1].new_points[0].camera_ids, (std::vector<uint64_t>{1, 2}));
}

TEST(Conventions, QuaternionsAndRotationChecks) {
  const Mat3 r1 = QuaternionToRotation({std::sqrt(0.5), 0, 0, -std::sqrt(0.5)});
  const Mat3 expected = {{{0, 1, 0}, {-1, 0, 0}, {0, 0, 1}}};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) EXPECT_NEAR(r1[i][j], expected[i][j], 1e-15);
  std::mt19937 rng(5);
  std::normal_distribution<double> g;
  for (int n = 0; n < 200; ++n) {
    const Mat3 r = QuaternionToRotation({g(rng), g(rng), g(rng), g(rng)});
    EXPECT_EQ(RotationProblem(r), "");
    const Mat3 back = QuaternionToRotation(RotationToQuaternion(r));
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) EXPECT_NEAR(back[i][j], r[i][j], 1e-14);
  }
  Mat3 scaled = expected;
  scaled[0][1] = 1.1;
  EXPECT_NE(RotationProblem(scaled).find("not orthonormal"), std::string::npos);
  Mat3 reflection = expected;
  reflection[2][2] = -1;
  EXPECT_NE(RotationProblem(reflection).find("reflection"), std::string::npos);
}

TEST(Conventions, RotationsWithinTheToleranceAreReOrthonormalised) {
  // 6 significant digits (1e-6 off, as dinoSparseRing): accepted and made orthonormal to
  // rounding, near where it was; 2e-4 off: refused, naming the tolerance.
  const Mat3 exact = QuaternionToRotation({0.9, 0.1, -0.3, 0.2});
  Mat3 r = exact;
  for (auto& row : r)
    for (double& x : row) x = std::round(x * 1e6) / 1e6 * (1 + 1.4e-6);
  EXPECT_GT(std::abs(Determinant(r) - 1.0), 1e-6);
  EXPECT_EQ(CheckRotation(&r), "");
  EXPECT_EQ(RotationProblem(r, 1e-14), "");
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) EXPECT_NEAR(r[i][j], exact[i][j], 5e-6);
  Mat3 off = exact;
  for (double& x : off[0]) x *= 1 + 2e-4;
  const Mat3 kept = off;
  EXPECT_NE(CheckRotation(&off).find("more than the 0.0001 imr re-orthonormalises"), std::string::npos);
  EXPECT_EQ(off, kept);  // a refused rotation is left as it was
  EXPECT_EQ(CoordinateProblem(-1e12), "");
  EXPECT_EQ(CoordinateProblem(1e300), "expected a coordinate within +-1e12 (scene units), got 1e+300");
}

TEST(Conventions, DistortionFollowsOpenCvForEveryModel) {
  // OpenMVG pinhole_brown_t2 (k1 k2 k3 t1 t2) and COLMAP OPENCV (k1 k2 p1 p2) agree when k3 = 0.
  JsonFields f("test");
  Intrinsics a = OpenMvgIntrinsicFromData(
      f, "pinhole_brown_t2",
      json::parse(R"({"focal_length": 800, "principal_point": [320, 240],
                      "disto_t2": [0.1, -0.05, 0, 0.001, 0.002]})"),
      "x");
  Intrinsics b;
  std::string error;
  ASSERT_TRUE(IntrinsicsFromColmap("OPENCV", {800, 800, 320, 240, 0.1, -0.05, 0.001, 0.002}, 640,
                                   480, &b, &error));
  CameraGeometry ga, gb;
  ga.has_intrinsics = gb.has_intrinsics = true;
  ga.intrinsics = a, gb.intrinsics = b;
  double ua, va, ub, vb;
  ASSERT_TRUE(Project(ga, {0.3, -0.2, 1.0}, &ua, &va));
  ASSERT_TRUE(Project(gb, {0.3, -0.2, 1.0}, &ub, &vb));
  EXPECT_DOUBLE_EQ(ua, ub);
  EXPECT_DOUBLE_EQ(va, vb);
  // By hand: x = 0.3, y = -0.2, r2 = 0.13, radial = 1 + 0.1 * 0.13 - 0.05 * 0.0169 = 1.012155;
  // xd = 0.3 * radial + 2 * 0.001 * 0.3 * -0.2 + 0.002 * (0.13 + 0.18)
  //    = 0.3036465 - 0.00012 + 0.00062 = 0.3041465; u = 800 * xd + 320 = 563.3172.
  EXPECT_NEAR(ua, 563.3172, 1e-9);
  // Written back as COLMAP, the same model and parameters.
  std::string model;
  std::vector<double> params;
  ASSERT_TRUE(IntrinsicsToColmap(a, &model, &params));
  EXPECT_EQ(model, "OPENCV");
  EXPECT_EQ(params, (std::vector<double>{800, 800, 320, 240, 0.1, -0.05, 0.001, 0.002}));
}

// --- Round trips ---------------------------------------------------------------------------------

TEST(RoundTrip, ColmapTextWriteAndReadAreExact) {
  TempDir dir;
  WriteColmapBinaryScene(dir / "bin");
  ColmapModel m = ReadColmapBinary(dir / "bin");
  m.points[0].xyz = {0.1, 1.0 / 3.0, -2.718281828459045};  // needs all 17 digits
  m.images[0].tvec[0] = 1e-300;
  WriteColmapText(m, dir / "text");
  const ColmapModel r = ReadColmapText(dir / "text");
  ASSERT_EQ(r.cameras.size(), 1u);
  EXPECT_EQ(r.cameras[0].params, m.cameras[0].params);
  EXPECT_EQ(r.cameras[0].model, "SIMPLE_PINHOLE");
  ASSERT_EQ(r.images.size(), 3u);
  for (std::size_t i = 0; i < 3; ++i) {
    EXPECT_EQ(r.images[i].qvec, m.images[i].qvec);
    EXPECT_EQ(r.images[i].tvec, m.images[i].tvec);
    EXPECT_EQ(r.images[i].name, m.images[i].name);
    ASSERT_EQ(r.images[i].points2d.size(), m.images[i].points2d.size());
    for (std::size_t k = 0; k < r.images[i].points2d.size(); ++k) {
      EXPECT_EQ(r.images[i].points2d[k].x, m.images[i].points2d[k].x);
      EXPECT_EQ(r.images[i].points2d[k].point3d_id, m.images[i].points2d[k].point3d_id);
    }
  }
  ASSERT_EQ(r.points.size(), 1u);
  EXPECT_EQ(r.points[0].xyz, m.points[0].xyz);
  EXPECT_EQ(r.points[0].rgb, m.points[0].rgb);
  ASSERT_EQ(r.points[0].track.size(), 2u);
  EXPECT_EQ(r.points[0].track[1].image_id, 3u);
  EXPECT_EQ(r.points[0].track[1].point2d_idx, 1u);
}

// A stream with everything the engine can receive: cameras out of arrival order in a point's
// list, an old camera joining a new point, moves with and without new cameras, a removal, an
// update without cameras and an empty one.
std::vector<engine::KeyframeUpdate> Stream() {
  std::vector<engine::KeyframeUpdate> s(4);
  s[0].cameras = {{10, {0, 0, 0}}, {11, {1, 0, 0}}};
  s[0].new_points = {{1, {0.1, 1.0 / 3.0, 5}, {11, 10}}, {2, {1, 2, 6}, {10}}};
  s[1].cameras = {{12, {2, 0.5, 0}}};
  s[1].moved_points = {{1, {0.1, 0.3, 5.2}, {12}}, {2, {1.5, 2, 6}, {}}};
  s[1].new_points = {{3, {2, 2, 7}, {10, 12}}};
  s[2].removed_points = {2};
  s[2].moved_points = {{3, {2, 2.25, 7}, {}}, {1, {0.1, 0.3, 5.2}, {11, 12, 10}}};
  return s;  // s[3] is empty
}

bool SameUpdate(const engine::KeyframeUpdate& a, const engine::KeyframeUpdate& b, std::string* why) {
  auto cams = [](const engine::KeyframeUpdate& u) {
    std::vector<std::pair<uint64_t, Vec3>> c;
    for (const auto& x : u.cameras) c.push_back({x.id, x.center});
    return c;
  };
  auto pts = [](const auto& v) {
    std::vector<std::tuple<uint64_t, Vec3, std::vector<uint64_t>>> p;
    for (const auto& x : v) p.push_back({x.id, x.position, x.camera_ids});
    return p;
  };
  if (cams(a) != cams(b)) *why = "cameras";
  else if (pts(a.new_points) != pts(b.new_points)) *why = "new points";
  else if (pts(a.moved_points) != pts(b.moved_points)) *why = "moved points";
  else if (a.removed_points != b.removed_points) *why = "removed points";
  else return true;
  return false;
}

// Cameras in arrival order whatever their ids, and what the order holds over a drive (issue 46):
// a run per stretch of consecutive ids, not a record per camera.
TEST(CanonicalOrder, CamerasInArrivalOrderInRunsNotARecordPerFrame) {
  CanonicalOrder order;
  engine::KeyframeUpdate u;
  for (uint64_t id : {10, 11, 5, 12}) u.cameras.push_back({id, {}, {}});
  u.new_points.push_back({1, {0, 0, 0}, {12, 5, 99, 10, 5, 11}});  // 99: never arrived, last
  order.Apply(&u);
  EXPECT_EQ(u.new_points[0].camera_ids, (std::vector<uint64_t>{10, 11, 5, 12, 99}));
  EXPECT_EQ(order.runs(), 3u);  // 10..11, 5, 12 (12 came after 5, not after 11)

  // A drive numbering its frames in order (every frame's camera in the update, as the image
  // front end gives them): one run, however long.
  auto drive = [](int keyframes) {
    CanonicalOrder o;
    for (uint64_t k = 0; k < static_cast<uint64_t>(keyframes); ++k) {
      engine::KeyframeUpdate d;
      for (uint64_t f = 5 * k; f < 5 * k + 5; ++f) d.cameras.push_back({f, {}, {}});
      d.new_points.push_back({k, {0, 0, 0}, {5 * k + 4, 5 * k}});
      o.Apply(&d);
      EXPECT_EQ(d.new_points[0].camera_ids, (std::vector<uint64_t>{5 * k, 5 * k + 4}));
    }
    return o.runs();
  };
  const std::size_t at_200 = drive(200), at_800 = drive(800);
  EXPECT_EQ(at_200, 1u);
  EXPECT_LE(at_800, at_200) << "a record per frame: 1,000 -> 4,000";
}

TEST(RoundTrip, AnExportedStreamReplaysToTheSameUpdates) {
  TempDir dir;
  fs::create_directories(dir / "spool");
  fs::create_directories(dir / "spool2");
  std::vector<engine::KeyframeUpdate> stream = Stream();
  CanonicalOrder order;
  StreamRecorder recorder(nullptr, "test", {dir / "spool"});
  for (std::size_t k = 0; k < stream.size(); ++k) {
    order.Apply(&stream[k]);
    recorder.Record(stream[k], {static_cast<int>(k), static_cast<int>(10 * k)});
  }
  // Point 1's last "move" changes nothing (same position, cameras it already has): the engine
  // ignores it, the file does not carry it, the replay does not deliver it.
  EXPECT_EQ(stream[2].moved_points[0].id, 1u);  // canonical: by id
  EXPECT_EQ(stream[0].new_points[0].camera_ids, (std::vector<uint64_t>{10, 11}));  // arrival
  stream[2].moved_points.erase(stream[2].moved_points.begin());
  EXPECT_EQ(recorder.unrepresentable(), 0);
  recorder.WriteSlamJson(dir / "stream.json");
  auto replay = Open("slam_json", dir / "stream.json");
  ASSERT_EQ(replay->KeyframeCount(), 4);
  std::vector<engine::KeyframeUpdate> back = All(replay.get());
  ASSERT_EQ(back.size(), stream.size());
  for (std::size_t k = 0; k < back.size(); ++k) {
    std::string why;
    EXPECT_TRUE(SameUpdate(stream[k], back[k], &why)) << "keyframe " << k << ": " << why;
  }
  // Recording the replay writes the same file.
  StreamRecorder again(nullptr, "test", {dir / "spool2"});
  CanonicalOrder order2;
  for (std::size_t k = 0; k < back.size(); ++k) {
    order2.Apply(&back[k]);
    again.Record(back[k], {static_cast<int>(k), static_cast<int>(10 * k)});
  }
  again.WriteSlamJson(dir / "again.json");
  EXPECT_EQ(Read(dir / "again.json"), Read(dir / "stream.json"));

  // The final COLMAP model: live points only, every track entry an existing 2D point.
  fs::create_directories(dir / "colmap");
  recorder.WriteColmap(dir / "colmap");
  const ColmapModel m = ReadColmapModel(dir / "colmap");
  EXPECT_NO_THROW(CheckColmapModel(m, "export"));
  ASSERT_EQ(m.points.size(), 2u);  // point 2 was removed
  EXPECT_EQ(m.points[0].id, 1u);
  EXPECT_EQ(m.points[0].xyz, (Vec3{0.1, 0.3, 5.2}));
  EXPECT_EQ(m.points[0].track.size(), 3u);
  EXPECT_EQ(m.images.size(), 3u);
}

// A SLAM JSON drive of `views` views 1 m apart, every view one keyframe: at each view 12 new
// points, each seen by it and the `track` - 1 views after it, its estimate moving at every one.
std::string SlamDrive(int views, int track = 8) {
  std::string s = R"({"slam_data_version": "0.3", "views": [)";
  for (int v = 0; v < views; ++v) {
    s += v ? ",\n" : "\n";
    s += R"({"viewId": )" + std::to_string(v) + R"(, "extrinsic": {"rotation": [[1,0,0],[0,1,0],[0,0,1]], "center": [)" +
         std::to_string(v) + R"(, 0, 0]}, "observations": [)";
    bool first = true;
    for (int start = std::max(0, v - (track - 1)); start <= v; ++start)
      for (int j = 0; j < 12; ++j) {
        s += first ? "" : ", ";
        first = false;
        s += R"({"pointId": )" + std::to_string(start * 12 + j) + R"(, "X": [)" +
             std::to_string(start + 0.1 * j) + ", " + std::to_string(1.0 + 0.01 * (v - start)) + ", 10]}";
      }
    s += "]}";
  }
  return s + "]}\n";
}

TEST(Memory, TheSlamJsonReaderLetsGoOfEveryKeyframeItHandsOut) {
  TempDir dir;
  SlamJsonOptions o;
  o.views_per_keyframe = 1;
  // What the reader holds 50 keyframes before the end of a drive of 300 views and of one of 600
  // (the same 50 views left): a record of 8 bytes kept per keyframe handed out would put 2,400
  // bytes between them.
  int64_t before_end[2] = {0, 0};
  for (int run = 0; run < 2; ++run) {
    const int views = run ? 600 : 300;
    const fs::path file = dir / ("drive" + std::to_string(views) + ".json");
    Write(file, SlamDrive(views));
    auto source = OpenSlamJson(file, o);
    ASSERT_EQ(source->KeyframeCount(), views);
    // At open: the release schedule, 8 bytes a point, nothing per observation (96 per view).
    const int64_t at_open = source->PendingBytes();
    EXPECT_LE(at_open, int64_t{8} * 12 * views);
    EXPECT_GE(at_open, int64_t{8} * 12 * views / 2);
    engine::KeyframeUpdate u;
    KeyframeInfo info;
    for (int k = 0; k < views - 50; ++k) ASSERT_TRUE(source->Next(&u, &info));
    before_end[run] = source->PendingBytes();
    int handed = views - 50;
    while (source->Next(&u, &info)) ++handed;
    EXPECT_EQ(handed, views);
    EXPECT_TRUE(u.last);
    EXPECT_EQ(source->PendingBytes(), 0) << views << " views";
    // The report's figures are the whole file's.
    EXPECT_EQ(source->Summary()["points"], 12 * views);
  }
  EXPECT_LE(std::abs(before_end[1] - before_end[0]), 800)
      << before_end[0] << " bytes held 50 keyframes before the end of 300, " << before_end[1]
      << " of 600";
}

// What the reader holds at open does not follow the observations: the same points seen by twice
// as many views each (twice the observations, a file twice the size) hold the same bytes, and
// the updates are what they were with every observation held (the tracks read whole).
TEST(Memory, TheSlamJsonReaderHoldsNoObservationAtOpen) {
  TempDir dir;
  SlamJsonOptions o;
  o.views_per_keyframe = 1;
  Write(dir / "short.json", SlamDrive(400, 8));
  Write(dir / "long.json", SlamDrive(400, 16));
  ASSERT_GT(fs::file_size(dir / "long.json"), fs::file_size(dir / "short.json") * 3 / 2);
  auto short_tracks = OpenSlamJson(dir / "short.json", o);
  auto long_tracks = OpenSlamJson(dir / "long.json", o);
  auto observations = [](int views, int track) {
    int64_t n = 0;
    for (int v = 0; v < views; ++v) n += 12 * std::min(v + 1, track);
    return n;
  };
  EXPECT_EQ(short_tracks->Summary()["observations"].get<int64_t>(), observations(400, 8));
  EXPECT_EQ(long_tracks->Summary()["observations"].get<int64_t>(), observations(400, 16));
  EXPECT_EQ(long_tracks->PendingBytes(), short_tracks->PendingBytes());
  EXPECT_LE(long_tracks->PendingBytes(), int64_t{8} * 12 * 400);
  // The tracks as long as the file says, from views read again one at a time.
  engine::KeyframeUpdate u;
  KeyframeInfo info;
  int64_t cameras_added = 0;
  while (long_tracks->Next(&u, &info))
    for (const engine::MovedPoint& m : u.moved_points) cameras_added += static_cast<int64_t>(m.camera_ids.size());
  // Each point gains 14 cameras after entering with 2 (min_views), but those near the end.
  EXPECT_GT(cameras_added, int64_t{12} * 14 * (400 - 16));
}

// --- Bad files -----------------------------------------------------------------------------------

std::string ErrorOf(const std::string& format, const fs::path& path) {
  try {
    auto s = Open(format, path);
    All(s.get());
  } catch (const std::exception& e) {
    return e.what();
  }
  return "(no error)";
}

#define EXPECT_ERROR(error, ...)                                              \
  do {                                                                         \
    const std::string e_ = (error);                                            \
    for (const std::string& part : std::initializer_list<std::string>{__VA_ARGS__}) \
      EXPECT_NE(e_.find(part), std::string::npos) << "'" << part << "' not in: " << e_;  \
  } while (0)

TEST(BadFiles, OpenMvg) {
  TempDir dir;
  const fs::path p = dir / "sfm_data.json";
  const std::string name = p.string();
  json j = OpenMvgScene();
  j["structure"][0]["value"]["observations"][1]["key"] = 99;
  Write(p, j.dump());
  EXPECT_ERROR(ErrorOf("openmvg", p), name.c_str(),
               "structure[0].value.observations[1].key", "landmark 7", "view 99");

  j = OpenMvgScene();
  j["extrinsics"][1]["value"].erase("center");
  Write(p, j.dump());
  EXPECT_ERROR(ErrorOf("openmvg", p), "extrinsics[1].value: missing field \"center\"");

  j = OpenMvgScene();
  j["extrinsics"][0]["value"]["rotation"][0][1] = 2.0;
  Write(p, j.dump());
  EXPECT_ERROR(ErrorOf("openmvg", p), "extrinsics[0].value.rotation", "not a rotation");

  j = OpenMvgScene();
  j["views"][0]["value"]["ptr_wrapper"]["data"]["id_intrinsic"] = 5;
  Write(p, j.dump());
  EXPECT_ERROR(ErrorOf("openmvg", p), "id_intrinsic", "view 1 uses intrinsic 5");

  const std::string whole = OpenMvgScene().dump(2);
  Write(p, whole.substr(0, whole.size() / 2));
  EXPECT_ERROR(ErrorOf("openmvg", p), name.c_str(), "malformed JSON", "line");

  Write(p, "[1, 2]");
  EXPECT_ERROR(ErrorOf("openmvg", p), "top level is not a JSON object");
}

// Issue 44: a focal length of 0 or negative is no camera (the Python
// module's cameras are checked with the same io::IntrinsicsProblem).
TEST(BadFiles, IntrinsicsNotPositiveOrNotFinite) {
  TempDir dir;
  const fs::path p = dir / "sfm_data.json";
  for (const double f : {0.0, -800.0}) {
    json j = OpenMvgScene();
    j["intrinsics"][0]["value"]["ptr_wrapper"]["data"]["focal_length"] = f;
    Write(p, j.dump());
    EXPECT_ERROR(ErrorOf("openmvg", p), "intrinsics[0].value.ptr_wrapper.data.focal_length",
                 "expected focal lengths fx, fy finite and > 0 (pixels), got fx " + std::string(f == 0 ? "0" : "-800"));
  }
  const fs::path s = dir / "slam.json";
  json j = SlamScene();
  j["intrinsics"][0]["value"]["ptr_wrapper"]["data"]["focal_length"] = 0;
  Write(s, j.dump());
  EXPECT_ERROR(ErrorOf("slam_json", s), "focal_length", "expected focal lengths fx, fy finite and > 0");
  WriteColmapTextScene(dir / "m");
  Write(dir / "m" / "cameras.txt", "1 PINHOLE 640 480 800 0 320 240\n");
  EXPECT_ERROR(ErrorOf("colmap", dir / "m"), "camera 1", "got fx 800, fy 0");
  WriteColmapTextScene(dir / "m");
  Write(dir / "m" / "cameras.txt", "1 SIMPLE_RADIAL 640 480 -800 320 240 0.01\n");
  EXPECT_ERROR(ErrorOf("colmap", dir / "m"), "camera 1", "got fx -800, fy -800");
}

TEST(BadFiles, Colmap) {
  TempDir dir;
  WriteColmapTextScene(dir / "m");
  Write(dir / "m" / "points3D.txt", "7 2 2.5 7 255 0 0 0.5 1 0 99 1\n");
  EXPECT_ERROR(ErrorOf("colmap", dir / "m"), "points3D", "3D point 7", "image 99");

  WriteColmapTextScene(dir / "m");
  Write(dir / "m" / "points3D.txt", "7 2 2.5 7 255 0 0 0.5 1 5\n");
  EXPECT_ERROR(ErrorOf("colmap", dir / "m"), "2D point 5 of image 1");

  WriteColmapTextScene(dir / "m");
  Write(dir / "m" / "images.txt", "1 1 0 0 0 -2 1 -3 1\n\n");
  EXPECT_ERROR(ErrorOf("colmap", dir / "m"), "images.txt line 1", "NAME");

  WriteColmapTextScene(dir / "m");
  Write(dir / "m" / "images.txt", "1 0 0 0 0 -2 1 -3 1 a.png\n\n");
  EXPECT_ERROR(ErrorOf("colmap", dir / "m"), "image 1", "not a rotation");

  WriteColmapTextScene(dir / "m");
  Write(dir / "m" / "images.txt", "1 1 0 0 0 -2 1 -3 4 a.png\n\n");
  EXPECT_ERROR(ErrorOf("colmap", dir / "m"), "image 1 uses camera 4");

  WriteColmapBinaryScene(dir / "b");
  const std::string images = Read(dir / "b" / "images.bin");
  Write(dir / "b" / "images.bin", images.substr(0, images.size() - 7));
  EXPECT_ERROR(ErrorOf("colmap", dir / "b"), "images.bin", "truncated", "image 3");

  fs::remove(dir / "b" / "points3D.bin");
  fs::remove(dir / "b" / "cameras.bin");
  EXPECT_ERROR(ErrorOf("colmap", dir / "b"), "not a complete COLMAP model", "cameras.{txt,bin}");
}

TEST(BadFiles, SlamJson) {
  TempDir dir;
  const fs::path p = dir / "slam.json";
  const std::string name = p.string();
  json j = SlamScene();
  j["views"][1]["viewId"] = 1;
  Write(p, j.dump());
  EXPECT_ERROR(ErrorOf("slam_json", p), "views[1].viewId", "view 1 is listed twice");

  j = SlamScene();
  j["views"][0]["observations"][0].erase("X");
  Write(p, j.dump());
  EXPECT_ERROR(ErrorOf("slam_json", p), "views[0].observations[0]: missing field \"X\"");

  j = SlamScene();
  j["views"][1]["extrinsic"]["rotation"] = {{1, 0, 0}, {0, 1, 0}, {0, 0, -1}};
  Write(p, j.dump());
  EXPECT_ERROR(ErrorOf("slam_json", p), "views[1].extrinsic.rotation", "reflection");

  j = SlamScene();
  j["views"][1]["id_intrinsic"] = 3;
  Write(p, j.dump());
  EXPECT_ERROR(ErrorOf("slam_json", p), "views[1].id_intrinsic", "intrinsic 3");

  j = SlamScene();
  j["imr_stream"] = {{"keyframes", {{{"keyframe", 0}, {"frame", 0}, {"removed_points", {7}}},
                                    {{"keyframe", 1}, {"frame", 1}}}}};
  Write(p, j.dump());
  EXPECT_ERROR(ErrorOf("slam_json", p), "imr_stream.keyframes[0].removed_points", "point 7");

  const std::string whole = SlamScene().dump();
  Write(p, whole.substr(0, whole.size() - 40));
  EXPECT_ERROR(ErrorOf("slam_json", p), name.c_str(), "malformed JSON");
}

// --- COLMAP as found in the wild (issue 16) ------------------------------------------------------

// COLMAP's pixel of the normalised point (x, y) = (X/Z, Y/Z), written out model by model from
// the formulas of COLMAP's sensor/models.h (an independent check of camera_model.cc's generic
// form): f or fx fy, cx cy, then each model's distortion.
std::array<double, 2> ColmapPixel(const std::string& model, const std::vector<double>& p, double x,
                                  double y) {
  const auto fisheye = [](double* a, double* b) {  // equidistant: scale to theta = atan(r)
    const double r = std::hypot(*a, *b);
    if (r > 0) *a *= std::atan(r) / r, *b *= std::atan(r) / r;
  };
  if (model == "SIMPLE_PINHOLE") return {p[0] * x + p[1], p[0] * y + p[2]};
  if (model == "PINHOLE") return {p[0] * x + p[2], p[1] * y + p[3]};
  if (model == "SIMPLE_RADIAL") {
    const double r2 = x * x + y * y;
    return {p[0] * x * (1 + p[3] * r2) + p[1], p[0] * y * (1 + p[3] * r2) + p[2]};
  }
  if (model == "RADIAL") {
    const double r2 = x * x + y * y, d = 1 + p[3] * r2 + p[4] * r2 * r2;
    return {p[0] * x * d + p[1], p[0] * y * d + p[2]};
  }
  if (model == "OPENCV" || model == "FULL_OPENCV") {
    const bool full = model == "FULL_OPENCV";
    const double k1 = p[4], k2 = p[5], p1 = p[6], p2 = p[7];
    const double r2 = x * x + y * y;
    double d = 1 + k1 * r2 + k2 * r2 * r2;
    if (full) d = (d + p[8] * r2 * r2 * r2) / (1 + p[9] * r2 + p[10] * r2 * r2 + p[11] * r2 * r2 * r2);
    const double xd = x * d + 2 * p1 * x * y + p2 * (r2 + 2 * x * x);
    const double yd = y * d + 2 * p2 * x * y + p1 * (r2 + 2 * y * y);
    return {p[0] * xd + p[2], p[1] * yd + p[3]};
  }
  if (model == "FOV") {
    const double r = std::hypot(x, y), w = p[4];
    const double f = r > 0 ? std::atan(2 * r * std::tan(w / 2)) / (r * w) : 2 * std::tan(w / 2) / w;
    return {p[0] * x * f + p[2], p[1] * y * f + p[3]};
  }
  if (model == "SIMPLE_RADIAL_FISHEYE" || model == "RADIAL_FISHEYE") {
    fisheye(&x, &y);
    const double t2 = x * x + y * y;
    const double d = 1 + p[3] * t2 + (model == "RADIAL_FISHEYE" ? p[4] * t2 * t2 : 0.0);
    return {p[0] * x * d + p[1], p[0] * y * d + p[2]};
  }
  if (model == "OPENCV_FISHEYE") {
    fisheye(&x, &y);
    const double t2 = x * x + y * y;
    const double d = 1 + p[4] * t2 + p[5] * t2 * t2 + p[6] * t2 * t2 * t2 + p[7] * t2 * t2 * t2 * t2;
    return {p[0] * x * d + p[2], p[1] * y * d + p[3]};
  }
  if (model == "THIN_PRISM_FISHEYE") {
    fisheye(&x, &y);
    const double k1 = p[4], k2 = p[5], p1 = p[6], p2 = p[7], k3 = p[8], k4 = p[9], sx = p[10], sy = p[11];
    const double r2 = x * x + y * y;
    const double radial = k1 * r2 + k2 * r2 * r2 + k3 * r2 * r2 * r2 + k4 * r2 * r2 * r2 * r2;
    const double du = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x) + sx * r2;
    const double dv = y * radial + 2 * p2 * x * y + p1 * (r2 + 2 * y * y) + sy * r2;
    return {p[0] * (x + du) + p[2], p[1] * (y + dv) + p[3]};
  }
  ADD_FAILURE() << "no reference for " << model;
  return {0, 0};
}

struct CameraCase {
  const char* model;
  int id;  // COLMAP's model id (cameras.bin)
  std::vector<double> params;
};
// Every model COLMAP's reconstruction writes, with distortion strong enough to matter.
const CameraCase kCameraCases[] = {
    {"SIMPLE_PINHOLE", 0, {800, 320, 240}},
    {"PINHOLE", 1, {800, 810, 320, 240}},
    {"SIMPLE_RADIAL", 2, {800, 320, 240, 0.05}},
    {"RADIAL", 3, {800, 320, 240, 0.05, -0.02}},
    {"OPENCV", 4, {800, 810, 320, 240, 0.05, -0.02, 0.001, 0.002}},
    {"OPENCV_FISHEYE", 5, {400, 410, 320, 240, 0.05, -0.02, 0.003, -0.001}},
    {"FULL_OPENCV", 6, {800, 810, 320, 240, 0.05, -0.02, 0.001, 0.002, 0.01, 0.02, -0.01, 0.005}},
    {"FOV", 7, {500, 510, 320, 240, 0.9}},
    {"SIMPLE_RADIAL_FISHEYE", 8, {400, 320, 240, 0.05}},
    {"RADIAL_FISHEYE", 9, {400, 320, 240, 0.05, -0.02}},
    {"THIN_PRISM_FISHEYE", 10, {400, 410, 320, 240, 0.05, -0.02, 0.001, 0.002, 0.003, -0.001, 0.0005, -0.0004}},
};

TEST(ColmapInTheWild, EveryCameraModelIsReadWithItsIntrinsicsAndDistortion) {
  // Two anchors computed by hand (python, math.atan) for the reference above, at (0.3, -0.2).
  EXPECT_NEAR(ColmapPixel("OPENCV_FISHEYE", kCameraCases[5].params, 0.3, -0.2)[0], 435.82849932079574, 1e-9);
  EXPECT_NEAR(ColmapPixel("FOV", kCameraCases[7].params, 0.3, -0.2)[1], 134.63918353525412, 1e-9);
  TempDir dir;
  for (const CameraCase& c : kCameraCases) {
    SCOPED_TRACE(c.model);
    EXPECT_EQ(ColmapModelId(c.model), c.id);
    EXPECT_EQ(ColmapModelParamCount(c.model), static_cast<int>(c.params.size()));
    WriteColmapTextScene(dir / c.model / "text");
    std::string line = std::string("1 ") + c.model + " 640 480";
    for (double x : c.params) line += " " + ExactNumber(x);
    Write(dir / c.model / "text" / "cameras.txt", line + "\n");
    WriteColmapBinary(ReadColmapText(dir / c.model / "text"), dir / c.model / "bin");
    // The binary camera holds the model id and the parameters, nothing else (COLMAP's layout).
    EXPECT_EQ(fs::file_size(dir / c.model / "bin" / "cameras.bin"), 8 + 24 + 8 * c.params.size());
    for (const char* kind : {"text", "bin"}) {
      SCOPED_TRACE(kind);
      auto s = Open("colmap", dir / c.model / kind);
      const CameraGeometry* g = s->Camera(1);
      ASSERT_NE(g, nullptr);
      ASSERT_TRUE(g->has_intrinsics);
      const Intrinsics& k = g->intrinsics;
      EXPECT_EQ(k.source_model, c.model);
      EXPECT_EQ(k.source_params, c.params);
      EXPECT_EQ(k.width, 640);
      EXPECT_EQ(k.height, 480);
      EXPECT_TRUE(k.projectable);
      EXPECT_EQ(k.cx, 320);
      EXPECT_EQ(k.cy, 240);
      // X in camera 1 is (0.5, -1, 4): normalised (0.125, -0.25).
      const std::array<double, 2> expected = ColmapPixel(c.model, c.params, 0.125, -0.25);
      double u = 0, v = 0;
      ASSERT_TRUE(Project(*g, kX, &u, &v));
      EXPECT_NEAR(u, expected[0], 1e-9);
      EXPECT_NEAR(v, expected[1], 1e-9);
      // Off the axis far enough for every term to count, and on it (the fisheye's r = 0 case).
      CameraGeometry at_origin = *g;
      at_origin.rotation = Identity3(), at_origin.translation = {0, 0, 0};
      for (const Vec3& x : {Vec3{0.6, -0.45, 1.0}, Vec3{0, 0, 2}}) {
        const std::array<double, 2> e = ColmapPixel(c.model, c.params, x[0] / x[2], x[1] / x[2]);
        ASSERT_TRUE(Project(at_origin, x, &u, &v));
        EXPECT_NEAR(u, e[0], 1e-9);
        EXPECT_NEAR(v, e[1], 1e-9);
      }
      // Written back (--export-colmap), the same model and parameters.
      std::string model;
      std::vector<double> params;
      ASSERT_TRUE(IntrinsicsToColmap(k, &model, &params));
      EXPECT_EQ(model, c.model);
      EXPECT_EQ(params, c.params);
      // Through the stream export's OpenMVG intrinsic (--export-stream) and back: the same.
      json data;
      OpenMvgIntrinsicToData(k, &model, &data);
      const Intrinsics back = OpenMvgIntrinsicFromData(JsonFields("stream"), model, data, "d");
      EXPECT_EQ(back.source_model, c.model);
      EXPECT_EQ(back.source_params, c.params);
      CameraGeometry again = at_origin;
      again.intrinsics = back;
      double u2 = 0, v2 = 0;
      ASSERT_TRUE(Project(again, {0.6, -0.45, 1.0}, &u2, &v2));
      ASSERT_TRUE(Project(at_origin, {0.6, -0.45, 1.0}, &u, &v));
      EXPECT_EQ(u2, u);
      EXPECT_EQ(v2, v);
    }
  }
  // A fisheye from OpenMVG (disto_fisheye: OpenCV's k1..k4) projects as COLMAP's OPENCV_FISHEYE
  // with fx = fy, and is written back as one.
  JsonFields f("test");
  CameraGeometry g;
  g.has_intrinsics = true;
  g.intrinsics = OpenMvgIntrinsicFromData(
      f, "fisheye",
      json::parse(R"({"focal_length": 400, "principal_point": [320, 240], "disto_fisheye": [0.05, -0.02, 0.003, -0.001]})"),
      "x");
  double u = 0, v = 0;
  ASSERT_TRUE(Project(g, {0.6, -0.45, 1.0}, &u, &v));
  const std::vector<double> as_colmap = {400, 400, 320, 240, 0.05, -0.02, 0.003, -0.001};
  EXPECT_NEAR(u, ColmapPixel("OPENCV_FISHEYE", as_colmap, 0.6, -0.45)[0], 1e-9);
  std::string model;
  std::vector<double> params;
  ASSERT_TRUE(IntrinsicsToColmap(g.intrinsics, &model, &params));
  EXPECT_EQ(model, "OPENCV_FISHEYE");
  EXPECT_EQ(params, as_colmap);
  // Models of later COLMAPs: read and kept, projected when they are the equidistant fisheye.
  Intrinsics later;
  std::string error;
  ASSERT_TRUE(IntrinsicsFromColmap("RAD_TAN_THIN_PRISM_FISHEYE", std::vector<double>(16, 0.5), 640, 480,
                                   &later, &error));
  EXPECT_FALSE(later.projectable);
  EXPECT_EQ(ColmapModelId("EQUIRECTANGULAR"), 17);
  ASSERT_TRUE(IntrinsicsFromColmap("FISHEYE", {400, 410, 320, 240}, 640, 480, &g.intrinsics, &error));
  ASSERT_TRUE(Project(g, {0.6, -0.45, 1.0}, &u, &v));
  EXPECT_NEAR(u, ColmapPixel("OPENCV_FISHEYE", {400, 410, 320, 240, 0, 0, 0, 0}, 0.6, -0.45)[0], 1e-9);
  EXPECT_NEAR(v, ColmapPixel("OPENCV_FISHEYE", {400, 410, 320, 240, 0, 0, 0, 0}, 0.6, -0.45)[1], 1e-9);
}

// The scene of the tests above written as a third-party tool might: no '#' header lines, ids
// with gaps that do not start at 1, cameras out of order and one unused, two cameras of different
// sizes, image 10 seeing point 1007 twice, exponents with 3 digits and a '+', CRLF line ends and
// no newline at the end.
void WriteQuirkyColmapText(const fs::path& dir) {
  Write(dir / "cameras.txt",
        "9 PINHOLE 1280 720 1.6E+003 1600 640 360\r\n"
        "5 SIMPLE_PINHOLE 100 100 100 50 50\r\n"
        "3 SIMPLE_PINHOLE 640 480 8.00e+002 3.2E+002 +240\r\n");
  Write(dir / "images.txt",
        std::string("10 ") + kQ1 + " -2.0e+000 1.000E+000 -3 3 a.png\r\n"
        "420 40 1007 10 10 -1 420.0000 40.00000 1007\r\n"
        "20 1 0 0 0 -3 -2 -3 9 b.png\r\n"
        "\r\n"
        "35 1.0E+000 0 0 0.0e-005 -3 -2 -3 3 c.png\r\n"
        "5 5 -1 120 340 1007");  // no newline at the end
  Write(dir / "points3D.txt", "1007 2 2.5 7 255 0 0 5e-001 10 0 35 1 10 2");
}

TEST(ColmapInTheWild, QuirksOfRealModelsAreReadInTextAndBinary) {
  TempDir dir;
  WriteQuirkyColmapText(dir / "text");
  WriteColmapBinary(ReadColmapText(dir / "text"), dir / "bin");
  for (const char* kind : {"text", "bin"}) {
    SCOPED_TRACE(kind);
    const ColmapModel m = ReadColmapModel(dir / kind);
    ASSERT_EQ(m.cameras.size(), 3u);
    EXPECT_EQ(m.cameras[0].id, 9u);  // as listed
    EXPECT_EQ(m.cameras[2].params, (std::vector<double>{800, 320, 240}));
    ASSERT_EQ(m.images.size(), 3u);
    EXPECT_EQ(m.images[0].tvec, (Vec3{-2, 1, -3}));
    EXPECT_EQ(m.images[2].qvec, (std::array<double, 4>{1, 0, 0, 0}));
    ASSERT_EQ(m.points.size(), 1u);
    EXPECT_EQ(m.points[0].error, 0.5);
    ASSERT_EQ(m.points[0].track.size(), 3u);
    auto s = Open("colmap", dir / kind);
    const CameraGeometry* a = s->Camera(10);
    const CameraGeometry* b = s->Camera(20);
    ASSERT_NE(a, nullptr);
    ASSERT_NE(b, nullptr);
    for (int i = 0; i < 3; ++i) EXPECT_NEAR(a->center[i], kC1[i], 1e-12);
    EXPECT_EQ(a->intrinsics.width, 640);
    EXPECT_EQ(b->intrinsics.width, 1280);  // per-image cameras of different sizes
    EXPECT_EQ(b->intrinsics.source_model, "PINHOLE");
    double u = 0, v = 0;
    ASSERT_TRUE(Project(*a, kX, &u, &v));
    EXPECT_NEAR(u, kU1, 1e-9);
    EXPECT_NEAR(v, kV1, 1e-9);
    const auto updates = All(s.get());
    ASSERT_EQ(updates.size(), 1u);
    ASSERT_EQ(updates[0].cameras.size(), 3u);
    ASSERT_EQ(updates[0].new_points.size(), 1u);
    EXPECT_EQ(updates[0].new_points[0].id, 1007u);
    // Seen twice by image 10: one ray from camera 10, not two.
    EXPECT_EQ(updates[0].new_points[0].camera_ids, (std::vector<uint64_t>{10, 35}));
  }
  // The text with COLMAP's own layout gives the same model as the quirky one.
  const ColmapModel q = ReadColmapText(dir / "text");
  WriteColmapText(q, dir / "plain");
  const ColmapModel p = ReadColmapText(dir / "plain");
  EXPECT_EQ(p.images[0].qvec, q.images[0].qvec);
  EXPECT_EQ(p.points[0].xyz, q.points[0].xyz);
}

TEST(ColmapInTheWild, RigsAndFramesOfColmap312AreIgnoredSafely) {
  // COLMAP >= 3.12 writes rigs and frames beside the three files; images still hold each
  // registered image's pose (cam_from_world), which is what imr reads.
  TempDir dir;
  WriteColmapTextScene(dir / "text");
  WriteColmapBinary(ReadColmapText(dir / "text"), dir / "bin");
  fs::copy(dir / "text", dir / "text312", fs::copy_options::recursive);
  fs::copy(dir / "bin", dir / "bin312", fs::copy_options::recursive);
  Write(dir / "text312" / "rigs.txt",
        "# Rig calib list with one line of data per calib:\n"
        "#   RIG_ID, NUM_SENSORS, REF_SENSOR_TYPE, REF_SENSOR_ID, SENSORS[] as (SENSOR_TYPE, "
        "SENSOR_ID, HAS_POSE, [QW, QX, QY, QZ, TX, TY, TZ])\n# Number of rigs: 1\n1 1 CAMERA 1\n");
  Write(dir / "text312" / "frames.txt",
        "# Frame list with one line of data per frame:\n"
        "#   FRAME_ID, RIG_ID, RIG_FROM_WORLD[QW, QX, QY, QZ, TX, TY, TZ], NUM_DATA_IDS, DATA_IDS[] "
        "as (SENSOR_TYPE, SENSOR_ID, DATA_ID)\n# Number of frames: 3\n" +
            std::string("1 1 ") + kQ1 + " -2 1 -3 1 CAMERA 1 1\n2 1 1 0 0 0 -3 -2 -3 1 CAMERA 1 2\n"
            "3 1 1 0 0 0 -3 -2 -3 1 CAMERA 1 3\n");
  // rigs.bin: one rig, one sensor (type 0 = camera, id 1); frames.bin: three frames.
  Write(dir / "bin312" / "rigs.bin",
        Bytes().Put<uint64_t>(1).Put<uint32_t>(1).Put<uint32_t>(1).Put<int32_t>(0).Put<uint32_t>(1).str());
  Bytes frames;
  frames.Put<uint64_t>(3);
  for (uint32_t id = 1; id <= 3; ++id) {
    frames.Put<uint32_t>(id).Put<uint32_t>(1);
    for (double x : {1.0, 0.0, 0.0, 0.0, -3.0, -2.0, -3.0}) frames.Put(x);
    frames.Put<uint32_t>(1).Put<int32_t>(0).Put<uint32_t>(1).Put<uint64_t>(id);
  }
  Write(dir / "bin312" / "frames.bin", frames.str());
  for (const char* kind : {"text", "bin"}) {
    SCOPED_TRACE(kind);
    auto before = Open("colmap", dir / kind);
    auto after = Open("colmap", dir / (std::string(kind) + "312"));
    ExpectScene(after.get(), std::string(kind) + " with rigs and frames");
    const auto a = All(before.get()), b = All(after.get());
    ASSERT_EQ(a.size(), b.size());
    std::string why;
    EXPECT_TRUE(SameUpdate(a[0], b[0], &why)) << why;
  }
}

TEST(ColmapInTheWild, NothingToMeshIsSaidWithTheFileAndWhy) {
  TempDir dir;
  WriteColmapTextScene(dir / "none");
  Write(dir / "none" / "images.txt", "1 1 0 0 0 -2 1 -3 1 a.png\n\n2 1 0 0 0 -3 -2 -3 1 b.png\n\n"
                                     "3 1 0 0 0 -3 -2 -4 1 c.png\n\n");
  Write(dir / "none" / "points3D.txt", "# Number of points: 0, mean track length: 0\n");
  EXPECT_ERROR(ErrorOf("colmap", dir / "none"), (dir / "none" / "points3D.txt").string(),
               "nothing to mesh: the model has no 3D points", "point_triangulator");
  WriteColmapBinary(ReadColmapText(dir / "none"), dir / "none-bin");
  EXPECT_ERROR(ErrorOf("colmap", dir / "none-bin"), (dir / "none-bin" / "points3D.bin").string(),
               "nothing to mesh: the model has no 3D points");

  WriteColmapTextScene(dir / "two");
  Write(dir / "two" / "images.txt", std::string(kQ1).insert(0, "1 ") + " -2 1 -3 1 a.png\n420 40 7\n"
                                    "3 1 0 0 0 -3 -2 -3 1 c.png\n120 340 7\n");
  Write(dir / "two" / "points3D.txt", "7 2 2.5 7 255 0 0 0.5 1 0 3 0\n");
  EXPECT_ERROR(ErrorOf("colmap", dir / "two"), (dir / "two" / "images.txt").string(),
               "nothing to mesh: only 2 posed views", "at least 3", "register more images");

  // Every point seen by one image only (min_views 2).
  WriteColmapTextScene(dir / "single");
  Write(dir / "single" / "points3D.txt", "7 2 2.5 7 255 0 0 0.5 1 0\n");
  Write(dir / "single" / "images.txt", std::string("1 ") + kQ1 + " -2 1 -3 1 a.png\n420 40 7\n"
                                       "2 1 0 0 0 -3 -2 -3 1 b.png\n\n3 1 0 0 0 -3 -2 -3 1 c.png\n\n");
  EXPECT_ERROR(ErrorOf("colmap", dir / "single"), (dir / "single" / "points3D.txt").string(),
               "nothing to mesh: none of the 1 3D points is seen by 2 posed views");
}

// --- OpenMVG as found in the wild ----------------------------------------------------------------

TEST(OpenMvgInTheWild, WhatSfMInitImageListingWritesIsRefusedSayingHowToGetTheStructure) {
  TempDir dir;
  const fs::path p = dir / "sfm_data.json";
  json j = OpenMvgScene();
  j.erase("structure");
  j.erase("extrinsics");
  Write(p, j.dump());
  EXPECT_ERROR(ErrorOf("openmvg", p), p.string(), "missing field \"extrinsics\"",
               "SfMInit_ImageListing", "openMVG_main_ComputeStructureFromKnownPoses");
  j = OpenMvgScene();
  j.erase("structure");
  Write(p, j.dump());
  EXPECT_ERROR(ErrorOf("openmvg", p), "missing field \"structure\": the file has no 3D points",
               "openMVG_main_SfM", "openMVG_main_ComputeStructureFromKnownPoses");
  j = OpenMvgScene();
  j["structure"] = json::array();  // older OpenMVG writes the parts it was not asked for empty
  Write(p, j.dump());
  EXPECT_ERROR(ErrorOf("openmvg", p), p.string() + ": structure: nothing to mesh",
               "openMVG_main_ComputeStructureFromKnownPoses");
  j = OpenMvgScene();
  j["extrinsics"].erase(2);
  Write(p, j.dump());
  EXPECT_ERROR(ErrorOf("openmvg", p), p.string() + ": extrinsics: nothing to mesh: only 2 posed views");
}

TEST(OpenMvgInTheWild, ABinarySfmDataIsRefusedWithTheCommandThatConvertsIt) {
  TempDir dir;
  // cereal's portable binary archive: an endianness byte, then the version string's length.
  Write(dir / "sfm_data.bin", Bytes().Put<uint8_t>(1).Put<uint64_t>(3).Name("0.3").Put<uint64_t>(0).str());
  EXPECT_ERROR(ErrorOf("openmvg", dir / "sfm_data.bin"), (dir / "sfm_data.bin").string(),
               "an OpenMVG binary sfm_data", "openMVG_main_ConvertSfM_DataFormat -i",
               (dir / "sfm_data.json").string());
  // The same bytes under another name; and a JSON file named .bin is read as JSON.
  fs::copy(dir / "sfm_data.bin", dir / "scene.json");
  EXPECT_ERROR(ErrorOf("openmvg", dir / "scene.json"), "an OpenMVG binary sfm_data");
  Write(dir / "json.bin", OpenMvgScene().dump());
  EXPECT_EQ(ErrorOf("openmvg", dir / "json.bin"), "(no error)");
}

TEST(OpenMvgInTheWild, OddFieldsOfVersions02And03AreReadOrRefusedByField) {
  TempDir dir;
  const fs::path p = dir / "sfm_data.json";
  // Version 0.2, views as view_priors (GPS/pose priors: polymorphic, extra fields), an
  // intrinsic with prior_focal_length beside focal_length: read, the priors ignored.
  json j = OpenMvgScene();
  j["sfm_data_version"] = "0.2";
  json& view = j["views"][0]["value"];
  view["polymorphic_id"] = 2147483650u;
  view["polymorphic_name"] = "view_priors";
  view["ptr_wrapper"]["data"].update({{"use_pose_center_prior", true}, {"center_weight", {1.0, 1.0, 1.0}},
                                      {"center", {9.0, 9.0, 9.0}}, {"use_pose_rotation_prior", false},
                                      {"rotation_weight", 1.0}, {"rotation", json::parse(kR2)}});
  j["views"][1]["value"]["polymorphic_id"] = 2;  // the type named above, by id
  j["intrinsics"][0]["value"]["ptr_wrapper"]["data"]["prior_focal_length"] = 750;
  Write(p, j.dump());
  auto s = Open("openmvg", p);
  ExpectScene(s.get(), "0.2 with priors");  // the pose, not the prior's centre (9, 9, 9)
  EXPECT_EQ(s->Camera(1)->intrinsics.fx, 800);

  // prior_focal_length without focal_length: refused by field.
  j["intrinsics"][0]["value"]["ptr_wrapper"]["data"].erase("focal_length");
  Write(p, j.dump());
  EXPECT_ERROR(ErrorOf("openmvg", p), "intrinsics[0].value.ptr_wrapper.data: missing field \"focal_length\"",
               "prior_focal_length");

  // Fewer distortion values than the model has: refused naming the field and the count.
  j = OpenMvgScene();
  j["intrinsics"][0]["value"]["polymorphic_name"] = "pinhole_radial_k3";
  j["intrinsics"][0]["value"]["ptr_wrapper"]["data"]["disto_k3"] = {0.1, 0.01};
  Write(p, j.dump());
  EXPECT_ERROR(ErrorOf("openmvg", p), "intrinsics[0].value.ptr_wrapper.data.disto_k3",
               "the pinhole_radial_k3 model has 3 distortion values, got 2");
  j["intrinsics"][0]["value"]["polymorphic_name"] = "pinhole_brown_t2";
  j["intrinsics"][0]["value"]["ptr_wrapper"]["data"]["disto_t2"] = {0.1, 0.01, 0, 0.001};
  Write(p, j.dump());
  EXPECT_ERROR(ErrorOf("openmvg", p), "disto_t2", "the pinhole_brown_t2 model has 5 distortion values, got 4");
}

}  // namespace
}  // namespace imr::io

namespace imr::io {
namespace {

// The synthetic format's tracked model through the job's options: an update per frame that the
// engine accepts (cameras known, ids new or known), the stream's figures in the summary, and an
// evaluation that says why completeness is left out when the truth was not kept.
TEST(SyntheticInput, TrackedOptionsSummaryAndEvaluationWithoutTruth) {
  for (bool keep_truth : {true, false}) {
    SCOPED_TRACE(keep_truth);
    auto s = Open("synthetic", "street",
                  {{"frames", 40}, {"keyframe_every", 1}, {"track_frames", 17}, {"max_range", 40.0},
                   {"keep_truth", keep_truth}});
    std::set<uint64_t> cameras, points;
    int updates = 0;
    engine::KeyframeUpdate u;
    KeyframeInfo info;
    while (s->Next(&u, &info)) {
      ASSERT_EQ(u.cameras.size(), 1u);
      EXPECT_EQ(u.cameras[0].id, static_cast<uint64_t>(info.frame));
      cameras.insert(u.cameras[0].id);
      EXPECT_NE(s->Camera(u.cameras[0].id), nullptr);
      for (const auto& p : u.new_points) {
        EXPECT_TRUE(points.insert(p.id).second);
        for (uint64_t c : p.camera_ids) EXPECT_TRUE(cameras.count(c));
      }
      for (const auto& p : u.moved_points) {
        EXPECT_TRUE(points.count(p.id));
        for (uint64_t c : p.camera_ids) EXPECT_TRUE(cameras.count(c));
      }
      if (info.frame > 1) {  // frame 1 reports the tracks of frame 0 as new; moves from frame 2
        EXPECT_FALSE(u.moved_points.empty());
      }
      ++updates;
    }
    EXPECT_EQ(updates, 40);
    const json summary = s->Summary();
    EXPECT_EQ(summary["model"], "tracked");
    EXPECT_EQ(summary["frames"], 40);
    EXPECT_GT(summary["observations_per_frame"].get<double>(), 800.0);
    EXPECT_EQ(summary["true_points_kept"].get<size_t>(), keep_truth ? points.size() : 0u);
    EXPECT_EQ(summary["tracks"]["length_histogram"].size(), 18u);
    // A triangle on the ground under the first cameras: on the scene, so precision 1.
    engine::Mesh mesh;
    mesh.vertices = {-2, 5, 0, 2, 5, 0, 0, 9, 0};
    mesh.faces = {0, 1, 2};
    const json a = s->Evaluate(mesh);
    EXPECT_NEAR(a["precision"].get<double>(), 1.0, 1e-12);
    EXPECT_EQ(a.contains("completeness"), keep_truth);
    EXPECT_EQ(a.contains("completeness_omitted"), !keep_truth);
  }
  // The block model (track_frames 0) says so; options only their combination breaks are refused
  // naming them.
  EXPECT_EQ(Open("synthetic", "street", {{"frames", 10}})->Summary()["model"], "block");
  // Both models keep the cameras a point may still name, not one per frame of the drive (issue
  // 46): every point's cameras known when it comes, the first frames' gone at the end.
  for (int track_frames : {0, 17}) {
    SCOPED_TRACE(track_frames);
    auto s = Open("synthetic", "street",
                  {{"frames", 400}, {"track_frames", track_frames}, {"max_range", 40.0}});
    engine::KeyframeUpdate u;
    KeyframeInfo info;
    uint64_t last = 0;
    while (s->Next(&u, &info)) {
      for (const auto& p : u.new_points)
        for (uint64_t c : p.camera_ids) ASSERT_NE(s->Camera(c), nullptr) << c;
      for (const auto& p : u.moved_points)
        for (uint64_t c : p.camera_ids) ASSERT_NE(s->Camera(c), nullptr) << c;
      last = u.cameras.back().id;
    }
    EXPECT_NE(s->Camera(last), nullptr);
    for (uint64_t c = 0; c < 300; ++c) EXPECT_EQ(s->Camera(c), nullptr) << c;
  }
  const InputFormat* f = FindInputFormat("synthetic");
  const json too_long = WithDefaults(f->options_schema, {{"frames", 150000}, {"speed", 2.0}});
  ASSERT_TRUE(f->check);
  const std::vector<std::string> found = f->check(too_long);
  ASSERT_EQ(found.size(), 1u);
  EXPECT_EQ(found[0].rfind("frames x speed: 300000 m", 0), 0u) << found[0];
  EXPECT_TRUE(f->check(WithDefaults(f->options_schema, json::object())).empty());
  EXPECT_THROW(
      {
        try {
          f->open("room", too_long);  // not validated: still refused, by name
        } catch (const std::runtime_error& e) {
          EXPECT_NE(std::string(e.what()).find("input.options: frames x speed"), std::string::npos)
              << e.what();
          throw;
        }
      },
      std::runtime_error);
  std::vector<Problem> problems;
  ValidateAgainstSchema(f->options_schema, {{"frames", 10000000}}, "input.options", &problems);
  ASSERT_EQ(problems.size(), 1u);
  EXPECT_EQ(problems[0].path, "input.options.frames");
}

}  // namespace
}  // namespace imr::io
