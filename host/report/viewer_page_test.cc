// The viewer page without a browser: what index.html holds for both summary shapes (imr run's
// SequenceResult fields and host/batch's summary.json rows), HTML escaping, the assets written
// beside it, glTF packed into GLB (read back with host/eval's reader), and the refusals.
// tests/viewer_browser_test.cc opens a real page in headless Chromium.
#include "host/report/viewer_page.h"

#include "host/eval/mesh_io.h"

#include <gtest/gtest.h>

#include <cstring>
#include <fstream>
#include <random>
#include <sstream>
#include <unistd.h>

namespace imr::report {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

void PutU32(std::string* s, uint32_t v) {
  for (int k = 0; k < 4; ++k) s->push_back(static_cast<char>((v >> (8 * k)) & 0xff));
}

// A tetrahedron's vertex (float) and index (uint32) bytes, and the glTF JSON describing them in
// buffer `uri` (absent: GLB's BIN chunk).
std::string TetraBin() {
  const float pos[12] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1};
  const uint32_t idx[12] = {0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3};
  std::string b(reinterpret_cast<const char*>(pos), sizeof(pos));
  b.append(reinterpret_cast<const char*>(idx), sizeof(idx));
  return b;
}

json TetraGltf(const std::string& uri) {
  json buffer = {{"byteLength", 96}};
  if (!uri.empty()) buffer["uri"] = uri;
  return {{"asset", {{"version", "2.0"}}},
          {"scene", 0},
          {"scenes", {{{"nodes", {0}}}}},
          {"nodes", {{{"mesh", 0}}}},
          {"meshes", {{{"primitives", {{{"attributes", {{"POSITION", 0}}}, {"indices", 1}}}}}}},
          {"buffers", {buffer}},
          {"bufferViews", {{{"buffer", 0}, {"byteOffset", 0}, {"byteLength", 48}},
                           {{"buffer", 0}, {"byteOffset", 48}, {"byteLength", 48}}}},
          {"accessors", {{{"bufferView", 0}, {"componentType", 5126}, {"count", 4}, {"type", "VEC3"},
                          {"min", {0, 0, 0}}, {"max", {1, 1, 1}}},
                         {{"bufferView", 1}, {"componentType", 5125}, {"count", 12}, {"type", "SCALAR"}}}}};
}

std::string TetraGlb() {
  std::string text = TetraGltf("").dump();
  while (text.size() % 4) text.push_back(' ');
  const std::string bin = TetraBin();
  std::string glb = "glTF";
  PutU32(&glb, 2);
  PutU32(&glb, static_cast<uint32_t>(12 + 8 + text.size() + 8 + bin.size()));
  PutU32(&glb, static_cast<uint32_t>(text.size()));
  glb += "JSON" + text;
  PutU32(&glb, static_cast<uint32_t>(bin.size()));
  glb += std::string("BIN\0", 4) + bin;
  return glb;
}

class ViewerPage : public ::testing::Test {
 protected:
  ViewerPage() {
    dir_ = fs::temp_directory_path() /
           ("imr-viewer-page-" + std::to_string(::getpid()) + "-" + std::to_string(std::random_device{}()));
    fs::create_directories(dir_);
    Write("mv/model-viewer-umd.min.js", "/* model-viewer stand-in */");
    options_.model_viewer_script = dir_ / "mv" / "model-viewer-umd.min.js";
  }
  ~ViewerPage() override { fs::remove_all(dir_); }
  fs::path Write(const std::string& name, const std::string& bytes) {
    const fs::path p = dir_ / name;
    fs::create_directories(p.parent_path());
    std::ofstream(p, std::ios::binary) << bytes;
    return p;
  }
  static std::string Read(const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    std::ostringstream ss;
    ss << in.rdbuf();
    return ss.str();
  }
  fs::path dir_;
  ViewerPageOptions options_;
};

