#include "host/report/viewer_page.h"

#include "host/util/atomic_file.h"
#include "host/util/input_file.h"
#include "host/util/json_text.h"
#include "host/util/text_codec.h"

#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <fstream>
#include <list>
#include <optional>
#include <set>
#include <sstream>
#include <stdexcept>

#ifndef IMR_MODEL_VIEWER_SOURCE
#define IMR_MODEL_VIEWER_SOURCE ""
#endif
#ifndef IMR_TILES_VIEWER_SCRIPT
#define IMR_TILES_VIEWER_SCRIPT ""
#endif
#ifndef IMR_VIEWER_PAGE_TEMPLATE
#define IMR_VIEWER_PAGE_TEMPLATE ""
#endif

namespace imr::report {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

constexpr const char* kModelViewerName = "model-viewer-umd.min.js";
constexpr const char* kTilesViewerName = "imr-tiles-viewer.js";
constexpr const char* kPageTemplateName = "viewer_page.html";

// Through the open rule (host/util/input_file.h): a FIFO or a device where a run's file was is
// refused by name, never waited on. What a page shows is imr's own output, not an input.
std::string ReadBytes(const fs::path& path, const std::string& what) {
  return ReadInputFile(path, what, kDefaultMaxInputBytes, InputRole::kOwnOutput);
}

std::string Lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

std::string HtmlEscape(const std::string& s) {
  std::string out;
  out.reserve(s.size());
  for (char c : s) {
    switch (c) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      case '\'': out += "&#39;"; break;
      default: out += c;
    }
  }
  return out;
}

// A relative path as a URL path: each segment percent-encoded (RFC 3986 unreserved kept).
std::string UrlPath(const fs::path& relative) {
  std::string out;
  for (const auto& part : relative) {
    if (!out.empty()) out += '/';
    for (unsigned char c : part.string()) {
      if (std::isalnum(c) || c == '-' || c == '.' || c == '_' || c == '~') {
        out += static_cast<char>(c);
      } else {
        char buf[4];
        std::snprintf(buf, sizeof(buf), "%%%02X", c);
        out += buf;
      }
    }
  }
  return out;
}

void PutU32(std::string* s, uint32_t v) {
  for (int k = 0; k < 4; ++k) s->push_back(static_cast<char>((v >> (8 * k)) & 0xff));
}

std::string FormatNumber(double v, const char* format) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), format, v);
  return buf;
}

// A value at a JSON pointer, or null.
json At(const json& j, const char* pointer) {
  const json::json_pointer p(pointer);
  return j.is_object() && j.contains(p) ? j.at(p) : json();
}

std::string LocalTime() {
  const std::time_t t = std::chrono::system_clock::to_time_t(std::chrono::system_clock::now());
  std::tm tm{};
  localtime_r(&t, &tm);
  char buf[64];
  std::strftime(buf, sizeof(buf), "%Y-%m-%d %H:%M", &tm);
  return buf;
}

// One table row, from either summary shape (see the header).
struct Row {
  std::string name;
  std::string status;  // "ok", "failed", "not run", ...
  bool ok = false;
  std::string error;
  fs::path output;     // absolute
  std::vector<fs::path> files;
  std::optional<double> seconds;
  json report;         // null when none
  json row;            // the summary row itself
  fs::path mesh;       // the mesh shown in 3D (GLB or glTF), empty when none
  fs::path tileset;    // its 3D Tiles (output.tiles), empty when none
};

fs::path Absolute(const fs::path& p, const fs::path& run_dir) {
  return (p.is_absolute() ? p : run_dir / p).lexically_normal();
}

