// A run's 3D Tiles in a real 3D Tiles client (label `browser`, issue 32): `imr run` writes tiles
// of a synthetic street; headless Chromium (Debian's, driven by playwright-core from tools/node)
// loads tileset.json with 3d-tiles-renderer on three.js (npm, tools/node) from a local HTTP
// server (tests/tiles_browser.cjs): every tile the tileset names is requested and parsed, no
// load error, no console error, no request elsewhere, and the view shows the street. Skips,
// saying what is missing, without Chromium, node or the npm packages (tools/setup.sh installs
// them). IMR_VIEWER_TEST_OUT=DIR keeps the screenshot.
#include "host/io/image_io.h"
#include "host/report/viewer_page.h"
#include "host/pipeline/tiles.h"
#include "test_util.h"

#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include <set>
#include <string>

namespace imr {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;
using testing::Quote;
using testing::ReadText;
using testing::RunShell;
using testing::ScratchDir;
using testing::WriteText;

std::string Chromium() {
  const char* env = std::getenv("IMR_CHROMIUM");
  return env != nullptr && *env != '\0' ? env : "/usr/bin/chromium";
}

const fs::path kNodeModules = fs::path(IMR_SOURCE_DIR) / "tools" / "node" / "node_modules";

std::string Missing() {
  const std::string node = IMR_NODE_EXE;
  if (!fs::exists(Chromium())) return Chromium() + " is missing: run tools/setup.sh (Debian chromium)";
  if (node.empty() || !fs::exists(node)) return "node is missing: run tools/setup.sh";
  for (const char* m : {"playwright-core", "three", "3d-tiles-renderer"})
    if (!fs::exists(kNodeModules / m))
      return std::string(m) + " is missing from " + kNodeModules.string() +
             ": run tools/setup.sh (npm ci --prefix tools/node)";
  return {};
}


// tests/tiles_browser.cjs with `args` (--run or --page, --screenshot): its JSON result, or a
// failure and an empty object.
json Browser(const std::string& args) {
  const auto b = RunShell(Quote(IMR_NODE_EXE) + " " + Quote(std::string(IMR_SOURCE_DIR) + "/tests/tiles_browser.cjs") +
                          " " + args + " --node-modules " + Quote(kNodeModules.string()) + " --chromium " +
                          Quote(Chromium()) + " --timeout-ms 90000");
  json r;
  try {
    r = json::parse(b.out);
  } catch (const std::exception&) {
    ADD_FAILURE() << "no result from the browser (exit " << b.status << "): " << b.out << "\n" << b.err;
    return json::object();
  }
  EXPECT_EQ(b.status, 0) << r.dump(2) << "\n" << b.err;
  return r;
}

TEST(TilesBrowser, EveryTileLoadsIn3dTilesRenderer) {
  if (const std::string m = Missing(); !m.empty()) GTEST_SKIP() << m;
  ScratchDir dir("tiles-browser");
  const json job = {
      {"sequences", {"street"}},
      {"input", {{"format", "synthetic"}, {"options", {{"frames", 60}, {"seed", 3}}}}},
      {"pipeline", {{{"kind", "exporter"}, {"plugin", "org.imr.exporter.assimp"}}}},
      {"output", {{"directory", "runs/{sequence}"}, {"formats", json::array()}, {"tiles", {{"size", 20}}}}}};
  WriteText(dir / "job.json", job.dump(2));
  const auto run = RunShell(std::string(IMR_EXE) + " run -q " + Quote((dir / "job.json").string()));
  ASSERT_EQ(run.status, 0) << run.err;
  const fs::path out = dir / "runs" / "street";
  const json tileset = json::parse(ReadText(out / "tileset.json"));
  const json report = json::parse(ReadText(out / "report.json"));
  std::vector<std::string> uris = pipeline::TileContentUris(tileset["root"]);
  ASSERT_GE(uris.size(), 9u);

  const fs::path shot = dir / "tiles.png";
  const json r = Browser("--run " + Quote(out.string()) + " --screenshot " + Quote(shot.string()));
  ASSERT_TRUE(r.contains("tileset_loaded"));
  EXPECT_TRUE(r["tileset_loaded"].get<bool>()) << r.dump(2);
  // Every tile the tileset names was requested once and parsed into the scene.
  std::sort(uris.begin(), uris.end());
  EXPECT_EQ(r["tiles_requested"].get<std::vector<std::string>>(), uris) << r.dump(2);
  EXPECT_EQ(r["models_loaded"].get<std::size_t>(), uris.size()) << r.dump(2);
  EXPECT_EQ(r["triangles"], report["tiles"]["triangles"]);
  EXPECT_EQ(r["load_errors"], json::array()) << r.dump(2);
  EXPECT_EQ(r["console_errors"], json::array()) << r.dump(2);
  EXPECT_EQ(r["requests_refused"], json::array()) << r.dump(2);
  EXPECT_EQ(r["http_errors"], json::array()) << r.dump(2);
  const auto attributes = r["attributes"].get<std::vector<std::string>>();
  EXPECT_NE(std::find(attributes.begin(), attributes.end(), "_vertex_key"), attributes.end()) << r.dump();

  // The street fills a good part of the view, shaded (not one flat colour).
  const io::Image view = io::ReadImage(shot.string());
  ASSERT_EQ(view.channels, 3);
  std::set<uint32_t> colors;
  int64_t background = 0;
  for (int y = 0; y < view.height; ++y)
    for (int x = 0; x < view.width; ++x) {
      const uint8_t* p = view.pixels.data() + y * view.stride_bytes + 3 * x;
      const uint32_t c = uint32_t(p[0]) << 16 | uint32_t(p[1]) << 8 | p[2];
      colors.insert(c);
      background += c == 0xf0f0f0;
    }
  EXPECT_GT(colors.size(), 20u);
  EXPECT_LT(background, int64_t{view.width} * view.height * 95 / 100);
  EXPECT_GT(background, int64_t{view.width} * view.height / 10);
  if (const char* keep = std::getenv("IMR_VIEWER_TEST_OUT"); keep != nullptr && *keep != '\0') {
    fs::create_directories(keep);
    fs::copy_file(shot, fs::path(keep) / "tiles.png", fs::copy_options::overwrite_existing);
  }
}

// The batch viewer page shows a tiled run (tiles only: no single mesh), opened from disk: its
// tiles view loads the tileset and every tile in view from the page's own scripts, with nothing
// fetched from the network.
TEST(TilesBrowser, ViewerPageShowsATiledRun) {
  if (const std::string m = Missing(); !m.empty()) GTEST_SKIP() << m;
  if (!fs::exists(IMR_TILES_VIEWER_SCRIPT))
    GTEST_SKIP() << IMR_TILES_VIEWER_SCRIPT << " was not built (node and tools/node's esbuild: tools/setup.sh)";
  ScratchDir dir("tiles-page");
  const json job = {
      {"sequences", {"street"}},
      {"input", {{"format", "synthetic"}, {"options", {{"frames", 60}, {"seed", 3}}}}},
      {"pipeline", {{{"kind", "exporter"}, {"plugin", "org.imr.exporter.assimp"}}}},
      {"output", {{"directory", "runs/{sequence}"}, {"formats", json::array()}, {"tiles", {{"size", 20}}}}}};
  WriteText(dir / "job.json", job.dump(2));
  const auto run = RunShell(std::string(IMR_EXE) + " run -q --no-viewer " + Quote((dir / "job.json").string()));
  ASSERT_EQ(run.status, 0) << run.err;
  const fs::path out = dir / "runs" / "street";
  const json report = json::parse(ReadText(out / "report.json"));
  const std::size_t tiles = pipeline::TileContentUris(json::parse(ReadText(out / "tileset.json"))["root"]).size();
  const json summary = {{"title", "tiles page test"},
                        {"sequences", {{{"name", "street"}, {"ok", true}, {"error", ""},
                                        {"output_directory", out.string()}, {"report", report}}}}};
  report::ViewerPageOptions options;
  options.model_viewer_script = IMR_MODEL_VIEWER_SOURCE;
  options.tiles_viewer_script = IMR_TILES_VIEWER_SCRIPT;
  const report::ViewerPageResult page = report::WriteBatchPage(dir / "runs", summary, options);
  EXPECT_EQ(page.tilesets_viewable, 1);
  EXPECT_EQ(page.meshes_viewable, 0);
  const fs::path shot = dir / "page-tiles.png";
  const json r = Browser("--page " + Quote(page.page.string()) + " --screenshot " + Quote(shot.string()));
  ASSERT_TRUE(r.contains("tiles_shown"));
  EXPECT_EQ(r["tiles_shown"], 0);
  EXPECT_TRUE(r["tileset_loaded"].get<bool>()) << r.dump(2);
  // The whole street is in view: every tile is loaded.
  EXPECT_EQ(r["models_loaded"].get<std::size_t>(), tiles) << r.dump(2);
  EXPECT_EQ(r["load_errors"], json::array()) << r.dump(2);
  EXPECT_EQ(r["console_errors"], json::array()) << r.dump(2);
  EXPECT_EQ(r["requests_refused"], json::array()) << r.dump(2);
  const io::Image view = io::ReadImage(shot.string());
  std::set<uint32_t> colors;
  for (int y = 0; y < view.height; ++y)
    for (int x = 0; x < view.width; ++x) {
      const uint8_t* p = view.pixels.data() + y * view.stride_bytes + 3 * x;
      colors.insert(uint32_t(p[0]) << 16 | uint32_t(p[1]) << 8 | p[2]);
    }
  EXPECT_GT(colors.size(), 20u) << "the tiles view looks flat";
  if (const char* keep = std::getenv("IMR_VIEWER_TEST_OUT"); keep != nullptr && *keep != '\0') {
    fs::create_directories(keep);
    fs::copy_file(shot, fs::path(keep) / "page-tiles.png", fs::copy_options::overwrite_existing);
  }
}

}  // namespace
}  // namespace imr
