#include "host/pipeline/tiles.h"

#include "host/engine/mesh_topology.h"
#include "host/engine/simplify.h"
#include "host/eval/mesh_io.h"
#include "host/io/schema.h"
#include "host/pipeline/run.h"
#include "host/util/atomic_file.h"
#include "host/util/clock.h"
#include "host/util/input_file.h"
#include "host/util/json_text.h"
#include "host/util/write_rule.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <functional>
#include <iterator>
#include <list>
#include <numbers>
#include <regex>
#include <set>
#include <stdexcept>
#include <unordered_map>

namespace imr::pipeline {
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

constexpr int kChildrenPerNode = 8;  // the tileset's fan-out above the tiles
constexpr int kMaxTreeDepth = 64;     // imr's trees are log8(tiles) + 2 deep
constexpr double kTilesetSeconds = 5.0;  // tileset.json at least this often while tiles come
// The octree of the levels of detail counts cells from here. Anchored at the sequence's origin,
// where a drive starts, cells -1 and 0 would share no node below the top (a seam locked at every
// level through the middle of the surface); at binary 1010...101 the seam of level L nearest to
// the origin is 2^L / 3 cells away, as far as it can be at every level at once.
constexpr int64_t kLodOffset = ((int64_t{1} << kMaxLodLevel) - 1) / 3;
// A simplification step moves no vertex further than this many cells from the mesh it simplifies
// (Lindstrom-Turk's placement shot spikes of tens of metres off the surface's edge; measured in
// the geometric error, they were still spikes).
constexpr double kLodMaxStep = 0.25;

// "tiles/tile_000012.glb" -> 12; 0 when `uri` is not a tile name of imr.
int TileIndex(const std::string& uri) {
  if (uri.rfind("tiles/", 0) != 0 || uri.size() != 21) return 0;
  const std::string name = uri.substr(6);
  static const std::regex kTile("tile_[0-9]{6}\\.glb");
  if (!std::regex_match(name, kTile)) return 0;
  return std::stoi(name.substr(5, 6));
}

bool IsTileName(const std::string& name) {
  static const std::regex kTile("tile_[0-9]{6}\\.glb");
  return std::regex_match(name, kTile);
}

// "tiles/lod_000012.glb" -> 12 (a level of detail), and its subtree's tileset
// "tiles/lod_000012.json" -> 12; 0 when it is neither.
int LodIndex(const std::string& uri) {
  if (uri.rfind("tiles/", 0) != 0 || (uri.size() != 20 && uri.size() != 21)) return 0;
  const std::string name = uri.substr(6);
  static const std::regex kLod("lod_[0-9]{6}\\.(glb|json)");
  if (!std::regex_match(name, kLod)) return 0;
  return std::stoi(name.substr(4, 6));
}

bool IsJsonUri(const std::string& uri) { return uri.size() > 5 && uri.compare(uri.size() - 5, 5, ".json") == 0; }

bool IsLodName(const std::string& name) { return LodIndex("tiles/" + name) > 0; }

std::string LodStem(int index) {
  char stem[32];
  std::snprintf(stem, sizeof(stem), "lod_%06d", index);
  return stem;
}

std::string LodUri(int index) { return "tiles/" + LodStem(index) + ".glb"; }
std::string LodTreeUri(int index) { return "tiles/" + LodStem(index) + ".json"; }

// Per vertex: on an edge of one triangle only (the mesh's border: a seam with a neighbour's
// content, written or not yet, or the surface's own edge).
std::vector<char> BorderVertices(const engine::Mesh& m) {
  std::set<std::pair<uint32_t, uint32_t>> edges;
  for (std::size_t f = 0; f + 2 < m.faces.size(); f += 3)
    for (int k = 0; k < 3; ++k) edges.insert({m.faces[f + k], m.faces[f + (k + 1) % 3]});
  std::vector<char> border(m.vertices.size() / 3, 0);
  for (const auto& [a, b] : edges)
    if (!edges.count({b, a})) border[a] = border[b] = 1;
  return border;
}

// The centroids of a mesh's triangles, packed xyz (where a simplification's error is measured
// besides the vertices).
std::vector<double> Centroids(const engine::Mesh& m) {
  std::vector<double> c;
  c.reserve(m.faces.size());
  for (std::size_t f = 0; f + 2 < m.faces.size(); f += 3)
    for (int d = 0; d < 3; ++d)
      c.push_back((m.vertices[3 * m.faces[f] + d] + m.vertices[3 * m.faces[f + 1] + d] +
                   m.vertices[3 * m.faces[f + 2] + d]) / 3.0);
  return c;
}

std::array<double, 6> MeshBox(const engine::Mesh& m);

std::string TileStem(int index) {
  char stem[32];
  std::snprintf(stem, sizeof(stem), "tile_%06d", index);
  return stem;
}

std::string TileUri(int index) { return "tiles/" + TileStem(index) + ".glb"; }

// A number as a person writes it (1e-09, 0.5, 250), for messages.
std::string Number(double x) {
  char text[32];
  std::snprintf(text, sizeof(text), "%g", x);
  return text;
}

// The JSON chunk of a GLB file (its binary chunk is not read).
json GlbJson(const fs::path& path, InputRole role = InputRole::kInput) {
  // The open rule: a folder, a FIFO or a device named like a tile is refused by name.
  InputStream in(path, "a GLB tile", role);
  char header[20];
  if (!in.read(header, 20)) throw std::runtime_error(path.string() + ": not a GLB file (too short)");
  uint32_t magic, version, length, chunk_length, chunk_type;
  std::memcpy(&magic, header, 4);
  std::memcpy(&version, header + 4, 4);
  std::memcpy(&length, header + 8, 4);
  std::memcpy(&chunk_length, header + 12, 4);
  std::memcpy(&chunk_type, header + 16, 4);
  if (magic != 0x46546C67u || version != 2 || chunk_type != 0x4E4F534Au || chunk_length > length)
    throw std::runtime_error(path.string() + ": not a GLB 2.0 file with a JSON chunk");
  std::string text(chunk_length, '\0');
  if (!in.read(text.data(), chunk_length)) throw std::runtime_error(path.string() + ": truncated");
  try {
    return json::parse(text);
  } catch (const json::exception& e) {
    throw std::runtime_error(path.string() + ": its JSON chunk is not JSON: " + e.what());
  }
}

// Whether every triangle primitive of the GLB has the attribute.
bool EveryPrimitiveHas(const json& gltf, const std::string& attribute) {
  bool any = false;
  for (const json& mesh : gltf.value("meshes", json::array()))
    for (const json& p : mesh.value("primitives", json::array())) {
      if (!p.contains("attributes") || !p["attributes"].contains(attribute)) return false;
      any = true;
    }
  return any;
}

std::array<double, 6> EmptyBox() { return {1e300, 1e300, 1e300, -1e300, -1e300, -1e300}; }

std::array<double, 6> MeshBox(const engine::Mesh& m) {
  std::array<double, 6> box = EmptyBox();
  for (std::size_t i = 0; i < m.vertices.size(); ++i) {
    box[i % 3] = std::min(box[i % 3], m.vertices[i]);
    box[3 + i % 3] = std::max(box[3 + i % 3], m.vertices[i]);
  }
  return box;
}

void Grow(std::array<double, 6>* box, const std::array<double, 6>& other) {
  for (int k = 0; k < 3; ++k) {
    (*box)[k] = std::min((*box)[k], other[k]);
    (*box)[3 + k] = std::max((*box)[3 + k], other[3 + k]);
  }
}

double Diagonal(const std::array<double, 6>& b) {
  return std::hypot(b[3] - b[0], b[4] - b[1], b[5] - b[2]);
}

// A 3D Tiles box: centre, then three half axes (never flat: viewers divide by them).
json BoxJson(const std::array<double, 6>& b) {
  json box = json::array();
  for (int k = 0; k < 3; ++k) box.push_back((b[k] + b[3 + k]) / 2.0);
  for (int axis = 0; axis < 3; ++axis)
    for (int k = 0; k < 3; ++k) box.push_back(k == axis ? std::max((b[3 + k] - b[k]) / 2.0, 0.005) : 0.0);
  return {{"box", box}};
}

// Column-major 4x4 product a * b.
std::array<double, 16> Multiply(const std::array<double, 16>& a, const std::array<double, 16>& b) {
  std::array<double, 16> m{};
  for (int c = 0; c < 4; ++c)
    for (int r = 0; r < 4; ++r)
      for (int k = 0; k < 4; ++k) m[4 * c + r] += a[4 * k + r] * b[4 * c + k];
  return m;
}

}  // namespace

