// The batch viewer page in a real browser (label `browser`): `imr run` reconstructs a small
// synthetic street and its exporter writes a GLB; WriteBatchPage writes the page over that run
// folder (with a failed sequence and a plot beside it); headless Chromium (Debian's, driven by
// playwright-core from tools/node) opens it from disk, waits for <model-viewer>'s `load` event,
// and takes screenshots — with no console error and no network request. The 3D view's
// screenshot must show a picture, not one flat colour (IMR_VIEWER_TEST_OUT=DIR keeps them).
// Skips, saying what is missing, when Chromium, node or the npm packages are not installed
// (tools/setup.sh installs them).
#include "host/io/image_io.h"
#include "host/report/viewer_page.h"
#include "test_util.h"

#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include <map>
#include <set>
#include <string>

namespace imr::report {
namespace {

namespace fs = std::filesystem;
using imr::testing::Quote;
using imr::testing::ReadText;
using imr::testing::RunShell;
using imr::testing::ScratchDir;
using imr::testing::WriteText;
using nlohmann::json;

std::string Chromium() {
  const char* env = std::getenv("IMR_CHROMIUM");
  return env != nullptr && *env != '\0' ? env : "/usr/bin/chromium";
}

const fs::path kNodeModules = fs::path(IMR_SOURCE_DIR) / "tools" / "node" / "node_modules";

// Empty when the browser tests can run, else what is missing.
std::string Missing() {
  const std::string node = IMR_NODE_EXE;
  if (!fs::exists(Chromium())) return Chromium() + " is missing: run tools/setup.sh (Debian chromium)";
  if (node.empty() || !fs::exists(node)) return "node is missing: run tools/setup.sh";
  if (!fs::exists(kNodeModules / "playwright-core") || !fs::exists(IMR_MODEL_VIEWER_SOURCE))
    return "playwright-core or @google/model-viewer is missing from " + kNodeModules.string() +
           ": run tools/setup.sh (npm ci --prefix tools/node)";
  return {};
}

// Opens `page` in headless Chromium (viewer_browser.cjs); its JSON result (a failure when none).
json OpenInBrowser(const fs::path& page, const fs::path& shot, const fs::path& viewer_shot) {
  const auto b = RunShell(Quote(IMR_NODE_EXE) + " " + Quote(std::string(IMR_SOURCE_DIR) + "/tests/viewer_browser.cjs") +
                          " --page " + Quote(page.string()) + " --node-modules " +
                          Quote(kNodeModules.string()) + " --chromium " + Quote(Chromium()) +
                          " --screenshot " + Quote(shot.string()) + " --viewer-screenshot " +
                          Quote(viewer_shot.string()) + " --timeout-ms 90000");
  json result;
  try {
    result = json::parse(b.out);
  } catch (const std::exception&) {
    ADD_FAILURE() << "no result from the browser (exit " << b.status << "): " << b.out << "\n" << b.err;
    return json::object();
  }
  EXPECT_EQ(b.status, 0) << result.dump(2) << "\n" << b.err;
  return result;
}

// Distinct colours of a screenshot, and how many pixels have the top-left corner's colour.
std::pair<std::size_t, int64_t> Colors(const io::Image& view) {
  auto color_at = [&](int x, int y) {
    const uint8_t* p = view.pixels.data() + y * view.stride_bytes + 3 * x;
    return uint32_t(p[0]) << 16 | uint32_t(p[1]) << 8 | p[2];
  };
  std::set<uint32_t> colors;
  int64_t background = 0;
  const uint32_t corner = color_at(0, 0);
  for (int y = 0; y < view.height; ++y)
    for (int x = 0; x < view.width; ++x) {
      colors.insert(color_at(x, y));
      background += color_at(x, y) == corner;
    }
  return {colors.size(), background};
}

// A one-sequence summary of a run's folder, as `imr run` hands it to the page.
json SummaryOf(const fs::path& output, const std::string& name) {
  const json report = json::parse(ReadText(output / "report.json"));
  json files = json::array();
  for (const auto& f : report.at("files")) files.push_back((output / f.get<std::string>()).string());
  return {{"title", "viewer page test"},
          {"sequences",
           {{{"name", name}, {"ok", true}, {"error", ""}, {"output_directory", output.string()},
             {"files", files}, {"seconds", report.at("seconds")}, {"report", report}}}}};
}

TEST(ViewerBrowser, PageShowsTheRunsMeshInHeadlessChromium) {
  if (const std::string m = Missing(); !m.empty()) GTEST_SKIP() << m;

  // A real run: the engine on a short synthetic street, meshes through the exporter plugin.
  ScratchDir dir("viewer-browser");
  const json job = json::parse(R"({
    "description": "viewer page test",
    "sequences": ["street"],
    "input": {"format": "synthetic", "options": {"frames": 40, "seed": 3}},
    "pipeline": [
      {"kind": "weight_policy", "plugin": "org.imr.policy.nearest"},
      {"kind": "exporter", "plugin": "org.imr.exporter.assimp"}
    ],
    "output": {"directory": "runs/{sequence}", "formats": ["ply", "glb"]}
  })");
  WriteText(dir / "job.json", job.dump(2));
  const auto run = RunShell(std::string(IMR_EXE) + " run -q " + Quote((dir / "job.json").string()));
  ASSERT_EQ(run.status, 0) << run.err;
  const fs::path run_dir = dir / "runs";
  const fs::path street = run_dir / "street";
  const json report = json::parse(ReadText(street / "report.json"));
  json files = json::array();
  for (const auto& f : report.at("files")) files.push_back((street / f.get<std::string>()).string());
  files.push_back((street / "report.json").string());
  const json summary = {
      {"title", "viewer page test"},
      {"job", (dir / "job.json").string()},
      {"sequences",
       {{{"name", "street"}, {"ok", true}, {"error", ""}, {"output_directory", street.string()},
         {"files", files}, {"seconds", report.at("seconds")}, {"report", report}},
        {{"name", "broken"}, {"ok", false}, {"error", "input: /data/broken: no such folder"},
         {"output_directory", "broken"}, {"files", json::array()}, {"seconds", 0.01},
         {"report", nullptr}}}}};
  // A plot beside the page (the page must load it too).
  io::Image plot;
  plot.width = 320;
  plot.height = 200;
  plot.channels = 3;
  plot.stride_bytes = 960;
  for (int y = 0; y < 200; ++y)
    for (int x = 0; x < 320; ++x)
      plot.pixels.insert(plot.pixels.end(), {uint8_t(x * 255 / 319), uint8_t(y), uint8_t(128)});
  fs::create_directories(run_dir / "plots");
  io::WriteImage((run_dir / "plots" / "accuracy.png").string(), plot);