Row ReadRow(const json& s, std::size_t index, const fs::path& run_dir, std::vector<std::string>* notes,
            std::vector<std::string>* no_mesh) {
  const std::string where = "summary: sequences[" + std::to_string(index) + "]";
  if (!s.is_object()) throw std::invalid_argument(where + ": expected an object");
  Row r;
  r.row = s;
  if (!s.contains("name") || !s["name"].is_string())
    throw std::invalid_argument(where + ".name: expected a string");
  r.name = JsonText(s["name"].get<std::string>());
  if (s.contains("ok")) {
    if (!s["ok"].is_boolean()) throw std::invalid_argument(where + ".ok: expected true or false");
    r.ok = s["ok"].get<bool>();
    r.status = r.ok ? "ok" : "failed";
  } else if (s.contains("status") && s["status"].is_string()) {
    r.status = s["status"].get<std::string>();
    r.ok = r.status == "ok";
  } else {
    throw std::invalid_argument(where + ": neither \"ok\" (bool) nor \"status\" (string)");
  }
  if (s.contains("error") && s["error"].is_string()) r.error = s["error"].get<std::string>();
  for (const char* key : {"output_directory", "output"})
    if (s.contains(key) && s[key].is_string() && r.output.empty())
      r.output = Absolute(GetBytes(s, key), run_dir);  // a name's bytes (host/util/json_text.h)
  if (s.contains("files")) {
    if (!s["files"].is_array()) throw std::invalid_argument(where + ".files: expected an array");
    for (const json& f : s["files"]) {
      if (!f.is_string()) throw std::invalid_argument(where + ".files: expected strings");
      r.files.push_back(Absolute(f.get<std::string>(), run_dir));
    }
  }
  if (s.contains("seconds") && s["seconds"].is_number()) r.seconds = s["seconds"].get<double>();
  if (s.contains("report") && s["report"].is_object()) {
    r.report = s["report"];
  } else if (!r.output.empty() && fs::is_regular_file(r.output / "report.json")) {
    try {
      r.report = json::parse(ReadBytes(r.output / "report.json", "the sequence's report"));
    } catch (const std::exception& e) {
      notes->push_back(r.name + ": report not read: " + e.what());
    }
  }
  if (!r.ok) return r;
  // The mesh: the first .glb listed, else the first .gltf; without a file list, the output
  // folder's (not its snapshots/).
  std::vector<fs::path> candidates = r.files;
  if (candidates.empty() && !r.output.empty() && fs::is_directory(r.output)) {
    for (const auto& e : fs::directory_iterator(r.output))
      if (e.is_regular_file()) candidates.push_back(e.path());
    std::sort(candidates.begin(), candidates.end());
  }
  for (const char* ext : {".glb", ".gltf"}) {
    for (const fs::path& f : candidates)
      if (Lower(f.extension().string()) == ext && f.filename().string().front() != '.') {
        r.mesh = f;
        break;
      }
    if (!r.mesh.empty()) break;
  }
  if (!r.output.empty() && fs::is_regular_file(r.output / "tileset.json")) r.tileset = r.output / "tileset.json";
  // Only a sequence that finished could have written one.
  const bool finished = (s.contains("status") && s["status"] == "ok") ||
                        (s.contains("ok") && s["ok"] == true);
  if (r.mesh.empty() && r.tileset.empty() && finished) no_mesh->push_back(r.name);
  return r;
}

std::string FramesCell(const Row& r) {
  for (const json& v : {At(r.report, "/input/summary/frames"), At(r.row, "/frames")})
    if (v.is_number_integer()) return std::to_string(v.get<int64_t>());
  const json k = At(r.report, "/engine/keyframes");
  if (k.is_number_integer()) return std::to_string(k.get<int64_t>()) + " keyframes";
  const json rk = At(r.row, "/keyframes");
  if (rk.is_number_integer()) return std::to_string(rk.get<int64_t>()) + " keyframes";
  return "";
}

// The paper's accuracy: the mean distance from the ground truth to the mesh.
std::optional<double> Accuracy(const json& accuracy) {
  for (const char* p : {"/truth_to_mesh/mean", "/mean_truth_to_mesh"}) {
    const json v = At(accuracy, p);
    if (v.is_number()) return v.get<double>();
  }
  return std::nullopt;
}

json AccuracyOf(const Row& r) {
  const json a = At(r.report, "/accuracy");
  return a.is_null() ? At(r.row, "/accuracy") : a;
}

// A GLB's JSON chunk (null when it has none that parses).
json GlbJson(const std::string& glb) {
  if (glb.size() < 20) return nullptr;
  uint32_t length = 0;
  std::memcpy(&length, glb.data() + 12, 4);
  if (20 + static_cast<std::size_t>(length) > glb.size()) return nullptr;
  json g = json::parse(glb.begin() + 20, glb.begin() + 20 + length, nullptr, false);
  return g.is_object() ? g : json(nullptr);
}

// Where the view opens for an upright imr mesh: from its first keyframe toward one a few
// keyframes on (the exporter's "imr_upright" root node records both, in glTF coordinates);
// null for other meshes (the viewer frames the whole mesh).
json OpeningView(const json& g) {
  if (!g.is_object()) return nullptr;
  for (const json& n : g.value("nodes", json::array())) {
    if (!n.is_object() || !n.contains("extras") || !n["extras"].is_object()) continue;
    const json u = n["extras"].value("imr_upright", json());
    if (!u.is_object() || !u.contains("view_from") || !u.contains("view_to")) continue;
    const json& from = u["view_from"];
    const json& to = u["view_to"];
    auto point = [](const json& p) {
      if (!p.is_array() || p.size() != 3) return false;
      for (const json& x : p)
        if (!x.is_number() || !std::isfinite(x.get<double>())) return false;
      return true;
    };
    if (point(from) && point(to)) return {{"from", from}, {"to", to}};
  }
  return nullptr;
}

// True when a GLB's materials carry a base colour texture or a primitive has COLOR_0: the page
// then shows its own colours instead of painting it.
bool HasColor(const json& g) {
  if (!g.is_object()) return false;
  for (const json& m : g.value("materials", json::array()))
    if (m.is_object() && m.contains("pbrMetallicRoughness") &&
        m["pbrMetallicRoughness"].contains("baseColorTexture"))
      return true;
  for (const json& mesh : g.value("meshes", json::array()))
    for (const json& p : mesh.value("primitives", json::array()))
      if (p.is_object() && p.contains("attributes") && p["attributes"].contains("COLOR_0")) return true;
  return false;
}

}  // namespace