// A tiled run (issue 32): its tileset and each tile as scripts for the tiles view, a button and
// a link; a tileset naming a file outside tiles/ is not followed; without the view's script the
// page says so.
TEST_F(ViewerPage, TiledRunGetsTheTilesView) {
  Write("tv/imr-tiles-viewer.js", "/* tiles view stand-in */");
  options_.tiles_viewer_script = dir_ / "tv" / "imr-tiles-viewer.js";
  const json tileset = {{"asset", {{"version", "1.1"}}},
                        {"geometricError", 10},
                        {"root", {{"geometricError", 10}, {"refine", "ADD"},
                                  {"children", {{{"content", {{"uri", "tiles/tile_000001.glb"}}}},
                                                {{"content", {{"uri", "tiles/tile_000002.glb"}}}}}}}}};
  Write("run/street/tileset.json", tileset.dump());
  Write("run/street/tiles/tile_000001.glb", TetraGlb());
  Write("run/street/tiles/tile_000002.glb", TetraGlb());
  const json summary = {{"sequences", {{{"name", "street"}, {"ok", true}, {"output_directory", "street"},
                                        {"report", {{"tiles", {{"triangles", 8}}}}}}}}};
  ViewerPageResult r = WriteBatchPage(dir_ / "run", summary, options_);
  EXPECT_EQ(r.tilesets_viewable, 1);
  EXPECT_EQ(r.meshes_viewable, 0);
  EXPECT_TRUE(r.notes.empty()) << r.notes.front();  // tiles only: no note about a missing mesh
  const std::string html = Read(r.page);
  EXPECT_NE(html.find("<button data-tiles=\"0\">tiles</button>"), std::string::npos) << html;
  EXPECT_NE(html.find("<a href=\"street/tileset.json\">tileset</a>"), std::string::npos);
  EXPECT_NE(html.find("<div id=\"tiles-viewer\"></div>"), std::string::npos);
  EXPECT_NE(html.find("\"scripts\":\"assets/tiles/0\""), std::string::npos);
  EXPECT_NE(html.find("<script src=\"assets/imr-tiles-viewer.js\"></script>"), std::string::npos);
  EXPECT_EQ(Read(dir_ / "run/assets/imr-tiles-viewer.js"), "/* tiles view stand-in */");
  EXPECT_EQ(Read(dir_ / "run/assets/tiles/0/tileset.js").rfind("imrTileData(0,\"tileset.json\",\"", 0), 0u);
  const std::string tile = Read(dir_ / "run/assets/tiles/0/tile_000002.js");
  EXPECT_EQ(tile.rfind("imrTileData(0,\"tiles/tile_000002.glb\",\"", 0), 0u) << tile.substr(0, 60);
  // A tileset that names a file outside tiles/ is not followed.
  json outside = tileset;
  outside["root"]["children"][1]["content"]["uri"] = "../../etc/passwd";
  Write("run/street/tileset.json", outside.dump());
  r = WriteBatchPage(dir_ / "run", summary, options_);
  EXPECT_EQ(r.tilesets_viewable, 0);
  ASSERT_EQ(r.notes.size(), 1u);
  EXPECT_NE(r.notes[0].find("is not a tile of imr"), std::string::npos) << r.notes[0];
  // No script for the view: said, and the page is still written.
  Write("run/street/tileset.json", tileset.dump());
  options_.tiles_viewer_script.clear();
  ::setenv("IMR_TILES_VIEWER_JS", (dir_ / "missing.js").c_str(), 1);
  r = WriteBatchPage(dir_ / "run", summary, options_);
  ::unsetenv("IMR_TILES_VIEWER_JS");
  EXPECT_EQ(r.tilesets_viewable, 0);
  ASSERT_FALSE(r.notes.empty());
  EXPECT_NE(r.notes[0].find("imr-tiles-viewer.js not found"), std::string::npos) << r.notes[0];
}

