// The SDK across minor versions (issue 17): a plugin built against the frozen ABI 1.0 headers
// (tests/sdk_1_0, an exporter writing OFF) loads in today's host and exports the geometry of a
// real image run — whose host hands exporters the 1.1 request (keyframes) and services table
// (keyframe images), both longer than the plugin knows — beside the 1.1 assimp exporter, which
// textures the same mesh. And an exporter that asks the host for a keyframe image out of range
// gets a clear error, which fails the sequence with it.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include <cmath>
#include <fstream>
#include <sstream>
#include <vector>
#include <array>

#include "host/eval/mesh_io.h"
#include "test_util.h"

namespace imr::testing {
namespace {
namespace fs = std::filesystem;
using nlohmann::json;

json ReadJson(const fs::path& p) { return json::parse(ReadText(p)); }

class SdkCompat : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new ScratchDir("sdk-compat");
    const CommandResult r = RunShell(Quote(IMR_SYNTH_EXE) + " --out " + Quote((*dir_ / "street").string()) +
                                     " --frames 30 --width 621 --height 188 --color --no-lidar -q");
    ASSERT_EQ(r.status, 0) << r.out << r.err;
  }
  static void TearDownTestSuite() {
    delete dir_;
    dir_ = nullptr;
  }
  // The image pipeline on the sequence with these exporter stages and formats.
  static CommandResult Run(const std::string& name, const json& exporters, const json& formats) {
    json pipeline = {{{"kind", "features"}, {"plugin", "org.imr.features.edge_klt"}},
                     {{"kind", "refiner"}, {"plugin", "org.imr.refiner.ceres"}},
                     {{"kind", "weight_policy"}, {"plugin", "org.imr.policy.nearest"}}};
    for (const json& e : exporters) pipeline.push_back(e);
    const json job = {{"sequences", {(*dir_ / "street").string()}},
                      {"input", {{"format", "kitti_odometry"}}},
                      {"engine", {{"steiner_export", "any_steiner"}}},
                      {"pipeline", pipeline},
                      {"plugin_paths", {IMR_SDK_TEST_PLUGIN_DIR, IMR_EXAMPLE_PLUGIN_DIR}},
                      {"output", {{"directory", (*dir_ / name).string()}, {"formats", formats}}}};
    WriteText(*dir_ / (name + ".json"), job.dump(2));
    return RunShell(Quote(IMR_EXE) + " run -q " + Quote((*dir_ / (name + ".json")).string()));
  }
  static ScratchDir* dir_;
};
ScratchDir* SdkCompat::dir_ = nullptr;