std::string TilesOrigin::Check() const {
  const auto within = [](double x, double lo, double hi) { return std::isfinite(x) && x >= lo && x <= hi; };
  if (!within(latitude, -90.0, 90.0))
    return "origin.latitude: expected degrees in [-90, 90], got " + Number(latitude);
  if (!within(longitude, -180.0, 180.0))
    return "origin.longitude: expected degrees in [-180, 180], got " + Number(longitude);
  if (!within(height, kMinOriginHeight, kMaxOriginHeight))
    return "origin.height: expected metres above the WGS84 ellipsoid in [" + Number(kMinOriginHeight) +
           ", " + Number(kMaxOriginHeight) + "], got " + Number(height);
  if (!std::isfinite(heading)) return "origin.heading: expected degrees clockwise from north, got " + Number(heading);
  return "";
}

json TilesOrigin::ToJson() const {
  json j = {{"latitude", latitude}, {"longitude", longitude}, {"height", height}, {"heading", heading},
            {"source", JsonText(source)}};
  if (enu_from_local) j["tilt"] = tilt;  // the input's attitude, not levelled
  return j;
}

const json& TilesOriginSchema() {
  static const json schema = {
      {"latitude", {{"type", "number"}, {"minimum", -90.0}, {"maximum", 90.0}, {"unit", "degrees"},
                    {"description", "WGS84 latitude of the local frame's origin (the sequence's "
                                    "0, 0, 0), north positive; required"}}},
      {"longitude", {{"type", "number"}, {"minimum", -180.0}, {"maximum", 180.0}, {"unit", "degrees"},
                     {"description", "WGS84 longitude of that origin, east positive; required"}}},
      {"height", {{"type", "number"}, {"minimum", kMinOriginHeight}, {"maximum", kMaxOriginHeight},
                  {"unit", "metres"},
                  {"description", "height of that origin above the WGS84 ellipsoid (not above sea "
                                  "level); required"}}},
      {"heading", {{"type", "number"}, {"unit", "degrees"},
                   {"description", "direction of the local frame's +Y (the cameras' mean viewing "
                                   "direction, level) clockwise from north; required"}}}};
  return schema;
}

std::string TilesOptions::Check() const {
  if (!std::isfinite(size) || size < 0.0) return "size: expected a length >= 0 (0: 10 x steiner_spacing)";
  if (max_triangles < kMinTileTriangles)
    return "max_triangles: expected >= " + std::to_string(kMinTileTriangles) + ", got " +
           std::to_string(max_triangles);
  if (idle_parts < 1) return "idle_parts: expected >= 1";
  if (origin.given) return origin.Check();
  return "";
}

std::string TilesOptions::CheckSize(double steiner_spacing) const {
  if (size == 0.0 || !(steiner_spacing > 0.0) || size >= steiner_spacing) return "";
  return "expected 0 (10 x engine.steiner_spacing) or a length >= engine.steiner_spacing as "
         "used (" + Number(steiner_spacing) + "), got " + Number(size) + ": a smaller cell cuts the "
         "surface into tiles of a triangle or two, each a file";
}

const json& TilesSchema() {
  static const json schema = {
      {"size", {{"type", "number"}, {"default", 0.0}, {"minimum", 0.0},
                {"description", "side of the grid cells tiles are cut from (the sequence's units, "
                                "metres); 0: 10 x the engine's steiner_spacing as used (50 m); "
                                "else at least steiner_spacing"}}},
      {"max_triangles", {{"type", "integer"}, {"default", 200000}, {"minimum", kMinTileTriangles},
                         {"description", "a cell's tile is written once it holds this many triangles "
                                         "(the cell then starts another; at least 100: a tile is a "
                                         "file and a viewer's request)"}}},
      {"idle_parts", {{"type", "integer"}, {"default", 2}, {"minimum", 1},
                      {"description", "a tile is written once this many parts of the surface in a "
                                      "row (the engine hands one out as the cameras move on) added "
                                      "nothing to it"}}},
      {"lod", {{"type", "boolean"}, {"default", true},
               {"description", "levels of detail: inner nodes of the tileset carry their children's "
                               "surface simplified (a quarter of the triangles a level), written as "
                               "the drive goes; false: full-resolution tiles only"}}}};
  return schema;
}

TilesOptions TilesOptionsFromJson(const json& tiles) {
  TilesOptions o;
  if (tiles.is_null() || (tiles.is_boolean() && !tiles.get<bool>())) return o;
  o.enabled = true;
  if (!tiles.is_object()) return o;
  o.size = tiles.value("size", o.size);
  o.max_triangles = tiles.value("max_triangles", o.max_triangles);
  o.idle_parts = tiles.value("idle_parts", o.idle_parts);
  o.lod = tiles.value("lod", o.lod);
  if (const auto g = tiles.find("origin"); g != tiles.end() && g->is_object()) {
    o.origin.given = true;
    o.origin.latitude = g->value("latitude", 0.0);
    o.origin.longitude = g->value("longitude", 0.0);
    o.origin.height = g->value("height", 0.0);
    o.origin.heading = g->value("heading", 0.0);
    o.origin.source = "output.tiles.origin";
  }
  return o;
}

std::string ForeignTiles(const fs::path& output_dir, const std::string& job, const std::string& sequence) {
  const std::string advice = "; give each job its own output folder (e.g. {job} in "
                             "output.directory), or remove it if it is not needed";
  std::error_code ec;
  const fs::path tileset = output_dir / "tileset.json", tiles = output_dir / "tiles";
  const bool has_tileset = fs::exists(tileset, ec);
  if (has_tileset) {
    json j;
    try {
      j = ReadTilesetFile(tileset, InputRole::kOwnOutput);
    } catch (const std::exception&) {
    }
    const json* imr = nullptr;
    if (j.is_object() && j.contains("asset") && j["asset"].is_object() && j["asset"].contains("extras") &&
        j["asset"]["extras"].is_object() && j["asset"]["extras"].contains("imr"))
      imr = &j["asset"]["extras"]["imr"];
    const bool ours = imr != nullptr && imr->is_object() && imr->value("job", "") == JsonText(job) &&
                      imr->value("sequence", "") == JsonText(sequence);
    if (!ours)
      return tileset.string() + ": not a tileset imr wrote for sequence '" + JsonText(sequence) +
             "' of " + JsonText(job) + ": imr would overwrite it" + advice;
  }
  if (fs::exists(tiles, ec) || fs::is_symlink(tiles, ec)) {
    if (!fs::is_directory(tiles, ec))
      return tiles.string() + ": not a folder: imr writes the tiles there";
    if (!has_tileset)
      for (const auto& e : fs::directory_iterator(tiles, ec))
        if (IsTileName(e.path().filename().string()) || IsLodName(e.path().filename().string()))
          return e.path().string() + ": a tile with no tileset.json of imr beside its folder: imr "
                 "would overwrite it" + advice;
  }
  return "";
}