TEST_F(ViewerPage, SequenceResultSummaryGivesTableMeshScriptsAndPlots) {
  const fs::path glb = Write("run/street/mesh.glb", TetraGlb());
  Write("run/street/report.json", "{}");
  Write("run/plots/accuracy.png", "png");
  const json report = {{"input", {{"summary", {{"frames", 120}}}}},
                       {"mesh", {{"vertices", 4}, {"faces", 4}}},
                       {"accuracy", {{"truth_to_mesh", {{"mean", 0.0123456}}}}}};
  const json summary = {
      {"title", "street & room"},
      {"job", "/jobs/j.json"},
      {"sequences",
       {{{"name", "street"}, {"ok", true}, {"error", ""}, {"output_directory", (dir_ / "run/street").string()},
         {"files", {glb.string(), (dir_ / "run/street/report.json").string()}}, {"seconds", 12.34},
         {"report", report}},
        {{"name", "room<1>"}, {"ok", false}, {"error", "engine: <bad> & worse"},
         {"output_directory", "room"}, {"files", json::array()}, {"seconds", 0.5}, {"report", nullptr}}}}};
  const ViewerPageResult r = WriteBatchPage(dir_ / "run", summary, options_);
  EXPECT_EQ(r.page, dir_ / "run" / "index.html");
  EXPECT_EQ(r.meshes_viewable, 1);
  ASSERT_FALSE(r.files.empty());
  EXPECT_EQ(r.files.back(), r.page);
  EXPECT_TRUE(r.notes.empty()) << r.notes.front();
  const std::string html = Read(r.page);
  EXPECT_NE(html.find("<title>street &amp; room</title>"), std::string::npos);
  EXPECT_NE(html.find("<code>/jobs/j.json</code>"), std::string::npos);
  EXPECT_NE(html.find("2 sequences, 1 ok, 1 not"), std::string::npos);
  EXPECT_NE(html.find("<td>street</td><td class=\"status-ok\">ok</td><td class=\"num\">120</td>"
                      "<td class=\"num\">12.3</td><td class=\"num\">4</td><td class=\"num\">4</td>"),
            std::string::npos)
      << html;
  EXPECT_NE(html.find(">0.01235</td>"), std::string::npos);
  EXPECT_NE(html.find("<td>room&lt;1&gt;</td><td class=\"status-bad\">failed</td>"), std::string::npos);
  EXPECT_NE(html.find("engine: &lt;bad&gt; &amp; worse"), std::string::npos);
  EXPECT_EQ(html.find("<bad>"), std::string::npos);
  EXPECT_NE(html.find("<a href=\"street/report.json\">report</a> <a href=\"street/mesh.glb\">glb</a>"),
            std::string::npos);
  EXPECT_NE(html.find("<button data-mesh=\"0\">view</button>"), std::string::npos);
  EXPECT_NE(html.find("<script src=\"assets/model-viewer-umd.min.js\"></script>"), std::string::npos);
  EXPECT_NE(html.find("<model-viewer id=\"viewer\""), std::string::npos);
  EXPECT_NE(html.find("<img src=\"plots/accuracy.png\""), std::string::npos);
  EXPECT_NE(html.find("\"script\":\"assets/meshes/0.js\""), std::string::npos);
  // The assets: model-viewer copied, the GLB as base64 in a script.
  EXPECT_EQ(Read(dir_ / "run/assets/model-viewer-umd.min.js"), "/* model-viewer stand-in */");
  const std::string js = Read(dir_ / "run/assets/meshes/0.js");
  ASSERT_EQ(js.rfind("imrMeshLoaded(0,\"", 0), 0u) << js.substr(0, 40);
  const std::size_t b64 = js.size() - std::strlen("imrMeshLoaded(0,\"") - std::strlen("\");\n");
  EXPECT_EQ(b64, (TetraGlb().size() + 2) / 3 * 4);
  EXPECT_FALSE(fs::exists(dir_ / "run/assets/meshes/1.js"));
}

