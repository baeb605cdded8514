// A run's 3D Tiles in a real 3D Tiles client (label `browser`, issue 32): `imr run` writes tiles
// of a synthetic street; headless Chromium (Debian's, driven by playwright-core from tools/node)
// loads tileset.json with 3d-tiles-renderer on three.js (npm, tools/node) from a local HTTP
// server (tests/tiles_browser.cjs): every tile the tileset names is requested and parsed, no
// load error, no console error, no request elsewhere, and the view shows the street; a
// geo-referenced run in CesiumJS (tests/cesium_browser.cjs) stands where its origin says. Skips,
// saying what is missing, without Chromium, node or the npm packages (tools/setup.sh installs
// them). IMR_VIEWER_TEST_OUT=DIR keeps the screenshot.
#include "host/io/image_io.h"
#include "host/report/viewer_page.h"
#include "host/pipeline/tiles.h"
#include "host/util/geodesy.h"
#include "test_util.h"

#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include <array>
#include <cmath>
#include <cstdio>
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
      // The leaves only: every one is asked for (levels of detail: below).
      {"output", {{"directory", "runs/{sequence}"}, {"formats", json::array()}, {"tiles", {{"size", 20}, {"lod", false}}}}}};
  WriteText(dir / "job.json", job.dump(2));
  const auto run = RunShell(std::string(IMR_EXE) + " run -q " + Quote((dir / "job.json").string()));
  ASSERT_EQ(run.status, 0) << run.err;
  const fs::path out = dir / "runs" / "street";
  const json tileset = json::parse(ReadText(out / "tileset.json"));
  const json report = json::parse(ReadText(out / "report.json"));
  std::vector<std::string> uris = pipeline::TileContentUris(out, tileset["root"]);
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

// Issue 46 items 2 and 4: levels of detail in 3d-tiles-renderer at its own error target (16 px).
// The whole drive seen from 30 times its radius (as issue 46 measured: all 13 full-resolution
// tiles were asked for) asks for at most 10 % of the leaves' bytes, and
// for levels of detail; at street level (a third of a leaf's radius from it) leaves are asked for.
TEST(TilesBrowser, AFarViewLoadsLevelsOfDetailAndANearOneLeaves) {
  if (const std::string m = Missing(); !m.empty()) GTEST_SKIP() << m;
  ScratchDir dir("tiles-browser-lod");
  const json job = {
      {"sequences", {"street"}},
      {"input", {{"format", "synthetic"}, {"options", {{"frames", 150}, {"seed", 3}}}}},
      {"pipeline", {{{"kind", "exporter"}, {"plugin", "org.imr.exporter.assimp"}}}},
      {"output", {{"directory", "runs/{sequence}"}, {"formats", json::array()}, {"tiles", {{"size", 10}}}}}};
  WriteText(dir / "job.json", job.dump(2));
  const auto run = RunShell(std::string(IMR_EXE) + " run -q " + Quote((dir / "job.json").string()));
  ASSERT_EQ(run.status, 0) << run.err;
  const fs::path out = dir / "runs" / "street";
  const json report = json::parse(ReadText(out / "report.json"));
  ASSERT_TRUE(report["tiles"].contains("lod")) << report["tiles"].dump();
  ASSERT_GE(report["tiles"]["lod"]["tiles_per_level"].size(), 3u) << report["tiles"].dump();
  const auto leaf_bytes = report["tiles"]["bytes"].get<double>();
  auto requested = [&](const json& r, double* bytes, int* leaves, int* lods) {
    *bytes = 0;
    *leaves = *lods = 0;
    for (const auto& uri : r["tiles_requested"]) {
      const std::string u = uri.get<std::string>();
      *bytes += static_cast<double>(fs::file_size(out / u));
      ++*(u.find("tiles/tile_") == 0 ? leaves : lods);
    }
  };
  double far_bytes = 0, near_bytes = 0;
  int far_leaves = 0, far_lods = 0, near_leaves = 0, near_lods = 0;
  const json far = Browser("--run " + Quote(out.string()) + " --view far --screenshot " + Quote((dir / "far.png").string()));
  ASSERT_TRUE(far.contains("tiles_requested")) << far.dump();
  requested(far, &far_bytes, &far_leaves, &far_lods);
  const json near = Browser("--run " + Quote(out.string()) + " --view near --screenshot " + Quote((dir / "near.png").string()));
  ASSERT_TRUE(near.contains("tiles_requested")) << near.dump();
  requested(near, &near_bytes, &near_leaves, &near_lods);
  std::printf("far view: %d levels of detail, %d leaves, %.0f bytes = %.1f %% of the leaves' %.0f; near view: %d "
              "levels of detail, %d leaves, %.0f bytes (%.1f %%)\n",
              far_lods, far_leaves, far_bytes, 100.0 * far_bytes / leaf_bytes, leaf_bytes, near_lods, near_leaves,
              near_bytes, 100.0 * near_bytes / leaf_bytes);
  EXPECT_GT(far_lods, 0);
  EXPECT_LE(far_bytes, 0.10 * leaf_bytes);
  EXPECT_GT(near_leaves, 0);
  for (const json* r : {&far, &near}) {
    EXPECT_EQ((*r)["load_errors"], json::array()) << r->dump(2);
    EXPECT_EQ((*r)["console_errors"], json::array()) << r->dump(2);
    EXPECT_EQ((*r)["http_errors"], json::array()) << r->dump(2);
  }
  if (const char* keep = std::getenv("IMR_VIEWER_TEST_OUT"); keep != nullptr && *keep != '\0') {
    fs::create_directories(keep);
    fs::copy_file(dir / "far.png", fs::path(keep) / "tiles_far.png", fs::copy_options::overwrite_existing);
    fs::copy_file(dir / "near.png", fs::path(keep) / "tiles_near.png", fs::copy_options::overwrite_existing);
  }
}