// ---- TileWriter ---------------------------------------------------------------------------------

TileWriter::TileWriter(const TilesOptions& options, fs::path output_dir, json identity,
                       std::function<std::array<double, 16>()> local_frame, WriteTileGlb write,
                       OriginFor origin_for)
    : options_(options), output_dir_(std::move(output_dir)), tiles_dir_(output_dir_ / "tiles"),
      identity_(std::move(identity)), root_transform_fn_(std::move(local_frame)),
      origin_for_(std::move(origin_for)), write_(std::move(write)) {
  if (const std::string e = options_.Check(); !e.empty()) throw std::invalid_argument("output.tiles." + e);
  if (!(options_.size > 0.0)) throw std::invalid_argument("output.tiles.size: 0 must be resolved first");
  EnsureWritableDirectory(tiles_dir_);
  // An earlier run's tiles (this job's: ForeignTiles): those its tileset names and those it wrote
  // after its last version, as `imr tiles merge` takes them; other files of tile names are not
  // imr's and stay. What a killed run left staged goes too.
  std::vector<fs::path> old;
  std::error_code ec;
  if (fs::exists(tileset_path(), ec)) {
    RunTiles earlier;
    try {
      earlier = ListRunTiles(output_dir_, ReadTilesetFile(tileset_path(), InputRole::kOwnOutput),
                             InputRole::kOwnOutput);
    } catch (const std::runtime_error& e) {  // ReadTilesetFile's messages name the file already
      const std::string what = e.what();
      throw std::runtime_error(what.rfind(tileset_path().string(), 0) == 0 ? what
                                                                           : tileset_path().string() + ": " + what);
    }
    for (const auto* list : {&earlier.named, &earlier.after, &earlier.lod, &earlier.lod_trees, &earlier.lod_after})
      for (const std::string& uri : *list)
        if (fs::exists(fs::symlink_status(output_dir_ / uri, ec))) old.push_back(output_dir_ / uri);
  }
  for (const auto& e : fs::directory_iterator(tiles_dir_)) {
    const std::string name = e.path().filename().string();
    if (name.rfind(".imr-staging-", 0) == 0) old.push_back(e.path());
  }
  for (const fs::path& p : old) {
    if (p.filename().string().rfind(".imr-staging-", 0) == 0) {
      fs::remove_all(p, ec);
      if (ec) throw std::runtime_error(p.string() + ": cannot remove an earlier run's tile: " + ec.message());
    } else if (std::string why; !RemoveWrittenFile(p, &why)) {  // the write rule's removal
      throw WriteRefused(why + " (an earlier run's tile: imr removes only tiles it wrote)");
    }
  }
  root_transform_ = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
  local_frame_ = root_transform_;
  WriteTileset("running");
}

void TileWriter::Add(const engine::SurfacePart& part) {
  ++parts_;
  const double size = options_.size;
  for (std::size_t f = 0; f + 2 < part.faces.size(); f += 3) {
    double c[3] = {0, 0, 0};
    for (int k = 0; k < 3; ++k)
      for (int d = 0; d < 3; ++d) c[d] += part.vertices[3 * part.faces[f + k] + d] / 3.0;
    const Cell cell = {static_cast<int64_t>(std::floor(c[0] / size)),
                       static_cast<int64_t>(std::floor(c[1] / size)),
                       static_cast<int64_t>(std::floor(c[2] / size))};
    OpenTile& t = open_[cell];
    for (int k = 0; k < 3; ++k) {
      const uint32_t v = part.faces[f + k];
      const auto [it, fresh] = t.index.emplace(part.keys[v], static_cast<uint32_t>(t.keys.size()));
      if (fresh) {
        t.keys.push_back(part.keys[v]);
        t.mesh.vertices.insert(t.mesh.vertices.end(), &part.vertices[3 * v], &part.vertices[3 * v] + 3);
        t.mesh.point_ids.push_back(part.point_ids[v]);
      }
      if (options_.lod) {
        const auto vc = vertex_cells_.try_emplace(part.keys[v], VertexCells{cell, 0, 0, false}).first;
        if (fresh) ++vc->second.open_tiles;
        // The lowest level whose node holds both cells.
        int span = 0;
        for (int d = 0; d < 3; ++d) {
          const int64_t a = d == 0 ? std::get<0>(cell) : d == 1 ? std::get<1>(cell) : std::get<2>(cell);
          const Cell& f0 = vc->second.first;
          const int64_t b = d == 0 ? std::get<0>(f0) : d == 1 ? std::get<1>(f0) : std::get<2>(f0);
          int l = 0;
          while (l <= kMaxLodLevel && ((a + kLodOffset) >> l) != ((b + kLodOffset) >> l)) ++l;
          span = std::max(span, l);
        }
        vc->second.span = std::max(vc->second.span, span);
      }
      t.mesh.faces.push_back(it->second);
    }
    t.last_part = parts_;
    stats_.open_tiles_peak = std::max<int64_t>(stats_.open_tiles_peak, static_cast<int64_t>(open_.size()));
    if (static_cast<int64_t>(t.mesh.faces.size() / 3) >= options_.max_triangles) {
      Write(cell, t);
      open_.erase(cell);
    }
  }
  if (options_.lod)
    for (int64_t k : part.completed)
      if (const auto c = vertex_cells_.find(k); c != vertex_cells_.end()) {
        c->second.completed = true;
        if (c->second.open_tiles == 0 && c->second.unknown_in_nodes == 0) vertex_cells_.erase(c);
      }
  for (auto it = open_.begin(); it != open_.end();) {
    if (parts_ - it->second.last_part >= options_.idle_parts) {
      Write(it->first, it->second);
      it = open_.erase(it);
    } else {
      ++it;
    }
  }
  if (options_.lod) FlushNodes(false);
}

void TileWriter::Finish() {
  // No part comes after the last: every vertex is complete (the stream names none it keeps).
  for (auto& [key, cells] : vertex_cells_) cells.completed = true;
  for (auto& [cell, tile] : open_) Write(cell, tile);
  open_.clear();
  if (options_.lod) FlushNodes(true);
  const auto start = std::chrono::steady_clock::now();
  WriteTileset("complete");
  stats_.seconds += SecondsSince(start);
}

void TileWriter::MarkFailed(const std::string& error) noexcept {
  try {
    WriteTileset("failed", error);
  } catch (...) {  // the last tileset.json stays ("running": not complete either)
  }
}

void TileWriter::Write(const Cell& cell, OpenTile& t) {
  TileMesh tile;
  tile.origin = {(static_cast<double>(std::get<0>(cell)) + 0.5) * options_.size,
                 (static_cast<double>(std::get<1>(cell)) + 0.5) * options_.size,
                 (static_cast<double>(std::get<2>(cell)) + 0.5) * options_.size};
  tile.mesh = std::move(t.mesh);
  tile.keys = std::move(t.keys);
  const int written = WriteContent(tile);
  MaybeWriteTileset();
  if (options_.lod) {
    // Only its simplified content stays, in the parent node.
    const auto start = std::chrono::steady_clock::now();
    // What is known of where each vertex's triangles are: a vertex not completed yet may have
    // some in a cell no tile holds yet, and stays locked until a node holding it is flushed after
    // its completion (completions may come parts after a tile is written).
    std::vector<int> spans(tile.keys.size(), kMaxLodLevel + 1);
    for (std::size_t v = 0; v < spans.size(); ++v) {
      const auto c = vertex_cells_.find(tile.keys[v]);
      if (c == vertex_cells_.end()) continue;
      if (c->second.completed) spans[v] = c->second.span;
      if (--c->second.open_tiles == 0 && c->second.completed && c->second.unknown_in_nodes == 0)
        vertex_cells_.erase(c);
    }
    PushUp(1, cell, tile.mesh, tile.keys, spans, {written}, static_cast<int64_t>(tile.mesh.faces.size() / 3), 0.0);
    const double s = SecondsSince(start);
    stats_.lod_seconds += s;
    stats_.seconds += s;
  }
}

