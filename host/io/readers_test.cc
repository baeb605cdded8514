// The SfM/SLAM readers against hand-computed cases: one convention for every format (the same
// world point projects to the same pixel through each), exact export/re-import round trips, and
// bad files (dangling ids, missing fields, non-rotations, truncation) refused with the id or field.
#include "host/io/colmap_model.h"
#include "host/io/input_formats.h"
#include "host/io/openmvg_reader.h"
#include "host/io/schema.h"
#include "host/io/slam_json.h"
#include "host/io/testing/temp_dir.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <fstream>
#include <random>

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
        "width": 640, "height": 480, "id_view": 3, "id_intrinsic": 0, "id_pose": 4294967295}}}}],
    "intrinsics": [{"key": 0, "value": {"polymorphic_id": 2147483649, "polymorphic_name": "pinhole",
        "ptr_wrapper": {"id": 2147483652, "data": {"width": 640, "height": 480, "focal_length": 800,
        "principal_point": [320, 240]}}}}],
    "extrinsics": [
      {"key": 1, "value": {"rotation": )") + kR1 + R"(, "center": [1, 2, 3]}},
      {"key": 2, "value": {"rotation": )" + kR2 + R"(, "center": [3, 2, 3]}}],
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
  ASSERT_EQ(mu[0].cameras.size(), 2u);  // view 3 has no pose: skipped
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

TEST(RoundTrip, AnExportedStreamReplaysToTheSameUpdates) {
  TempDir dir;
  std::vector<engine::KeyframeUpdate> stream = Stream();
  CanonicalOrder order;
  StreamRecorder recorder(nullptr, "test");
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
  Write(dir / "stream.json", recorder.SlamJson());
  auto replay = Open("slam_json", dir / "stream.json");
  ASSERT_EQ(replay->KeyframeCount(), 4);
  std::vector<engine::KeyframeUpdate> back = All(replay.get());
  ASSERT_EQ(back.size(), stream.size());
  for (std::size_t k = 0; k < back.size(); ++k) {
    std::string why;
    EXPECT_TRUE(SameUpdate(stream[k], back[k], &why)) << "keyframe " << k << ": " << why;
  }
  // Recording the replay writes the same file.
  StreamRecorder again(nullptr, "test");
  CanonicalOrder order2;
  for (std::size_t k = 0; k < back.size(); ++k) {
    order2.Apply(&back[k]);
    again.Record(back[k], {static_cast<int>(k), static_cast<int>(10 * k)});
  }
  EXPECT_EQ(again.SlamJson(), Read(dir / "stream.json"));

  // The final COLMAP model: live points only, every track entry an existing 2D point.
  const ColmapModel m = recorder.Colmap();
  EXPECT_NO_THROW(CheckColmapModel(m, "export"));
  ASSERT_EQ(m.points.size(), 2u);  // point 2 was removed
  EXPECT_EQ(m.points[0].id, 1u);
  EXPECT_EQ(m.points[0].xyz, (Vec3{0.1, 0.3, 5.2}));
  EXPECT_EQ(m.points[0].track.size(), 3u);
  EXPECT_EQ(m.images.size(), 3u);
  WriteColmapText(m, dir / "colmap");
  EXPECT_NO_THROW(ReadColmapModel(dir / "colmap"));
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
    for (const char* part : {__VA_ARGS__})                                     \
      EXPECT_NE(e_.find(part), std::string::npos) << "'" << part << "' not in: " << e_; \
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

}  // namespace
}  // namespace imr::io