std::string ViewerPageOptions::Check() const {
  if (max_mesh_bytes == 0) return "max_mesh_bytes must be positive";
  if (!model_viewer_script.empty() && !fs::is_regular_file(model_viewer_script))
    return "model_viewer_script " + model_viewer_script.string() + ": no such file";
  if (!page_template.empty() && !fs::is_regular_file(page_template))
    return "page_template " + page_template.string() + ": no such file";
  return "";
}

namespace {

// One of the page's files: $ENV_VAR if set (empty when it names no file); else <executable's
// folder>/../share/imr/NAME (an install, or the build tree's share/imr); else `fallback` (a path
// in the source or build tree fixed at build time). Empty when none exists.
fs::path FindShared(const char* env_var, const char* name, const fs::path& fallback) {
  if (const char* env = std::getenv(env_var); env != nullptr && *env != '\0')
    return fs::is_regular_file(env) ? fs::path(env) : fs::path();
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (!ec) {
    const fs::path beside = exe.parent_path().parent_path() / "share" / "imr" / name;
    if (fs::is_regular_file(beside, ec)) return beside;
  }
  if (!fallback.empty() && fs::is_regular_file(fallback, ec)) return fallback;
  return {};
}

}  // namespace

fs::path FindTilesViewerScript() {
  return FindShared("IMR_TILES_VIEWER_JS", kTilesViewerName, IMR_TILES_VIEWER_SCRIPT);
}

fs::path FindModelViewerScript() {
  return FindShared("IMR_MODEL_VIEWER_JS", kModelViewerName, IMR_MODEL_VIEWER_SOURCE);
}

fs::path FindViewerPageTemplate() {
  return FindShared("IMR_VIEWER_PAGE_TEMPLATE", kPageTemplateName, IMR_VIEWER_PAGE_TEMPLATE);
}

std::string ReadAsGlb(const fs::path& path) {
  const std::string bytes = ReadBytes(path, "a glTF mesh");
  if (bytes.size() >= 4 && bytes.compare(0, 4, "glTF") == 0) return bytes;
  json g;
  try {
    g = json::parse(bytes);
  } catch (const std::exception& e) {
    throw std::runtime_error(path.string() + ": neither a GLB nor glTF JSON (" + e.what() + ")");
  }
  if (!g.is_object() || !g.contains("asset") || At(g, "/asset/version") != "2.0")
    throw std::runtime_error(path.string() + ": not glTF 2.0 (asset.version is not \"2.0\")");
  // Buffers, concatenated, each 4-byte aligned.
  std::string bin;
  std::vector<std::size_t> base;
  if (g.contains("buffers")) {
    for (std::size_t i = 0; i < g["buffers"].size(); ++i) {
      const json& b = g["buffers"][i];
      std::string data;
      if (!b.contains("uri") || !b["uri"].is_string())
        throw std::runtime_error(path.string() + ": buffers[" + std::to_string(i) + "] has no uri");
      const std::string uri = b["uri"].get<std::string>();
      if (uri.rfind("data:", 0) == 0) {
        const std::size_t comma = uri.find(',');
        if (comma == std::string::npos || uri.substr(0, comma).find(";base64") == std::string::npos ||
            !Base64Decode(uri.substr(comma + 1), &data))
          throw std::runtime_error(path.string() + ": buffers[" + std::to_string(i) + "]: bad data URI");
      } else {
        data = ReadBytes(path.parent_path() / PercentDecode(uri),
                         "buffers[" + std::to_string(i) + "] of " + path.string());
      }
      const std::size_t length = b.value("byteLength", std::size_t{0});
      if (data.size() < length)
        throw std::runtime_error(path.string() + ": buffers[" + std::to_string(i) + "] holds " +
                                 std::to_string(data.size()) + " bytes, byteLength says " +
                                 std::to_string(length));
      data.resize(length);
      base.push_back(bin.size());
      bin += data;
      while (bin.size() % 4 != 0) bin.push_back('\0');
    }
  }
  if (g.contains("bufferViews"))
    for (json& v : g["bufferViews"]) {
      const std::size_t b = v.value("buffer", std::size_t{0});
      if (b >= base.size()) throw std::runtime_error(path.string() + ": a bufferView names a missing buffer");
      v["buffer"] = 0;
      v["byteOffset"] = v.value("byteOffset", std::size_t{0}) + base[b];
    }
  // Images beside the .gltf (a texture atlas) or in data URIs go into the binary chunk too.
  if (g.contains("images"))
    for (std::size_t i = 0; i < g["images"].size(); ++i) {
      json& im = g["images"][i];
      if (!im.contains("uri")) continue;
      const std::string what = "images[" + std::to_string(i) + "] of " + path.string();
      if (!im["uri"].is_string()) throw std::runtime_error(path.string() + ": " + what + ": uri is not a string");
      const std::string uri = im["uri"].get<std::string>();
      std::string data, mime;
      if (uri.rfind("data:", 0) == 0) {
        const std::size_t comma = uri.find(',');
        if (comma == std::string::npos || uri.substr(0, comma).find(";base64") == std::string::npos ||
            !Base64Decode(uri.substr(comma + 1), &data))
          throw std::runtime_error(path.string() + ": images[" + std::to_string(i) + "]: bad data URI");
        mime = uri.substr(5, uri.find(';') - 5);
      } else {
        const fs::path file = path.parent_path() / PercentDecode(uri);
        data = ReadBytes(file, what);
        const std::string ext = Lower(file.extension().string());
        mime = ext == ".png" ? "image/png" : ext == ".jpg" || ext == ".jpeg" ? "image/jpeg" : "";
        if (mime.empty())
          throw std::runtime_error(path.string() + ": " + what + ": " + uri +
                                   " is neither PNG nor JPEG (the only images a GLB holds)");
      }
      if (!g.contains("bufferViews")) g["bufferViews"] = json::array();
      g["bufferViews"].push_back({{"buffer", 0}, {"byteOffset", bin.size()}, {"byteLength", data.size()}});
      bin += data;
      while (bin.size() % 4 != 0) bin.push_back('\0');
      im.erase("uri");
      im["bufferView"] = g["bufferViews"].size() - 1;
      if (!im.contains("mimeType")) im["mimeType"] = mime;
    }
  if (bin.empty()) g.erase("buffers");
  else g["buffers"] = json::array({{{"byteLength", bin.size()}}});
  std::string text = DumpJson(g);
  while (text.size() % 4 != 0) text.push_back(' ');
  std::string glb = "glTF";
  PutU32(&glb, 2);
  PutU32(&glb, static_cast<uint32_t>(12 + 8 + text.size() + (bin.empty() ? 0 : 8 + bin.size())));
  PutU32(&glb, static_cast<uint32_t>(text.size()));
  glb += "JSON";
  glb += text;
  if (!bin.empty()) {
    PutU32(&glb, static_cast<uint32_t>(bin.size()));
    glb += std::string("BIN\0", 4);
    glb += bin;
  }
  return glb;
}