// Issue 46 item 3: a geo-referenced run (output.tiles.origin) in CesiumJS (npm `cesium`):
// Cesium3DTileset.fromUrl puts the tileset's bounding sphere, as a cartographic, within 1 m
// horizontally and 1 m in height of where Cesium's own maths (headingPitchRollToFixedFrame at the
// origin, the heading as Cesium's) puts the centre of the root box of the local frame, and the
// local frame's origin within 1 cm of Cesium's Cartesian3.fromDegrees of the origin; and that
// centre at the distance and bearing from the origin the local frame and the heading give. Then
// drawn (SwiftShader's
// WebGL): every tile loads, none fails, nothing is asked of the network.
TEST(TilesBrowser, CesiumPutsAGeoReferencedTilesetAtItsOrigin) {
  if (const std::string m = Missing(); !m.empty()) GTEST_SKIP() << m;
  if (!fs::exists(kNodeModules / "cesium"))
    GTEST_SKIP() << "cesium is missing from " << kNodeModules.string() << ": run tools/setup.sh (npm ci --prefix tools/node)";
  ScratchDir dir("tiles-cesium");
  const json origin = {{"latitude", 49.01126}, {"longitude", 8.41674}, {"height", 115.5}, {"heading", 63.0}};
  const json job = {
      {"sequences", {"street"}},
      {"input", {{"format", "synthetic"}, {"options", {{"frames", 60}, {"seed", 3}}}}},
      {"pipeline", {{{"kind", "exporter"}, {"plugin", "org.imr.exporter.assimp"}}}},
      {"output", {{"directory", "runs/{sequence}"}, {"formats", json::array()},
                  {"tiles", {{"size", 20}, {"origin", origin}}}}}};
  WriteText(dir / "job.json", job.dump(2));
  const auto run = RunShell(std::string(IMR_EXE) + " run -q " + Quote((dir / "job.json").string()));
  ASSERT_EQ(run.status, 0) << run.err;
  const fs::path out = dir / "runs" / "street";
  const json tileset = json::parse(ReadText(out / "tileset.json"));
  ASSERT_TRUE(tileset["asset"]["extras"]["imr"].contains("origin")) << tileset["asset"].dump();
  // CesiumJS's tileLoad counts the levels of detail's subtrees (external tilesets) as tiles too.
  std::vector<std::string> subtrees;
  const std::size_t tiles =
      pipeline::TileContentUris(out, tileset["root"], InputRole::kInput, &subtrees).size() + subtrees.size();

  const auto b = RunShell(Quote(IMR_NODE_EXE) + " " + Quote(std::string(IMR_SOURCE_DIR) + "/tests/cesium_browser.cjs") +
                          " --run " + Quote(out.string()) + " --node-modules " + Quote(kNodeModules.string()) +
                          " --chromium " + Quote(Chromium()) + " --screenshot " +
                          Quote((dir / "cesium.png").string()) + " --timeout-ms 120000");
  json r;
  try {
    r = json::parse(b.out);
  } catch (const std::exception&) {
    FAIL() << "no result from the browser (exit " << b.status << "): " << b.out << "\n" << b.err;
  }
  std::printf("CesiumJS: bounding sphere centre %s, expected %s: %.2e m horizontally, %.2e m in "
              "height; origin %.2e m from fromDegrees; radius %.1f m; %d tiles loaded\n",
              r["center"].dump().c_str(), r["expected"].dump().c_str(), r.value("horizontal_m", -1.0),
              r.value("height_m", -1.0), r.value("origin_ecef_m", -1.0), r.value("radius", -1.0),
              r.value("tiles_loaded", -1));
  EXPECT_EQ(b.status, 0) << r.dump(2) << "\n" << b.err;
  ASSERT_TRUE(r["loaded"].get<bool>()) << r.dump(2);
  ASSERT_TRUE(r["horizontal_m"].is_number()) << r.dump(2);
  EXPECT_LE(r["horizontal_m"].get<double>(), 1.0) << r.dump(2);
  EXPECT_LE(std::abs(r["height_m"].get<double>()), 1.0) << r.dump(2);
  EXPECT_LE(r["origin_ecef_m"].get<double>(), 0.01) << r.dump(2);
  // Where that is from the origin, without Cesium's frames: the root box's centre in the local
  // frame (lx, ly) lies hypot(lx, ly) away at the bearing heading + atan2(lx, ly), clockwise from
  // north; Cesium's centre, in the origin's east-north plane, within 0.1 m of it.
  const auto local = tileset["asset"]["extras"]["imr"]["local_transform"].get<std::array<double, 16>>();
  const json& box = tileset["root"]["boundingVolume"]["box"];
  double l[3];
  for (int k = 0; k < 3; ++k)
    l[k] = local[k] * box[0].get<double>() + local[4 + k] * box[1].get<double>() + local[8 + k] * box[2].get<double>() +
           local[12 + k];
  const double bearing = (63.0 * M_PI / 180.0) + std::atan2(l[0], l[1]), distance = std::hypot(l[0], l[1]);
  const std::array<double, 3> o = geo::EcefFromGeodetic({49.01126, 8.41674, 115.5});
  const std::array<double, 3> c = geo::EcefFromGeodetic(
      {r["center"]["latitude"].get<double>(), r["center"]["longitude"].get<double>(), r["center"]["height"].get<double>()});
  const std::array<double, 9> enu = geo::EnuAxes(49.01126, 8.41674);
  double en[2] = {0, 0};
  for (int a = 0; a < 2; ++a)
    for (int k = 0; k < 3; ++k) en[a] += enu[3 * a + k] * (c[k] - o[k]);
  std::printf("the centre %.3f m east, %.3f m north of the origin; expected %.3f, %.3f (local %.3f, %.3f)\n",
              en[0], en[1], distance * std::sin(bearing), distance * std::cos(bearing), l[0], l[1]);
  EXPECT_GT(distance, 1.0);  // the scene's centre is not at its origin: the test can see a turn
  EXPECT_NEAR(en[0], distance * std::sin(bearing), 0.1);
  EXPECT_NEAR(en[1], distance * std::cos(bearing), 0.1);
  EXPECT_EQ(r["origin"]["heading"], 63.0);
  // Drawn with every tile.
  EXPECT_TRUE(r["webgl"].get<bool>()) << r.dump(2);
  EXPECT_EQ(r["tiles_loaded"].get<std::size_t>(), tiles) << r.dump(2);
  EXPECT_EQ(r["tiles_failed"], json::array()) << r.dump(2);
  EXPECT_EQ(r["requests_refused"], json::array()) << r.dump(2);
  EXPECT_EQ(r["http_errors"], json::array()) << r.dump(2);
  // The street fills a good part of the view, shaded.
  const io::Image view = io::ReadImage((dir / "cesium.png").string());
  std::set<uint32_t> colors;
  int64_t background = 0;
  for (int y = 0; y < view.height; ++y)
    for (int x = 0; x < view.width; ++x) {
      const uint8_t* p = view.pixels.data() + y * view.stride_bytes + view.channels * x;
      const uint32_t rgb = uint32_t(p[0]) << 16 | uint32_t(p[1]) << 8 | p[2];
      colors.insert(rgb);
      background += rgb == 0xf0f0f0;
    }
  EXPECT_GT(colors.size(), 20u);
  EXPECT_LT(background, int64_t{view.width} * view.height * 95 / 100);
  if (const char* keep = std::getenv("IMR_VIEWER_TEST_OUT"); keep != nullptr && *keep != '\0') {
    fs::create_directories(keep);
    fs::copy_file(dir / "cesium.png", fs::path(keep) / "cesium.png", fs::copy_options::overwrite_existing);
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
  const std::size_t tiles = pipeline::TileContentUris(out, json::parse(ReadText(out / "tileset.json"))["root"]).size();
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
  const json r = Browser("--page " + Quote(page.page.string()) + " --screenshot " + Quote(shot.string()) +
                         " --screenshot-far " + Quote((dir / "page-tiles-far.png").string()) + " --screenshot-near " +
                         Quote((dir / "page-tiles-near.png").string()));
  ASSERT_TRUE(r.contains("tiles_shown"));
  EXPECT_EQ(r["tiles_shown"], 0);
  EXPECT_TRUE(r["tileset_loaded"].get<bool>()) << r.dump(2);
  // The whole street in view, then zoomed out to 30 radii: drawn, and from levels of detail only
  // (issue 46 item 4: zoomed out the view was empty); at street level by the first leaf, leaves.
  EXPECT_GT(r["models_loaded"].get<std::size_t>(), 0u) << r.dump(2);
  int far_lod = 0, far_leaves = 0, near_lod = 0, near_leaves = 0;
  for (const json& u : r.value("visible_far", json::array()))
    ++*(u.get<std::string>().find("tiles/lod_") == 0 ? &far_lod : &far_leaves);
  for (const json& u : r.value("visible_near", json::array()))
    ++*(u.get<std::string>().find("tiles/lod_") == 0 ? &near_lod : &near_leaves);
  EXPECT_GT(far_lod, 0) << r.dump(2);
  EXPECT_EQ(far_leaves, 0) << r.dump(2);
  EXPECT_GT(near_leaves, 0) << r.dump(2);
  std::printf("viewer page: %zu tiles; first view loaded %zu; zoomed out draws %d levels of detail, %d leaves; "
              "at street level %d levels of detail, %d leaves\n", tiles, r["models_loaded"].get<std::size_t>(),
              far_lod, far_leaves, near_lod, near_leaves);
  {
    const io::Image far = io::ReadImage((dir / "page-tiles-far.png").string());
    int64_t drawn = 0;
    for (int y = 0; y < far.height; ++y)
      for (int x = 0; x < far.width; ++x) {
        const uint8_t* p = far.pixels.data() + y * far.stride_bytes + 3 * x;
        drawn += (uint32_t(p[0]) << 16 | uint32_t(p[1]) << 8 | p[2]) != 0xeef1f4;
      }
    EXPECT_GT(drawn, 20) << "zoomed out, the tiles view is empty";
  }
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
    for (const char* name : {"page-tiles-far.png", "page-tiles-near.png"})
      fs::copy_file(dir / name, fs::path(keep) / name, fs::copy_options::overwrite_existing);
  }
}