int TileWriter::WriteContent(TileMesh& tile) {
  const auto start = std::chrono::steady_clock::now();
  if (!have_root_transform_) {
    if (root_transform_fn_) local_frame_ = root_transform_fn_();
    TilesOrigin origin = options_.origin;
    if (!origin.given && origin_for_) origin = origin_for_(local_frame_);
    if (origin.given) {
      if (const std::string e = origin.Check(); !e.empty())
        throw std::runtime_error(origin.source + ": " + e);
      stats_.origin = origin.ToJson();
      root_transform_ = GeoreferencedFrame(origin, local_frame_);
    } else {
      root_transform_ = local_frame_;
    }
    have_root_transform_ = true;
  }
  const bool leaf = tile.level == 0;
  if ((leaf ? stats_.tiles : stats_.lod_tiles) >= kMaxTiles)
    throw std::runtime_error("output.tiles: more than " + std::to_string(kMaxTiles) + " tiles, more "
                             "than imr tiles merge reads: choose a larger size or max_triangles");
  tile.index = static_cast<int>(leaf ? stats_.tiles : stats_.lod_tiles) + 1;
  tile.box = MeshBox(tile.mesh);
  const std::string stem = leaf ? TileStem(tile.index) : LodStem(tile.index);
  StagingDirectory staging(tiles_dir_);
  write_(tile, staging.path(), stem);
  const fs::path staged = staging.path() / (stem + ".glb");
  if (!fs::exists(staged)) throw std::runtime_error(staged.string() + ": the exporter wrote no GLB");
  if (!EveryPrimitiveHas(GlbJson(staged, InputRole::kOwnOutput), "_VERTEX_KEY"))
    throw std::runtime_error(staged.string() + ": the exporter wrote the tile without `_VERTEX_KEY`: "
                             "tiles need an exporter that writes vertex keys (SDK 1.2; "
                             "org.imr.exporter.assimp 1.2 does), or they cannot be merged");
  const fs::path final_path = tiles_dir_ / (stem + ".glb");
  // The earlier run's tiles are gone (the constructor): a file here is not imr's.
  std::error_code ec;
  if (fs::exists(fs::symlink_status(final_path, ec)))
    throw std::runtime_error(final_path.string() + ": a file that no tileset of this run names is "
                             "where imr writes tile " + std::to_string(tile.index) + ": imr would "
                             "overwrite it; move it away");
  staging.Commit();
  const auto bytes = static_cast<int64_t>(fs::file_size(final_path));
  const auto triangles = static_cast<int64_t>(tile.mesh.faces.size() / 3);
  if (leaf) {
    stats_.bytes += bytes;
    ++stats_.tiles;
    stats_.triangles += triangles;
    stats_.vertices += static_cast<int64_t>(tile.keys.size());
  } else {
    stats_.lod_bytes += bytes;
    ++stats_.lod_tiles;
    stats_.lod_triangles += triangles;
  }
  if (static_cast<int>(stats_.tiles_per_level.size()) <= tile.level) stats_.tiles_per_level.resize(tile.level + 1, 0);
  ++stats_.tiles_per_level[tile.level];
  written_.push_back({"tiles/" + stem + ".glb", tile.box, triangles, tile.level, tile.geometric_error, {}, false});
  stats_.seconds += SecondsSince(start);
  return static_cast<int>(written_.size()) - 1;
}

// Called once what was written last is whole on disk (a level of detail: its subtree too), so
// that no version of tileset.json names a file not there yet. Rewritten when the tiles since its
// last version are a quarter of those it names (or time has passed): O(1) bytes per tile in all,
// where every tile would make it O(tiles^2).
void TileWriter::MaybeWriteTileset() {
  const auto start = std::chrono::steady_clock::now();
  const std::size_t since = written_.size() - tileset_names_;
  if (since >= std::max<std::size_t>(1, tileset_names_ / 4) || SecondsSince(tileset_time_) >= kTilesetSeconds)
    WriteTileset("running");
  stats_.seconds += SecondsSince(start);
}

void TileWriter::PushUp(int level, const Cell& cell, const engine::Mesh& mesh, const std::vector<int64_t>& keys,
                        const std::vector<int>& spans, std::vector<int> children, int64_t triangles,
                        double error) {
  if (level > kMaxLodLevel) return;  // the children stay at the top of the tree
  // The child's content simplified to a quarter, its seams locked (the vertices of its border
  // with triangles in another node of its level, which locks them too), before it waits for its
  // siblings: never a full-resolution copy. The surface's own edge may move.
  std::vector<char> locked = BorderVertices(mesh);
  for (std::size_t v = 0; v < locked.size(); ++v) locked[v] = locked[v] && spans[v] > level - 1;
  const engine::SimplifiedMesh s =
      engine::SimplifyMesh(mesh, locked, std::max<int64_t>(1, triangles / 4), kLodMaxStep * options_.size);
  const NodeKey key = {level, (std::get<0>(cell) + kLodOffset) >> level, (std::get<1>(cell) + kLodOffset) >> level,
                       (std::get<2>(cell) + kLodOffset) >> level};
  PendingNode& node = pending_[key];
  std::vector<uint32_t> local(s.source.size());
  for (std::size_t v = 0; v < s.source.size(); ++v) {
    const int64_t k = keys[s.source[v]];
    const auto [it, fresh] = node.index.emplace(k, static_cast<uint32_t>(node.keys.size()));
    const int span = spans[s.source[v]];
    if (fresh) {
      node.keys.push_back(k);
      node.spans.push_back(span);
      node.mesh.vertices.insert(node.mesh.vertices.end(), &s.mesh.vertices[3 * v], &s.mesh.vertices[3 * v] + 3);
      node.mesh.point_ids.push_back(s.mesh.point_ids[v]);
      if (span > kMaxLodLevel) CountUnknownSpan(k, +1);
    } else if (node.spans[it->second] > kMaxLodLevel && span <= kMaxLodLevel) {
      node.spans[it->second] = span;  // known since (completed): the same for every copy
      CountUnknownSpan(k, -1);
    }
    local[v] = it->second;
  }
  for (uint32_t f : s.mesh.faces) node.mesh.faces.push_back(local[f]);
  node.children.insert(node.children.end(), children.begin(), children.end());
  node.child_triangles += triangles;
  node.child_error = std::max(node.child_error, error + s.error);
  int64_t held = 0;
  for (const auto& [k, n] : pending_) held += static_cast<int64_t>(n.mesh.faces.size() / 3);
  stats_.lod_pending_triangles_peak = std::max(stats_.lod_pending_triangles_peak, held);
}