namespace {

// "the 3D view shows ..." said once for the sequences that wrote no .glb/.gltf nor tiles.
std::string NoMeshInfo(const std::vector<std::string>& no_mesh) {
  std::string names;
  for (std::size_t i = 0; i < no_mesh.size() && i < 3; ++i) names += (i ? ", " : "") + no_mesh[i];
  if (no_mesh.size() > 3) names += ", ...";
  return "the 3D view shows .glb and .gltf meshes; " +
         (no_mesh.size() == 1 ? std::string("1 sequence")
                              : std::to_string(no_mesh.size()) + " sequences") +
         " wrote neither (" + names + "): add \"glb\" to output.formats to see " +
         (no_mesh.size() == 1 ? "it" : "them") + " there";
}

// <model-viewer> beside the page; false (and a note) when there is none to copy.
bool CopyModelViewer(const fs::path& assets, const ViewerPageOptions& options,
                     ViewerPageResult& result) {
  const fs::path script =
      options.model_viewer_script.empty() ? FindModelViewerScript() : options.model_viewer_script;
  if (script.empty()) {
    result.notes.push_back("no 3D view: <model-viewer> not found (run tools/setup.sh, or set IMR_MODEL_VIEWER_JS)");
    return false;
  }
  fs::create_directories(assets / "meshes");
  WriteFileAtomically(assets / kModelViewerName, ReadBytes(script, "the <model-viewer> script"));
  result.files.push_back(assets / kModelViewerName);
  return true;
}

// Row i's mesh as a script for the 3D view, and its entry in the page's mesh table (null when
// it has none to show, with a note saying why when it could not be shown).
json WriteMeshScript(const Row& r, std::size_t i, const fs::path& run_dir, const fs::path& assets,
                     const ViewerPageOptions& options, ViewerPageResult& result) {
  std::string glb;
  try {
    glb = ReadAsGlb(r.mesh);
  } catch (const std::exception& e) {
    result.notes.push_back(r.name + ": no 3D view: " + e.what());
    return nullptr;
  }
  if (glb.size() > options.max_mesh_bytes) {
    result.notes.push_back(r.name + ": no 3D view: " + r.mesh.string() + " is " +
                           std::to_string(glb.size() >> 20) + " MiB, more than max_mesh_bytes");
    return nullptr;
  }
  const fs::path js = assets / "meshes" / (std::to_string(i) + ".js");
  const json gltf = GlbJson(glb);
  const bool colored = HasColor(gltf);
  WriteFileAtomically(js, "imrMeshLoaded(" + std::to_string(i) + ",\"" + Base64Encode(glb) + "\");\n");
  result.files.push_back(js);
  const json faces = At(r.report, "/mesh/faces");
  ++result.meshes_viewable;
  return {{"name", r.name},
          {"script", UrlPath(js.lexically_relative(run_dir))},
          {"faces", faces.is_null() ? json("?") : faces},
          {"colored", colored},
          {"view", OpeningView(gltf)}};
}

// Meshes as scripts, for the 3D view: the page's mesh table, one entry (or null) per row.
json WriteMeshScripts(const std::vector<Row>& rows, bool viewer, const fs::path& run_dir,
                      const fs::path& assets, const ViewerPageOptions& options,
                      ViewerPageResult& result) {
  json meshes = json::array();
  for (std::size_t i = 0; i < rows.size(); ++i)
    meshes.push_back(!viewer || rows[i].mesh.empty()
                         ? json(nullptr)
                         : WriteMeshScript(rows[i], i, run_dir, assets, options, result));
  return meshes;
}

// The tiles view's script beside the page when a row has tiles; empty (and a note) when none.
fs::path CopyTilesViewer(const std::vector<Row>& rows, const fs::path& assets,
                         const ViewerPageOptions& options, ViewerPageResult& result) {
  bool any_tiles = false;
  for (const Row& r : rows) any_tiles = any_tiles || !r.tileset.empty();
  if (!any_tiles) return {};
  fs::path tiles_script =
      options.tiles_viewer_script.empty() ? FindTilesViewerScript() : options.tiles_viewer_script;
  if (tiles_script.empty()) {
    result.notes.push_back("no view of 3D Tiles: imr-tiles-viewer.js not found (built with node "
                           "and tools/node's esbuild: tools/setup.sh; or set IMR_TILES_VIEWER_JS)");
    return {};
  }
  fs::create_directories(assets);
  WriteFileAtomically(assets / kTilesViewerName, ReadBytes(tiles_script, "the tiles view's script"));
  result.files.push_back(assets / kTilesViewerName);
  return tiles_script;
}

// Only imr's tile names (a leaf, tile_NNNNNN.glb, or a level of detail, lod_NNNNNN.glb, and its
// subtree's tileset, lod_NNNNNN.json), inside the run's tiles/ folder: the tileset is read, not
// trusted. The name of its script: without ".glb", a subtree's with "_tree".
std::string CheckTileUri(const std::string& u, const fs::path& tileset) {
  const std::string name = u.rfind("tiles/", 0) == 0 ? u.substr(6) : "";
  for (const std::string prefix : {"tile_", "lod_"})
    for (const std::string ext : {".glb", ".json"}) {
      if (ext == ".json" && prefix != "lod_") continue;
      if (name.size() == prefix.size() + 6 + ext.size() && name.rfind(prefix, 0) == 0 &&
          name.substr(prefix.size() + 6) == ext &&
          name.substr(prefix.size(), 6).find_first_not_of("0123456789") == std::string::npos)
        return name.substr(0, prefix.size() + 6) + (ext == ".json" ? "_tree" : "");
    }
  throw std::runtime_error(tileset.string() + ": content uri '" + JsonText(u) + "' is not a tile of imr");
}

// The content uris of a tileset, depth first as its children are listed, as paths from the run's
// output folder: tiles, levels of detail and their subtrees' tilesets (read from `output` and
// followed: their uris are relative to tiles/).
std::vector<std::string> TileUris(const json& ts, const fs::path& output, const fs::path& tileset) {
  std::vector<std::string> uris;
  std::list<json> trees;  // the subtrees read, while their tiles are walked
  std::set<std::string> read;
  std::vector<std::pair<const json*, std::string>> todo = {{&ts.at("root"), ""}};
  while (!todo.empty()) {
    const auto [t, base] = todo.back();
    todo.pop_back();
    if (t->contains("content")) {
      const std::string u = base + t->at("content").at("uri").get<std::string>();
      uris.push_back(u);
      if (u.size() > 5 && u.compare(u.size() - 5, 5, ".json") == 0) {
        CheckTileUri(u, tileset);
        if (!read.insert(u).second) throw std::runtime_error(tileset.string() + ": " + u + " is named twice");
        trees.push_back(json::parse(ReadBytes(output / u, "a tileset")));
        todo.push_back({&trees.back().at("root"), "tiles/"});
      }
    }
    if (t->contains("children"))
      for (const json& c : t->at("children")) todo.push_back({&c, base});
  }
  return uris;
}

// Row i's tileset and tiles as scripts, and its entry in the page's tiles table (null, with a
// note, when they are too large or cannot be read).
json WriteTileScripts(const Row& r, std::size_t i, const fs::path& run_dir, const fs::path& assets,
                      const ViewerPageOptions& options, ViewerPageResult& result) {
  try {
    const std::string text = ReadBytes(r.tileset, "a tileset");
    const std::vector<std::string> uris = TileUris(json::parse(text), r.output, r.tileset);
    std::uintmax_t bytes = 0;
    for (const std::string& u : uris) {
      CheckTileUri(u, r.tileset);
      bytes += fs::file_size(r.output / u);
    }
    if (bytes > options.max_tiles_bytes) {
      result.notes.push_back(r.name + ": no view of its tiles: " + std::to_string(bytes >> 20) +
                             " MiB of tiles, more than max_tiles_bytes");
      return nullptr;
    }
    const fs::path dir = assets / "tiles" / std::to_string(i);
    fs::create_directories(dir);
    auto put = [&](const std::string& path, const std::string& name, const std::string& data) {
      WriteFileAtomically(dir / (name + ".js"), "imrTileData(" + std::to_string(i) + "," + DumpJson(json(path)) +
                                                    ",\"" + Base64Encode(data) + "\");\n");
      result.files.push_back(dir / (name + ".js"));
    };
    put("tileset.json", "tileset", text);
    for (const std::string& u : uris)
      put(u, CheckTileUri(u, r.tileset), ReadBytes(r.output / u, "a tile"));
    ++result.tilesets_viewable;
    const json triangles = At(r.report, "/tiles/triangles");
    return {{"name", r.name},
            {"scripts", UrlPath(dir.lexically_relative(run_dir))},
            {"tiles", uris.size()},
            {"triangles", triangles.is_null() ? json("?") : triangles}};
  } catch (const std::exception& e) {
    result.notes.push_back(r.name + ": no view of its tiles: " + e.what());
    return nullptr;
  }
}

// The PNGs the page shows: the options' list, else every *.png in RUN_DIR and RUN_DIR/plots.
std::vector<fs::path> FindPlots(const fs::path& run_dir, const ViewerPageOptions& options,
                                ViewerPageResult& result) {
  std::vector<fs::path> plots;
  if (!options.plots.empty()) {
    for (const fs::path& p : options.plots) {
      const fs::path a = Absolute(p, run_dir);
      if (!fs::is_regular_file(a)) result.notes.push_back(a.string() + ": no such plot");
      else plots.push_back(a);
    }
    return plots;
  }
  for (const fs::path& dir : {run_dir, run_dir / "plots"}) {
    if (!fs::is_directory(dir)) continue;
    std::vector<fs::path> found;
    for (const auto& e : fs::directory_iterator(dir))
      if (e.is_regular_file() && Lower(e.path().extension().string()) == ".png" &&
          e.path().filename().string().front() != '.')
        found.push_back(e.path());
    std::sort(found.begin(), found.end());
    plots.insert(plots.end(), found.begin(), found.end());
  }
  return plots;
}

// What a page is made of, gathered before it is written.
struct PageParts {
  std::vector<Row> rows;
  std::vector<std::string> no_mesh;  // sequences with neither a .glb/.gltf mesh nor tiles
  bool viewer = false;               // <model-viewer> copied beside the page
  json meshes = json::array();       // per row: its 3D view, or null
  json tilesets = json::array();     // per row: the view of its tiles, or null
  std::vector<fs::path> plots;
};

std::string SubtitleHtml(const json& summary, const std::vector<Row>& rows) {
  std::ostringstream h;
  if (summary.contains("job") && summary["job"].is_string())
    h << "Job <code>" << HtmlEscape(summary["job"].get<std::string>()) << "</code> &middot; ";
  int ok = 0;
  for (const Row& r : rows) ok += r.ok ? 1 : 0;
  h << rows.size() << " sequence" << (rows.size() == 1 ? "" : "s") << ", " << ok << " ok, "
    << rows.size() - static_cast<std::size_t>(ok) << " not &middot; page written " << LocalTime();
  return h.str();
}

// Row i of the sequences table.
std::string RowHtml(const PageParts& parts, std::size_t i, const fs::path& run_dir) {
  const Row& r = parts.rows[i];
  std::ostringstream h;
  h << "<tr class=\"" << (r.ok ? "ok" : "failed") << "\"><td class=\"num\">" << i + 1 << "</td><td>"
    << HtmlEscape(r.name) << "</td><td class=\"" << (r.ok ? "status-ok" : "status-bad") << "\">"
    << HtmlEscape(r.status) << "</td><td class=\"num\">" << FramesCell(r) << "</td><td class=\"num\">"
    << (r.seconds ? FormatNumber(*r.seconds, "%.1f") : "") << "</td>";
  json vertices = At(r.report, "/mesh/vertices"), faces = At(r.report, "/mesh/faces");
  if (vertices.is_null()) vertices = At(r.row, "/mesh/vertices");
  if (faces.is_null()) faces = At(r.row, "/mesh/faces");
  h << "<td class=\"num\">" << (vertices.is_number() ? vertices.dump() : "") << "</td><td class=\"num\">"
    << (faces.is_number() ? faces.dump() : "") << "</td>";
  const json accuracy = AccuracyOf(r);
  const std::optional<double> mean = Accuracy(accuracy);
  h << "<td class=\"num\"" << (accuracy.is_null() ? "" : " title=\"" + HtmlEscape(accuracy.dump()) + "\"")
    << ">" << (mean ? FormatNumber(*mean, "%.4g") : "") << "</td>";
  h << "<td class=\"error\">" << HtmlEscape(r.error) << "</td><td>";
  std::vector<std::pair<std::string, fs::path>> links;
  if (!r.output.empty() && fs::is_regular_file(r.output / "report.json"))
    links.emplace_back("report", r.output / "report.json");
  if (!r.mesh.empty()) links.emplace_back(r.mesh.extension().string().substr(1), r.mesh);
  if (!r.tileset.empty()) links.emplace_back("tileset", r.tileset);
  for (std::size_t k = 0; k < links.size(); ++k)
    h << (k ? " " : "") << "<a href=\"" << HtmlEscape(UrlPath(links[k].second.lexically_relative(run_dir)))
      << "\">" << HtmlEscape(links[k].first) << "</a>";
  h << "</td><td>";
  if (!parts.meshes[i].is_null()) h << "<button data-mesh=\"" << i << "\">view</button>";
  if (!parts.tilesets[i].is_null()) h << " <button data-tiles=\"" << i << "\">tiles</button>";
  h << "</td></tr>\n";
  return h.str();
}

// The sections after the table: the mesh view (or why there is none), the tiles view, the
// plots, the notes.
std::string SectionsHtml(const PageParts& parts, const fs::path& run_dir,
                         const ViewerPageResult& result) {
  std::ostringstream h;
  if (parts.viewer && result.meshes_viewable > 0) {
    h << "<h2>Mesh</h2>\n<p id=\"viewer-status\">Loading ...</p>\n"
      << "<model-viewer id=\"viewer\" camera-controls interaction-prompt=\"none\" "
         "shadow-intensity=\"0\" exposure=\"1.1\" alt=\"the selected sequence's mesh\">"
         "</model-viewer>\n";
  } else if (parts.viewer && !parts.no_mesh.empty()) {
    // No empty, grey viewer that looks broken (issue 47): why there is no 3D view, and what
    // gives one.
    const std::size_t n = parts.no_mesh.size();
    h << "<h2>Mesh</h2>\n<p id=\"viewer-status\" class=\"note\">No 3D view: it shows .glb and "
         ".gltf meshes, and "
      << (n == 1 ? "this run" : std::to_string(n) + " sequences")
      << " wrote neither (the mesh files are linked in the table). Add \"glb\" to the job's "
         "output.formats (with imr mesh: --out NAME.glb) to see "
      << (n == 1 ? "it" : "them") << " here.</p>\n";
  } else if (parts.viewer && result.tilesets_viewable == 0) {
    h << "<h2>Mesh</h2>\n<p id=\"viewer-status\" class=\"note\">No mesh to show: no sequence "
         "finished with one.</p>\n";
  }
  if (result.tilesets_viewable > 0)
    h << "<h2>Tiles</h2>\n<p id=\"tiles-status\">Loading ...</p>\n<div id=\"tiles-viewer\"></div>\n";
  if (!parts.plots.empty()) {
    h << "<h2>Plots</h2>\n<div class=\"plots\">\n";
    for (const fs::path& p : parts.plots) {
      const fs::path rel = p.lexically_relative(run_dir);
      h << "<figure><img src=\"" << HtmlEscape(UrlPath(rel)) << "\" alt=\"" << HtmlEscape(p.stem().string())
        << "\"><figcaption>" << HtmlEscape(rel.generic_string()) << "</figcaption></figure>\n";
    }
    h << "</div>\n";
  }
  if (!result.notes.empty()) {
    h << "<h2>Notes</h2>\n<ul class=\"note\">\n";
    for (const std::string& n : result.notes) h << "<li>" << HtmlEscape(n) << "</li>\n";
    h << "</ul>\n";
  }
  return h.str();
}

// JSON for a <script type="application/json">: "</" cannot end the element early once escaped.
std::string ScriptJson(const json& j) {
  std::string text = DumpJson(j);
  for (std::size_t pos = 0; (pos = text.find("</", pos)) != std::string::npos; pos += 3)
    text.replace(pos, 2, "<\\/");
  return text;
}

// The page's template with each {{name}} replaced by values[name]; the values are not scanned
// again, so a title holding "{{" stays as it is. A name the template has and `values` has not
// (or a "{{" without "}}") is an error naming the template, so a template from another version
// of imr is refused rather than shown half filled.
std::string FillTemplate(const std::string& text, const fs::path& path,
                         const std::vector<std::pair<std::string, std::string>>& values) {
  std::string out;
  out.reserve(text.size());
  std::size_t at = 0;
  for (std::size_t open; (open = text.find("{{", at)) != std::string::npos;) {
    const std::size_t close = text.find("}}", open + 2);
    const std::string line = std::to_string(1 + std::count(text.begin(), text.begin() + static_cast<std::ptrdiff_t>(open), '\n'));
    if (close == std::string::npos)
      throw std::runtime_error(path.string() + ":" + line + ": \"{{\" without \"}}\"");
    const std::string name = text.substr(open + 2, close - open - 2);
    const auto v = std::find_if(values.begin(), values.end(), [&](const auto& p) { return p.first == name; });
    if (v == values.end())
      throw std::runtime_error(path.string() + ":" + line + ": unknown placeholder {{" + JsonText(name) + "}}");
    out.append(text, at, open - at);
    out += v->second;
    at = close + 2;
  }
  out.append(text, at, std::string::npos);
  return out;
}

// What the page's template may hold: {{title}} (escaped), {{head_scripts}} (<model-viewer>'s
// script element, or nothing), {{subtitle}}, {{rows}} (the sequences table's rows), {{sections}}
// (the mesh and tiles views, plots, notes), {{meshes_json}}, {{tiles_scripts}}.
constexpr const char* kPagePlaceholders[] = {"title", "head_scripts", "subtitle", "rows",
                                             "sections", "meshes_json", "tiles_scripts"};

// The page's template (viewer_page.html: the markup, style and script that never change), read
// before anything is written.
struct PageTemplate {
  fs::path path;
  std::string text;
};

PageTemplate ReadPageTemplate(const ViewerPageOptions& options) {
  const fs::path path = options.page_template.empty() ? FindViewerPageTemplate() : options.page_template;
  if (path.empty())
    throw std::runtime_error("the viewer page's template " + std::string(kPageTemplateName) +
                             " is not installed (share/imr beside the executables; or set "
                             "IMR_VIEWER_PAGE_TEMPLATE)");
  PageTemplate page{path, ReadBytes(path, "the viewer page's template")};
  std::vector<std::pair<std::string, std::string>> names;
  for (const char* name : kPagePlaceholders) names.emplace_back(name, "");
  FillTemplate(page.text, page.path, names);  // its placeholders checked before anything is written
  return page;
}

// The page: its template filled with the parts of this batch.
std::string PageHtml(const PageTemplate& page, const json& summary, const PageParts& parts,
                     const fs::path& run_dir, const ViewerPageOptions& options,
                     const ViewerPageResult& result) {
  std::string rows;
  for (std::size_t i = 0; i < parts.rows.size(); ++i) rows += RowHtml(parts, i, run_dir);
  const std::string title = HtmlEscape(summary.value("title", options.title));
  return FillTemplate(
      page.text, page.path,
      {{"title", title},
       {"head_scripts", parts.viewer ? "<script src=\"assets/" + std::string(kModelViewerName) + "\"></script>\n" : ""},
       {"subtitle", SubtitleHtml(summary, parts.rows)},
       {"rows", rows},
       {"sections", SectionsHtml(parts, run_dir, result)},
       {"meshes_json", ScriptJson(parts.meshes)},
       {"tiles_scripts", result.tilesets_viewable == 0 ? "" :
            "<script type=\"application/json\" id=\"imr-tiles\">" + ScriptJson(parts.tilesets) +
            "</script>\n<script src=\"assets/" + kTilesViewerName + "\"></script>\n"}});
}

}  // namespace