TEST_F(SdkCompat, PluginBuiltAgainstAbi10ExportsGeometryInToday) {
  const CommandResult plugins = RunShell(Quote(IMR_EXE) + " plugins -p " + Quote(IMR_SDK_TEST_PLUGIN_DIR));
  ASSERT_EQ(plugins.status, 0) << plugins.err;
  std::istringstream lines(plugins.out);
  std::string line, listed;
  while (std::getline(lines, line))
    if (line.find("org.imr.test.exporter.off_sdk_1_0") != std::string::npos) listed = line;
  EXPECT_NE(listed.find(" 1.0 "), std::string::npos) << "listed with ABI 1.0: " << plugins.out;

  const CommandResult r = Run("run", {{{"kind", "exporter"}, {"plugin", "org.imr.test.exporter.off_sdk_1_0"}},
                                      {{"kind", "exporter"}, {"plugin", "org.imr.exporter.assimp"}}},
                              {"off", "ply", "glb"});
  ASSERT_EQ(r.status, 0) << r.out << r.err;
  const fs::path out = *dir_ / "run";
  const json report = json::parse(ReadText(out / "report.json"));
  // The host served keyframe images in this run (the assimp exporter textured the GLB).
  EXPECT_EQ(report["export_input"]["keyframe_images"], true);
  EXPECT_GT(report["export_input"]["image_service"]["requests"].get<int>(), 0);
  EXPECT_NE(ReadText(out / "mesh.glb").find("baseColorTexture"), std::string::npos);

  // The 1.0 plugin's OFF: the mesh of the report, vertex for vertex and face for face the PLY's.
  std::ifstream off(out / "mesh.off");
  std::string magic;
  std::size_t nv = 0, nf = 0, ne = 0;
  off >> magic >> nv >> nf >> ne;
  ASSERT_EQ(magic, "OFF");
  EXPECT_EQ(nv, report["mesh"]["vertices"].get<std::size_t>());
  EXPECT_EQ(nf, report["mesh"]["faces"].get<std::size_t>());
  const eval::TriangleMesh ply = eval::ReadMesh((out / "mesh.ply").string());
  ASSERT_EQ(ply.vertices.size(), nv);
  ASSERT_EQ(ply.triangles.size(), nf);
  for (std::size_t i = 0; i < nv; ++i) {
    double x[3];
    off >> x[0] >> x[1] >> x[2];
    for (int k = 0; k < 3; ++k)
      ASSERT_NEAR(x[k], ply.vertices[i][k], 1e-4 * (1 + std::fabs(x[k]))) << "vertex " << i;
  }
  for (std::size_t t = 0; t < nf; ++t) {
    std::size_t n = 0;
    uint32_t a = 0, b = 0, c = 0;
    off >> n >> a >> b >> c;
    ASSERT_EQ(n, 3u);
    ASSERT_EQ((std::array<uint32_t, 3>{a, b, c}), ply.triangles[t]) << "face " << t;
  }
}

// The SDK's example of ABI 1.1 (sdk/examples/vertex_color_exporter): a PLY coloured from the
// nearest keyframe image, close to the assimp exporter's vertex colours of the same run.
TEST_F(SdkCompat, ExampleExporterColoursFromTheKeyframeImages) {
  const CommandResult r = Run("example", {{{"kind", "exporter"}, {"plugin", "org.imr.example.exporter.vertex_color"}},
                                          {{"kind", "exporter"}, {"plugin", "org.imr.exporter.assimp"}}},
                              {"colored_ply", "ply"});
  ASSERT_EQ(r.status, 0) << r.out << r.err;
  auto colours = [](const fs::path& ply) {  // ASCII: x y z r g b per vertex
    std::ifstream in(ply);
    std::string line;
    std::size_t n = 0;
    while (std::getline(in, line) && line != "end_header")
      if (line.rfind("element vertex ", 0) == 0) n = std::stoul(line.substr(15));
    std::vector<std::array<int, 3>> c(n);
    for (auto& rgb : c) {
      double x, y, z;
      in >> x >> y >> z >> rgb[0] >> rgb[1] >> rgb[2];
    }
    return c;
  };
  const auto example = colours(*dir_ / "example" / "mesh_colored.ply");
  ASSERT_FALSE(example.empty());
  // The assimp exporter's binary PLY: x y z nx ny nz (floats), point_id (int), red green blue.
  const std::string bytes = ReadText(*dir_ / "example" / "mesh.ply");
  const std::size_t body = bytes.find("end_header\n") + 11;
  ASSERT_EQ((bytes.size() - body - 13 * ReadJson(*dir_ / "example" / "report.json")["mesh"]["faces"].get<std::size_t>()),
            example.size() * 31);
  double differ = 0;
  int grey = 0;
  for (std::size_t i = 0; i < example.size(); ++i) {
    const auto* c = reinterpret_cast<const uint8_t*>(bytes.data() + body + 31 * i + 28);
    for (int k = 0; k < 3; ++k) differ += std::abs(example[i][k] - c[k]) / 3.0;
    grey += example[i] == std::array<int, 3>{128, 128, 128};
  }
  EXPECT_LT(grey, static_cast<int>(example.size()) / 10) << "most vertices take an image's colour";
  EXPECT_LT(differ / static_cast<double>(example.size()), 25.0) << "mean difference from the exporter's colours";
}