void TileWriter::FlushNodes(bool all) {
  const auto start = std::chrono::steady_clock::now();
  const double seconds_before = stats_.seconds;  // WriteContent counts its own
  // pending_ is ordered by level: a node flushed goes up into a later entry (seen in this pass or,
  // when it lands before the next one of the level above, in the next).
  do {
    for (auto it = pending_.begin(); it != pending_.end();) {
      const auto [level, x, y, z] = it->first;
      bool ready = true;
      if (!all) {
        // The drive has left its region: no open tile in it or next to it.
        const int64_t span = int64_t{1} << level;  // its side in cells
        const int64_t lo[3] = {x * span - kLodOffset - 1, y * span - kLodOffset - 1, z * span - kLodOffset - 1};
        const int64_t hi[3] = {(x + 1) * span - kLodOffset, (y + 1) * span - kLodOffset, (z + 1) * span - kLodOffset};
        for (const auto& [c, t] : open_) {
          const int64_t p[3] = {std::get<0>(c), std::get<1>(c), std::get<2>(c)};
          if (p[0] >= lo[0] && p[0] <= hi[0] && p[1] >= lo[1] && p[1] <= hi[1] && p[2] >= lo[2] && p[2] <= hi[2]) {
            ready = false;
            break;
          }
        }
      }
      // No node below it waiting, at the end too: one flushed in this pass may have gone up into a
      // node behind the loop's place, and flushed now this one would be a second node of its key.
      for (auto below = pending_.begin(); ready && below != it; ++below) {
        const auto [l, a, b, c] = below->first;
        if (l < level && (a >> (level - l)) == x && (b >> (level - l)) == y && (c >> (level - l)) == z) ready = false;
      }
      if (ready) {
        PendingNode node = std::move(it->second);
        const NodeKey key = it->first;
        it = pending_.erase(it);
        // At the end, the last node waiting is the top of the tree: nothing comes above it.
        FlushNode(key, node, all && pending_.empty());
      } else {
        ++it;
      }
    }
  } while (all && !pending_.empty());
  const double s = SecondsSince(start);
  stats_.lod_seconds += s;
  stats_.seconds = seconds_before + s;
}

void TileWriter::CountUnknownSpan(int64_t key, int delta) {
  const auto c = vertex_cells_.find(key);
  if (c == vertex_cells_.end()) return;
  c->second.unknown_in_nodes += delta;
  if (c->second.unknown_in_nodes == 0 && c->second.open_tiles == 0 && c->second.completed) vertex_cells_.erase(c);
}

void TileWriter::FlushNode(const NodeKey& key, PendingNode& node, bool top) {
  const auto [level, x, y, z] = key;
  // Spans unknown when the content came up: known now if the vertex was completed since (its
  // entry is kept while this node names it; released once the content has gone up).
  std::vector<int64_t> unknown;
  for (std::size_t v = 0; v < node.keys.size(); ++v) {
    if (node.spans[v] <= kMaxLodLevel) continue;
    unknown.push_back(node.keys[v]);
    if (const auto c = vertex_cells_.find(node.keys[v]); c != vertex_cells_.end() && c->second.completed)
      node.spans[v] = c->second.span;
  }
  struct Release {  // on every way out, after the content went up (PushUp counts its own)
    TileWriter* w;
    const std::vector<int64_t>& keys;
    ~Release() {
      for (int64_t k : keys) w->CountUnknownSpan(k, -1);
    }
  } release{this, unknown};
  // The seams between the children are inside now: only the node's own border stays locked.
  const int64_t target = std::max<int64_t>(1, node.child_triangles / 4);
  std::vector<char> locked = BorderVertices(node.mesh);
  for (std::size_t v = 0; v < locked.size(); ++v) locked[v] = locked[v] && node.spans[v] > level;
  engine::SimplifiedMesh s = engine::SimplifyMesh(node.mesh, locked, target, kLodMaxStep * options_.size);
  // Measured on the merged children's vertices (SimplifyMesh) and their triangles' centroids.
  const double merged_error = std::max(s.error, engine::MaxDistanceToMesh(Centroids(node.mesh), s.mesh));
  const double error = node.child_error + merged_error;
  std::vector<int64_t> keys(s.source.size());
  std::vector<int> spans(s.source.size());
  for (std::size_t v = 0; v < keys.size(); ++v) {
    keys[v] = node.keys[s.source[v]];
    spans[v] = node.spans[s.source[v]];
  }
  const auto triangles = static_cast<int64_t>(s.mesh.faces.size() / 3);
  const Cell cell = {(x << level) - kLodOffset, (y << level) - kLodOffset, (z << level) - kLodOffset};
  const double share = static_cast<double>(triangles) / static_cast<double>(std::max<int64_t>(1, node.child_triangles));
  const bool worth = share <= kMaxLodShare ||
                     (static_cast<int>(node.children.size()) >= kLodManyChildren && share <= kMaxLodShareMany);
  // The top node is written however small: gathered, its children would hang at the top of the
  // tree and a view from far would ask for each of them (a simpler surface, e.g. without its
  // specks, makes a smaller top).
  const bool too_small = triangles < kMinTileTriangles && !(top && node.children.size() >= 2);
  if (too_small || !worth) {
    // Too small a tile, or hardly simpler than its children: not written; its children hang
    // under the next node up and its content goes up in its place.
    ++stats_.lod_gathered;
    PushUp(level + 1, cell, s.mesh, keys, spans, std::move(node.children), triangles, error);
    return;
  }
  TileMesh tile;
  tile.level = level;
  tile.geometric_error = error;
  const double side = options_.size * static_cast<double>(int64_t{1} << level);
  const double shift = static_cast<double>(kLodOffset) * options_.size;
  tile.origin = {(static_cast<double>(x) + 0.5) * side - shift, (static_cast<double>(y) + 0.5) * side - shift,
                 (static_cast<double>(z) + 0.5) * side - shift};
  tile.mesh = std::move(s.mesh);
  tile.keys = std::move(keys);
  const int index = WriteContent(tile);
  // Its bounding volume holds its children's too.
  for (int c : node.children) {
    written_[c].has_parent = true;
    Grow(&written_[index].box, written_[c].box);
  }
  written_[index].children = std::move(node.children);
  WriteLodTree(index);
  MaybeWriteTileset();
  PushUp(level + 1, cell, tile.mesh, tile.keys, spans, {index}, triangles, error);
}

// A level of detail's subtree as a tileset of its own (an external tileset, written once: its
// children are final), so that tileset.json names it in one tile and its rewrite stays the size
// of the tiles and nodes not yet under a written level of detail, not the drive's.
void TileWriter::WriteLodTree(int index) {
  const Written& w = written_[index];
  const std::string stem = LodStem(LodIndex(w.uri));
  json root = {{"boundingVolume", BoxJson(w.box)},
               {"geometricError", w.error},
               {"refine", "REPLACE"},
               {"content", {{"uri", stem + ".glb"}}},
               {"children", json::array()}};
  for (int c : w.children) {
    const Written& child = written_[c];
    // Beside it in tiles/: a leaf's GLB, or a level of detail's own subtree.
    const std::string uri = child.level > 0 ? LodStem(LodIndex(child.uri)) + ".json"
                                            : fs::path(child.uri).filename().string();
    root["children"].push_back({{"boundingVolume", BoxJson(child.box)},
                                {"geometricError", child.error},
                                {"content", {{"uri", uri}}}});
  }
  const json tree = {{"asset", {{"version", "1.1"}, {"generator", std::string("imr ") + Version()}}},
                     {"geometricError", w.error},
                     {"root", root}};
  const fs::path path = tiles_dir_ / (stem + ".json");
  std::error_code ec;
  if (fs::exists(fs::symlink_status(path, ec)))
    throw std::runtime_error(path.string() + ": a file that no tileset of this run names is where imr "
                             "writes a level of detail's subtree: imr would overwrite it; move it away");
  const std::string text = DumpJson(tree, 1) + "\n";
  WriteFileAtomically(path, text);
  stats_.lod_tree_bytes += static_cast<int64_t>(text.size());
}