TEST_F(ViewerPage, BatchSummaryRowsReadReportAndMeshFromTheOutputFolder) {
  Write("runs/a/mesh.glb", TetraGlb());
  Write("runs/a/snapshots/mesh_kf000010.glb", TetraGlb());
  Write("runs/a/report.json",
        json({{"engine", {{"keyframes", 8}}}, {"mesh", {{"vertices", 4}, {"faces", 4}}},
              {"accuracy", {{"mean_truth_to_mesh", 0.25}}}}).dump());
  const json summary = {{"imr_summary", 1},
                        {"sequences",
                         {{{"name", "a"}, {"status", "ok"}, {"output", (dir_ / "runs/a").string()},
                           {"seconds", 3.0}, {"frames", nullptr}, {"error", nullptr}},
                          {{"name", "b"}, {"status", "not run"}, {"output", (dir_ / "runs/b").string()},
                           {"seconds", nullptr}, {"error", nullptr}}}}};
  const ViewerPageResult r = WriteBatchPage(dir_ / "runs", summary, options_);
  EXPECT_EQ(r.meshes_viewable, 1);
  const std::string html = Read(r.page);
  EXPECT_NE(html.find("<td class=\"num\">8 keyframes</td>"), std::string::npos) << html;
  EXPECT_NE(html.find(">0.25</td>"), std::string::npos);
  EXPECT_NE(html.find("<a href=\"a/mesh.glb\">glb</a>"), std::string::npos);  // not the snapshot
  EXPECT_NE(html.find("<td class=\"status-bad\">not run</td>"), std::string::npos);
  EXPECT_TRUE(r.info.empty()) << r.info.front();  // b did not run: nothing to say about its mesh
}

// PLY asked for: not a problem, said once for the batch (issue 37), no warning per sequence.
TEST_F(ViewerPage, SequencesWithoutAGlbAreNamedOnceAsInfo) {
  json sequences = json::array();
  for (const char* name : {"a", "b", "c", "d"}) {
    Write(std::string("runs/") + name + "/mesh.ply", "ply\n");
    sequences.push_back({{"name", name}, {"status", "ok"}, {"output", (dir_ / "runs" / name).string()},
                         {"seconds", 1.0}, {"error", nullptr}});
  }
  const ViewerPageResult r = WriteBatchPage(dir_ / "runs", {{"imr_summary", 1}, {"sequences", sequences}}, options_);
  EXPECT_EQ(r.meshes_viewable, 0);
  EXPECT_TRUE(r.notes.empty()) << r.notes.front();
  ASSERT_EQ(r.info.size(), 1u);
  EXPECT_NE(r.info[0].find("4 sequences wrote neither (a, b, c, ...)"), std::string::npos) << r.info[0];
  EXPECT_NE(r.info[0].find("add \"glb\" to output.formats"), std::string::npos) << r.info[0];
  // The page says why there is no 3D view, with no empty viewer (issue 47: "No mesh to show"
  // above a grey, empty frame looked broken).
  const std::string html = Read(r.page);
  EXPECT_EQ(html.find("<model-viewer id"), std::string::npos);
  EXPECT_EQ(html.find("No mesh to show"), std::string::npos);
  EXPECT_NE(html.find("No 3D view: it shows .glb and .gltf meshes, and 4 sequences wrote neither"),
            std::string::npos) << html;
  EXPECT_NE(html.find("Add \"glb\" to the job's output.formats (with imr mesh: --out NAME.glb)"),
            std::string::npos) << html;
}

TEST_F(ViewerPage, WithoutModelViewerThePageSaysSo) {
  Write("run/s/mesh.glb", TetraGlb());
  options_.model_viewer_script.clear();
  ::setenv("IMR_MODEL_VIEWER_JS", (dir_ / "nowhere.js").c_str(), 1);
  const json summary = {{"sequences", {{{"name", "s"}, {"ok", true}, {"output_directory", "s"}}}}};
  const ViewerPageResult r = WriteBatchPage(dir_ / "run", summary, options_);
  ::unsetenv("IMR_MODEL_VIEWER_JS");
  EXPECT_EQ(r.meshes_viewable, 0);
  ASSERT_EQ(r.notes.size(), 1u);
  EXPECT_NE(r.notes[0].find("<model-viewer> not found"), std::string::npos);
  const std::string html = Read(r.page);
  EXPECT_EQ(html.find("<model-viewer id"), std::string::npos);
  EXPECT_NE(html.find("no 3D view: &lt;model-viewer&gt; not found"), std::string::npos);
  EXPECT_FALSE(fs::exists(dir_ / "run/assets"));
}

TEST_F(ViewerPage, FindsTheModelViewerInstalledBySetup) {
  const fs::path found = FindModelViewerScript();
  if (!fs::exists(IMR_MODEL_VIEWER_SOURCE))
    GTEST_SKIP() << IMR_MODEL_VIEWER_SOURCE << " is missing: run tools/setup.sh (npm ci)";
  EXPECT_FALSE(found.empty());
}