TEST_F(SdkCompat, ImageOutOfRangeIsAClearError) {
  const CommandResult ok = Run("probe-last", {{{"kind", "exporter"}, {"plugin", "org.imr.test.exporter.image_probe"},
                                               {"params", {{"beyond", -1}}}}},
                               {"probe"});
  ASSERT_EQ(ok.status, 0) << ok.out << ok.err;
  const json report = json::parse(ReadText(*dir_ / "probe-last" / "report.json"));
  const int keyframes = report["export_input"]["keyframes"];
  EXPECT_EQ(ReadText(*dir_ / "probe-last" / "mesh.probe"),
            std::to_string(keyframes - 1) + " 621x188x3\n");

  const CommandResult bad = Run("probe-beyond", {{{"kind", "exporter"}, {"plugin", "org.imr.test.exporter.image_probe"}}},
                                {"probe"});
  EXPECT_EQ(bad.status, 1) << bad.out << bad.err;
  const std::string want = "org.imr.test.exporter.image_probe: export failed (invalid argument): keyframe image " +
                           std::to_string(keyframes) + " is out of range: this export has " +
                           std::to_string(keyframes) + " keyframes (0.." + std::to_string(keyframes - 1) + ")";
  EXPECT_NE((bad.out + bad.err).find(want), std::string::npos) << bad.out << bad.err;
  EXPECT_FALSE(fs::exists(*dir_ / "probe-beyond" / "mesh.probe"));
}

}  // namespace
}  // namespace imr::testing

namespace imr::testing {
namespace {

// ABI 1.5 added a kind (dense) in the descriptor's reserved tail: a mesh refiner built against the
// frozen 1.4 header (tests/sdk_1_4) still loads, listed with its ABI, and runs in the same job as
// the 1.5 dense stage, whose points reach the engine beside the refiner's.
TEST_F(SdkCompat, PluginBuiltAgainstAbi14RunsBesideTheDenseStage) {
  const CommandResult plugins = RunShell(Quote(IMR_EXE) + " plugins -p " + Quote(IMR_SDK_TEST_PLUGIN_DIR));
  ASSERT_EQ(plugins.status, 0) << plugins.err;
  std::istringstream lines(plugins.out);
  std::string line, listed, dense;
  while (std::getline(lines, line)) {
    if (line.find("org.imr.test.mesh_refiner.identity_sdk_1_4") != std::string::npos) listed = line;
    if (line.find("org.imr.dense.patchmatch") != std::string::npos) dense = line;
  }
  EXPECT_NE(listed.find(" 1.4 "), std::string::npos) << "listed with ABI 1.4: " << plugins.out;
  EXPECT_NE(dense.find("dense"), std::string::npos) << "the dense plugin, kind dense: " << plugins.out;

  const CommandResult r = Run("abi14", {{{"kind", "dense"}, {"plugin", "org.imr.dense.patchmatch"}},
                                        {{"kind", "mesh_refiner"}, {"plugin", "org.imr.test.mesh_refiner.identity_sdk_1_4"},
                                         {"every_keyframes", 2}},
                                        {{"kind", "exporter"}, {"plugin", "org.imr.exporter.assimp"}}},
                              {"ply"});
  ASSERT_EQ(r.status, 0) << r.out << r.err;
  const json report = json::parse(ReadText(*dir_ / "abi14" / "report.json"));
  const json& input = report["input"]["summary"];
  ASSERT_TRUE(input.contains("dense_points")) << input.dump();
  EXPECT_GT(input["dense_points"]["new"].get<int>(), 100) << "dense points reached the engine";
  EXPECT_GT(input["seconds"]["dense"].get<double>(), 0.0);
  // The dense points are in the mesh's vertices (their ids above 2^30, the refiner's below).
  const int64_t inserted = report["engine"]["points_inserted"].get<int64_t>();
  EXPECT_GT(inserted, input["dense_points"]["new"].get<int64_t>());
  EXPECT_GT(report["mesh"]["faces"].get<int>(), 100);
}

}  // namespace
}  // namespace imr::testing