void TileWriter::WriteTileset(const std::string& state, const std::string& error) {
  struct Node {
    json j;
    std::array<double, 6> box;
  };
  // A written tile, or a level of detail's subtree as the external tileset it was written to
  // (WriteLodTree): what is named here is the tiles and nodes no written node holds yet.
  auto subtree = [&](const Written& w) {
    if (w.level == 0)
      return json{{"boundingVolume", BoxJson(w.box)}, {"geometricError", w.error}, {"content", {{"uri", w.uri}}}};
    // "REPLACE": the subtree's root (the same error) stands for this tile; under "ADD" viewers
    // (3d-tiles-renderer, as CesiumJS) skip a child whose parent meets the error target already,
    // and this tile draws nothing itself.
    return json{{"boundingVolume", BoxJson(w.box)},
                {"geometricError", w.error},
                {"refine", "REPLACE"},
                {"content", {{"uri", LodTreeUri(LodIndex(w.uri))}}}};
  };
  std::vector<Node> level;
  for (const Written& w : written_)
    if (!w.has_parent) level.push_back({subtree(w), w.box});
  // Groups of kChildrenPerNode in writing order (along the drive: near each other), upward.
  while (level.size() > static_cast<std::size_t>(kChildrenPerNode)) {
    std::vector<Node> up;
    for (std::size_t i = 0; i < level.size(); i += kChildrenPerNode) {
      Node n{{{"refine", "ADD"}, {"children", json::array()}}, EmptyBox()};
      double children_error = 0.0;
      for (std::size_t k = i; k < std::min(level.size(), i + kChildrenPerNode); ++k) {
        Grow(&n.box, level[k].box);
        children_error = std::max(children_error, level[k].j["geometricError"].get<double>());
        n.j["children"].push_back(std::move(level[k].j));
      }
      n.j["boundingVolume"] = BoxJson(n.box);
      // Never below its children's (3D Tiles: a parent's error is at least theirs).
      n.j["geometricError"] = std::max(Diagonal(n.box), children_error);
      up.push_back(std::move(n));
    }
    level = std::move(up);
  }
  std::array<double, 6> box = EmptyBox();
  double top_error = 0.0;
  for (const Node& n : level) {
    Grow(&box, n.box);
    top_error = std::max(top_error, n.j["geometricError"].get<double>());
  }
  if (level.empty()) box = {-0.5, -0.5, -0.5, 0.5, 0.5, 0.5};
  top_error = std::max(top_error, Diagonal(box));
  json root = {{"transform", root_transform_},
               {"boundingVolume", BoxJson(box)},
               {"geometricError", top_error},
               {"refine", "ADD"},
               {"children", json::array()}};
  for (Node& n : level) root["children"].push_back(std::move(n.j));
  json imr = identity_;
  imr["complete"] = state == "complete";
  imr["state"] = state;
  if (!error.empty()) imr["error"] = JsonText(error);
  // The leaves (what `imr tiles merge` merges); the levels of detail apart.
  imr["tiles"] = stats_.tiles;
  imr["triangles"] = stats_.triangles;
  if (options_.lod) imr["lod_tiles"] = stats_.lod_tiles;
  // Geo-referenced: where, and the frame before it (what the transform is without an origin).
  if (!stats_.origin.is_null()) {
    imr["origin"] = stats_.origin;
    imr["local_transform"] = local_frame_;
  }
  const json tileset = {
      {"asset", {{"version", "1.1"}, {"generator", std::string("imr ") + Version()}, {"extras", {{"imr", imr}}}}},
      {"geometricError", top_error},
      {"root", root}};
  const std::string text = DumpJson(tileset, 1) + "\n";
  WriteFileAtomically(tileset_path(), text);
  ++stats_.tileset_writes;
  stats_.tileset_bytes += static_cast<int64_t>(text.size());
  tileset_names_ = written_.size();
  tileset_time_ = std::chrono::steady_clock::now();
}

std::vector<fs::path> TileWriter::files() const {  // leaves and levels of detail
  std::vector<fs::path> out;
  for (const Written& w : written_) out.push_back(output_dir_ / w.uri);
  out.push_back(tileset_path());
  return out;
}

std::array<double, 16> TilesetFrame(const std::vector<std::array<double, 9>>& rotations) {
  std::array<double, 3> up{}, forward{};
  for (const auto& r : rotations) {
    bool finite = true;
    for (double x : r) finite = finite && std::isfinite(x);
    if (!finite) continue;
    for (int k = 0; k < 3; ++k) {
      up[k] -= r[3 + k];       // the camera's y axis (image down) in world coordinates
      forward[k] += r[6 + k];  // its viewing direction
    }
  }
  std::array<double, 16> m = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
  const double n = std::hypot(up[0], up[1], up[2]);
  if (!(n > 1e-9)) return m;
  for (double& x : up) x /= n;
  const double along = forward[0] * up[0] + forward[1] * up[1] + forward[2] * up[2];
  for (int k = 0; k < 3; ++k) forward[k] -= along * up[k];
  if (!(std::hypot(forward[0], forward[1], forward[2]) > 1e-9))
    forward = std::fabs(up[0]) < 0.9 ? std::array<double, 3>{0, -up[2], up[1]}
                                     : std::array<double, 3>{up[2], 0, -up[0]};  // up x (1,0,0) / (0,1,0)
  const double fn = std::hypot(forward[0], forward[1], forward[2]);
  for (double& x : forward) x /= fn;
  const std::array<double, 3> x = {forward[1] * up[2] - forward[2] * up[1],
                                   forward[2] * up[0] - forward[0] * up[2],
                                   forward[0] * up[1] - forward[1] * up[0]};  // Y x Z
  // Rows X, Y, Z (world -> local), column-major.
  for (int col = 0; col < 3; ++col) {
    m[4 * col + 0] = x[col] + 0.0;
    m[4 * col + 1] = forward[col] + 0.0;
    m[4 * col + 2] = up[col] + 0.0;
  }
  return m;
}

