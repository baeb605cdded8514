// The surface as OGC 3D Tiles 1.1 (issue 32, DESIGN.md section 10): the triangles the surface
// stream releases (host/engine/surface_stream.h: final, fixed up) are grouped into tiles by a
// grid over the sequence's frame; a tile is written when it is full, when the surface has moved
// on from it, or at the end, each as GLB through the job's exporter (the callback) into
// <output>/tiles/ (staged, then renamed: a killed run keeps every finished tile and never a half
// one under a final name), and <output>/tileset.json is rewritten (atomically) as tiles are
// written: after each of the first few, then whenever the tiles written since its last version
// are a quarter of those it names (or 5 s have passed), so the rewrites cost O(1) per tile however
// many tiles a run writes; tiles written after the last version follow its numbers, and
// MergeTiles takes them.
//
// Frames. Tile content is glTF, y-up; 3D Tiles is z-up and turns a glTF's +Y into +Z when it
// loads it. A tile's GLB holds its vertices relative to the tile's origin (a grid cell's centre,
// float32 keeps millimetres: the glTF node's translation) under a root node rotating the
// sequence's frame as if it were z-up into glTF's y-up, (x, y, z) -> (x, z, -y), so that 3D
// Tiles reads the sequence's own coordinates back; tiles have no transform of their own and their
// bounding boxes are in the sequence's frame. The root's transform is the local frame: the
// sequence's frame turned so that the cameras' mean up is +Z (their mean viewing direction +Y),
// as viewers of 3D Tiles expect the ground; with an origin (TilesOrigin: the job's, or the
// input's place on the Earth) that frame placed in ECEF (GeoreferencedFrame). Vertices carry their keys (`_VERTEX_KEY`): tiles share
// their seam vertices and merge without duplicates (MergeTiles).
#pragma once

#include "host/util/input_file.h"

#include "host/engine/engine.h"
#include "host/util/geodesy.h"

#include <nlohmann/json.hpp>

#include <array>
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <tuple>
#include <unordered_map>
#include <vector>

