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

TEST(ViewerBrowser, PageShowsTheRunsMeshInHeadlessChromium) {
  const fs::path node_modules = fs::path(IMR_SOURCE_DIR) / "tools" / "node" / "node_modules";
  const std::string node = IMR_NODE_EXE;
  if (!fs::exists(Chromium())) GTEST_SKIP() << Chromium() << " is missing: run tools/setup.sh (Debian chromium)";
  if (node.empty() || !fs::exists(node)) GTEST_SKIP() << "node is missing: run tools/setup.sh";
  if (!fs::exists(node_modules / "playwright-core") || !fs::exists(IMR_MODEL_VIEWER_SOURCE))
    GTEST_SKIP() << "playwright-core or @google/model-viewer is missing from " << node_modules
                 << ": run tools/setup.sh (npm ci --prefix tools/node)";

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
  const auto b = RunShell(Quote(node) + " " + Quote(std::string(IMR_SOURCE_DIR) + "/tests/viewer_browser.cjs") +
                          " --page " + Quote(page.page.string()) + " --node-modules " +
                          Quote(node_modules.string()) + " --chromium " + Quote(Chromium()) +
                          " --screenshot " + Quote(shot.string()) + " --viewer-screenshot " +
                          Quote(viewer_shot.string()) + " --timeout-ms 90000");
  json result;
  try {
    result = json::parse(b.out);
  } catch (const std::exception&) {
    FAIL() << "no result from the browser (exit " << b.status << "): " << b.out << "\n" << b.err;
  }
  EXPECT_EQ(b.status, 0) << result.dump(2) << "\n" << b.err;
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
  EXPECT_GT(colors.size(), 50u) << "the 3D view looks flat";
  // The mesh covers a good part of the view (its top-left corner is background).
  EXPECT_LT(background, int64_t{view.width} * view.height * 9 / 10);
}

}  // namespace
}  // namespace imr::report
