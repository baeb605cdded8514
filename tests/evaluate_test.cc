// `imr evaluate` end to end, on a mesh the built `imr` reconstructs from the synthetic street:
// the exporter's four formats read back natively, the CLI's report and errors, the CloudCompare
// cross-check of the per-point distances, and the real KITTI sample's Velodyne scans.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include <cmath>
#include <cstring>
#include <fstream>
#include <random>
#include <sstream>

#include "host/eval/mesh_io.h"
#include "host/synthetic/stream.h"
#include "test_util.h"

namespace imr::testing {
namespace {

namespace fs = std::filesystem;
using eval::TriangleMesh;
using eval::Vec3;
using nlohmann::json;

const std::string kImr = IMR_EXE;
constexpr int kFrames = 60;
constexpr uint64_t kSeed = 3;

// One reconstruction for the whole suite: the street, 60 frames, every exporter format.
class Evaluate : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new ScratchDir("evaluate");
    const json job = {
        {"description", "evaluate_test street"},
        {"sequences", {"street"}},
        {"input", {{"format", "synthetic"}, {"options", {{"frames", kFrames}, {"seed", kSeed}}}}},
        {"pipeline",
         {{{"kind", "weight_policy"}, {"plugin", "org.imr.policy.nearest"}},
          {{"kind", "exporter"}, {"plugin", "org.imr.exporter.assimp"}}}},
        {"output", {{"directory", "runs/{sequence}"}, {"formats", {"obj", "ply", "gltf", "glb"}}}}};
    WriteText(*dir_ / "job.json", job.dump(2));
    run_ = new CommandResult(RunShell(kImr + " run " + Quote((*dir_ / "job.json").string())));
  }
  static void TearDownTestSuite() {
    delete run_;
    delete dir_;
  }
  void SetUp() override { ASSERT_EQ(run_->status, 0) << run_->out << run_->err; }
  static fs::path Mesh(const std::string& ext) { return *dir_ / "runs" / "street" / ("mesh." + ext); }
  static CommandResult Imr(const std::string& args) { return RunShell(kImr + " " + args); }

  static ScratchDir* dir_;
  static CommandResult* run_;
};
ScratchDir* Evaluate::dir_ = nullptr;
CommandResult* Evaluate::run_ = nullptr;