namespace imr::pipeline {

// Where the tileset's local frame (TilesetFrame) stands on the Earth (issue 46): its origin, the
// sequence's (0, 0, 0), at WGS84 latitude/longitude/ellipsoidal height, its +Y (the cameras' mean
// viewing direction, level) `heading` degrees clockwise from north, its +Z up. The job's
// "output.tiles.origin", or one an input gives (KITTI raw's oxts: OriginFromAnchor).
struct TilesOrigin {
  bool given = false;
  double latitude = 0.0;   // degrees, [-90, 90]
  double longitude = 0.0;  // degrees, [-180, 180]
  double height = 0.0;     // metres above the WGS84 ellipsoid, [kMinOriginHeight, kMaxOriginHeight]
  double heading = 0.0;    // degrees clockwise from north of the local frame's +Y
  std::string source;      // for the log and the tileset: "output.tiles.origin" or the input's file
  // An input that knows its frame's attitude (KITTI raw's oxts) gives ENU <- local whole,
  // row-major: used instead of the heading's level turn (the cameras' mean up is not quite the
  // vertical: a degree is 9 m in height 500 m on), with `tilt`, its +Z's angle from up (degrees).
  std::optional<std::array<double, 9>> enu_from_local;
  double tilt = 0.0;
  // Empty when usable, else which key and why.
  std::string Check() const;
  nlohmann::json ToJson() const;
};
// The deepest trench to the edge of space: a height outside is a mistake (feet, or a geocentric
// radius).
inline constexpr double kMinOriginHeight = -11000.0;
inline constexpr double kMaxOriginHeight = 100000.0;
// The JSON schema of "output.tiles.origin" (latitude, longitude and height have no default: the
// validation asks for them).
const nlohmann::json& TilesOriginSchema();

// The job's "output": {"tiles": {...}} (job_validation.cc reads it; REPORT.md, docs/tiles.md).
struct TilesOptions {
  bool enabled = false;        // "tiles" given (an object, or true)
  double size = 0.0;           // side of the grid cells (sequence units, metres); 0: 10 x the
                               // engine's steiner_spacing as used (50 m metric)
  int64_t max_triangles = 200000;  // a cell's tile is written when it holds this many
  int idle_parts = 2;          // ... or when this many released parts in a row added nothing
                               // to it (the surface has moved on)
  TilesOrigin origin;          // "origin" given: the tileset in ECEF
  bool lod = true;             // levels of detail: inner nodes carry their children simplified
  // Empty when usable, else which key and why.
  std::string Check() const;
  // `size` against the Steiner spacing the run uses (a cell smaller than the surface's coarsest
  // triangles makes tiles of a triangle or two, each a file): "" or why (the key is `size`).
  std::string CheckSize(double steiner_spacing) const;
};
// A tile is a request of a 3D Tiles viewer and a file: fewer triangles cost more in requests and
// files than they hold.
inline constexpr int64_t kMinTileTriangles = 100;
// Levels of detail (TilesOptions::lod): a node of level L covers 2^L x 2^L x 2^L grid cells (an
// octree over the cells: the grid is in the sequence's frame, whose up is not known when it is
// cut, and on a street it is one or two cells high, so the octree is a quadtree along the ground).
// Its content is its children's merged by vertex key and simplified to about a quarter of their
// triangles, the vertices on its content's border (shared with a neighbour of the same level, or
// the surface's edge) locked, so that neighbouring nodes meet without cracks. A node is written
// when no open tile lies in or next to its region and no node below it waits; one whose content
// would be under kMinTileTriangles, or not at most kMaxLodShare of its children's triangles (or
// kMaxLodShareMany when it stands for kLodManyChildren tiles or more: one request for many), is
// not written (its children are hung under the next node up, its content goes up in its place);
// the top node with two children or more is written under kMinTileTriangles too (one request
// from far, not one per child).
inline constexpr int kMaxLodLevel = 20;
inline constexpr double kMaxLodShare = 0.5;
inline constexpr double kMaxLodShareMany = 0.8;
inline constexpr int kLodManyChildren = 4;
// A level of detail's texture: a texel of its geometric error / this (ABI 1.6 texel_size). A
// viewer turns to the children when the error would cover its screen-space error target (16
// pixels in 3d-tiles-renderer and CesiumJS by default), so a texel is about a screen pixel there.
inline constexpr double kLodTexelsPerError = 16.0;
// What a run may write and `imr tiles merge` reads: at most this many tiles (about 40 MiB of
// tileset.json) and a tileset.json of at most this many bytes.
inline constexpr int64_t kMaxTiles = 100000;
inline constexpr std::uintmax_t kMaxTilesetBytes = 64u << 20;
TilesOptions TilesOptionsFromJson(const nlohmann::json& tiles);  // after validation
// The JSON schema of "output.tiles" (for validation and `imr options`) but its "origin", an object
// of its own (TilesOriginSchema; job_validation.cc checks it apart).
const nlohmann::json& TilesSchema();

// One tile as the exporter gets it.
struct TileMesh {
  int index = 0;                    // 1, 2, ...: tiles/tile_<index, 6 digits>.glb (a level of
                                    // detail: tiles/lod_<index, 6 digits>.glb)
  int level = 0;                    // 0: a leaf, full resolution; L: a level of detail
  double geometric_error = 0.0;     // measured (a leaf: 0)
  engine::Mesh mesh;                // in the sequence's frame
  std::vector<int64_t> keys;        // per vertex: its key (the surface stream's)
  std::array<double, 3> origin{};   // the vertices are written relative to it
  std::array<double, 6> box{};      // min x y z, max x y z of its vertices
};

// The tile's GLB, written as `stem`.glb into `dir` (a private staging folder).
using WriteTileGlb =
    std::function<void(const TileMesh& tile, const std::filesystem::path& dir, const std::string& stem)>;

struct TilesStats {
  int64_t tiles = 0;
  int64_t triangles = 0;
  int64_t vertices = 0;      // summed over tiles (a seam vertex counts in each of its tiles)
  int64_t bytes = 0;         // of the tiles' GLB files
  int64_t open_tiles_peak = 0;
  double seconds = 0.0;      // writing tiles and the tileset (exporter included)
  int64_t tileset_writes = 0;  // tileset.json versions written
  int64_t tileset_bytes = 0;   // summed over them
  int64_t lod_tree_bytes = 0;  // the levels of detail's subtrees (tiles/lod_NNNNNN.json), each written once
  nlohmann::json origin;       // TilesOrigin::ToJson of the one used; null: not geo-referenced
  // Levels of detail (not in the counts above, which are the leaves').
  int64_t lod_tiles = 0;
  int64_t lod_triangles = 0;
  int64_t lod_bytes = 0;
  int64_t lod_gathered = 0;    // nodes not written (too small, or not simpler than their children)
  double lod_seconds = 0.0;    // simplifying and writing them (within `seconds`)
  int64_t lod_pending_triangles_peak = 0;  // coarse content held for nodes waiting for children
  std::vector<int64_t> tiles_per_level;    // [0] leaves, [L] level L
};

// <output>/tileset.json and <output>/tiles/ are imr's (a tileset written for this sequence of
// this job): "" when imr may replace them (or there are none), else which file is another's.
std::string ForeignTiles(const std::filesystem::path& output_dir, const std::string& job,
                         const std::string& sequence);

class TileWriter {
 public:
  // Replaces an earlier run's tiles (after ForeignTiles said they are this job's), creates
  // <output>/tiles/ and writes an empty tileset.json (marking the folder as imr's at once).
  // `identity` goes into the tileset's asset.extras.imr (job, sequence). `local_frame` is asked
  // once, at the first tile (the keyframes so far give the local frame, TilesetFrame). The root's
  // transform is that frame, or with options.origin (else what `origin_for` makes of the local
  // frame, when it gives one) GeoreferencedFrame of it. Throws naming the path when the folder
  // cannot be written.
  using OriginFor = std::function<TilesOrigin(const std::array<double, 16>& local_frame)>;
  TileWriter(const TilesOptions& options, std::filesystem::path output_dir, nlohmann::json identity,
             std::function<std::array<double, 16>()> local_frame, WriteTileGlb write,
             OriginFor origin_for = nullptr);
  // One part released by the surface stream (keys are the stream's).
  void Add(const engine::SurfacePart& released);
  // Writes every open tile and the final tileset.json (asset.extras.imr.complete: true).
  void Finish();
  // The sequence failed (`error`, after the tiles or during them): tileset.json names every tile
  // written and says so (state "failed", complete false, the error). Best effort: when even that
  // cannot be written (a full disk), the last tileset stays, which says "running". Never throws.
  void MarkFailed(const std::string& error) noexcept;