TEST_F(ViewerPage, GltfWithExternalOrDataUriBufferIsPackedIntoAGlbThatReadsTheSame) {
  Write("m/tetra data.bin", TetraBin());
  const fs::path gltf = Write("m/tetra.gltf", TetraGltf("tetra%20data.bin").dump());
  const std::string glb = ReadAsGlb(gltf);
  ASSERT_EQ(glb.compare(0, 4, "glTF"), 0);
  EXPECT_EQ(glb.size() % 4, 0u);
  const fs::path packed = Write("m/packed.glb", glb);
  const eval::TriangleMesh a = eval::ReadMesh(gltf), b = eval::ReadMesh(packed);
  EXPECT_EQ(a.vertices, b.vertices);
  EXPECT_EQ(a.triangles, b.triangles);
  EXPECT_EQ(b.triangles.size(), 4u);

  // The same as a data URI.
  const std::string bin = TetraBin();
  static const char* k = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string b64;
  for (std::size_t i = 0; i < bin.size(); i += 3) {  // 96 bytes: no padding
    const uint32_t v = (uint32_t(uint8_t(bin[i])) << 16) | (uint32_t(uint8_t(bin[i + 1])) << 8) | uint8_t(bin[i + 2]);
    for (int s = 18; s >= 0; s -= 6) b64 += k[(v >> s) & 63];
  }
  const fs::path inline_gltf =
      Write("m/inline.gltf", TetraGltf("data:application/octet-stream;base64," + b64).dump());
  const fs::path packed2 = Write("m/packed2.glb", ReadAsGlb(inline_gltf));
  EXPECT_EQ(eval::ReadMesh(packed2).vertices, a.vertices);

  // A GLB comes back as it is.
  const fs::path g = Write("m/t.glb", TetraGlb());
  EXPECT_EQ(ReadAsGlb(g), TetraGlb());
  // Refusals name the file.
  const fs::path missing = Write("m/missing.gltf", TetraGltf("nothere.bin").dump());
  try {
    ReadAsGlb(missing);
    FAIL() << "no throw";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("nothere.bin: no such file"), std::string::npos) << e.what();
  }
  EXPECT_THROW(ReadAsGlb(Write("m/bad.gltf", "{\"asset\": {\"version\": \"1.0\"}}")), std::runtime_error);
}

TEST_F(ViewerPage, GltfOnlyOutputIsShownPacked) {
  Write("run/s/mesh.bin", TetraBin());
  Write("run/s/mesh.gltf", TetraGltf("mesh.bin").dump());
  const json summary = {{"sequences", {{{"name", "s"}, {"ok", true}, {"output_directory", "s"},
                                        {"files", {"s/mesh.gltf", "s/mesh.bin"}}}}}};
  const ViewerPageResult r = WriteBatchPage(dir_ / "run", summary, options_);
  EXPECT_EQ(r.meshes_viewable, 1);
  EXPECT_TRUE(fs::exists(dir_ / "run/assets/meshes/0.js"));
}

TEST_F(ViewerPage, TooLargeMeshIsLinkedNotEmbedded) {
  Write("run/s/mesh.glb", TetraGlb());
  options_.max_mesh_bytes = 100;
  const json summary = {{"sequences", {{{"name", "s"}, {"ok", true}, {"output_directory", "s"}}}}};
  const ViewerPageResult r = WriteBatchPage(dir_ / "run", summary, options_);
  EXPECT_EQ(r.meshes_viewable, 0);
  ASSERT_EQ(r.notes.size(), 1u);
  EXPECT_NE(r.notes[0].find("more than max_mesh_bytes"), std::string::npos);
  EXPECT_NE(Read(r.page).find("<a href=\"s/mesh.glb\">glb</a>"), std::string::npos);
}

