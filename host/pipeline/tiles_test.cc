// TileWriter without an exporter (a stand-in writes each tile's GLB header and records the tile):
// the surface handed out in many parts, as the engine's forgetting will, becomes tiles while the
// parts come (not all at the end), each triangle in exactly one tile, open tiles few; the
// tileset's tree; the local frame; whose files imr may replace. tests/tiles_test runs the real
// thing through the imr executable.
#include "host/pipeline/tiles.h"

#include "host/eval/mesh_stats.h"
#include "host/pipeline/streamed_surface.h"

#include "host/engine/mesh_topology.h"
#include "host/engine/simplify.h"
#include "host/engine/surface_stream.h"
#include "host/engine/testing/run_stream.h"
#include "host/engine/testing/slice_parts.h"
#include "host/io/image_io.h"
#include "host/io/image_sequence.h"
#include "host/io/testing/temp_dir.h"
#include "host/util/atomic_file.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <fstream>
#include <functional>
#include <map>
#include <numbers>
#include <iterator>
#include <set>

namespace imr::pipeline {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

// A GLB whose JSON chunk names `_VERTEX_KEY` (all TileWriter reads back).
void WriteStandInGlb(const fs::path& path) {
  std::string text = R"({"asset":{"version":"2.0"},"meshes":[{"primitives":[{"attributes":{"POSITION":0,"_VERTEX_KEY":1}}]}]})";
  while (text.size() % 4) text.push_back(' ');
  std::string glb = "glTF";
  auto u32 = [&](uint32_t v) { glb.append(reinterpret_cast<const char*>(&v), 4); };
  u32(2);
  u32(static_cast<uint32_t>(20 + text.size()));
  u32(static_cast<uint32_t>(text.size()));
  glb += "JSON" + text;
  std::ofstream(path, std::ios::binary) << glb;
}


// The engine the street tests run: its defaults on one thread.
engine::EngineOptions StreetEngineOptions() {
  engine::EngineOptions eo;
  eo.num_threads = 1;
  return eo;
}

// The tree with the levels of detail's subtrees (external tilesets, tiles/lod_NNNNNN.json) put
// in place of the tiles that name them, their uris from the run folder; each such tile's bounding
// volume and error are its subtree root's.
json Inlined(const fs::path& run, json tile, const std::string& base = "") {
  if (tile.contains("content")) {
    const std::string uri = base + tile["content"]["uri"].get<std::string>();
    if (uri.size() > 5 && uri.substr(uri.size() - 5) == ".json") {
      const json tree = json::parse(std::ifstream(run / uri));
      EXPECT_EQ(tree["root"]["geometricError"], tile["geometricError"]) << uri;
      EXPECT_EQ(tree["root"]["boundingVolume"], tile["boundingVolume"]) << uri;
      EXPECT_FALSE(tile.contains("children")) << uri;
      return Inlined(run, tree["root"], "tiles/");
    }
    tile["content"]["uri"] = uri;
  }
  if (tile.contains("children"))
    for (json& c : tile["children"]) c = Inlined(run, c, base);
  return tile;
}

// imr-synth's street stream of `frames` frames through that engine, its boundary cut into 40
// parts along the street as forgetting would hand them out (empty when the run failed).
std::vector<engine::SurfacePart> StreetParts(int frames) {
  synthetic::StreamOptions so;
  so.scene = synthetic::SceneKind::kStreet;
  so.frames = frames;
  so.points_per_keyframe = 150;
  synthetic::SyntheticStream stream(so);
  const engine::EngineOptions eo = StreetEngineOptions();
  engine::Engine engine(eo, nullptr);
  if (!engine::testing::RunStream(&stream, &engine).ok()) return {};
  return engine::testing::SliceIntoParts(engine.ExtractBoundary(), eo.steiner_export, 40,
                                         engine::testing::CutOrder::kAlongY);
}

TEST(TileWriterTest, PartsBecomeTilesAsTheyCome) {
  const std::vector<engine::SurfacePart> parts = StreetParts(60);
  ASSERT_FALSE(parts.empty());

  io::testing::TempDir dir("imr-tiles-writer");
  std::vector<TileMesh> written;
  TilesOptions o;
  o.enabled = true;
  o.size = 10.0;
  o.max_triangles = 150;
  o.lod = false;  // the leaves (LevelsOfDetail... below: with them)
  TileWriter writer(o, dir.path(), json{{"job", "/j.json"}, {"sequence", "street"}},
                    [] { return TilesetFrame({}); },
                    [&](const TileMesh& t, const fs::path& staging, const std::string& stem) {
                      WriteStandInGlb(staging / (stem + ".glb"));
                      written.push_back(t);
                    });
  // Before any tile: an empty tileset of imr, marking the folder.
  EXPECT_EQ(json::parse(std::ifstream(dir / "tileset.json"))["asset"]["extras"]["imr"]["tiles"], 0);
  engine::SurfaceStream surface(engine::SurfaceStreamOptions::FromEngine(StreetEngineOptions()));
  std::size_t before_last = 0;
  for (std::size_t p = 0; p < parts.size(); ++p) {
    ASSERT_EQ(surface.Add(parts[p]), "");
    writer.Add(surface.TakeReleased());
    if (p + 1 == parts.size() / 2) before_last = written.size();
  }
  const std::size_t during = written.size();
  writer.Finish();
  ASSERT_EQ(surface.Finish(), "");
  // Tiles were written while the parts came, not only at the end; few were open at once.
  EXPECT_GT(before_last, 3u);
  EXPECT_GT(during, written.size() / 2);
  EXPECT_LT(writer.stats().open_tiles_peak, static_cast<int64_t>(written.size() / 2));
  // Every released triangle in exactly one tile (by its keys), none over max_triangles.
  std::multiset<std::array<int64_t, 3>> triangles;
  for (const TileMesh& t : written) {
    EXPECT_LE(t.mesh.faces.size() / 3, 150u);
    for (std::size_t f = 0; f < t.mesh.faces.size(); f += 3) {
      std::array<int64_t, 3> k = {t.keys[t.mesh.faces[f]], t.keys[t.mesh.faces[f + 1]], t.keys[t.mesh.faces[f + 2]]};
      std::rotate(k.begin(), std::min_element(k.begin(), k.end()), k.end());
      triangles.insert(k);
    }
    for (std::size_t i = 0; i < t.mesh.vertices.size(); ++i) {  // the box holds the tile
      EXPECT_GE(t.mesh.vertices[i], t.box[i % 3]);
      EXPECT_LE(t.mesh.vertices[i], t.box[3 + i % 3]);
    }
    for (int k = 0; k < 3; ++k)  // the origin is its cell's centre
      EXPECT_EQ(std::fmod(t.origin[k] - 5.0, 10.0), 0.0);
  }
  EXPECT_EQ(static_cast<int64_t>(triangles.size()), surface.stats().triangles_released);
  const std::set<std::array<int64_t, 3>> distinct(triangles.begin(), triangles.end());
  EXPECT_EQ(distinct.size(), triangles.size());
  // The tileset: every tile once, in writing order, under nodes of at most 8.
  const json ts = json::parse(std::ifstream(dir / "tileset.json"));
  EXPECT_EQ(ts["asset"]["extras"]["imr"]["complete"], true);
  const std::vector<std::string> uris = TileContentUris(dir.path(), ts["root"]);
  ASSERT_EQ(uris.size(), written.size());
  for (std::size_t i = 0; i < uris.size(); ++i) {
    char name[64];
    std::snprintf(name, sizeof(name), "tiles/tile_%06zu.glb", i + 1);
    EXPECT_EQ(uris[i], name);
    EXPECT_TRUE(fs::exists(dir / name));
  }
  std::vector<const json*> nodes = {&ts["root"]};
  while (!nodes.empty()) {
    const json* n = nodes.back();
    nodes.pop_back();
    EXPECT_LE(n->value("children", json::array()).size(), 8u);
    EXPECT_EQ((*n)["boundingVolume"]["box"].size(), 12u);
    if (n->contains("children"))
      for (const json& c : (*n)["children"]) nodes.push_back(&c);
  }
  EXPECT_EQ(writer.files().size(), written.size() + 1);
}

// Issue 46 item 2: levels of detail written as the parts come. Every node's content holds its
// children's vertices within its geometricError; cut at any level (a node of that level or below
// where it stands, its subtree left out) and merged by key, the tiles are a 2-manifold with the
// leaves' own border exactly (locked seams: no crack, no gap); coarser levels hold fewer
// triangles; nodes are written while the parts come; the leaves are what they are without LOD.
TEST(TileWriterTest, LevelsOfDetailCoverTheirChildrenWithinTheirErrorWithoutCracks) {
  const std::vector<engine::SurfacePart> parts = StreetParts(120);
  ASSERT_FALSE(parts.empty());
  struct Run {
    std::map<std::string, TileMesh> tiles;  // by uri
    json tileset;
    TilesStats stats;
    int64_t lod_during = 0;
    int64_t named_in_tileset = 0;
  };
  auto run = [&](bool lod) {
    io::testing::TempDir dir("imr-tiles-lod");
    Run r;
    TilesOptions o;
    o.enabled = true;
    o.size = 10.0;
    o.max_triangles = 400;
    o.lod = lod;
    TileWriter writer(o, dir.path(), json{{"job", "/j.json"}, {"sequence", "street"}}, {},
                      [&](const TileMesh& t, const fs::path& staging, const std::string& stem) {
                        WriteStandInGlb(staging / (stem + ".glb"));
                        r.tiles["tiles/" + stem + ".glb"] = t;
                      });
    engine::SurfaceStream surface(engine::SurfaceStreamOptions::FromEngine(StreetEngineOptions()));
    for (const auto& part : parts) {
      EXPECT_EQ(surface.Add(part), "");
      writer.Add(surface.TakeReleased());
    }
    r.lod_during = writer.stats().lod_tiles;
    writer.Finish();
    r.stats = writer.stats();
    r.tileset = json::parse(std::ifstream(dir / "tileset.json"));
    // What tileset.json itself names: the tiles and nodes no written level of detail holds.
    std::function<int64_t(const json&)> named = [&](const json& n) {
      int64_t k = n.contains("content") ? 1 : 0;
      for (const json& c : n.value("children", json::array())) k += named(c);
      return k;
    };
    r.named_in_tileset = named(r.tileset["root"]);
    r.tileset["root"] = Inlined(dir.path(), r.tileset["root"]);
    return r;
  };
  const Run with = run(true), without = run(false);
  ASSERT_GE(with.stats.tiles_per_level.size(), 3u) << "two levels of detail at least";
  EXPECT_GT(with.lod_during, 0) << "levels of detail written while the parts come";
  // The written subtrees are external tilesets: tileset.json (rewritten as tiles come) names far
  // fewer tiles than there are.
  EXPECT_LT(with.named_in_tileset, (with.stats.tiles + with.stats.lod_tiles) / 3);
  EXPECT_EQ(without.named_in_tileset, without.stats.tiles);
  EXPECT_EQ(with.tileset["asset"]["extras"]["imr"]["lod_tiles"], with.stats.lod_tiles);
  EXPECT_EQ(with.tileset["asset"]["extras"]["imr"]["tiles"], with.stats.tiles);
  // The leaves are the same tiles as without levels of detail.
  std::map<std::string, std::vector<int64_t>> leaves_with, leaves_without;
  for (const auto& [uri, t] : with.tiles) if (t.level == 0) leaves_with[uri] = t.keys;
  for (const auto& [uri, t] : without.tiles) leaves_without[uri] = t.keys;
  EXPECT_EQ(leaves_with, leaves_without);
  // Every node: its children's vertices within its geometric error of its content.
  int checked = 0;
  int tops = 0;
  std::function<void(const json&, bool)> check = [&](const json& n, bool under_content) {
    const json children = n.value("children", json::array());
    if (n.contains("content")) {
      const TileMesh& parent = with.tiles.at(n["content"]["uri"].get<std::string>());
      EXPECT_EQ(n["geometricError"].get<double>(), parent.geometric_error);
      tops += !under_content;
      if (parent.level > 0) {
        EXPECT_EQ(n["refine"], "REPLACE");
        // Never tiny, but for the top node (one request from far instead of one per child).
        if (under_content || children.size() < 2) {
          EXPECT_GE(static_cast<int64_t>(parent.mesh.faces.size() / 3), kMinTileTriangles);
        }
        int64_t below = 0;
        for (const json& c : children) {
          const TileMesh& child = with.tiles.at(c["content"]["uri"].get<std::string>());
          below += static_cast<int64_t>(child.mesh.faces.size() / 3);
          EXPECT_LE(engine::MaxDistanceToMesh(child.mesh.vertices, parent.mesh), parent.geometric_error + 1e-9)
              << n["content"]["uri"] << " over " << c["content"]["uri"];
          EXPECT_LE(child.geometric_error, parent.geometric_error);
          ++checked;
        }
        EXPECT_LE(static_cast<double>(parent.mesh.faces.size() / 3),
                  (children.size() >= static_cast<std::size_t>(kLodManyChildren) ? kMaxLodShareMany : kMaxLodShare) *
                      static_cast<double>(below));
      }
    }
    for (const json& c : children) check(c, under_content || n.contains("content"));
  };
  check(with.tileset["root"], false);
  EXPECT_GT(checked, 4);
  EXPECT_EQ(tops, 1) << "one node at the top: a view from far asks for one tile";
  // Cut at each level and merged by key: a 2-manifold whose border is the leaves' border.
  auto merged_cut = [&](int level) {
    engine::Mesh m;
    std::map<int64_t, uint32_t> index;
    std::function<void(const json&)> take = [&](const json& n) {
      if (n.contains("content")) {
        const TileMesh& t = with.tiles.at(n["content"]["uri"].get<std::string>());
        if (t.level <= level) {
          for (uint32_t f : t.mesh.faces) {
            const auto [it, fresh] = index.emplace(t.keys[f], static_cast<uint32_t>(index.size()));
            if (fresh) {
              m.vertices.insert(m.vertices.end(), &t.mesh.vertices[3 * f], &t.mesh.vertices[3 * f] + 3);
              m.point_ids.push_back(t.keys[f]);
            }
            m.faces.push_back(it->second);
          }
          return;
        }
      }
      for (const json& c : n.value("children", json::array())) take(c);
    };
    take(with.tileset["root"]);
    return m;
  };
  auto border = [](const engine::Mesh& m) {
    std::set<std::pair<int64_t, int64_t>> edges, out;
    for (std::size_t f = 0; f < m.faces.size(); f += 3)
      for (int k = 0; k < 3; ++k)
        edges.insert({m.point_ids[m.faces[f + k]], m.point_ids[m.faces[f + (k + 1) % 3]]});
    for (const auto& [a, b] : edges)
      if (!edges.count({b, a})) out.insert({a, b});
    return out;
  };
  const engine::Mesh leaves = merged_cut(0);
  std::size_t previous = leaves.faces.size();
  for (int level = 1; level < static_cast<int>(with.stats.tiles_per_level.size()); ++level) {
    const engine::Mesh cut = merged_cut(level);
    engine::Mesh split = cut;
    engine::SplitPinchedVertices(&split);  // as the leaves merge
    engine::Mesh leaves_split = leaves;
    engine::SplitPinchedVertices(&leaves_split);
    const auto check_cut = engine::CheckMesh(split, false);
    EXPECT_TRUE(check_cut.ok) << "level " << level << ": " << check_cut.message;
    // A crack: a vertex of a seam (a key in two tiles of the cut; locked) inside the leaves' surface
    // but on the border of the cut.
    std::map<int64_t, int> tiles_naming;
    std::function<void(const json&)> count = [&](const json& n) {
      if (n.contains("content")) {
        const TileMesh& t = with.tiles.at(n["content"]["uri"].get<std::string>());
        if (t.level <= level) {
          for (int64_t k : t.keys) ++tiles_naming[k];
          return;
        }
      }
      for (const json& c : n.value("children", json::array())) count(c);
    };
    count(with.tileset["root"]);
    std::set<int64_t> leaf_border, cut_border;
    for (const auto& [a, b] : border(leaves)) leaf_border.insert({a, b});
    for (const auto& [a, b] : border(cut)) cut_border.insert({a, b});
    int cracks = 0;
    for (const auto& [k, n] : tiles_naming)
      if (n > 1 && cut_border.count(k) && !leaf_border.count(k)) ++cracks;
    EXPECT_EQ(cracks, 0) << "level " << level;
    // A level with no node written (all gathered) cuts as the one below.
    if (with.stats.tiles_per_level[level] > 0) {
      EXPECT_LT(cut.faces.size(), previous) << "level " << level;
    }
    previous = cut.faces.size();
  }
  // From far (the coarsest cut) a small share of the leaves' triangles.
  std::printf("coarsest cut: %zu triangles of the leaves' %zu\n", previous / 3, leaves.faces.size() / 3);
  EXPECT_LT(previous, leaves.faces.size() / 5);
  // Coarse content held while the parts came: a share of the surface, never all of it.
  EXPECT_LT(with.stats.lod_pending_triangles_peak, with.stats.triangles / 2);
  std::printf("levels of detail: tiles per level");
  for (int64_t n : with.stats.tiles_per_level) std::printf(" %lld", static_cast<long long>(n));
  std::printf("; leaf triangles %lld, lod %lld, held at most %lld, %.3f s\n",
              static_cast<long long>(with.stats.triangles), static_cast<long long>(with.stats.lod_triangles),
              static_cast<long long>(with.stats.lod_pending_triangles_peak), with.stats.lod_seconds);
}

// A flat strip 160 m long, 4 m wide, on a 1 m grid, handed out in parts of 10 m along x (a part
// completes the vertices behind it): 16 leaves of 80 triangles.
std::vector<engine::SurfacePart> StripParts() {
  constexpr int kLength = 160, kWidth = 4;
  auto key = [](int x, int y) { return int64_t{x} * (kWidth + 1) + y; };
  std::vector<engine::SurfacePart> parts;
  for (int x0 = 0; x0 < kLength; x0 += 10) {
    engine::SurfacePart p;
    std::map<int64_t, uint32_t> index;
    auto vertex = [&](int x, int y) {
      const auto [it, fresh] = index.emplace(key(x, y), static_cast<uint32_t>(p.keys.size()));
      if (fresh) {
        p.keys.push_back(key(x, y));
        p.point_ids.push_back(-1);
        p.vertices.insert(p.vertices.end(), {static_cast<double>(x), static_cast<double>(y), 0.0});
      }
      return it->second;
    };
    for (int x = x0; x < x0 + 10; ++x)
      for (int y = 0; y < kWidth; ++y)
        for (const uint32_t v : {vertex(x, y), vertex(x + 1, y), vertex(x + 1, y + 1), vertex(x, y),
                                 vertex(x + 1, y + 1), vertex(x, y + 1)})
          p.faces.push_back(v);
    const int done = x0 + 10 == kLength ? kLength : x0 + 9;  // the last column waits for the next part
    for (int x = x0; x <= done; ++x)
      for (int y = 0; y <= kWidth; ++y) p.completed.push_back(key(x, y));
    p.update = static_cast<int64_t>(parts.size()) + 1;
    parts.push_back(std::move(p));
  }
  return parts;
}

// The tiles a view from far asks for: the first content down each branch from the root.
std::vector<std::string> TopTiles(const json& root) {
  std::vector<std::string> top;
  std::function<void(const json&)> first_content = [&](const json& n) {
    if (n.contains("content")) {
      top.push_back(n["content"]["uri"].get<std::string>());
      return;
    }
    for (const json& c : n.value("children", json::array())) first_content(c);
  };
  first_content(root);
  return top;
}

// Issue 45: a surface whose top of the tree simplifies under kMinTileTriangles (here a flat strip;
// on a street, the same street without its specks) still has one node at the top: gathered, its
// 16 children would hang at the top of the tileset and a view from far would ask for each.
TEST(TileWriterTest, TheTopOfTheTreeIsOneNodeHoweverSmall) {
  io::testing::TempDir dir("imr-tiles-top");
  std::map<std::string, TileMesh> tiles;
  TilesOptions o;
  o.enabled = true;
  o.size = 10.0;
  TileWriter writer(o, dir.path(), json{{"job", "/j.json"}, {"sequence", "strip"}}, {},
                    [&](const TileMesh& t, const fs::path& staging, const std::string& stem) {
                      WriteStandInGlb(staging / (stem + ".glb"));
                      tiles["tiles/" + stem + ".glb"] = t;
                    });
  for (const engine::SurfacePart& p : StripParts()) writer.Add(p);
  writer.Finish();
  ASSERT_EQ(writer.stats().tiles, 16);
  const json ts = json::parse(std::ifstream(dir / "tileset.json"));
  const std::vector<std::string> top = TopTiles(Inlined(dir.path(), ts["root"]));
  ASSERT_EQ(top.size(), 1u) << ts["root"].dump(1);
  const TileMesh& t = tiles.at(top[0]);
  EXPECT_GT(t.level, 0);
  EXPECT_LT(static_cast<int64_t>(t.mesh.faces.size() / 3), kMinTileTriangles) << "the case this test is for";
  EXPECT_EQ(TileContentUris(dir.path(), ts["root"]).size(), tiles.size()) << "every tile under it";
}

// Issue 45: a vertex's lock is decided when the node holding it is flushed, not when its tile is
// written: completions that come parts after the tiles (as when the stream holds a small piece's
// completions) give the same levels as on time, and however late, the tree keeps one node at the
// top (locked at every level, the nodes were not worth writing and the top was lost).
TEST(TileWriterTest, CompletionsThatComeLateGiveTheSameLevels) {
  const std::vector<engine::SurfacePart> parts = StreetParts(120);
  ASSERT_FALSE(parts.empty());
  std::vector<engine::SurfacePart> released;
  engine::SurfaceStream surface(engine::SurfaceStreamOptions::FromEngine(StreetEngineOptions()));
  for (const auto& part : parts) {
    ASSERT_EQ(surface.Add(part), "");
    released.push_back(surface.TakeReleased());
  }
  struct Run {
    TilesStats stats;
    std::vector<std::string> top;
  };
  auto run = [&](std::size_t late) {  // each part's completions handed `late` parts later
    io::testing::TempDir dir("imr-tiles-late");
    TilesOptions o;
    o.enabled = true;
    o.size = 10.0;
    o.max_triangles = 400;
    TileWriter writer(o, dir.path(), json{{"job", "/j.json"}, {"sequence", "street"}}, {},
                      [&](const TileMesh&, const fs::path& staging, const std::string& stem) {
                        WriteStandInGlb(staging / (stem + ".glb"));
                      });
    for (std::size_t i = 0; i < released.size(); ++i) {
      engine::SurfacePart p = released[i];
      p.completed = i >= late ? released[i - late].completed : std::vector<int64_t>();
      writer.Add(p);
    }
    writer.Finish();  // the last `late` parts' completions: every vertex is complete at the end
    return Run{writer.stats(), TopTiles(Inlined(dir.path(), json::parse(std::ifstream(dir / "tileset.json"))["root"]))};
  };
  const Run on_time = run(0);
  ASSERT_GE(on_time.stats.tiles_per_level.size(), 3u);
  EXPECT_EQ(on_time.top.size(), 1u);
  for (std::size_t late : {2, 3, 4}) {
    const Run r = run(late);
    EXPECT_EQ(r.stats.tiles_per_level, on_time.stats.tiles_per_level) << late << " parts late";
    EXPECT_NEAR(static_cast<double>(r.stats.lod_triangles), static_cast<double>(on_time.stats.lod_triangles),
                0.1 * static_cast<double>(on_time.stats.lod_triangles)) << late << " parts late";
  }
  // Later than the nodes are flushed (the drive has left): locked there, not above.
  const Run very_late = run(12);
  EXPECT_EQ(very_late.top.size(), 1u);
  EXPECT_EQ(very_late.stats.tiles_per_level.size(), on_time.stats.tiles_per_level.size());
}

// A run stopped mid-way (the exporter throws): the levels of detail it wrote are the run's
// (named, or numbered on after the last tileset), never another's files; a re-run removes them.
TEST(TileWriterTest, AStoppedRunsLevelsOfDetailAreItsOwn) {
  const std::vector<engine::SurfacePart> parts = StreetParts(120);
  ASSERT_FALSE(parts.empty());
  io::testing::TempDir dir("imr-tiles-lod-stop");
  TilesOptions o;
  o.enabled = true;
  o.size = 10.0;
  o.max_triangles = 400;
  int lod_written = 0, leaves_written = 0;
  {
    TileWriter writer(o, dir.path(), json{{"job", "/j.json"}, {"sequence", "street"}}, {},
                      [&](const TileMesh& t, const fs::path& staging, const std::string& stem) {
                        if (lod_written == 3) throw std::runtime_error("stopped");
                        WriteStandInGlb(staging / (stem + ".glb"));
                        ++(t.level > 0 ? lod_written : leaves_written);
                      });
    engine::SurfaceStream surface(engine::SurfaceStreamOptions::FromEngine(StreetEngineOptions()));
    try {
      for (const auto& part : parts) {
        ASSERT_EQ(surface.Add(part), "");
        writer.Add(surface.TakeReleased());
      }
      writer.Finish();
      ADD_FAILURE() << "the run was not stopped";
    } catch (const std::runtime_error& e) {
      EXPECT_EQ(std::string(e.what()), "stopped");
    }
  }
  ASSERT_EQ(lod_written, 3);
  std::ofstream(dir / "tiles" / "lod_000009.glb") << "not the run's";
  const RunTiles tiles = ListRunTiles(dir.path(), json::parse(std::ifstream(dir / "tileset.json")));
  // Each level of detail is its GLB and its subtree's tileset.
  EXPECT_EQ(tiles.lod.size() + tiles.lod_trees.size() + tiles.lod_after.size(), 6u);
  for (const auto* list : {&tiles.lod, &tiles.lod_trees, &tiles.lod_after})
    for (const std::string& uri : *list) EXPECT_TRUE(fs::exists(dir / uri)) << uri;
  EXPECT_EQ(tiles.named.size() + tiles.after.size(), static_cast<std::size_t>(leaves_written));
  EXPECT_EQ(tiles.other, std::vector<std::string>{"tiles/lod_000009.glb"});
  // A re-run replaces them all but the other file.
  o.lod = false;
  TileWriter again(o, dir.path(), json{{"job", "/j.json"}, {"sequence", "street"}}, {},
                   [](const TileMesh&, const fs::path&, const std::string&) {});
  EXPECT_FALSE(fs::exists(dir / "tiles" / "lod_000001.glb"));
  EXPECT_FALSE(fs::exists(dir / "tiles" / "lod_000001.json"));
  EXPECT_FALSE(fs::exists(dir / "tiles" / "tile_000001.glb"));
  EXPECT_TRUE(fs::exists(dir / "tiles" / "lod_000009.glb"));
}

// The local frame: a KITTI-style camera (x right, y down, z forward) driving along world +z,
// world up -y: up becomes +Z, the viewing direction +Y.
TEST(TileWriterTest, TilesetFrameTurnsTheCamerasUpToZ) {
  const std::array<double, 16> m = TilesetFrame({{1, 0, 0, 0, 1, 0, 0, 0, 1}});
  auto apply = [&](std::array<double, 3> v) {
    return std::array<double, 3>{m[0] * v[0] + m[4] * v[1] + m[8] * v[2], m[1] * v[0] + m[5] * v[1] + m[9] * v[2],
                                 m[2] * v[0] + m[6] * v[1] + m[10] * v[2]};
  };
  EXPECT_EQ(apply({0, -1, 0}), (std::array<double, 3>{0, 0, 1}));
  EXPECT_EQ(apply({0, 0, 1}), (std::array<double, 3>{0, 1, 0}));
  EXPECT_EQ(apply({1, 0, 0}), (std::array<double, 3>{1, 0, 0}));
  EXPECT_EQ(m[15], 1.0);
  EXPECT_EQ(TilesetFrame({}), (std::array<double, 16>{1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1}));
  // glTF content: z-up to y-up.
  EXPECT_EQ(TileGltfRotation(), (std::array<double, 9>{1, 0, 0, 0, 0, 1, 0, -1, 0}));
}

TEST(TileWriterTest, ForeignTilesAreNamed) {
  io::testing::TempDir dir("imr-tiles-foreign");
  EXPECT_EQ(ForeignTiles(dir.path(), "/j.json", "street"), "");
  fs::create_directories(dir / "tiles");
  WriteFileAtomically(dir / "tiles" / "tile_000001.glb", "x");  // imr's (its ledger says so)
  EXPECT_NE(ForeignTiles(dir.path(), "/j.json", "street").find("tile_000001.glb: a tile with no tileset.json of imr"),
            std::string::npos);
  WriteFileAtomically(dir / "tileset.json", R"({"asset": {"extras": {"imr": {"job": "/j.json", "sequence": "street"}}}})");
  EXPECT_EQ(ForeignTiles(dir.path(), "/j.json", "street"), "");
  EXPECT_NE(ForeignTiles(dir.path(), "/other.json", "street").find("not a tileset imr wrote"), std::string::npos);
  EXPECT_NE(ForeignTiles(dir.path(), "/j.json", "room").find("not a tileset imr wrote"), std::string::npos);
  // A file of another name in tiles/ is neither ours nor in the way: left alone.
  std::ofstream(dir / "tiles" / "notes.txt") << "mine";
  EXPECT_EQ(ForeignTiles(dir.path(), "/j.json", "street"), "");
  TilesOptions o;
  o.enabled = true;
  o.size = 10;
  TileWriter w(o, dir.path(), json{{"job", "/j.json"}, {"sequence", "street"}}, {},
               [](const TileMesh&, const fs::path&, const std::string&) {});
  EXPECT_FALSE(fs::exists(dir / "tiles" / "tile_000001.glb"));  // the earlier run's tile: replaced
  EXPECT_TRUE(fs::exists(dir / "tiles" / "notes.txt"));
  // An exporter that leaves `_VERTEX_KEY` out: the tile is refused, naming the file.
  TileWriter bad(o, dir.path(), json{{"job", "/j.json"}, {"sequence", "street"}}, {},
                 [](const TileMesh&, const fs::path& staging, const std::string& stem) {
                   std::ofstream(staging / (stem + ".glb")) << "glTF";
                 });
  engine::SurfacePart p;
  p.vertices = {0, 0, 0, 1, 0, 0, 0, 1, 0};
  p.keys = {0, 1, 2};
  p.point_ids = {0, 1, 2};
  p.faces = {0, 1, 2};
  bad.Add(p);
  try {
    bad.Finish();
    ADD_FAILURE() << "a tile without keys was accepted";
  } catch (const std::exception& e) {
    EXPECT_NE(std::string(e.what()).find("tile_000001.glb"), std::string::npos) << e.what();
  }
}

// One triangle in cell (i, 0, 0) of 1 m cells: a part per tile with idle_parts 1.
engine::SurfacePart OneTriangle(int i) {
  engine::SurfacePart p;
  const double x = i + 0.25;
  p.vertices = {x, 0.25, 0.25, x + 0.5, 0.25, 0.25, x, 0.75, 0.25};
  p.keys = {3 * i, 3 * i + 1, 3 * i + 2};
  p.point_ids = {-1, -1, -1};
  p.faces = {0, 1, 2};
  return p;
}

// Issue 44, finding 10: tileset.json was rewritten (and synced) after every tile, O(tiles^2)
// bytes. It is rewritten as the tiles it names grow by a quarter: a few dozen versions for 1,000
// tiles, and in all a few times the last one's bytes; what a stop leaves follows its numbers.
TEST(TileWriterTest, TheTilesetsRewriteCostIsBoundedPerTile) {
  io::testing::TempDir dir("imr-tiles-rewrite");
  TilesOptions o;
  o.enabled = true;
  o.size = 1.0;
  o.idle_parts = 1;
  o.lod = false;  // one-triangle tiles: every node would be gathered
  int exported = 0;
  TileWriter writer(o, dir.path(), json{{"job", "/j.json"}, {"sequence", "street"}}, {},
                    [&](const TileMesh&, const fs::path& staging, const std::string& stem) {
                      WriteStandInGlb(staging / (stem + ".glb"));
                      ++exported;
                    });
  constexpr int kTiles = 1000;
  for (int i = 0; i < kTiles; ++i) writer.Add(OneTriangle(i));
  ASSERT_EQ(exported, kTiles - 1);  // the last one is still open
  // As a stop now would leave it: the tileset names a prefix, the rest follow its numbers.
  const json stopped = json::parse(std::ifstream(dir / "tileset.json"));
  EXPECT_EQ(stopped["asset"]["extras"]["imr"]["state"], "running");
  const RunTiles run = ListRunTiles(dir.path(), stopped);
  EXPECT_GE(run.named.size(), static_cast<std::size_t>(kTiles * 3 / 4));
  EXPECT_EQ(run.named.size() + run.after.size(), static_cast<std::size_t>(kTiles - 1));
  EXPECT_TRUE(run.other.empty());
  writer.Finish();
  const std::uintmax_t last = fs::file_size(dir / "tileset.json");
  EXPECT_EQ(writer.stats().tiles, kTiles);
  EXPECT_LE(writer.stats().tileset_writes, 40) << "every tile rewrote it";
  EXPECT_LE(writer.stats().tileset_bytes, static_cast<int64_t>(8 * last));
  EXPECT_EQ(TileContentUris(dir.path(), json::parse(std::ifstream(dir / "tileset.json"))["root"]).size(),
            static_cast<std::size_t>(kTiles));
}

// Issue 46 item 3: the geo-referenced root transform, ECEF <- ENU <- heading <- local, at points
// whose axes are known. At (0, 0, 0) east is ECEF +y, north +z, up +x.
std::array<double, 3> Apply(const std::array<double, 16>& m, const std::array<double, 3>& v, double w = 1.0) {
  return {m[0] * v[0] + m[4] * v[1] + m[8] * v[2] + w * m[12], m[1] * v[0] + m[5] * v[1] + m[9] * v[2] + w * m[13],
          m[2] * v[0] + m[6] * v[1] + m[10] * v[2] + w * m[14]};
}
void ExpectNear3(const std::array<double, 3>& got, const std::array<double, 3>& want, double tol) {
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(got[k], want[k], tol) << "component " << k;
}

TilesOrigin LevelOrigin(double latitude, double longitude, double height, double heading) {
  TilesOrigin o;
  o.given = true;
  o.latitude = latitude;
  o.longitude = longitude;
  o.height = height;
  o.heading = heading;
  o.source = "output.tiles.origin";
  return o;
}

TEST(TileWriterTest, GeoreferencedFramePutsTheLocalFrameInEcef) {
  const std::array<double, 16> identity = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
  TilesOrigin o;
  o.given = true;
  std::array<double, 16> m = GeoreferencedFrame(o, identity);
  ExpectNear3(Apply(m, {0, 0, 0}), {6378137.0, 0, 0}, 1e-6);
  ExpectNear3(Apply(m, {0, 1, 0}, 0.0), {0, 0, 1}, 1e-15);  // heading 0: +Y north
  ExpectNear3(Apply(m, {1, 0, 0}, 0.0), {0, 1, 0}, 1e-15);  // +X east
  ExpectNear3(Apply(m, {0, 0, 1}, 0.0), {1, 0, 0}, 1e-15);  // +Z up
  o.heading = 90;  // +Y east, +X south
  m = GeoreferencedFrame(o, identity);
  ExpectNear3(Apply(m, {0, 1, 0}, 0.0), {0, 1, 0}, 1e-15);
  ExpectNear3(Apply(m, {1, 0, 0}, 0.0), {0, 0, -1}, 1e-15);
  // 100 m along +Y at heading 90 from (0, 0): 100 m east on the equator, 1 m up stays 1 m up.
  const geo::Geodetic g = geo::GeodeticFromEcef(Apply(m, {0, 100, 1}));
  EXPECT_NEAR(g.latitude, 0.0, 1e-12);
  EXPECT_NEAR(g.longitude * 6378137.0 * std::numbers::pi / 180.0, 100.0, 1e-3);
  EXPECT_NEAR(g.height, 1.0 + 100.0 * 100.0 / (2 * 6378137.0), 1e-4);  // the plane leaves the sphere
  // With the local frame of a KITTI camera (x right, y down, z forward): driving forward (world
  // +z) at heading 30 goes 30 degrees east of north; the camera's up (-y) is up.
  o = LevelOrigin(49.0, 8.4, 110.0, 30.0);
  m = GeoreferencedFrame(o, TilesetFrame({{1, 0, 0, 0, 1, 0, 0, 0, 1}}));
  const std::array<double, 9> enu = geo::EnuAxes(49.0, 8.4);
  const std::array<double, 3> forward = Apply(m, {0, 0, 1}, 0.0), up = Apply(m, {0, -1, 0}, 0.0);
  auto dot = [](const double* a, const std::array<double, 3>& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; };
  EXPECT_NEAR(dot(&enu[0], forward), std::sin(std::numbers::pi / 6), 1e-12);  // east
  EXPECT_NEAR(dot(&enu[3], forward), std::cos(std::numbers::pi / 6), 1e-12);  // north
  EXPECT_NEAR(dot(&enu[6], up), 1.0, 1e-12);
  ExpectNear3(Apply(m, {0, 0, 0}), geo::EcefFromGeodetic({49.0, 8.4, 110.0}), 1e-6);
}

// The origin an input's anchor gives: the heading of the local +Y as the anchor turns it, the
// local up's tilt from the vertical.
TEST(TileWriterTest, OriginFromAnchorTakesTheHeadingOfTheLocalForward) {
  const std::array<double, 16> local = TilesetFrame({{1, 0, 0, 0, 1, 0, 0, 0, 1}});  // +Y = world +z
  geo::GeoAnchor a;
  a.origin = {49.0, 8.4, 110.0};
  a.source = "oxts";
  // World (a camera: x right, y down, z forward) facing east: z -> east, x -> south, y -> down.
  a.enu_from_world = {0, 0, 1, -1, 0, 0, 0, -1, 0};
  TilesOrigin o = OriginFromAnchor(a, local);
  EXPECT_TRUE(o.given);
  EXPECT_NEAR(o.heading, 90.0, 1e-12);
  EXPECT_NEAR(o.tilt, 0.0, 1e-6);
  EXPECT_EQ(o.latitude, 49.0);
  EXPECT_EQ(o.height, 110.0);
  EXPECT_EQ(o.source, "oxts");
  // Facing south-west (z -> (-1, -1, 0)/sqrt2), pitched 5 degrees down: heading -135, tilt 5.
  const double c = std::cos(5 * std::numbers::pi / 180), s = std::sin(5 * std::numbers::pi / 180);
  const double h = std::sqrt(0.5);
  // Columns: world x (right: north-west), y (down, tilted back), z (forward, tilted down).
  const std::array<double, 3> x = {-h, h, 0}, z = {-h * c, -h * c, -s}, y = {h * s, h * s, -c};
  for (int r = 0; r < 3; ++r) {
    a.enu_from_world[3 * r + 0] = x[r];
    a.enu_from_world[3 * r + 1] = y[r];
    a.enu_from_world[3 * r + 2] = z[r];
  }
  o = OriginFromAnchor(a, local);
  EXPECT_NEAR(o.heading, -135.0, 1e-9);
  EXPECT_NEAR(o.tilt, 5.0, 1e-9);
  EXPECT_EQ(o.ToJson()["tilt"], o.tilt);
  // The transform it makes keeps the anchor's attitude: the world's forward to the south-west,
  // 5 degrees down; the same origin levelled (a job's: heading only) keeps it level.
  const std::array<double, 9> enu = geo::EnuAxes(49.0, 8.4);
  auto in_enu = [&](const std::array<double, 3>& v) {
    return std::array<double, 3>{enu[0] * v[0] + enu[1] * v[1] + enu[2] * v[2], enu[3] * v[0] + enu[4] * v[1] + enu[5] * v[2],
                                 enu[6] * v[0] + enu[7] * v[1] + enu[8] * v[2]};
  };
  ExpectNear3(in_enu(Apply(GeoreferencedFrame(o, local), {0, 0, 1}, 0.0)), z, 1e-9);
  ExpectNear3(in_enu(Apply(GeoreferencedFrame(o, local), {1, 0, 0}, 0.0)), x, 1e-9);
  o.enu_from_local.reset();
  EXPECT_FALSE(o.ToJson().contains("tilt"));
  ExpectNear3(in_enu(Apply(GeoreferencedFrame(o, local), {0, 0, 1}, 0.0)), {-h, -h, 0}, 1e-9);
}

// A KITTI raw drive with oxts, end to end to the tiles' transform: 41 records along a 400 m
// curve (yaw 1.2 to 2.4 rad, a little roll and pitch), the 2011_09_26 calibration, camera 2. The
// reader's poses (the devkit's Mercator), the origin its anchor gives (OriginFromAnchor: the
// heading of the local +Y, and the anchor's attitude) and GeoreferencedFrame put each frame's
// camera centre within 1 m horizontally and 0.5 m in height of where its own oxts record and the
// camera's lever arm put it (the devkit's spherical Mercator is off the ellipsoid by about 1 m
// per km at 49 degrees).
TEST(TileWriterTest, AKittiDrivesFramesLandWhereTheirOxtsSays) {
  io::testing::TempDir dir("imr-tiles-oxts");
  const fs::path date = dir / "2011_09_26", drive = date / "2011_09_26_drive_0001_sync";
  const int frames = 41;
  fs::create_directories(drive / "oxts" / "data");
  std::ofstream(date / "calib_cam_to_cam.txt")
      << "R_rect_00: 9.999239e-01 9.837760e-03 -7.445048e-03 -9.869795e-03 9.999421e-01 -4.278459e-03 "
         "7.402527e-03 4.351614e-03 9.999631e-01\n"
         "P_rect_02: 7.215377e+02 0.000000e+00 6.095593e+02 4.485728e+01 0.000000e+00 7.215377e+02 "
         "1.728540e+02 2.163791e-01 0.000000e+00 0.000000e+00 1.000000e+00 2.745884e-03\n";
  std::ofstream(date / "calib_velo_to_cam.txt")
      << "R: 7.533745e-03 -9.999714e-01 -6.166020e-04 1.480249e-02 7.280733e-04 -9.998902e-01 "
         "9.998621e-01 7.523790e-03 1.480755e-02\nT: -4.069766e-03 -7.631618e-02 -2.717806e-01\n";
  std::ofstream(date / "calib_imu_to_velo.txt")
      << "R: 9.999976e-01 7.553071e-04 -2.035826e-03 -7.854027e-04 9.998898e-01 -1.482298e-02 "
         "2.024406e-03 1.482454e-02 9.998881e-01\nT: -8.086759e-01 3.195559e-01 -7.997231e-01\n";
  io::Image gray;
  gray.width = 64;
  gray.height = 32;
  gray.channels = 1;
  gray.stride_bytes = 64;
  gray.pixels.assign(64 * 32, 128);
  // The records: 10 m steps along the yaw (east of north... counter-clockwise from east, as oxts),
  // positions through the devkit's Mercator inverted (so the poses are exact; the records are
  // the truth the test compares with).
  const double pi = std::numbers::pi, er = 6378137.0, lat0 = 49.011, lon0 = 8.4167;
  const double scale = std::cos(lat0 * pi / 180.0);
  const double east0 = scale * lon0 * pi * er / 180.0;
  const double north0 = scale * er * std::log(std::tan((90.0 + lat0) * pi / 360.0));
  struct Record {
    double lat, lon, alt, roll, pitch, yaw;
  };
  std::vector<Record> records;
  double e = 0, n = 0;
  for (int i = 0; i < frames; ++i) {
    const double yaw = 1.2 + 1.2 * i / (frames - 1);
    Record r{std::atan(std::exp((north0 + n) / (scale * er))) * 360.0 / pi - 90.0,
             (east0 + e) * 180.0 / (scale * pi * er), 115.0 + 0.02 * i, 0.02 * std::sin(i * 0.3),
             -0.015 + 0.01 * std::cos(i * 0.2), yaw};
    records.push_back(r);
    char name[32];
    std::snprintf(name, sizeof(name), "%010d", i);
    std::ofstream out(drive / "oxts" / "data" / (std::string(name) + ".txt"));
    char line[256];
    std::snprintf(line, sizeof(line), "%.12f %.12f %.6f %.9f %.9f %.9f", r.lat, r.lon, r.alt, r.roll, r.pitch, r.yaw);
    out << line;
    for (int k = 0; k < 24; ++k) out << " 0";
    out << "\n";
    fs::create_directories(drive / "image_02" / "data");
    io::WriteImage((drive / "image_02" / "data" / (std::string(name) + ".png")).string(), gray);
    e += 10.0 * std::cos(yaw);
    n += 10.0 * std::sin(yaw);
  }
  io::ImageSequenceOptions options;
  options.camera = 2;
  const io::ImageSequence seq = io::ReadKittiRaw(drive.string(), options);
  ASSERT_TRUE(seq.geo.has_value());
  ASSERT_EQ(seq.frames.size(), static_cast<std::size_t>(frames));
  std::vector<std::array<double, 9>> rotations;
  for (const io::ImageFrame& f : seq.frames) {
    std::array<double, 9> r;
    for (int k = 0; k < 9; ++k) r[k] = f.camera.rotation[k / 3][k % 3];
    rotations.push_back(r);
  }
  const std::array<double, 16> local = TilesetFrame(rotations);
  const TilesOrigin origin = OriginFromAnchor(*seq.geo, local);
  const std::array<double, 16> m = GeoreferencedFrame(origin, local);
  // The IMU -> camera lever arm in the IMU's axes, from frame 0 (the anchor is camera 2 there).
  auto attitude = [](const Record& r) {  // IMU -> ENU: Rz(yaw) Ry(pitch) Rx(roll), row-major
    const double cx = std::cos(r.roll), sx = std::sin(r.roll), cy = std::cos(r.pitch), sy = std::sin(r.pitch);
    const double cz = std::cos(r.yaw), sz = std::sin(r.yaw);
    return std::array<double, 9>{cz * cy, cz * sy * sx - sz * cx, cz * sy * cx + sz * sx,
                                 sz * cy, sz * sy * sx + cz * cx, sz * sy * cx - cz * sx,
                                 -sy, cy * sx, cy * cx};
  };
  auto enu_offset = [](const geo::Geodetic& from, const std::array<double, 3>& to) {
    const std::array<double, 3> o = geo::EcefFromGeodetic(from);
    const std::array<double, 9> a = geo::EnuAxes(from.latitude, from.longitude);
    std::array<double, 3> d{};
    for (int r = 0; r < 3; ++r)
      for (int k = 0; k < 3; ++k) d[r] += a[3 * r + k] * (to[k] - o[k]);
    return d;
  };
  const Record& r0 = records[0];
  const std::array<double, 3> offset0 = enu_offset({r0.lat, r0.lon, r0.alt}, geo::EcefFromGeodetic(seq.geo->origin));
  const std::array<double, 9> a0 = attitude(r0);
  std::array<double, 3> lever{};
  for (int r = 0; r < 3; ++r)
    for (int k = 0; k < 3; ++k) lever[r] += a0[3 * k + r] * offset0[k];
  EXPECT_GT(std::hypot(lever[0], lever[1], lever[2]), 0.5);  // camera 2 is not at the IMU
  double worst = 0;
  for (int i : {0, 10, 20, 30, 40}) {
    const Record& r = records[static_cast<std::size_t>(i)];
    const std::array<double, 9> a = attitude(r);
    // Where the camera is: its record's position plus the lever arm turned by its attitude.
    std::array<double, 3> want = geo::EcefFromGeodetic({r.lat, r.lon, r.alt});
    const std::array<double, 9> enu = geo::EnuAxes(r.lat, r.lon);
    for (int k = 0; k < 3; ++k)
      for (int j = 0; j < 3; ++j)
        want[k] += enu[3 * j + k] * (a[3 * j] * lever[0] + a[3 * j + 1] * lever[1] + a[3 * j + 2] * lever[2]);
    // Where the tiles' transform puts it.
    const Vec3 c = seq.frames[static_cast<std::size_t>(i)].camera.center;
    const std::array<double, 3> got = Apply(m, {c[0], c[1], c[2]});
    const std::array<double, 3> d = enu_offset(geo::GeodeticFromEcef(want), got);
    const double from_start = std::hypot(c[0], c[1], c[2]);
    std::printf("frame %d, %.0f m from the first: %.3f m east, %.3f m north, %.3f m up of its oxts position\n", i,
                from_start, d[0], d[1], d[2]);
    worst = std::max(worst, std::hypot(d[0], d[1]));
    EXPECT_LE(std::hypot(d[0], d[1]), 1.0) << "frame " << i;
    EXPECT_LE(std::abs(d[2]), 0.5) << "frame " << i;  // the attitude kept, not levelled
  }
  std::printf("heading %.3f deg, tilt %.3f deg, worst horizontal %.3f m\n", origin.heading, origin.tilt, worst);
  EXPECT_GT(origin.tilt, 0.5);  // levelled, the far frames would be metres off in height
  // The heading is the local +Y's: the cameras' mean direction over the curve, between the first
  // record's azimuth (90 - 1.2 rad) and the last's (90 - 2.4 rad).
  EXPECT_LT(origin.heading, 90.0 - 1.2 * 180.0 / pi);
  EXPECT_GT(origin.heading, 90.0 - 2.4 * 180.0 / pi);
}

TEST(TileWriterTest, AnOriginOffTheEarthIsRefused) {
  TilesOrigin o = LevelOrigin(49.0, 8.4, 110.0, 0.0);
  EXPECT_EQ(o.Check(), "");
  o.latitude = 91;
  EXPECT_EQ(o.Check(), "origin.latitude: expected degrees in [-90, 90], got 91");
  o.latitude = -90;
  o.longitude = 180.5;
  EXPECT_EQ(o.Check(), "origin.longitude: expected degrees in [-180, 180], got 180.5");
  o.longitude = -180;
  o.height = 6378137;  // a geocentric radius, not a height
  EXPECT_EQ(o.Check(), "origin.height: expected metres above the WGS84 ellipsoid in [-11000, 100000], "
                       "got 6.37814e+06");
  o.height = 0;
  o.heading = std::nan("");
  EXPECT_EQ(o.Check(), "origin.heading: expected degrees clockwise from north, got nan");
  // Through the options, named as a key of output.tiles.
  TilesOptions t;
  t.origin = o;
  EXPECT_EQ(t.Check(), "origin.heading: expected degrees clockwise from north, got nan");
  // From the job's JSON.
  t = TilesOptionsFromJson({{"origin", {{"latitude", 1.5}, {"longitude", -2}, {"height", 3}, {"heading", 4}}}});
  EXPECT_TRUE(t.origin.given);
  EXPECT_EQ(t.origin.ToJson(), (json{{"latitude", 1.5}, {"longitude", -2.0}, {"height", 3.0}, {"heading", 4.0},
                                     {"source", "output.tiles.origin"}}));
  EXPECT_FALSE(TilesOptionsFromJson(json::object()).origin.given);
}

// Issue 44, finding 10: options that make a tile of a triangle are refused, in the validation's
// words.
TEST(TileWriterTest, OptionsThatMakeTilesOfATriangleAreRefused) {
  TilesOptions o;
  o.enabled = true;
  EXPECT_EQ(o.Check(), "");
  o.max_triangles = 1;
  EXPECT_EQ(o.Check(), "max_triangles: expected >= 100, got 1");
  o.max_triangles = 100;
  EXPECT_EQ(o.Check(), "");
  EXPECT_EQ(o.CheckSize(5.0), "");  // 0: 10 x steiner_spacing
  o.size = 1e-9;
  EXPECT_EQ(o.CheckSize(5.0), "expected 0 (10 x engine.steiner_spacing) or a length >= "
                              "engine.steiner_spacing as used (5), got 1e-09: a smaller cell cuts the "
                              "surface into tiles of a triangle or two, each a file");
  o.size = 5.0;
  EXPECT_EQ(o.CheckSize(5.0), "");
}

// Issue 44, finding 14: a re-run removes the tiles the earlier tileset named and those its run
// wrote after it (numbered on), not a file of a tile's name that neither is.
TEST(TileWriterTest, AReRunRemovesOnlyTheEarlierRunsTiles) {
  io::testing::TempDir dir("imr-tiles-rerun");
  fs::create_directories(dir / "tiles");
  WriteFileAtomically(dir / "tileset.json", R"({"asset": {"extras": {"imr": {"job": "/j.json",
      "sequence": "street", "tiles": 2}}}, "root": {"children": [
      {"content": {"uri": "tiles/tile_000001.glb"}}, {"content": {"uri": "tiles/tile_000002.glb"}}]}})");
  // The earlier run's tiles are imr's (written through the write rule); tile_555555 is a user's.
  for (const char* name : {"tile_000001.glb", "tile_000002.glb", "tile_000003.glb"})
    WriteFileAtomically(dir / "tiles" / name, std::string("glTF ") + name);
  std::ofstream(dir / "tiles" / "tile_555555.glb") << "glTF tile_555555.glb";
  ASSERT_EQ(ForeignTiles(dir.path(), "/j.json", "street"), "");
  TilesOptions o;
  o.enabled = true;
  o.size = 10;
  TileWriter w(o, dir.path(), json{{"job", "/j.json"}, {"sequence", "street"}}, {},
               [](const TileMesh&, const fs::path&, const std::string&) {});
  for (const char* name : {"tile_000001.glb", "tile_000002.glb", "tile_000003.glb"})
    EXPECT_FALSE(fs::exists(dir / "tiles" / name)) << name;
  ASSERT_TRUE(fs::exists(dir / "tiles" / "tile_555555.glb"));
  std::ifstream in(dir / "tiles" / "tile_555555.glb");
  EXPECT_EQ(std::string(std::istreambuf_iterator<char>(in), {}), "glTF tile_555555.glb");
}