  ViewerPageOptions options;
  options.model_viewer_script = IMR_MODEL_VIEWER_SOURCE;
  const ViewerPageResult page = WriteBatchPage(run_dir, summary, options);
  EXPECT_EQ(page.meshes_viewable, 1);
  EXPECT_TRUE(page.notes.empty()) << page.notes.front();

  const fs::path shot = dir / "page.png", viewer_shot = dir / "viewer.png";
  const json result = OpenInBrowser(page.page, shot, viewer_shot);
  ASSERT_TRUE(result.contains("loads"));
  EXPECT_GE(result["loads"].get<int>(), 1) << result.dump(2);
  EXPECT_EQ(result["shown"], 0);
  EXPECT_EQ(result["errors"], json::array()) << result.dump(2);
  EXPECT_EQ(result["console_errors"], json::array()) << result.dump(2);
  EXPECT_EQ(result["requests_refused"], json::array()) << result.dump(2);
  EXPECT_EQ(result["images"]["total"], 1);
  EXPECT_EQ(result["images"]["loaded"], 1);

  // To look at it: IMR_VIEWER_TEST_OUT=DIR keeps the run folder and the screenshots there.
  if (const char* keep = std::getenv("IMR_VIEWER_TEST_OUT"); keep != nullptr && *keep != '\0') {
    fs::create_directories(keep);
    fs::copy(run_dir, fs::path(keep) / "runs", fs::copy_options::recursive | fs::copy_options::overwrite_existing);
    fs::copy_file(shot, fs::path(keep) / "page.png", fs::copy_options::overwrite_existing);
    fs::copy_file(viewer_shot, fs::path(keep) / "viewer.png", fs::copy_options::overwrite_existing);
  }