TEST_F(ViewerPage, BadSummaryIsRefusedNamingTheKey) {
  fs::create_directories(dir_ / "run");
  auto error_of = [&](const json& s) -> std::string {
    try {
      WriteBatchPage(dir_ / "run", s, options_);
    } catch (const std::invalid_argument& e) {
      return e.what();
    }
    return "";
  };
  EXPECT_EQ(error_of(json::array()), "summary: expected an object with a \"sequences\" array");
  EXPECT_EQ(error_of({{"sequences", {{{"ok", true}}}}}), "summary: sequences[0].name: expected a string");
  EXPECT_EQ(error_of({{"sequences", {{{"name", "x"}}}}}),
            "summary: sequences[0]: neither \"ok\" (bool) nor \"status\" (string)");
  EXPECT_EQ(error_of({{"sequences", {{{"name", "x"}, {"ok", true}, {"files", "a"}}}}}),
            "summary: sequences[0].files: expected an array");
  EXPECT_THROW(WriteBatchPage(dir_ / "nope", {{"sequences", json::array()}}, options_), std::runtime_error);
}

// The page is its template (viewer_page.html) with each {{name}} filled once: a value holding
// "{{" is not expanded again.
TEST_F(ViewerPage, PageIsItsTemplateFilledOnce) {
  fs::create_directories(dir_ / "run");
  fs::create_directories(dir_ / "run");
  options_.page_template = Write("page.html", "<h1>{{title}}</h1>\n{{rows}}{{head_scripts}}end\n");
  const json summary = {{"title", "a {{rows}} <b>"},
                        {"sequences", {{{"name", "s"}, {"ok", false}, {"error", "e"}}}}};
  const ViewerPageResult r = WriteBatchPage(dir_ / "run", summary, options_);
  const std::string html = Read(r.page);
  const std::string head = "<h1>a {{rows}} &lt;b&gt;</h1>\n<tr class=\"failed\"><td class=\"num\">1</td>";
  EXPECT_EQ(html.substr(0, head.size()), head);
  EXPECT_NE(html.find("</tr>\n<script src=\"assets/model-viewer-umd.min.js\"></script>\nend\n"),
            std::string::npos);
  EXPECT_EQ(html.find("{{head_scripts}}"), std::string::npos);
}

// A template with a name the page does not fill (one from another version of imr) is refused
// naming the file and line, before anything is written; a missing one is a bad option.
TEST_F(ViewerPage, TemplateWithAnUnknownPlaceholderIsRefusedBeforeAnythingIsWritten) {
  Write("run/s/mesh.glb", TetraGlb());
  const json summary = {{"sequences", {{{"name", "s"}, {"ok", true}, {"output_directory", "s"}}}}};
  options_.page_template = Write("page.html", "<h1>{{title}}</h1>\n<p>{{sidebar}}</p>\n");
  try {
    WriteBatchPage(dir_ / "run", summary, options_);
    ADD_FAILURE() << "no error";
  } catch (const std::runtime_error& e) {
    EXPECT_EQ(std::string(e.what()), (dir_ / "page.html").string() + ":2: unknown placeholder {{sidebar}}");
  }
  options_.page_template = Write("page.html", "<h1>{{title</h1>\n");
  EXPECT_THROW(WriteBatchPage(dir_ / "run", summary, options_), std::runtime_error);
  EXPECT_FALSE(fs::exists(dir_ / "run/assets"));
  EXPECT_FALSE(fs::exists(dir_ / "run/index.html"));
  options_.page_template = dir_ / "missing.html";
  EXPECT_EQ(options_.Check(), "page_template " + (dir_ / "missing.html").string() + ": no such file");
}

TEST_F(ViewerPage, FindsItsTemplateBesideTheSources) {
  const fs::path found = FindViewerPageTemplate();
  ASSERT_FALSE(found.empty());
  const std::string text = Read(found);
  for (const char* name : {"{{title}}", "{{rows}}", "{{sections}}", "{{meshes_json}}"})
    EXPECT_NE(text.find(name), std::string::npos) << name;
  ::setenv("IMR_VIEWER_PAGE_TEMPLATE", (dir_ / "nowhere.html").c_str(), 1);
  EXPECT_TRUE(FindViewerPageTemplate().empty());
  ::unsetenv("IMR_VIEWER_PAGE_TEMPLATE");
}

}  // namespace
}  // namespace imr::report