// Issue 44, finding 14: a file of a tile's name that no tileset of the run counts (kept by the
// constructor) is never written over: the tile that would replace it fails, naming it.
TEST(TileWriterTest, ATileIsNeverWrittenOverAFileItDidNotWrite) {
  io::testing::TempDir dir("imr-tiles-in-the-way");
  fs::create_directories(dir / "tiles");
  WriteFileAtomically(dir / "tileset.json", R"({"asset": {"extras": {"imr": {"job": "/j.json",
      "sequence": "street", "tiles": 1}}}, "root": {"content": {"uri": "tiles/tile_000001.glb"}}})");
  WriteFileAtomically(dir / "tiles" / "tile_000001.glb", "the earlier run's");
  std::ofstream(dir / "tiles" / "tile_000003.glb") << "mine";  // not numbered on from tile 1
  TilesOptions o;
  o.enabled = true;
  o.size = 1.0;
  o.idle_parts = 1;
  TileWriter w(o, dir.path(), json{{"job", "/j.json"}, {"sequence", "street"}}, {},
               [](const TileMesh&, const fs::path& staging, const std::string& stem) {
                 WriteStandInGlb(staging / (stem + ".glb"));
               });
  EXPECT_FALSE(fs::exists(dir / "tiles" / "tile_000001.glb"));
  try {
    for (int i = 0; i < 4; ++i) w.Add(OneTriangle(i));  // tiles 1, 2, then 3
    ADD_FAILURE() << "tile 3 was written over the user's file";
  } catch (const std::exception& e) {
    EXPECT_NE(std::string(e.what()).find("tile_000003.glb: a file that no tileset of this run names"),
              std::string::npos) << e.what();
  }
  std::ifstream in(dir / "tiles" / "tile_000003.glb");
  EXPECT_EQ(std::string(std::istreambuf_iterator<char>(in), {}), "mine");
}