  const TilesStats& stats() const { return stats_; }
  // Written so far: the tiles, then tileset.json.
  std::vector<std::filesystem::path> files() const;
  std::filesystem::path tileset_path() const { return output_dir_ / "tileset.json"; }

 private:
  using Cell = std::tuple<int64_t, int64_t, int64_t>;
  using NodeKey = std::tuple<int, int64_t, int64_t, int64_t>;  // level, cell >> level
  struct OpenTile {
    engine::Mesh mesh;
    std::vector<int64_t> keys;
    std::map<int64_t, uint32_t> index;  // key -> vertex
    int64_t last_part = 0;
  };
  struct Written {
    std::string uri;
    std::array<double, 6> box;
    int64_t triangles = 0;
    int level = 0;
    double error = 0.0;
    std::vector<int> children;  // indices into written_ (a level of detail's)
    bool has_parent = false;
  };
  // Where a vertex's triangles are, while a tile holding it is open, it is not completed, or a
  // node waiting holds it with its span unknown: the level from which one node holds them all (a
  // vertex is on the seam of nodes below it).
  struct VertexCells {
    Cell first;
    int span = 0;
    int open_tiles = 0;
    int unknown_in_nodes = 0;  // pending nodes holding it with span kMaxLodLevel + 1
    bool completed = false;
  };
  // A node of a level of detail waiting for its children: their content simplified, merged by key.
  struct PendingNode {
    engine::Mesh mesh;
    std::vector<int64_t> keys;
    std::vector<int> spans;          // per vertex: VertexCells::span (kMaxLodLevel + 1: unknown,
                                     // not completed when last looked up: looked up again when
                                     // the node is flushed)
    std::map<int64_t, uint32_t> index;
    std::vector<int> children;       // written tiles it will hold
    int64_t child_triangles = 0;     // of its children's content
    double child_error = 0.0;        // max over children: their error + their simplification's
  };
  void Write(const Cell& cell, OpenTile& tile);
  // Writes `tile` (staged, renamed) as a leaf or a level of detail; its index into written_.
  int WriteContent(TileMesh& tile);
  // A written tile's (or a node not written: `children`) content goes up into its parent node.
  void PushUp(int level, const Cell& cell, const engine::Mesh& mesh, const std::vector<int64_t>& keys,
              const std::vector<int>& spans, std::vector<int> children, int64_t triangles, double error);
  // Nodes whose region the drive has left (all when `all`), level by level upward.
  void FlushNodes(bool all);
  // `top`: the last node of the tree (at the end, none other waits).
  void FlushNode(const NodeKey& key, PendingNode& node, bool top);
  void WriteLodTree(int index);
  void MaybeWriteTileset();
  // A pending node holds (+1) or no longer holds (-1) vertex `key` with its span unknown; the
  // vertex's VertexCells goes when nothing needs it.
  void CountUnknownSpan(int64_t key, int delta);
  // state: "running", "complete" or "failed" (with error).
  void WriteTileset(const std::string& state, const std::string& error = "");