ViewerPageResult WriteBatchPage(const fs::path& run_dir_in, const json& summary,
                                const ViewerPageOptions& options) {
  if (const std::string p = options.Check(); !p.empty()) throw std::invalid_argument("viewer page options: " + p);
  if (!summary.is_object() || !summary.contains("sequences") || !summary["sequences"].is_array())
    throw std::invalid_argument("summary: expected an object with a \"sequences\" array");
  const fs::path run_dir = fs::absolute(run_dir_in).lexically_normal();
  if (!fs::is_directory(run_dir)) throw std::runtime_error(run_dir.string() + ": no such folder");
  ViewerPageResult result;
  result.page = run_dir / "index.html";
  const PageTemplate page = ReadPageTemplate(options);

  PageParts parts;
  for (std::size_t i = 0; i < summary["sequences"].size(); ++i)
    parts.rows.push_back(ReadRow(summary["sequences"][i], i, run_dir, &result.notes, &parts.no_mesh));
  if (!parts.no_mesh.empty()) result.info.push_back(NoMeshInfo(parts.no_mesh));
  const fs::path assets = run_dir / "assets";
  parts.viewer = CopyModelViewer(assets, options, result);
  parts.meshes = WriteMeshScripts(parts.rows, parts.viewer, run_dir, assets, options, result);
  const fs::path tiles_script = CopyTilesViewer(parts.rows, assets, options, result);
  for (std::size_t i = 0; i < parts.rows.size(); ++i)
    parts.tilesets.push_back(tiles_script.empty() || parts.rows[i].tileset.empty()
                                 ? json(nullptr)
                                 : WriteTileScripts(parts.rows[i], i, run_dir, assets, options, result));
  parts.plots = FindPlots(run_dir, options, result);
  WriteFileAtomically(result.page, PageHtml(page, summary, parts, run_dir, options, result));
  result.files.push_back(result.page);
  return result;
}

}  // namespace imr::report