// A geo-referenced run (output.tiles.origin) on the batch viewer page: its tiles view shows the
// tileset in its local frame (asset.extras.imr.local_transform), ground down, as the same run
// without an origin: every tile loaded, and the two views the same picture (not the street seen
// from the side, as the ECEF frame's up would give).
TEST(TilesBrowser, ViewerPageShowsAGeoReferencedRunAsWithout) {
  if (const std::string m = Missing(); !m.empty()) GTEST_SKIP() << m;
  if (!fs::exists(IMR_TILES_VIEWER_SCRIPT))
    GTEST_SKIP() << IMR_TILES_VIEWER_SCRIPT << " was not built (node and tools/node's esbuild: tools/setup.sh)";
  ScratchDir dir("tiles-page-geo");
  struct Shown {
    json result;
    io::Image view;
  };
  auto show = [&](const std::string& name, const json& tiles) {
    const json job = {
        {"sequences", {"street"}},
        {"input", {{"format", "synthetic"}, {"options", {{"frames", 60}, {"seed", 3}}}}},
        {"pipeline", {{{"kind", "exporter"}, {"plugin", "org.imr.exporter.assimp"}}}},
        {"output", {{"directory", name + "/{sequence}"}, {"formats", json::array()}, {"tiles", tiles}}}};
    WriteText(dir / (name + ".json"), job.dump(2));
    const auto run = RunShell(std::string(IMR_EXE) + " run -q --no-viewer " + Quote((dir / (name + ".json")).string()));
    EXPECT_EQ(run.status, 0) << run.err;
    const fs::path out = dir / name / "street";
    const json report = json::parse(ReadText(out / "report.json"));
    const json summary = {{"title", "tiles page test"},
                          {"sequences", {{{"name", "street"}, {"ok", true}, {"error", ""},
                                          {"output_directory", out.string()}, {"report", report}}}}};
    report::ViewerPageOptions options;
    options.model_viewer_script = IMR_MODEL_VIEWER_SOURCE;
    options.tiles_viewer_script = IMR_TILES_VIEWER_SCRIPT;
    const report::ViewerPageResult page = report::WriteBatchPage(dir / name, summary, options);
    const fs::path shot = dir / (name + ".png");
    Shown s{Browser("--page " + Quote(page.page.string()) + " --screenshot " + Quote(shot.string())), {}};
    s.view = io::ReadImage(shot.string());
    if (const char* keep = std::getenv("IMR_VIEWER_TEST_OUT"); keep != nullptr && *keep != '\0') {
      fs::create_directories(keep);
      fs::copy_file(shot, fs::path(keep) / ("page-" + name + ".png"), fs::copy_options::overwrite_existing);
    }
    return s;
  };
  const Shown plain = show("plain", {{"size", 20}});
  const Shown geo = show("geo", {{"size", 20}, {"origin", {{"latitude", -33.8568}, {"longitude", 151.2153},
                                                           {"height", 20.0}, {"heading", -120.0}}}});
  for (const Shown* s : {&plain, &geo}) {
    EXPECT_TRUE(s->result.value("tileset_loaded", false)) << s->result.dump(2);
    EXPECT_EQ(s->result["load_errors"], json::array()) << s->result.dump(2);
    EXPECT_EQ(s->result["console_errors"], json::array()) << s->result.dump(2);
  }
  EXPECT_EQ(geo.result["models_loaded"], plain.result["models_loaded"]);
  EXPECT_FALSE(plain.result.value("local", true));
  EXPECT_TRUE(geo.result.value("local", false));
  ASSERT_EQ(geo.view.width, plain.view.width);
  ASSERT_EQ(geo.view.height, plain.view.height);
  ASSERT_EQ(geo.view.channels, plain.view.channels);
  int64_t differ = 0;
  for (int y = 0; y < plain.view.height; ++y)
    for (int x = 0; x < plain.view.width * plain.view.channels; ++x) {
      const std::size_t i = static_cast<std::size_t>(y) * plain.view.stride_bytes + x;
      differ += std::abs(int(plain.view.pixels[i]) - int(geo.view.pixels[i])) > 24;
    }
  const int64_t values = int64_t{plain.view.width} * plain.view.height * plain.view.channels;
  std::printf("geo-referenced against plain page view: %lld of %lld values differ by more than 24\n",
              static_cast<long long>(differ), static_cast<long long>(values));
  EXPECT_LT(differ, values / 100);
}