  // The screenshots: real pictures; the 3D view shows more than its background.
  const io::Image full = io::ReadImage(shot.string());
  EXPECT_GE(full.width, 1000);
  const io::Image view = io::ReadImage(viewer_shot.string());
  EXPECT_GT(view.width, 300);
  EXPECT_GT(view.height, 300);
  ASSERT_EQ(view.channels, 3);
  const auto [colors, background] = Colors(view);
  EXPECT_GT(colors, 50u) << "the 3D view looks flat";
  // The mesh covers a good part of the view (its top-left corner is background).
  EXPECT_LT(background, int64_t{view.width} * view.height * 9 / 10);
}

// A textured mesh (issue 17): imr-synth's colour street through the whole image pipeline, its
// GLB textured from the keyframes, opens textured — the texture's image is fetched (a blob: URL
// three.js decodes) and loaded — upright at the start of the camera path, and its screenshot has
// many more colours than the same run's untextured mesh (painted orange, shaded).
TEST(ViewerBrowser, TexturedMeshOpensTextured) {
  if (const std::string m = Missing(); !m.empty()) GTEST_SKIP() << m;
  ScratchDir dir("viewer-texture");
  const auto synth = RunShell(Quote(IMR_SYNTH_EXE) + " --out " + Quote((dir / "street").string()) +
                              " --frames 40 --width 621 --height 188 --color --no-lidar -q");
  ASSERT_EQ(synth.status, 0) << synth.err;
  std::map<std::string, std::pair<json, std::size_t>> seen;  // name -> browser result, colours
  for (const auto& [name, params] : {std::pair<std::string, json>{"textured", json::object()},
                                     {"plain", {{"texture", false}, {"vertex_colors", false}}}}) {
    const json job = {
        {"sequences", {(dir / "street").string()}},
        {"input", {{"format", "kitti_odometry"}}},
        {"engine", {{"steiner_export", "any_steiner"}}},
        {"pipeline",
         {{{"kind", "features"}, {"plugin", "org.imr.features.edge_klt"}},
          {{"kind", "refiner"}, {"plugin", "org.imr.refiner.ceres"}},
          {{"kind", "weight_policy"}, {"plugin", "org.imr.policy.nearest"}},
          {{"kind", "exporter"}, {"plugin", "org.imr.exporter.assimp"}, {"params", params}}}},
        {"output", {{"directory", (dir / name / "street").string()}, {"formats", {"glb"}}}}};
    WriteText(dir / (name + ".json"), job.dump(2));
    const auto run = RunShell(std::string(IMR_EXE) + " run -q " + Quote((dir / (name + ".json")).string()));
    ASSERT_EQ(run.status, 0) << run.err;
    ViewerPageOptions options;
    options.model_viewer_script = IMR_MODEL_VIEWER_SOURCE;
    const ViewerPageResult page = WriteBatchPage(dir / name, SummaryOf(dir / name / "street", "street"), options);
    ASSERT_EQ(page.meshes_viewable, 1);
    const fs::path shot = dir / (name + "-page.png"), viewer_shot = dir / (name + "-viewer.png");
    const json result = OpenInBrowser(page.page, shot, viewer_shot);
    ASSERT_TRUE(result.contains("textures")) << result.dump(2);
    EXPECT_EQ(result["errors"], json::array()) << result.dump(2);
    EXPECT_EQ(result["console_errors"], json::array()) << result.dump(2);
    EXPECT_EQ(result["blob_requests"]["failed"], json::array()) << result.dump(2);
    const io::Image view = io::ReadImage(viewer_shot.string());
    seen[name] = {result, Colors(view).first};
    if (const char* keep = std::getenv("IMR_VIEWER_TEST_OUT"); keep != nullptr && *keep != '\0') {
      fs::create_directories(keep);
      fs::copy_file(viewer_shot, fs::path(keep) / (name + "-viewer.png"), fs::copy_options::overwrite_existing);
    }
  }
  const json& textured = seen["textured"].first;
  const json& plain = seen["plain"].first;
  EXPECT_GE(textured["textures"].get<int>(), 1) << textured.dump(2);
  EXPECT_EQ(plain["textures"].get<int>(), 0) << plain.dump(2);
  // The mesh itself, then one blob per atlas page: fetched and finished.
  EXPECT_GE(textured["blob_requests"]["finished"].get<int>(), 1 + textured["textures"].get<int>()) << textured.dump(2);
  EXPECT_EQ(plain["blob_requests"]["finished"].get<int>(), 1) << plain.dump(2);
  std::cout << "distinct colours in the 3D view: textured " << seen["textured"].second << ", untextured "
            << seen["plain"].second << "\n";
  EXPECT_GT(seen["textured"].second, 4 * seen["plain"].second) << "the texture does not show";
}

}  // namespace
}  // namespace imr::report