std::array<double, 16> GeoreferencedFrame(const TilesOrigin& origin, const std::array<double, 16>& local_frame) {
  // ENU <- local: +Y at `heading` clockwise from north, +X to its right, +Z up (column-major).
  const double h = origin.heading * std::numbers::pi / 180.0;
  const double c = std::cos(h), s = std::sin(h);
  std::array<double, 16> turn = {c, -s, 0, 0, s, c, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
  if (origin.enu_from_local)
    for (int r = 0; r < 3; ++r)
      for (int k = 0; k < 3; ++k) turn[4 * k + r] = (*origin.enu_from_local)[3 * r + k];
  const std::array<double, 16> enu =
      geo::EcefFromEnu({origin.latitude, origin.longitude, origin.height});
  return Multiply(enu, Multiply(turn, local_frame));
}

TilesOrigin OriginFromAnchor(const geo::GeoAnchor& anchor, const std::array<double, 16>& local_frame) {
  // The local axes in the sequence's frame (rows of local <- sequence), then in ENU: the columns
  // of ENU <- local.
  std::array<double, 9> enu_from_local{};
  for (int r = 0; r < 3; ++r)
    for (int axis = 0; axis < 3; ++axis)
      for (int j = 0; j < 3; ++j)
        enu_from_local[3 * r + axis] += anchor.enu_from_world[3 * r + j] * local_frame[4 * j + axis];
  const std::array<double, 3> forward = {enu_from_local[1], enu_from_local[4], enu_from_local[7]};
  const std::array<double, 3> up = {enu_from_local[2], enu_from_local[5], enu_from_local[8]};
  TilesOrigin o;
  o.given = true;
  o.latitude = anchor.origin.latitude;
  o.longitude = anchor.origin.longitude;
  o.height = anchor.origin.height;
  // atan2(east, north): clockwise from north, in (-180, 180].
  o.heading = std::atan2(forward[0], forward[1]) * 180.0 / std::numbers::pi;
  o.source = anchor.source;
  o.enu_from_local = enu_from_local;
  o.tilt = std::acos(std::clamp(up[2] / std::hypot(up[0], up[1], up[2]), -1.0, 1.0)) * 180.0 / std::numbers::pi;
  return o;
}

std::array<double, 9> TileGltfRotation() { return {1, 0, 0, 0, 0, 1, 0, -1, 0}; }

std::vector<std::string> TileContentUris(const fs::path& run, const json& tile, InputRole role,
                                         std::vector<std::string>* subtrees) {
  std::vector<std::string> out;
  struct Todo {
    const json* tile;
    int depth;
    std::string where;
    std::string base;  // where its uris are relative to, from the run folder ("" or "tiles/")
  };
  std::vector<Todo> todo = {{&tile, 0, "root", ""}};
  // The external tilesets read (a level of detail's subtree each), kept while their tiles are
  // walked; each read once (a subtree naming itself is refused, not followed).
  std::list<json> trees;
  std::set<std::string> read;
  int64_t tiles = 0;
  while (!todo.empty()) {
    const Todo t = std::move(todo.back());
    todo.pop_back();
    if (!t.tile->is_object())
      throw std::runtime_error(t.where + ": expected a tile (an object), got " + io::Describe(*t.tile));
    if (t.depth > kMaxTreeDepth)
      throw std::runtime_error(t.where + ": the tree is more than " + std::to_string(kMaxTreeDepth) +
                               " levels deep (imr's are a few)");
    if (++tiles > 4 * kMaxTiles)
      throw std::runtime_error("more than " + std::to_string(4 * kMaxTiles) + " tiles in the tree (a "
                               "run of imr writes at most " + std::to_string(kMaxTiles) + ")");
    if (const auto c = t.tile->find("content"); c != t.tile->end()) {
      if (!c->is_object() || !c->contains("uri") || !(*c)["uri"].is_string())
        throw std::runtime_error(t.where + ".content: expected {\"uri\": \"...\"}, got " + io::Describe(*c));
      const std::string uri = t.base + (*c)["uri"].get<std::string>();
      if (IsJsonUri(uri)) {
        // Only imr's own subtrees are followed: tiles/lod_NNNNNN.json, nowhere else.
        if (LodIndex(uri) <= 0)
          throw std::runtime_error(t.where + ".content: '" + JsonText(uri) + "' is not a tileset of imr "
                                   "(a level of detail's subtree is tiles/lod_NNNNNN.json)");
        if (!read.insert(uri).second)
          throw std::runtime_error(t.where + ".content: '" + uri + "' is named twice in the tree");
        if (subtrees != nullptr) subtrees->push_back(uri);
        trees.push_back(ReadTilesetFile(run / uri, role));
        const json& tree = trees.back();
        if (!tree.is_object() || !tree.contains("root"))
          throw std::runtime_error((run / uri).string() + ": a tileset with no root tile");
        todo.push_back({&tree["root"], t.depth + 1, uri + ": root", "tiles/"});
      } else {
        out.push_back(uri);
      }
      if (static_cast<int64_t>(out.size()) > 2 * kMaxTiles)
        throw std::runtime_error("more than " + std::to_string(2 * kMaxTiles) + " tiles (a run of imr "
                                 "writes at most " + std::to_string(kMaxTiles) + " and as many levels "
                                 "of detail)");
    }
    if (const auto c = t.tile->find("children"); c != t.tile->end()) {
      if (!c->is_array())
        throw std::runtime_error(t.where + ".children: expected an array, got " + io::Describe(*c));
      for (std::size_t k = c->size(); k-- > 0;)
        todo.push_back({&(*c)[k], t.depth + 1, t.where + ".children[" + std::to_string(k) + "]", t.base});
    }
  }
  return out;
}

json ReadTilesetFile(const fs::path& path, InputRole role) {
  std::error_code ec;
  if (fs::status(path, ec).type() == fs::file_type::not_found)
    throw std::runtime_error(path.string() + ": no such file: not the output folder of a run with "
                             "tiles (a job with output.tiles writes one)");
  // The open rule: a FIFO, a device (a link to /dev/zero) or a folder is refused by name.
  InputFile file = InputFile::Open(
      path, role == InputRole::kInput ? "the tileset.json of a run with tiles" : "a tileset.json of imr",
      role);
  if (file.size() > kMaxTilesetBytes)
    throw std::runtime_error(path.string() + ": " + std::to_string(file.size()) + " bytes, more than the " +
                             std::to_string(kMaxTilesetBytes >> 20) + " MiB a tileset of imr may have "
                             "(at most " + std::to_string(kMaxTiles) + " tiles)");
  // At most kMaxTilesetBytes + 1 bytes, whatever the size said (a file growing meanwhile).
  const std::string text = file.ReadUpTo(kMaxTilesetBytes + 1);
  if (text.size() > kMaxTilesetBytes)
    throw std::runtime_error(path.string() + ": more than the " + std::to_string(kMaxTilesetBytes >> 20) +
                             " MiB a tileset of imr may have");
  try {
    return json::parse(text);
  } catch (const json::exception& e) {
    throw std::runtime_error(path.string() + ": not JSON: " + e.what());
  }
}

RunTiles ListRunTiles(const fs::path& run, const json& tileset, InputRole role) {
  RunTiles out;
  if (tileset.is_object() && tileset.contains("root"))
    for (std::string& uri : TileContentUris(run, tileset["root"], role, &out.lod_trees))
      (LodIndex(uri) > 0 ? out.lod : out.named).push_back(std::move(uri));
  std::set<int> named, named_lod;
  int highest = 0, highest_lod = 0;
  for (const std::string& uri : out.named) {
    named.insert(TileIndex(uri));
    highest = std::max(highest, TileIndex(uri));
  }
  for (const std::string& uri : out.lod) {
    named_lod.insert(LodIndex(uri));
    highest_lod = std::max(highest_lod, LodIndex(uri));
  }
  std::set<int> on_disk, lod_on_disk;
  std::error_code ec;
  if (fs::is_directory(run / "tiles", ec))
    for (const auto& e : fs::directory_iterator(run / "tiles", ec)) {
      const std::string uri = "tiles/" + e.path().filename().string();
      if (const int i = TileIndex(uri); i > 0 && !named.count(i)) on_disk.insert(i);
      if (const int i = LodIndex(uri); i > 0 && !named_lod.count(i)) lod_on_disk.insert(i);
    }
  // The writer numbers tiles 1, 2, ... and names them in order: what follows the highest it
  // names without a gap was written after it. Levels of detail the same way, numbered apart.
  // A level of detail is its GLB and its subtree's tileset (written right after it): both, as
  // far as they are there.
  auto written_after = [&](const std::set<int>& found, int highest_named,
                           std::vector<std::string (*)(int)> uris, std::vector<std::string>* after) {
    int next = highest_named + 1;
    for (int i : found) {
      const bool ours = i == next;
      if (ours) ++next;
      for (auto uri : uris)
        if (uris.size() == 1 || fs::exists(fs::symlink_status(run / uri(i), ec)))
          (ours ? after : &out.other)->push_back(uri(i));
    }
  };
  written_after(lod_on_disk, highest_lod, {LodUri, LodTreeUri}, &out.lod_after);
  written_after(on_disk, highest, {TileUri}, &out.after);
  return out;
}

// ---- merging ------------------------------------------------------------------------------------

MergedTiles MergeTiles(const fs::path& run) {
  const fs::path tileset_path = run / "tileset.json";
  std::error_code ec;
  if (!fs::exists(run, ec)) throw std::runtime_error(run.string() + ": no such folder");
  if (!fs::is_directory(run, ec))
    throw std::runtime_error(run.string() +
                             (fs::is_regular_file(run, ec) ? ": is a file, not a run folder"
                                                           : ": is not a folder, not a run folder") +
                             " (name the output folder of a run with tiles, the one holding "
                             "tileset.json)");
  const json tileset = ReadTilesetFile(tileset_path);
  MergedTiles out;
  RunTiles tiles;
  int64_t count = 0;
  std::string error;
  try {
    const json& imr = tileset.at("asset").at("extras").at("imr");
    if (!imr.is_object()) throw std::runtime_error("asset.extras.imr: expected an object");
    out.complete = imr.value("complete", false);
    out.state = imr.value("state", out.complete ? "complete" : "running");
    error = imr.value("error", "");
    if (!tileset.at("root").is_object())
      throw std::runtime_error("root: expected a tile (an object), got " + io::Describe(tileset["root"]));
    tiles = ListRunTiles(run, tileset);
    if (static_cast<int64_t>(tiles.named.size()) > kMaxTiles)
      throw std::runtime_error("more than " + std::to_string(kMaxTiles) + " tiles (a run of imr writes at "
                               "most that many)");
    count = imr.value("tiles", static_cast<int64_t>(tiles.named.size()));
  } catch (const std::exception& e) {
    throw std::runtime_error(tileset_path.string() + ": not a tileset of imr (" + e.what() + ")");
  }
  std::set<int> listed;
  for (const std::string& uri : tiles.named) {
    // The tileset names files: only imr's own tile names, inside the run's tiles/ folder.
    if (TileIndex(uri) == 0)
      throw std::runtime_error(tileset_path.string() + ": content uri '" + JsonText(uri) +
                               "' is not a tile of imr (tiles/tile_NNNNNN.glb)");
    if (!listed.insert(TileIndex(uri)).second)
      throw std::runtime_error(tileset_path.string() + ": tile " + uri + " is listed twice");
  }
  // imr names tiles 1 .. `tiles` (asset.extras.imr): one not named is missing from the tileset.
  for (int64_t i = 1; i <= std::min<int64_t>(count, kMaxTiles); ++i)
    if (!listed.count(static_cast<int>(i)))
      throw std::runtime_error(tileset_path.string() + ": does not name " + TileUri(static_cast<int>(i)) +
                               ", tile " + std::to_string(i) + " of the " + std::to_string(count) +
                               " it counts: a tile is missing from it (changed after the run?)");
  if (static_cast<int64_t>(listed.size()) != count)
    throw std::runtime_error(tileset_path.string() + ": names " + std::to_string(listed.size()) +
                             " tiles, but counts " + std::to_string(count) + " (asset.extras.imr.tiles)");
  for (const std::string& uri : tiles.named)
    if (!fs::exists(fs::symlink_status(run / uri, ec)))
      throw std::runtime_error((run / uri).string() + ": no such file: a tile tileset.json names is "
                               "missing");
  std::vector<std::string> uris = tiles.named;
  // A stopped or failed run may have written tiles after its last tileset.json; a finished one
  // names all of its own.
  std::vector<std::string> left_out = tiles.other;
  if (out.complete) {
    left_out.insert(left_out.end(), tiles.after.begin(), tiles.after.end());
  } else if (!tiles.after.empty()) {
    out.notes.push_back(std::to_string(tiles.after.size()) + " tile(s) written after the last " +
                        "tileset.json (" + tiles.after.front() +
                        (tiles.after.size() > 1 ? " to " + tiles.after.back() : std::string()) +
                        "), merged too");
    uris.insert(uris.end(), tiles.after.begin(), tiles.after.end());
  }
  std::sort(left_out.begin(), left_out.end());
  if (!left_out.empty())
    out.notes.push_back(std::to_string(left_out.size()) + " file(s) of tile names in tiles/ that " +
                        "this run's tileset does not count (" + left_out.front() +
                        (left_out.size() > 1 ? ", ..." : "") + "): not its tiles, left out");
  if (out.state == "failed")
    out.notes.push_back("the run failed" + (error.empty() ? std::string() : " (" + error + ")") +
                        ": the tileset is not complete (the surface it had not handed out is "
                        "missing)");
  else if (!out.complete)
    out.notes.push_back("the tileset is not complete: the run did not finish (the surface it had "
                        "not handed out yet is missing)");
  if (uris.empty()) throw std::runtime_error(tileset_path.string() + ": lists no tile");

  std::unordered_map<int64_t, uint32_t> index;
  std::unordered_map<int64_t, int> tiles_naming;
  engine::Mesh& m = out.mesh;
  for (const std::string& uri : uris) {
    const fs::path file = run / uri;
    const json gltf = GlbJson(file);
    if (!EveryPrimitiveHas(gltf, "_VERTEX_KEY"))
      throw std::runtime_error(file.string() + ": no `_VERTEX_KEY` attribute: not a tile imr can "
                               "merge (written by an exporter without vertex keys)");
    const bool ids = EveryPrimitiveHas(gltf, "_POINT_ID");
    std::vector<std::string> names = {"_VERTEX_KEY"};
    if (ids) names.push_back("_POINT_ID");
    std::vector<std::vector<double>> values;
    std::vector<int> components;
    const eval::TriangleMesh t = eval::ReadGltfWithAttributes(file, names, &values, &components);
    if (components[0] != 2)
      throw std::runtime_error(file.string() + ": `_VERTEX_KEY` is not VEC2 (key = x * 2^24 + y)");
    std::vector<uint32_t> local(t.vertices.size());
    std::set<int64_t> in_this_tile;
    for (std::size_t v = 0; v < t.vertices.size(); ++v) {
      const double hi = values[0][2 * v], lo = values[0][2 * v + 1];
      if (!(hi >= 0 && lo >= 0 && hi < 16777216.0 && lo < 16777216.0) || hi != std::floor(hi) || lo != std::floor(lo))
        throw std::runtime_error(file.string() + ": vertex " + std::to_string(v) + " has no valid `_VERTEX_KEY`");
      const int64_t key = static_cast<int64_t>(hi) * 16777216 + static_cast<int64_t>(lo);
      const auto [it, fresh] = index.emplace(key, static_cast<uint32_t>(m.point_ids.size()));
      if (fresh) {
        m.vertices.insert(m.vertices.end(), t.vertices[v].begin(), t.vertices[v].end());
        m.point_ids.push_back(ids ? static_cast<int64_t>(values[1][v]) : -1);
      }
      if (in_this_tile.insert(key).second && ++tiles_naming[key] == 2) ++out.seam_vertices;
      local[v] = it->second;
    }
    for (const auto& tri : t.triangles)
      m.faces.insert(m.faces.end(), {local[tri[0]], local[tri[1]], local[tri[2]]});
    ++out.tiles;
  }
  engine::CanonicalizeMesh(&m);
  if (!out.complete) {
    // A vertex whose fans the surface not yet written would have joined: one copy per fan.
    const std::size_t before = m.point_ids.size();
    engine::SplitPinchedVertices(&m);
    out.vertices_kept_apart = static_cast<int64_t>(m.point_ids.size() - before);
    if (out.vertices_kept_apart > 0)
      out.notes.push_back(std::to_string(out.vertices_kept_apart) + " vertex cop" +
                          (out.vertices_kept_apart == 1 ? "y" : "ies") + " made where the tiles "
                          "written touch at a point only (the surface between them was not written): "
                          "each fan its own vertex");
  }
  return out;
}

}  // namespace imr::pipeline