// Issue 46 item 4: the page's "tiles" buttons switch its view to their run: of two tiled runs,
// the second's button shows the second (its tiles load, its button is disabled, the first's not).
TEST(TilesBrowser, ViewerPageTilesButtonsSwitchTheView) {
  if (const std::string m = Missing(); !m.empty()) GTEST_SKIP() << m;
  if (!fs::exists(IMR_TILES_VIEWER_SCRIPT))
    GTEST_SKIP() << IMR_TILES_VIEWER_SCRIPT << " was not built (node and tools/node's esbuild: tools/setup.sh)";
  ScratchDir dir("tiles-page-buttons");
  json sequences = json::array();
  for (const std::string name : {"first", "second"}) {
    const json job = {
        {"sequences", {"street"}},
        {"input", {{"format", "synthetic"}, {"options", {{"frames", 40}, {"seed", name == "first" ? 3 : 4}}}}},
        {"pipeline", {{{"kind", "exporter"}, {"plugin", "org.imr.exporter.assimp"}}}},
        {"output", {{"directory", name + "/{sequence}"}, {"formats", json::array()}, {"tiles", {{"size", 20}}}}}};
    WriteText(dir / (name + ".json"), job.dump(2));
    const auto run = RunShell(std::string(IMR_EXE) + " run -q --no-viewer " + Quote((dir / (name + ".json")).string()));
    ASSERT_EQ(run.status, 0) << run.err;
    const fs::path out = dir / name / "street";
    sequences.push_back({{"name", name}, {"ok", true}, {"error", ""}, {"output_directory", out.string()},
                         {"report", json::parse(ReadText(out / "report.json"))}});
  }
  report::ViewerPageOptions options;
  options.model_viewer_script = IMR_MODEL_VIEWER_SOURCE;
  options.tiles_viewer_script = IMR_TILES_VIEWER_SCRIPT;
  const report::ViewerPageResult page =
      report::WriteBatchPage(dir.path(), {{"title", "buttons"}, {"sequences", sequences}}, options);
  ASSERT_EQ(page.tilesets_viewable, 2);
  const json r = Browser("--page " + Quote(page.page.string()) + " --click-tiles 1 --screenshot " +
                         Quote((dir / "second.png").string()));
  EXPECT_EQ(r["tiles_shown"], 1) << r.dump(2);
  EXPECT_TRUE(r.value("tileset_loaded", false)) << r.dump(2);
  EXPECT_GT(r.value("models_loaded", 0), 0) << r.dump(2);
  EXPECT_EQ(r["buttons_disabled"], json::array({false, true})) << r.dump(2);
  EXPECT_EQ(r["load_errors"], json::array()) << r.dump(2);
  EXPECT_EQ(r["console_errors"], json::array()) << r.dump(2);
}

}  // namespace
}  // namespace imr