  TilesOptions options_;
  std::filesystem::path output_dir_, tiles_dir_;
  nlohmann::json identity_;
  std::function<std::array<double, 16>()> root_transform_fn_;
  OriginFor origin_for_;
  std::array<double, 16> root_transform_{};
  std::array<double, 16> local_frame_{};
  bool have_root_transform_ = false;
  WriteTileGlb write_;
  std::map<Cell, OpenTile> open_;
  std::vector<Written> written_;
  std::map<NodeKey, PendingNode> pending_;
  std::unordered_map<int64_t, VertexCells> vertex_cells_;  // with lod only
  int64_t lod_count_ = 0;
  int64_t parts_ = 0;
  std::size_t tileset_names_ = 0;                        // tiles the last tileset.json names
  std::chrono::steady_clock::time_point tileset_time_;   // when it was written
  TilesStats stats_;
};

// The content uris of a tileset's tile and its descendants, in tree order (depth first), as paths
// from the run folder `run`: the tiles and levels of detail, following the levels of detail's
// subtrees (external tilesets tiles/lod_NNNNNN.json, read from `run` as `role`; each listed in
// `subtrees` when given). Throws std::runtime_error saying where the tree is not one of tiles (a
// tile not an object, children not an array, a content without a string uri, a tileset content
// that is not imr's subtree or is named twice), is deeper than 64 or has more than kMaxTiles.
std::vector<std::string> TileContentUris(const std::filesystem::path& run, const nlohmann::json& tile,
                                         InputRole role = InputRole::kInput,
                                         std::vector<std::string>* subtrees = nullptr);

// A tileset.json read with bounds: a regular file of at most kMaxTilesetBytes, JSON. Throws
// std::runtime_error naming the file and what it is instead.
nlohmann::json ReadTilesetFile(const std::filesystem::path& path,
                               InputRole role = InputRole::kInput);

// The tiles of a run as its tileset.json (`tileset`, read) says: those it names, then those a
// killed or failed run wrote after its last version (tile files numbered on from the highest it
// names, without a gap), and tile files in tiles/ that are neither (left alone: not the run's).
struct RunTiles {
  std::vector<std::string> named;  // "tiles/tile_NNNNNN.glb", in tree order
  std::vector<std::string> after;  // written after the last tileset.json, in order
  std::vector<std::string> other;  // tile names that are not the run's
  // Levels of detail ("tiles/lod_NNNNNN.glb"): named, and written after the last tileset.json
  // (numbered on). Never merged: the leaves are the surface.
  std::vector<std::string> lod;
  std::vector<std::string> lod_trees;  // their subtrees' tilesets ("tiles/lod_NNNNNN.json") named
  std::vector<std::string> lod_after;  // GLBs and subtrees
};
RunTiles ListRunTiles(const std::filesystem::path& run_folder, const nlohmann::json& tileset,
                      InputRole role = InputRole::kInput);

// The local frame (TileWriter's root transform) from keyframe camera rotations (world -> camera,
// row-major): the cameras' mean up (-y axis) becomes +Z, their mean viewing direction +Y;
// column-major 4x4. Identity when the rotations give no up.
std::array<double, 16> TilesetFrame(const std::vector<std::array<double, 9>>& rotations);

// ECEF <- the local frame's coordinates at `origin`, column-major: ECEF <- ENU at the origin
// (WGS84), ENU <- local (the heading's turn about up, or the origin's enu_from_local), then
// `local_frame` (local <- sequence).
std::array<double, 16> GeoreferencedFrame(const TilesOrigin& origin,
                                          const std::array<double, 16>& local_frame);

// The origin of a local frame (TilesetFrame's, of a sequence whose frame stands at `anchor`):
// the anchor's position, the heading of the local +Y as the anchor turns it into ENU (for the
// log and the tileset), and the anchor's whole attitude (enu_from_local, tilt: the local +Z's
// angle from the anchor's up).
TilesOrigin OriginFromAnchor(const geo::GeoAnchor& anchor, const std::array<double, 16>& local_frame);

// z-up to glTF's y-up, row-major: a tile's root rotation (see the file comment).
std::array<double, 9> TileGltfRotation();

// A run's tiles as one mesh: tileset.json's tiles, and tile files a killed run wrote after its
// last tileset.json, vertices merged by key (positions from the first tile naming a key), in
// canonical order. Throws std::runtime_error naming the folder or file that cannot be read or
// does not fit (no tileset, a tile without `_VERTEX_KEY`).
// A run that did not finish leaves a part of the surface unwritten; where the tiles written so far
// touch only at a vertex (its fans split between written tiles and the surface never written),
// that vertex is kept apart, one copy per fan, so that what was written merges into a 2-manifold
// with boundary (a finished tileset is merged as it is: such a vertex is a defect there).
struct MergedTiles {
  engine::Mesh mesh;
  int tiles = 0;
  int64_t seam_vertices = 0;   // vertices named by more than one tile (merged)
  int64_t vertices_kept_apart = 0;  // copies made for the fans of a vertex the unwritten
                                    // surface would have joined (a run that did not finish)
  bool complete = false;       // the run finished its tileset (else it was killed or failed)
  std::string state;           // "complete", "running" (killed while running) or "failed"
  std::vector<std::string> notes;
};
MergedTiles MergeTiles(const std::filesystem::path& run_folder);

}  // namespace imr::pipeline