// Issue 44, finding 13 and the minor `"root": null`: the tree is read with bounds and checked.
TEST(TileWriterTest, ContentUrisOfATreeThatIsNotOneAreRefused) {
  auto error = [](const json& root) {
    try {
      TileContentUris(fs::path("."), root);
    } catch (const std::exception& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  EXPECT_EQ(error(nullptr), "root: expected a tile (an object), got null");
  EXPECT_EQ(error(json{{"children", 3}}), "root.children: expected an array, got 3");
  EXPECT_EQ(error(json{{"children", {{{"content", "x"}}}}}),
            "root.children[0].content: expected {\"uri\": \"...\"}, got \"x\"");
  json deep = json::object();
  for (int i = 0; i < 70; ++i) deep = json{{"children", {deep}}};
  EXPECT_NE(error(deep).find("more than 64 levels deep"), std::string::npos) << error(deep);
  json wide = {{"children", json::array()}};
  // The leaves and as many levels of detail at most.
  for (int64_t i = 0; i <= 2 * kMaxTiles; ++i) wide["children"].push_back({{"content", {{"uri", "tiles/tile_000001.glb"}}}});
  EXPECT_EQ(error(wide), "more than 200000 tiles (a run of imr writes at most 100000 and as many levels of detail)");

  // External tilesets: only imr's subtrees (tiles/lod_NNNNNN.json) are followed, each once.
  io::testing::TempDir dir("imr-tiles-subtrees");
  fs::create_directories(dir / "tiles");
  auto subtree_error = [&](const json& root) {
    try {
      TileContentUris(dir.path(), root);
    } catch (const std::exception& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  auto named = [](const std::string& uri) { return json{{"children", {{{"content", {{"uri", uri}}}}}}}; };
  EXPECT_EQ(subtree_error(named("../outside.json")),
            "root.children[0].content: '../outside.json' is not a tileset of imr (a level of detail's "
            "subtree is tiles/lod_NNNNNN.json)");
  EXPECT_NE(subtree_error(named("tiles/lod_000001.json")).find("no such file"), std::string::npos)
      << subtree_error(named("tiles/lod_000001.json"));
  std::ofstream(dir / "tiles" / "lod_000001.json")
      << json{{"root", {{"content", {{"uri", "lod_000001.glb"}}}, {"children", {{{"content", {{"uri", "lod_000001.json"}}}}}}}}}.dump();
  EXPECT_EQ(subtree_error(named("tiles/lod_000001.json")),
            "tiles/lod_000001.json: root.children[0].content: 'tiles/lod_000001.json' is named twice in the tree");
  std::ofstream(dir / "tiles" / "lod_000001.json")
      << json{{"root", {{"content", {{"uri", "lod_000001.glb"}}}, {"children", {{{"content", {{"uri", "tile_000002.glb"}}}}}}}}}.dump();
  std::vector<std::string> subtrees;
  EXPECT_EQ(TileContentUris(dir.path(), named("tiles/lod_000001.json"), InputRole::kInput, &subtrees),
            (std::vector<std::string>{"tiles/lod_000001.glb", "tiles/tile_000002.glb"}));
  EXPECT_EQ(subtrees, std::vector<std::string>{"tiles/lod_000001.json"});
}

// Issue 45 item 3: a drive with forgetting on, specks put into its parts as they come (a closed
// octahedron of 1.7 m^2 whole in one part, another across two parts): neither reaches the single
// mesh nor the tiles, which are the parts' own export (FinishExportedMesh of their union: no
// piece under engine.min_component_area, a 2-manifold) and agree triangle for triangle.
TEST(TileWriterTest, SpecksInAForgettingRunsPartsAreNotWritten) {
  engine::EngineOptions eo = StreetEngineOptions();
  eo.forget = engine::ForgetMode::kOn;
  synthetic::StreamOptions so;
  so.scene = synthetic::SceneKind::kStreet;
  so.frames = 200;
  so.points_per_keyframe = 150;
  synthetic::SyntheticStream stream(so);
  engine::Engine engine(eo, nullptr);
  io::testing::TempDir dir("imr-tiles-specks");
  fs::create_directories(dir / "spool");
  std::vector<TileMesh> written;
  TilesOptions o;
  o.enabled = true;
  o.size = 20.0;
  o.max_triangles = 1000;
  o.lod = false;
  TileWriter writer(o, dir.path(), json{{"job", "/j.json"}, {"sequence", "street"}},
                    [] { return TilesetFrame({}); },
                    [&](const TileMesh& t, const fs::path& staging, const std::string& stem) {
                      WriteStandInGlb(staging / (stem + ".glb"));
                      if (t.level == 0) written.push_back(t);
                    });
  StreamedSurface surface(eo, dir / "spool", &writer);
  // An octahedron of radius 0.5 at height 60 m, its keys far from the engine's.
  int64_t next_key = int64_t{1} << 40;
  auto speck = [&](double y, engine::SurfacePart* first, engine::SurfacePart* second) {
    const double c[6][3] = {{0.5, 0, 0}, {-0.5, 0, 0}, {0, 0.5, 0}, {0, -0.5, 0}, {0, 0, 0.5}, {0, 0, -0.5}};
    const int f[8][3] = {{0, 2, 4}, {2, 1, 4}, {1, 3, 4}, {3, 0, 4}, {2, 0, 5}, {1, 2, 5}, {3, 1, 5}, {0, 3, 5}};
    std::vector<int64_t> keys;
    for (int i = 0; i < 6; ++i) keys.push_back(next_key++);
    for (int t = 0; t < 8; ++t) {
      engine::SurfacePart* p = t < 4 ? first : second;
      for (int k = 0; k < 3; ++k) {
        const int v = f[t][k];
        p->faces.push_back(static_cast<uint32_t>(p->keys.size()));
        p->keys.push_back(keys[static_cast<std::size_t>(v)]);
        p->point_ids.push_back(-1);
        p->vertices.insert(p->vertices.end(), {c[v][0], y + c[v][1], 60.0 + c[v][2]});
      }
    }
    second->completed.insert(second->completed.end(), keys.begin(), keys.end());
  };
  std::vector<engine::SurfacePart> parts;  // as the stream got them
  engine::SurfacePart pending_;            // the second speck's second half
  surface.SetPartFilter([&](engine::SurfacePart* p) {
    // A part names a vertex once: merge the speck's repeated corners by key.
    auto dedup = [](engine::SurfacePart* q) {
      std::map<int64_t, uint32_t> at;
      engine::SurfacePart d = *q;
      d.vertices.clear();
      d.keys.clear();
      d.point_ids.clear();
      for (uint32_t& i : d.faces) {
        const auto [it, fresh] = at.emplace(q->keys[i], static_cast<uint32_t>(d.keys.size()));
        if (fresh) {
          d.keys.push_back(q->keys[i]);
          d.point_ids.push_back(q->point_ids[i]);
          d.vertices.insert(d.vertices.end(), &q->vertices[3 * i], &q->vertices[3 * i] + 3);
        }
        i = it->second;
      }
      *q = std::move(d);
    };
    if (parts.size() == 2) speck(20.0, p, p);  // whole in this part
    if (parts.size() == 3) {
      engine::SurfacePart tail;
      speck(40.0, p, &tail);  // half now, half (and its completion) with the next part
      pending_ = std::move(tail);
    } else if (parts.size() == 4) {
      for (std::size_t i = 0; i < pending_.faces.size(); ++i) {
        const uint32_t v = pending_.faces[i];
        p->faces.push_back(static_cast<uint32_t>(p->keys.size()));
        p->keys.push_back(pending_.keys[v]);
        p->point_ids.push_back(pending_.point_ids[v]);
        p->vertices.insert(p->vertices.end(), &pending_.vertices[3 * v], &pending_.vertices[3 * v] + 3);
      }
      p->completed.insert(p->completed.end(), pending_.completed.begin(), pending_.completed.end());
    }
    dedup(p);
    parts.push_back(*p);
  });
  ASSERT_TRUE(engine::testing::RunStream(&stream, &engine, [&](const synthetic::StreamKeyframe&) {
                surface.Take(engine);
                return true;
              }).ok());
  ASSERT_GT(parts.size(), 5u) << "the drive should hand its surface out in parts";
  surface.Finish(engine.FinishSurface());
  const engine::SurfaceStreamStats& st = surface.stats().stream;
  EXPECT_GE(st.dropped.components, 2);
  EXPECT_GE(st.dropped.faces, 16);
  EXPECT_EQ(st.held_small_triangles, 0);
  // The single mesh: the parts' export exactly, a manifold, no piece under the threshold.
  EXPECT_TRUE(surface.mesh_check().ok) << surface.mesh_check().message;
  const engine::Mesh mesh = surface.ReadMesh(/*canonical=*/true);
  engine::Mesh whole;
  ASSERT_EQ(engine::MergeSurfaceParts(parts, &whole), "");
  engine::DroppedComponents d;
  engine::FinishExportedMesh(&whole, eo, &d);
  EXPECT_EQ(d.components, st.dropped.components);
  EXPECT_EQ(mesh.faces, whole.faces);
  EXPECT_EQ(mesh.vertices, whole.vertices);
  EXPECT_EQ(static_cast<int64_t>(mesh.faces.size() / 3), st.triangles_released);
  const eval::MeshStatistics ms = eval::ComputeMeshStatistics(mesh.vertices, mesh.faces);
  ASSERT_GT(ms.component_list.size(), 0u);
  for (const eval::ComponentStatistics& c : ms.component_list) EXPECT_GE(c.area, eo.MinComponentArea());
  EXPECT_EQ(ms.unused_vertices, 0);
  for (std::size_t i = 2; i < mesh.vertices.size(); i += 3) EXPECT_LT(mesh.vertices[i], 59.0);
  // The tiles: the same triangles (by their corners' positions), none of a speck.
  // A triangle as its corners from the smallest (orientation kept).
  auto corners = [](const engine::Mesh& m, std::size_t f) {
    std::array<std::array<double, 3>, 3> c{};
    for (int k = 0; k < 3; ++k)
      for (int a = 0; a < 3; ++a) c[k][a] = m.vertices[3 * m.faces[f + k] + a];
    std::rotate(c.begin(), std::min_element(c.begin(), c.end()), c.end());
    return c;
  };
  std::multiset<std::array<std::array<double, 3>, 3>> from_tiles, from_mesh;
  for (const TileMesh& t : written)
    for (std::size_t f = 0; f < t.mesh.faces.size(); f += 3) from_tiles.insert(corners(t.mesh, f));
  for (std::size_t f = 0; f < mesh.faces.size(); f += 3) from_mesh.insert(corners(mesh, f));
  EXPECT_EQ(from_tiles.size(), from_mesh.size());
  EXPECT_TRUE(from_tiles == from_mesh);
}

}  // namespace
}  // namespace imr::pipeline
