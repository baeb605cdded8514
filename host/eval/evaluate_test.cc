// Evaluation by hand: point-to-triangle distances (above the interior, beyond an edge, beyond a
// vertex), statistics, the crop rules, completeness and precision on a tiny case, the Velodyne
// transform, and the file-level report with a fake image sequence.
#include "host/eval/distance.h"
#include "host/eval/evaluate.h"
#include "host/io/testing/temp_dir.h"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <random>
#include <unistd.h>

namespace imr::eval {
namespace {

namespace fs = std::filesystem;

TriangleMesh UnitTriangle() { return {{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}, {{0, 1, 2}}}; }

// The square [0, 1]^2 at z = 0, two triangles.
TriangleMesh UnitSquare() { return {{{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}}, {{0, 1, 2}, {0, 2, 3}}}; }

TEST(MeshDistanceTest, HandComputedDistances) {
  const MeshDistance md(UnitTriangle());
  const std::vector<Vec3> p = {
      {0.2, 0.2, 0.5},    // above the interior: the height
      {0.2, 0.2, -0.7},   // below: unsigned
      {0.5, -0.3, 0.4},   // beyond edge y = 0: sqrt(0.3^2 + 0.4^2)
      {1.0, 1.0, 0.0},    // beyond the hypotenuse x + y = 1: 1 / sqrt(2)
      {-0.3, -0.4, 0.0},  // beyond vertex (0, 0, 0)
      {1.3, -0.4, 1.2},   // beyond vertex (1, 0, 0): sqrt(0.09 + 0.16 + 1.44)
      {0.0, 1.0, 0.0},    // on a vertex
  };
  const std::vector<double> want = {0.5, 0.7, 0.5, std::sqrt(0.5), 0.5, 1.3, 0.0};
  for (int threads : {1, 3}) {
    const std::vector<double> d = md.Distances(p, threads);
    ASSERT_EQ(d.size(), want.size());
    for (std::size_t i = 0; i < d.size(); ++i) EXPECT_NEAR(d[i], want[i], 1e-12) << i;
  }
  EXPECT_EQ(md.triangles(), 1u);
  EXPECT_EQ(md.degenerate(), 0u);
}

TEST(MeshDistanceTest, ClosestPointsAreThePointsTheDistancesAreTo) {
  const MeshDistance md(UnitTriangle());
  const std::vector<Vec3> p = {{0.2, 0.2, 0.5}, {0.5, -0.3, 0.4}, {1.0, 1.0, 0.0}, {1.3, -0.4, 1.2}};
  const std::vector<Vec3> want = {{0.2, 0.2, 0}, {0.5, 0, 0}, {0.5, 0.5, 0}, {1, 0, 0}};
  for (int threads : {1, 3}) {
    const std::vector<Vec3> q = md.ClosestPoints(p, threads);
    ASSERT_EQ(q.size(), want.size());
    for (std::size_t i = 0; i < q.size(); ++i)
      for (int k = 0; k < 3; ++k) EXPECT_NEAR(q[i][k], want[i][k], 1e-12) << i << " " << k;
  }
}

TEST(MeshDistanceTest, NearestOfSeveralTrianglesAndDegenerateLeftOut) {
  TriangleMesh m = UnitSquare();
  m.vertices.push_back({5, 5, 5});
  m.triangles.push_back({0, 1, 1});  // repeated vertex
  m.triangles.push_back({0, 2, 4});  // collinear? no: (0,0,0), (1,1,0), (5,5,5) is not
  m.vertices.push_back({2, 2, 0});
  m.triangles.push_back({0, 2, 5});  // collinear: zero area
  const MeshDistance md(m);
  EXPECT_EQ(md.degenerate(), 2u);
  EXPECT_EQ(md.triangles(), 3u);
  EXPECT_NEAR(md.Distances({{0.9, 0.1, -2.0}}, 1)[0], 2.0, 1e-12);
  EXPECT_THROW(MeshDistance({{{0, 0, 0}, {1, 1, 1}}, {{0, 1, 1}}}), std::invalid_argument);
}

TEST(PointSetDistanceTest, Nearest) {
  const PointSetDistance ps({{0, 0, 0}, {10, 0, 0}, {0, 3, 4}});
  const auto d = ps.Distances({{1, 0, 0}, {9, 0, 0}, {0, 6, 8}, {0, 0, 0}}, 2);
  EXPECT_DOUBLE_EQ(d[0], 1.0);
  EXPECT_DOUBLE_EQ(d[1], 1.0);
  EXPECT_DOUBLE_EQ(d[2], 5.0);
  EXPECT_DOUBLE_EQ(d[3], 0.0);
}

TEST(SummarizeTest, MeanMedianRmsPercentile) {
  const DistanceStats s = Summarize({4, 1, 3, 2});
  EXPECT_EQ(s.count, 4u);
  EXPECT_DOUBLE_EQ(s.mean, 2.5);
  EXPECT_DOUBLE_EQ(s.median, 2.5);
  EXPECT_DOUBLE_EQ(s.rms, std::sqrt(30.0 / 4.0));
  EXPECT_DOUBLE_EQ(s.p90, 3.7);  // h = 0.9 * 3 = 2.7: 3 + 0.7 * (4 - 3)
  EXPECT_DOUBLE_EQ(s.max, 4.0);
  EXPECT_EQ(Summarize({}).count, 0u);
  EXPECT_DOUBLE_EQ(Summarize({7}).p90, 7.0);
}

// A camera at `center` looking down +z (R = I), 100 x 100 pixels, f = 100 (a 53 degree view).
io::CameraGeometry Camera(uint64_t id, const Vec3& center) {
  io::CameraGeometry g;
  g.id = id;
  io::SetFromCenter(io::Identity3(), center, &g);
  g.has_intrinsics = true;
  g.intrinsics.width = 100;
  g.intrinsics.height = 100;
  g.intrinsics.fx = g.intrinsics.fy = 100;
  g.intrinsics.cx = g.intrinsics.cy = 49.5;
  g.intrinsics.projectable = true;
  return g;
}

TEST(CropTest, FrustumAndRangeOfTheSameCamera) {
  const std::vector<io::CameraGeometry> cams = {Camera(0, {0, 0, 0}), Camera(1, {0, 0, 100})};
  const std::vector<Vec3> p = {
      {0, 0, 5},      // in front of camera 0, 5 away: kept
      {0, 0, -5},     // behind both cameras, 5 from camera 0: in range, in no frustum
      {0, 0, 50},     // in camera 0's frustum but 50 away; 50 behind camera 1: beyond range
      {10, 0, 5},     // in range of camera 0, u = 100 * 2 + 49.5: outside its image
      {0, 0, 95},     // in camera 0's frustum (too far) and within range of camera 1 (behind it)
      {0, 0, 110},    // in front of camera 1, 10 away: kept
      {2.4, 2.4, 5},  // u = v = 97.5: inside the image's last pixel
      {2.5, 0, 5},    // u = 99.5: just outside (pixels span [-0.5, 99.5))
  };
  CropCounts c;
  const auto keep = CropToCameras(p, cams, 30.0, 2, &c);
  EXPECT_EQ(keep, (std::vector<uint8_t>{1, 0, 0, 0, 0, 1, 1, 0}));
  EXPECT_EQ(c.input, 8u);
  EXPECT_EQ(c.kept, 3u);
  EXPECT_EQ(c.beyond_range, 1u);
  EXPECT_EQ(c.outside_frustum, 4u);
  // No range limit: the far point in camera 0's frustum is kept, so is the one at 95.
  const auto all = CropToCameras(p, cams, 0.0, 1, &c);
  EXPECT_EQ(all, (std::vector<uint8_t>{1, 0, 1, 0, 1, 1, 1, 0}));
  EXPECT_EQ(c.beyond_range, 0u);
  io::CameraGeometry bad = Camera(7, {0, 0, 0});
  bad.intrinsics.width = 0;
  EXPECT_THROW(CropToCameras(p, {bad}, 30.0, 1, &c), std::invalid_argument);
}

TEST(EvaluateTest, CompletenessAndPrecisionTinyCase) {
  // Truth: four points over the unit square at heights 0.01, 0.15, 1 and 0.
  const std::vector<Vec3> truth = {{0.5, 0.5, 0.01}, {0.5, 0.5, 0.15}, {0.5, 0.5, 1.0}, {0.2, 0.8, 0.0}};
  EvaluationOptions o;
  o.taus = {0.05, 0.1, 0.2, 0.5};
  o.precision_samples = 20000;
  const Evaluation e = Evaluate(UnitSquare(), truth, {}, o, true);
  EXPECT_FALSE(e.cropped);
  EXPECT_NE(e.crop_note.find("no cameras"), std::string::npos);
  EXPECT_EQ(e.completeness, (std::vector<double>{0.5, 0.5, 0.75, 0.75}));
  EXPECT_NEAR(e.truth_to_mesh.mean, (0.01 + 0.15 + 1.0) / 4, 1e-12);
  EXPECT_NEAR(e.truth_to_mesh.median, 0.08, 1e-12);
  ASSERT_EQ(e.per_point.size(), 4u);
  EXPECT_NEAR(e.per_point[1], 0.15, 1e-12);
  EXPECT_DOUBLE_EQ(e.mesh_area, 1.0);
  EXPECT_EQ(e.sample_crop.kept, 20000u);

  // Precision: truth covers x <= 0.5 densely (1 cm grid): area within tau of it is 0.5 + tau.
  std::vector<Vec3> half;
  for (int i = 0; i <= 50; ++i)
    for (int j = 0; j <= 100; ++j) half.push_back({i * 0.01, j * 0.01, 0.0});
  const Evaluation h = Evaluate(UnitSquare(), half, {}, o);
  for (std::size_t k = 0; k < o.taus.size(); ++k)
    EXPECT_NEAR(h.precision[k], std::min(1.0, 0.5 + o.taus[k]), 0.012) << o.taus[k];
  EXPECT_EQ(h.completeness, (std::vector<double>{1, 1, 1, 1}));
}

TEST(EvaluateTest, CropAppliesToTruthAndMeshSamples) {
  // The square seen by a camera 1 m above its corner (0, 0) looking down: only part is in view.
  io::CameraGeometry cam = Camera(0, {0, 0, 1});
  io::Mat3 down = {{{1, 0, 0}, {0, -1, 0}, {0, 0, -1}}};  // camera z = -world z
  io::SetFromCenter(down, {0, 0, 1}, &cam);
  const std::vector<Vec3> truth = {{0.1, 0.1, 0.0}, {0.45, 0.45, 0.0}, {0.9, 0.9, 0.0}, {0.1, 0.1, 2.0}};
  EvaluationOptions o;
  o.precision_samples = 10000;
  const Evaluation e = Evaluate(UnitSquare(), truth, {cam}, o, true);
  EXPECT_TRUE(e.cropped);
  // Visible: |x|, |y| < 0.5 (half image over f at 1 m); (0.1, 0.1, 2) is behind the camera.
  EXPECT_EQ(e.truth_crop.kept, 2u);
  EXPECT_EQ(e.truth_crop.outside_frustum, 2u);
  EXPECT_TRUE(std::isnan(e.per_point[2]));
  EXPECT_TRUE(std::isnan(e.per_point[3]));
  EXPECT_NEAR(e.per_point[1], 0.0, 1e-12);
  EXPECT_NEAR(static_cast<double>(e.sample_crop.kept) / 10000.0, 0.25, 0.02);  // a quarter in view
  o.crop = false;
  EXPECT_EQ(Evaluate(UnitSquare(), truth, {cam}, o).truth_crop.kept, 4u);
  // Everything cropped away: an error, not a report of nothing.
  EXPECT_THROW(Evaluate(UnitSquare(), {{5, 5, 5}}, {cam}, EvaluationOptions{}), std::runtime_error);
}

TEST(SampleSurfaceTest, DeterministicAndUniformByArea) {
  // Triangle A area 0.5 at x in [0, 1], triangle B area 4.5 at x in [10, 13].
  const TriangleMesh m = {{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {10, 0, 0}, {13, 0, 0}, {10, 3, 0}},
                          {{0, 1, 2}, {3, 4, 5}}};
  const auto a = SampleSurface(m, 20000, 7);
  EXPECT_EQ(a, SampleSurface(m, 20000, 7));
  EXPECT_NE(a, SampleSurface(m, 20000, 8));
  const double share_b = std::count_if(a.begin(), a.end(), [](const Vec3& p) { return p[0] >= 10; }) / 20000.0;
  EXPECT_NEAR(share_b, 0.9, 0.01);
  double mean_x = 0;
  for (const Vec3& p : a)
    if (p[0] < 10) mean_x += p[0];
  EXPECT_NEAR(mean_x / ((1 - share_b) * 20000), 1.0 / 3.0, 0.02);  // centroid of A
}

TEST(VelodyneTest, TransformToWorld) {
  // KITTI-like Tr: camera x = -velo y, camera y = -velo z, camera z = velo x, offset (0.1, 0.2, 0.3).
  const io::Mat34 tr = {{{0, -1, 0, 0.1}, {0, 0, -1, 0.2}, {1, 0, 0, 0.3}}};
  // Camera with R = I, centre (0, 0, 5): t = -R C = (0, 0, -5).
  const Vec3 w = VelodyneToWorld(tr, io::Identity3(), {0, 0, -5}, {10, 2, 1});
  EXPECT_NEAR(w[0], -2 + 0.1, 1e-12);
  EXPECT_NEAR(w[1], -1 + 0.2, 1e-12);
  EXPECT_NEAR(w[2], 10 + 0.3 + 5, 1e-12);
  // A rotated pose: mapping back with x_cam = R X_w + t gives Tr X_velo.
  const double c = std::cos(0.7), s = std::sin(0.7);
  const io::Mat3 r = {{{c, 0, s}, {0, 1, 0}, {-s, 0, c}}};
  const Vec3 t = {1, -2, 3}, x = {4, -5, 6};
  const Vec3 xw = VelodyneToWorld(tr, r, t, x);
  const Vec3 back = io::Mul(r, xw);
  for (int i = 0; i < 3; ++i)
    EXPECT_NEAR(back[i] + t[i], tr[i][0] * x[0] + tr[i][1] * x[1] + tr[i][2] * x[2] + tr[i][3], 1e-12);
}

// A scan point at `range`, `elevation` and `azimuth` (radians) in the scanner's frame.
Vec3 Polar(double range, double elevation, double azimuth) {
  return {range * std::cos(elevation) * std::cos(azimuth),
          range * std::cos(elevation) * std::sin(azimuth), range * std::sin(elevation)};
}

TEST(ScannerViewTest, ElevationBandPerRangeBin) {
  const double deg = M_PI / 180.0;
  // The scanner at (1, 2, 3), turned a quarter around z: its x is the world's y.
  const Vec3 origin = {1, 2, 3};
  const std::array<Vec3, 3> axes = {Vec3{0, 1, 0}, Vec3{-1, 0, 0}, Vec3{0, 0, 1}};
  const ScannerView v = ScannerViewOf(
      {Polar(20, -20 * deg, 0.3), Polar(20, 3 * deg, 2.0),  // far: -20 to +3 degrees
       Polar(2.0, 8 * deg, -1.0), Polar(2.2, -5 * deg, 1.0),  // close by the band is wider
       Polar(0.5, 60 * deg, 0.0)},                            // the vehicle: left out
      origin, axes);
  EXPECT_DOUBLE_EQ(v.max_range, 20.0);
  auto world = [&](double range, double elevation, double azimuth) {
    const Vec3 l = Polar(range, elevation, azimuth);
    Vec3 w = origin;
    for (std::size_t a = 0; a < 3; ++a)
      for (std::size_t i = 0; i < 3; ++i) w[i] += l[a] * axes[a][i];
    return w;
  };
  const std::vector<ScannerView> views = {v};
  EXPECT_TRUE(InScannerView(views, world(19, 2 * deg, -2.5)));   // any azimuth
  EXPECT_FALSE(InScannerView(views, world(19, 5 * deg, -2.5)));  // above the band
  EXPECT_FALSE(InScannerView(views, world(19, -21 * deg, 0)));   // below it
  EXPECT_TRUE(InScannerView(views, world(2.1, 7 * deg, 0)));     // the close bin's band
  EXPECT_FALSE(InScannerView(views, world(2.1, 9 * deg, 0)));
  // 5 m has no return: the band of the next farther bin that has some (20 m's).
  EXPECT_FALSE(InScannerView(views, world(5, 5 * deg, 0)));
  EXPECT_TRUE(InScannerView(views, world(5, 1 * deg, 0)));
  EXPECT_FALSE(InScannerView(views, world(20.5, 0, 0)));  // beyond the farthest return
  EXPECT_FALSE(InScannerView(views, world(0.5, 60 * deg, 0)));  // the vehicle's own returns
  // A second scan 1 m higher sees what the first missed; a scan with no return sees nothing.
  ScannerView up = v;
  up.origin[2] += 1;
  EXPECT_TRUE(InScannerView({v, up}, world(19, 5 * deg, -2.5)));
  EXPECT_FALSE(InScannerView({ScannerViewOf({}, origin, axes)}, world(19, 2 * deg, 0)));
}

class ScratchTest : public ::testing::Test {
 protected:
  io::testing::TempDir scratch_{"imr-eval"};
  const fs::path dir_ = scratch_.path();
};

void WriteScan(const fs::path& p, const std::vector<std::array<float, 4>>& pts) {
  std::ofstream f(p, std::ios::binary);
  for (const auto& q : pts) f.write(reinterpret_cast<const char*>(q.data()), 16);
}

using VelodyneFiles = ScratchTest;

TEST_F(VelodyneFiles, ReadScanAndLoadSequence) {
  WriteScan(dir_ / "0.bin", {{10, 0, 0, 0.5f}, {20, 0, 0, 0.1f}});
  WriteScan(dir_ / "2.bin", {{5, 0, 0, 0.5f}});
  EXPECT_EQ(ReadVelodyneScan(dir_ / "0.bin").size(), 2u);
  std::ofstream(dir_ / "odd.bin") << "12345";
  try {
    ReadVelodyneScan(dir_ / "odd.bin");
    FAIL();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("odd.bin: 5 bytes, not a multiple of 16"), std::string::npos) << e.what();
  }
  io::ImageSequence seq;
  seq.root = dir_.string();
  seq.has_lidar = true;
  seq.lidar.velo_to_camera = {{{0, -1, 0, 0}, {0, 0, -1, 0}, {1, 0, 0, 0}}};
  for (int i = 0; i < 4; ++i) {
    io::ImageFrame f;
    f.index = i;
    io::SetFromCenter(io::Identity3(), {0, 0, static_cast<double>(i)}, &f.camera);
    seq.frames.push_back(f);
  }
  seq.lidar.scan_paths = {(dir_ / "0.bin").string(), "", (dir_ / "2.bin").string(), ""};
  VelodyneTruth v = LoadVelodyneTruth(seq, 1);
  EXPECT_EQ(v.scans, 2u);
  EXPECT_EQ(v.frames_without_scan, 2u);
  ASSERT_EQ(v.points.size(), 3u);
  EXPECT_NEAR(v.points[2][2], 2 + 5, 1e-12);  // frame 2's camera at z = 2, 5 m ahead
  v = LoadVelodyneTruth(seq, 2);
  EXPECT_EQ(v.points.size(), 3u);
  v = LoadVelodyneTruth(seq, 3);  // frames 0 and 3
  EXPECT_EQ(v.points.size(), 2u);
  seq.has_lidar = false;
  EXPECT_THROW(LoadVelodyneTruth(seq, 1), std::runtime_error);
}

// A fake KITTI sequence for EvaluateFiles: one camera at the origin looking down +z, with one
// Velodyne scan whose Tr is the identity; `g_scan` names the scan file.
std::string g_scan;
io::ImageSequence FakeSequence(const std::string& path, const io::ImageSequenceOptions&) {
  io::ImageSequence seq;
  seq.layout = "fake";
  seq.root = path;
  io::ImageFrame f;
  f.camera = Camera(0, {0, 0, 0});
  seq.frames.push_back(f);
  seq.has_lidar = true;
  seq.lidar.velo_to_camera = {{{1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 0}}};
  seq.lidar.scan_paths = {g_scan};
  return seq;
}

using EvaluateFilesTest = ScratchTest;

// A fake KITTI sequence as FakeSequence, with a KITTI-like Tr: the scanner looks down the
// camera's z (camera x = -velo y, camera y = -velo z, camera z = velo x).
io::ImageSequence FakeKittiSequence(const std::string& path, const io::ImageSequenceOptions& o) {
  io::ImageSequence seq = FakeSequence(path, o);
  seq.lidar.velo_to_camera = {{{0, -1, 0, 0}, {0, 0, -1, 0}, {1, 0, 0, 0}}};
  return seq;
}

TEST_F(EvaluateFilesTest, VelodynePrecisionInTheScannersView) {
  // A wall 10 m ahead of the scanner, 2 m wide, from 1 m below it to 3 m above (velo x = 10,
  // y in [-1, 1], z in [-1, 3]); the scan's returns on it reach 0.5 m up (its highest laser,
  // +2.9 degrees): the wall above is outside every scan's view, right as it is.
  std::ofstream(dir_ / "wall.obj") << "v 1 1 10\nv -1 1 10\nv -1 -3 10\nv 1 -3 10\nf 1 2 3 4\n";
  std::vector<std::array<float, 4>> scan;
  for (int i = 0; i <= 20; ++i)
    for (int j = 0; j <= 30; ++j)
      scan.push_back({10.0f, -1.0f + 0.1f * static_cast<float>(i), -1.0f + 0.05f * static_cast<float>(j), 0});
  g_scan = (dir_ / "scan.bin").string();
  WriteScan(g_scan, scan);
  EvaluationInputs in;
  in.mesh = (dir_ / "wall.obj").string();
  in.sequence = "fake-kitti";
  EvaluationOptions o;
  o.precision_samples = 20000;
  o.threads = 2;
  o.taus = {0.2};
  const nlohmann::json r = EvaluateFiles(in, o, &FakeKittiSequence);
  ASSERT_TRUE(r.contains("scanner_view")) << r.dump();
  // A quarter of the wall lies under 0.2 m above the highest return: precision about 0.42;
  // in the scanner's view (1.5 m of the 4 m height) every sample is within 0.2 m.
  EXPECT_NEAR(r["precision"][0].get<double>(), 1.7 / 4.0, 0.02);
  EXPECT_NEAR(r["scanner_view"]["share"].get<double>(), 1.5 / 4.0, 0.02);
  EXPECT_GT(r["scanner_view"]["precision"][0].get<double>(), 0.99);
  EXPECT_NE(FormatReport(r).find("in the scanner's view"), std::string::npos);
  // A truth file is not a scanner: no such figure.
  std::ofstream(dir_ / "truth.xyz") << "0 0 10\n";
  in.truth = (dir_ / "truth.xyz").string();
  EXPECT_FALSE(EvaluateFiles(in, o, &FakeKittiSequence).contains("scanner_view"));
}

TEST_F(EvaluateFilesTest, VelodyneTruthCroppedReportAndPerPoint) {
  // A wall z = 10 in front of the camera, [-20, 20]^2; scan points on it, behind the camera and
  // out of range.
  std::ofstream(dir_ / "wall.obj") << "v -20 -20 10\nv 20 -20 10\nv 20 20 10\nv -20 20 10\nf 1 2 3 4\n";
  g_scan = (dir_ / "scan.bin").string();
  WriteScan(g_scan, {{0, 0, 10.2f, 0}, {1, 1, 9.9f, 0}, {0, 0, -10, 0}, {0, 0, 40, 0}});
  EvaluationInputs in;
  in.mesh = (dir_ / "wall.obj").string();
  in.sequence = "fake-seq";
  in.per_point = (dir_ / "d.txt").string();
  EvaluationOptions o;
  o.precision_samples = 1000;
  o.threads = 2;
  const nlohmann::json r = EvaluateFiles(in, o, &FakeSequence);
  EXPECT_EQ(r["truth"]["source"], "velodyne");
  EXPECT_EQ(r["truth"]["points"], 4);
  EXPECT_EQ(r["truth"]["scans"], 1);
  EXPECT_TRUE(r["crop"]["applied"].get<bool>());
  EXPECT_EQ(r["crop"]["truth"]["kept"], 2);
  EXPECT_EQ(r["crop"]["truth"]["beyond_range"], 1);
  EXPECT_EQ(r["crop"]["truth"]["outside_frustum"], 1);
  EXPECT_NEAR(r["truth_to_mesh"]["mean"].get<double>(), 0.15, 1e-6);  // float32 scan coordinates
  EXPECT_EQ(r["mesh"]["triangles"], 2);
  EXPECT_DOUBLE_EQ(r["mesh"]["area"].get<double>(), 1600.0);
  for (const char* key : {"mesh", "truth", "crop", "truth_to_mesh", "mesh_to_truth", "tau",
                          "completeness", "precision", "options", "seconds"})
    EXPECT_TRUE(r.contains(key)) << key;
  EXPECT_EQ(r["tau"].size(), r["completeness"].size());
  EXPECT_EQ(r["tau"].size(), r["precision"].size());
  std::ifstream f(in.per_point);
  std::vector<std::string> lines;
  for (std::string l; std::getline(f, l);) lines.push_back(l);
  ASSERT_EQ(lines.size(), 4u);
  EXPECT_NEAR(std::stod(lines[0]), 0.2, 1e-6);
  EXPECT_EQ(lines[2], "nan");
  const std::string text = FormatReport(r);
  EXPECT_NE(text.find("kept 2 of 4 points"), std::string::npos) << text;

  // The same truth as a point file, with the sequence's cameras cropping it.
  std::ofstream(dir_ / "truth.xyz") << "0 0 10.2\n1 1 9.9\n0 0 -10\n0 0 40\n";
  in.truth = (dir_ / "truth.xyz").string();
  in.per_point.clear();
  const nlohmann::json r2 = EvaluateFiles(in, o, &FakeSequence);
  EXPECT_EQ(r2["truth"]["source"], "point_cloud");
  EXPECT_EQ(r2["crop"]["truth"]["kept"], 2);
  // A reference mesh as truth, no sequence: sampled, not cropped.
  in.truth = in.mesh;
  in.sequence.clear();
  o.truth_density = 2.0;
  const nlohmann::json r3 = EvaluateFiles(in, o);
  EXPECT_EQ(r3["truth"]["source"], "mesh_samples");
  EXPECT_EQ(r3["truth"]["points"], 3200);
  EXPECT_FALSE(r3["crop"]["applied"].get<bool>());
  EXPECT_LT(r3["truth_to_mesh"]["max"].get<double>(), 1e-9);
  EXPECT_DOUBLE_EQ(r3["completeness"][0].get<double>(), 1.0);
}

TEST(OptionsTest, Problems) {
  EvaluationOptions o;
  EXPECT_EQ(o.Check(), "");
  o.taus = {0.1, -1};
  EXPECT_NE(o.Check().find("tau"), std::string::npos);
  o.taus = {};
  EXPECT_NE(o.Check(), "");
  o = {};
  o.precision_samples = 0;
  EXPECT_NE(o.Check(), "");
}

}  // namespace
}  // namespace imr::eval