// Points on the true street scene where the cameras saw it, with Gaussian noise: the same scene
// the synthetic job reconstructed (same frames and seed).
std::vector<Vec3> NoisyScenePoints(std::size_t count, double sigma, uint64_t seed) {
  synthetic::StreamOptions o;
  o.frames = kFrames;
  o.seed = kSeed;
  const synthetic::SyntheticStream stream(o);
  const auto& rects = stream.scene().rects();
  std::vector<double> cumulative;
  double total = 0.0;
  for (const auto& r : rects) cumulative.push_back(total += 4.0 * r.half_u * r.half_v);
  std::mt19937_64 g(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::normal_distribution<double> noise(0.0, sigma);
  std::vector<Vec3> out;
  while (out.size() < count) {
    const std::size_t i = std::upper_bound(cumulative.begin(), cumulative.end(), u(g) * total) - cumulative.begin();
    const auto& r = rects[std::min(i, rects.size() - 1)];
    const double s = (2 * u(g) - 1) * r.half_u, t = (2 * u(g) - 1) * r.half_v;
    Vec3 p;
    for (int k = 0; k < 3; ++k) p[k] = r.center[k] + s * r.u[k] + t * r.v[k];
    // Seen: within 30 m of a camera (the engine's ray length) and in its view (cameras look down
    // +y with the stream's default 90 x 40 degree field of view).
    bool seen = false;
    for (int f = 0; f < kFrames && !seen; f += 5) {
      const Vec3 c = stream.CameraCenter(f);
      const double dx = p[0] - c[0], dy = p[1] - c[1], dz = p[2] - c[2];
      seen = dy > 0 && std::hypot(dx, dy, dz) < 30.0 && std::fabs(dx) < dy && std::fabs(dz) < 0.36 * dy;
    }
    if (!seen) continue;
    for (int k = 0; k < 3; ++k) p[k] += noise(g);
    out.push_back(p);
  }
  return out;
}

// x - c rounded to float32: what both tools then read exactly (CloudCompare keeps float32).
Vec3 CentredFloat(const Vec3& x, const Vec3& c) {
  return {static_cast<float>(x[0] - c[0]), static_cast<float>(x[1] - c[1]), static_cast<float>(x[2] - c[2])};
}

void WriteXyz(const fs::path& path, const std::vector<Vec3>& pts) {
  std::ostringstream o;
  char buf[96];
  for (const Vec3& p : pts) {  // %.9g round-trips float32 exactly
    std::snprintf(buf, sizeof buf, "%.9g %.9g %.9g\n", p[0], p[1], p[2]);
    o << buf;
  }
  WriteText(path, o.str());
}

void WriteBinaryPly(const fs::path& path, const TriangleMesh& m) {
  std::string s = "ply\nformat binary_little_endian 1.0\nelement vertex " +
                  std::to_string(m.vertices.size()) +
                  "\nproperty float x\nproperty float y\nproperty float z\nelement face " +
                  std::to_string(m.triangles.size()) +
                  "\nproperty list uchar int vertex_indices\nend_header\n";
  for (const Vec3& v : m.vertices)
    for (double x : v) {
      const float f = static_cast<float>(x);
      s.append(reinterpret_cast<const char*>(&f), 4);
    }
  for (const auto& t : m.triangles) {
    s += static_cast<char>(3);
    for (uint32_t i : t) {
      const int32_t v = static_cast<int32_t>(i);
      s.append(reinterpret_cast<const char*>(&v), 4);
    }
  }
  WriteText(path, s);
}

std::vector<double> ReadColumn(const fs::path& path, int column) {
  std::ifstream f(path);
  std::vector<double> out;
  for (std::string line; std::getline(f, line);) {
    std::istringstream ss(line);
    std::vector<std::string> tok;
    for (std::string t; ss >> t;) tok.push_back(t);
    if (static_cast<int>(tok.size()) > column) out.push_back(std::stod(tok[column]));
  }
  return out;
}

TEST_F(Evaluate, ExporterFormatsReadBackAlike) {
  const TriangleMesh ply = eval::ReadMesh(Mesh("ply"));
  ASSERT_GT(ply.triangles.size(), 1000u) << "a real mesh: thousands of triangles";
  const double area = eval::MeshArea(ply);
  for (const char* ext : {"obj", "gltf", "glb"}) {
    const TriangleMesh m = eval::ReadMesh(Mesh(ext));
    EXPECT_EQ(m.triangles.size(), ply.triangles.size()) << ext;
    // OBJ is text with 9 significant digits; the others hold the same float32 coordinates.
    EXPECT_NEAR(eval::MeshArea(m), area, area * 1e-6) << ext;
  }
  // glTF, GLB and PLY hold the same float32 vertices (assimp reorders glTF's: compare sorted).
  const TriangleMesh glb = eval::ReadMesh(Mesh("glb"));
  auto sorted = [](std::vector<Vec3> v) {
    std::sort(v.begin(), v.end());
    return v;
  };
  EXPECT_EQ(sorted(glb.vertices), sorted(eval::ReadMesh(Mesh("gltf")).vertices));
  EXPECT_EQ(sorted(glb.vertices), sorted(ply.vertices));
}

TEST_F(Evaluate, CliWritesTheDocumentedReport) {
  const std::vector<Vec3> truth = NoisyScenePoints(3000, 0.05, 11);
  WriteXyz(*dir_ / "truth.xyz", truth);
  const fs::path out = *dir_ / "reports" / "r.json", per_point = *dir_ / "d.txt";
  const auto r = Imr("evaluate " + Quote(Mesh("glb").string()) + " --truth " +
                     Quote((*dir_ / "truth.xyz").string()) + " --tau 0.1,0.3 --precision-samples 20000" +
                     " --threads 2 --out " + Quote(out.string()) + " --per-point " + Quote(per_point.string()));
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.out.find("truth -> mesh"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("not cropped: no cameras"), std::string::npos) << r.out;
  const json j = json::parse(ReadText(out));
  for (const char* key : {"mesh", "truth", "crop", "truth_to_mesh", "mesh_to_truth", "tau",
                          "completeness", "precision", "options", "seconds", "per_point"})
    EXPECT_TRUE(j.contains(key)) << key << " missing from " << j.dump(2);
  for (const char* key : {"count", "mean", "median", "rms", "p90", "max"})
    EXPECT_TRUE(j["truth_to_mesh"].contains(key)) << key;
  EXPECT_EQ(j["truth"]["points"], 3000);
  EXPECT_EQ(j["truth"]["source"], "point_cloud");
  EXPECT_EQ(j["mesh"]["format"], "glb");
  EXPECT_FALSE(j["crop"]["applied"].get<bool>());
  EXPECT_EQ(j["tau"], json({0.1, 0.3}));
  EXPECT_EQ(j["completeness"].size(), 2u);
  EXPECT_EQ(j["precision"].size(), 2u);
  EXPECT_EQ(j["mesh_to_truth"]["samples"], 20000);
  EXPECT_EQ(j["options"]["threads"], 2);
  // The engine's street mesh lies on the true surfaces it saw: most truth points are close.
  EXPECT_LT(j["truth_to_mesh"]["median"].get<double>(), 0.5) << j.dump(2);
  EXPECT_LE(j["completeness"][0].get<double>(), j["completeness"][1].get<double>());
  const std::vector<double> d = ReadColumn(per_point, 0);
  ASSERT_EQ(d.size(), 3000u);
  double mean = 0;
  for (double x : d) mean += x / d.size();
  EXPECT_NEAR(mean, j["truth_to_mesh"]["mean"].get<double>(), 1e-9);
}

TEST_F(Evaluate, CliBadInputNamesTheFile) {
  WriteText(*dir_ / "t.xyz", "0 0 0\n1 1 1\n");
  const std::string truth = " --truth " + Quote((*dir_ / "t.xyz").string());
  // Missing mesh.
  auto r = Imr("evaluate " + Quote((*dir_ / "none.ply").string()) + truth);
  EXPECT_EQ(r.status, 1);
  EXPECT_NE(r.err.find("none.ply: no such file"), std::string::npos) << r.err;
  // Corrupt PLY: the header promises more faces than the body holds.
  std::string ply = ReadText(Mesh("ply"));
  WriteText(*dir_ / "cut.ply", ply.substr(0, ply.size() / 2));
  r = Imr("evaluate " + Quote((*dir_ / "cut.ply").string()) + truth);
  EXPECT_EQ(r.status, 1);
  EXPECT_NE(r.err.find("cut.ply: truncated"), std::string::npos) << r.err;
  // Unknown extension.
  WriteText(*dir_ / "mesh.stl", "solid x\n");
  r = Imr("evaluate " + Quote((*dir_ / "mesh.stl").string()) + truth);
  EXPECT_EQ(r.status, 1);
  EXPECT_NE(r.err.find("mesh.stl: unknown extension '.stl'"), std::string::npos) << r.err;
  // Bad ground truth file.
  WriteText(*dir_ / "bad.xyz", "1 2 3\n4 five 6\n");
  r = Imr("evaluate " + Quote(Mesh("ply").string()) + " --truth " + Quote((*dir_ / "bad.xyz").string()));
  EXPECT_EQ(r.status, 1);
  EXPECT_NE(r.err.find("bad.xyz: line 2"), std::string::npos) << r.err;
  // Usage: no ground truth, a bad tau list, no mesh.
  r = Imr("evaluate " + Quote(Mesh("ply").string()));
  EXPECT_EQ(r.status, 64);
  EXPECT_NE(r.err.find("no ground truth"), std::string::npos) << r.err;
  r = Imr("evaluate " + Quote(Mesh("ply").string()) + truth + " --tau 0.1,x");
  EXPECT_EQ(r.status, 64);
  EXPECT_NE(r.err.find("--tau"), std::string::npos) << r.err;
  r = Imr("evaluate " + Quote(Mesh("ply").string()) + truth + " --tau -1");
  EXPECT_EQ(r.status, 64);
  r = Imr("evaluate" + truth);
  EXPECT_EQ(r.status, 64);
  r = Imr("evaluate --help");
  EXPECT_EQ(r.status, 0);
  EXPECT_NE(r.out.find("Usage: imr evaluate MESH"), std::string::npos) << r.out;
}

// CloudCompare's command-line cloud-to-mesh distance against imr's, point by point.
TEST_F(Evaluate, MatchesCloudCompareCloudToMesh) {
  if (RunShell("command -v CloudCompare").status != 0)
    GTEST_SKIP() << "CloudCompare not installed (Debian package cloudcompare; tools/setup.sh "
                    "installs it): cross-check skipped";
  // The reconstructed street mesh and 20 000 noisy points of the true scene, both centred on the
  // mesh's bounding box and rounded to float32: CloudCompare reads coordinates as float32, so both
  // tools then work on exactly the same numbers.
  TriangleMesh mesh = eval::ReadMesh(Mesh("ply"));
  ASSERT_GT(mesh.triangles.size(), 1000u);
  Vec3 lo = mesh.vertices[0], hi = lo;
  for (const Vec3& v : mesh.vertices)
    for (int k = 0; k < 3; ++k) lo[k] = std::min(lo[k], v[k]), hi[k] = std::max(hi[k], v[k]);
  const Vec3 c = {(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, (lo[2] + hi[2]) / 2};
  for (Vec3& v : mesh.vertices) v = CentredFloat(v, c);
  std::vector<Vec3> cloud = NoisyScenePoints(20000, 0.1, 5);
  for (Vec3& p : cloud) p = CentredFloat(p, c);
  const fs::path work = *dir_ / "cc";
  fs::create_directories(work);
  WriteBinaryPly(work / "mesh.ply", mesh);
  WriteXyz(work / "cloud.xyz", cloud);

  const auto imr = Imr("evaluate " + Quote((work / "mesh.ply").string()) + " --truth " +
                       Quote((work / "cloud.xyz").string()) + " --precision-samples 1000 --per-point " +
                       Quote((work / "imr.txt").string()) + " --out " + Quote((work / "imr.json").string()));
  ASSERT_EQ(imr.status, 0) << imr.err;
  const auto cc = RunShell(
      "cd " + Quote(work.string()) +
      " && QT_QPA_PLATFORM=offscreen CloudCompare -SILENT -AUTO_SAVE OFF -C_EXPORT_FMT ASC -PREC 9 "
      "-SEP SPACE -NO_TIMESTAMP -O cloud.xyz -O mesh.ply -C2M_DIST -SAVE_CLOUDS FILE out.asc");
  ASSERT_EQ(cc.status, 0) << cc.out << cc.err;
  ASSERT_TRUE(fs::exists(work / "out.asc")) << cc.out << cc.err;

  const std::vector<double> ours = ReadColumn(work / "imr.txt", 0);
  const std::vector<double> theirs = ReadColumn(work / "out.asc", 3);
  const std::vector<double> x = ReadColumn(work / "out.asc", 0);
  ASSERT_EQ(ours.size(), cloud.size());
  ASSERT_EQ(theirs.size(), cloud.size()) << "CloudCompare wrote another number of points";
  // Tolerances. Both tools read the same float32 coordinates, but CloudCompare also computes in
  // float32 (its PointCoordinateType): with centred coordinates up to ~80 m (float32 spacing
  // 7.6e-6 m there) its distances carry an absolute error of a few 1e-6 m whatever their size
  // (measured: at most 2e-6 m below 10 m, 5e-6 m at 30 m). imr computes in double. So each
  // distance must agree to 1e-4 relative, or to 1e-5 m for the short ones (below 10 cm), where
  // float32 resolution and not the method sets the difference; the mean to 1e-5 relative
  // (measured 4e-10: the float32 errors average out).
  double sum_ours = 0, sum_theirs = 0, worst_rel = 0;
  std::size_t mismatches = 0;
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    ASSERT_NEAR(x[i], cloud[i][0], 1e-6) << "CloudCompare changed the point order at " << i;
    const double a = ours[i], b = std::fabs(theirs[i]);  // CloudCompare's distance is signed
    sum_ours += a;
    sum_theirs += b;
    const double diff = std::fabs(a - b);
    if (b > 1e-2) worst_rel = std::max(worst_rel, diff / b);
    if (diff > std::max(1e-4 * b, 1e-5)) {
      if (++mismatches <= 10) ADD_FAILURE() << "point " << i << ": imr " << a << ", CloudCompare " << b;
    }
  }
  EXPECT_EQ(mismatches, 0u);
  const double mean_ours = sum_ours / cloud.size(), mean_theirs = sum_theirs / cloud.size();
  EXPECT_NEAR(mean_ours, mean_theirs, 1e-5 * mean_theirs);
  const json report = json::parse(ReadText(work / "imr.json"));
  EXPECT_NEAR(report["truth_to_mesh"]["mean"].get<double>(), mean_theirs, 1e-5 * mean_theirs);
  std::printf("CloudCompare cross-check: %zu points, %zu triangles; mean %.9f (imr) vs %.9f "
              "(CloudCompare); worst relative difference (d > 1 cm) %.3g\n",
              cloud.size(), mesh.triangles.size(), mean_ours, mean_theirs, worst_rel);
}

// The real KITTI raw sample: Velodyne scans into the world frame of camera 2's poses, cropped by
// its cameras, against a ground plane 1.65 m below camera 2 (its mounting height): the road
// returns land on it, which they do only if the scan-to-world transform is right.
TEST_F(Evaluate, KittiVelodyneAgainstTheGroundPlane) {
  const fs::path drive = fs::path(IMR_SHARED_DIR) / "data" / "kitti-raw-2011_09_26-traffic" /
                         "2011_09_26" / "2011_09_26_drive_unknown_sync";
  if (!fs::exists(drive)) GTEST_SKIP() << drive.string() << " is absent: real-data test skipped";
  WriteText(*dir_ / "ground.obj", "v -30 1.65 -10\nv 30 1.65 -10\nv 30 1.65 80\nv -30 1.65 80\nf 1 2 3 4\n");
  const fs::path out = *dir_ / "kitti.json";
  const auto r = Imr("evaluate " + Quote((*dir_ / "ground.obj").string()) + " --velodyne-seq " +
                     Quote(drive.string()) + " --camera 2 --scan-step 10 --precision-samples 20000 --out " +
                     Quote(out.string()));
  ASSERT_EQ(r.status, 0) << r.err;
  const json j = json::parse(ReadText(out));
  EXPECT_EQ(j["truth"]["source"], "velodyne");
  EXPECT_EQ(j["truth"]["scans"], 8);  // frames 0, 10, ..., 70
  EXPECT_TRUE(j["crop"]["applied"].get<bool>());
  EXPECT_EQ(j["crop"]["cameras"], 78);
  const json& crop = j["crop"]["truth"];
  // A 360-degree scanner seen by a forward camera with a 30 m range: most points go.
  EXPECT_GT(crop["outside_frustum"].get<int>(), crop["kept"].get<int>() / 2) << crop;
  EXPECT_GT(crop["beyond_range"].get<int>(), 0) << crop;
  EXPECT_GT(crop["kept"].get<int>(), 100000) << crop;
  // About a third of what the camera sees is road within 5 cm of the plane; a wrong transform
  // (R for R^T, a missing Tr) puts almost nothing there.
  EXPECT_GT(j["completeness"][0].get<double>(), 0.2) << j.dump(2);
}

}  // namespace
}  // namespace imr::testing
