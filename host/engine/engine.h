// The reconstruction engine: incremental 2-manifold reconstruction with moving points
// (Romanoni & Matteucci, sections 2-3). A Delaunay triangulation of the points and a
// Steiner grid, tetrahedra weighted by viewing rays, and the manifold set O of outside tetrahedra
// whose boundary dO is the surface. Per keyframe it takes new, moved and removed points and keeps
// dO a 2-manifold. Knows nothing of files, JSON or plugins; CGAL stays behind the pimpl.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "host/engine/weight_transfer_policy.h"
#include "host/util/geometry.h"

namespace imr::engine {

using Vec3 = ::imr::Vec3;

// Errors are values: ok() or a message naming what was refused.
class Status {
 public:
  Status() = default;
  static Status Ok() { return Status(); }
  static Status Error(std::string message) { return Status(std::move(message), false); }
  bool ok() const { return ok_; }
  const std::string& message() const { return message_; }

 private:
  Status(std::string m, bool ok) : ok_(ok), message_(std::move(m)) {}
  bool ok_ = true;
  std::string message_;
};

// How visibility is stored and updated when points move.
enum class VisibilityMode {
  kWeights,  // The paper's efficient approach: weights only, backward casting + transfer policy.
  kRays,     // The straightforward baseline (Lovi et al. 2011): per-cell ray lists, re-casting.
  kExact,    // Every cell holds the set of rays that cross it; where the triangulation changes,
             // only the rays of the destroyed cells are walked again, through the new cells.
             // Weights are exact (what re-casting every ray would give) and no policy is needed.
};
std::string ToString(VisibilityMode mode);
bool FromString(const std::string& s, VisibilityMode* mode);

// Which triangles of dO touching Steiner points the exported mesh leaves out.
enum class SteinerExportRule {
  kNone,         // Export all of dO (a closed surface).
  kAllSteiner,   // Drop triangles whose three vertices are Steiner points.
  kAnySteiner,   // Drop triangles with at least one Steiner vertex (default).
  kOpenSteiner,  // all_steiner's, then the regions of triangles with a Steiner vertex whose rim
                 // mostly borders nothing (sheets into the sky) go; those closing a gap between
                 // point triangles stay (DropOpenSteinerRegions). Whole meshes only: a run that
                 // writes its surface in parts keeps all_steiner's triangles.
};
std::string ToString(SteinerExportRule rule);
bool FromString(const std::string& s, SteinerExportRule* rule);

// What a ray longer than max_ray_length carves.
enum class LongRays {
  kSkip,        // Nothing (the paper: a point that far is not trusted).
  kNearCamera,  // Its max_ray_length next to the camera: that space is free wherever the point is.
};
std::string ToString(LongRays rule);
bool FromString(const std::string& s, LongRays* rule);

// Whether the engine forgets what the cameras left behind (EngineOptions::forget).
enum class ForgetMode {
  kOff,
  kOn,
  kAuto,  // On once the cameras are seen to travel (a drive), off while they stay around what
          // they look at (an object ring) or come in one update (an SfM model): Forgetting's rule.
};
std::string ToString(ForgetMode mode);  // "false", "true", "auto"
bool FromString(const std::string& s, ForgetMode* mode);

// The most Steiner grid nodes around one camera that EngineOptions::CheckSteinerGrid accepts: the
// grid covers a camera's rays, at most a cube of +-(max_ray_length + steiner_margin) in steps of
// steiner_spacing; each node is a vertex of the triangulation (a kB or so). 1e7 nodes: a spacing of
// 0.42 m at the default reach of 45 m; a reach of 1e12 m or a spacing of 1e-9 m would never end.
inline constexpr double kMaxSteinerNodesPerCamera = 1e7;

struct EngineOptions {
  double steiner_spacing = 5.0;       // Steiner grid step, metres (paper: 5 m).
  double steiner_margin = 5.0;        // Grid covers every ray +- margin (>= 1 step; issue 47).
  Vec3 steiner_origin = {0.37, 0.61, 0.23};  // Grid offset in units of spacing (off the axes
                                      // and the z = 0 plane where synthetic surfaces lie).
  double steiner_jitter = 1e-3;       // Each Steiner point moves off its grid node by up to this
                                      // fraction of steiner_spacing (deterministic per node).
  double w1 = 1.0;                    // Weight added to cells traversed by a ray (T).
  double w2 = 0.8;                    // Weight added to their neighbours (N1).
  double w3 = 0.2;                    // Weight added to the neighbours of N1 (N2).
  double free_threshold = 1.0;        // T_w: a cell is free space when weight > T_w (weights
                                      // and rays modes).
  int exact_min_rays = 2;             // kExact: a cell is free space when at least this many
                                      // rays cross it.
  int window = 15;                    // W: rays re-cast on a move come from the last W cameras.
  double max_ray_length = 40.0;       // Rays longer than this (metres) are not cast whole.
  LongRays long_rays = LongRays::kNearCamera;  // What such a ray carves.
  VisibilityMode visibility_mode = VisibilityMode::kExact;  // Exact ray sets, the paper's
                                      // weights, or the baseline.
  int rays_per_cell = 5;              // K of the forgetting heuristic (kRays mode only).
  int camera_path = 20;               // After each update, the cells holding the last this many
                                      // camera centres and the segments between them join O
                                      // (free space: the vehicle drove there), each with the
                                      // free cells around it that keep dO manifold; 0: off.
  int camera_path_repair = 16;        // Rounds of such free cells per path cell (each round: the
                                      // free cells around a vertex the cell left irregular).
  double camera_path_radius = 10.0;   // A path camera whose cell still is not in O: cells within
                                      // this distance (m) of its cell's vertices leave O and grow
                                      // again, from the camera's cell first; 0: never.
  double regrow_radius = 2.0;         // After each update, cells within this distance of a moved
                                      // or new point leave O (keeping it manifold) and are grown
                                      // again in weight order; 0: off.
  double min_move_fraction = 0.0;     // A move shorter than this fraction of the distance from
                                      // the point's vertex to its nearest neighbour is not made:
                                      // the vertex and its rays stay (new cameras are cast from
                                      // it) and the next move is measured from it; 0: every move.
  SteinerExportRule steiner_export = SteinerExportRule::kAnySteiner;  // Export filter.
  double open_steiner_crease = 180.0; // open_steiner: triangles with a Steiner vertex join one
                                      // region across an edge only when their normals differ by
                                      // at most this (degrees; 180: always), so a sheet meeting
                                      // a truck's side at a crease is weighed on its own rim.
  double fill_holes_perimeter = 16.0; // Export: holes of the exported mesh with a perimeter up
                                      // to this (metres; 0: none) are closed by a fan around a
                                      // new vertex at their centroid.
  int smoothing_iterations = 0;       // Export: Taubin lambda|mu smoothing steps (boundary
                                      // vertices fixed; topology unchanged); 0: none.
  double min_component_area = 1.0;    // Export: a connected piece of the surface with less
                                      // area than this many steiner_spacing^2 is dropped (specks
                                      // stray points leave in free space); 0: keep every piece.
                                      // Streamed: a piece is weighed once it is whole
                                      // (SurfaceStream). Default measured: docs/benchmarks.md.
  double retriangulate_planes = 0.0;  // Export, after the mesh_refiner stage: regions whose
                                      // vertices lie within this many median edge lengths of one
                                      // plane are triangulated again on it, folds taken out,
                                      // boundary and vertices kept (plane_retriangulation.h);
                                      // streamed: per released piece. 0: off.
  bool flip_edges = false;            // Export, after retriangulate_planes: interior edges flipped
                                      // where the other diagonal lowers the angles between
                                      // neighbouring faces (edge_flips.h); vertices and boundary
                                      // kept; streamed: per released piece.
  int filter_normals = 0;             // Export, after flip_edges: rounds of bilateral normal
                                      // filtering (faces' normals filtered, vertices moved to fit
                                      // them; corners kept; normal_filter.h); boundary, faces and
                                      // seam vertices kept; streamed: per released piece. 0: off.
  double filter_normals_spatial = 1.0;  // filter_normals: the spatial Gaussian's sigma on the
                                        // distance between face centroids, x median edge length.
  double filter_normals_range = 0.35;   // filter_normals: the range Gaussian's sigma on the
                                        // difference of two unit normals (90 degrees: 1.41).
  int mesh_pass_rounds = 1;           // Export: times retriangulate_planes, flip_edges and
                                      // filter_normals run in turn (a later round triangulates
                                      // again what the filter flattened); streamed: per piece.
  bool drop_back_faces = false;       // Export of a whole mesh (no forgetting), after the passes:
                                      // faces the keyframes see from behind more than from the
                                      // front are dropped (the run's pipeline draws them;
                                      // host/pipeline/run.cc). Streamed: off.
  bool transfer_on_insert = false;    // Cells created by inserting a NEW point (or a Steiner
                                      // point) get weights through the policy (keyframe update, step 3: insert)
                                      // when true; else they start at 0 and the point's own rays,
                                      // cast right after, weight them. Moves always use the
                                      // policy. See the note in engine.cc on why false is default.
  bool transfer_camera_side = true;   // When the policy weights the cells around a point just
                                      // inserted or moved, a new cell behind the point (its
                                      // centroid on the far side from the point's cameras)
                                      // starts at 0 instead: a surface point has matter behind
                                      // it, and the policy would carry the free space in front
                                      // of its old position through the surface.
  bool nonnegative_weights = true;    // A backward cast never takes a weight below 0. Cells it
                                      // crosses may have got their weight from the policy (or 0
                                      // at an insertion), not from the ray cast forward; without
                                      // the floor they sink below 0 and stay matter.
  double shrink_radius = 6.0;         // Enclosing set E: D plus cells around D's vertices that
                                      // lie within this distance (metres) of the point.
  int shrink_passes = 3;              // Shrink work bound: tries per cell of E (a refused cell
                                      // is retried when a neighbour leaves O).
  double weight_unit = 1e-6;          // Weights are int64 multiples of this (exact backward cast).
  int max_cells_per_ray = 200000;     // Safety bound on one traversal (never an endless walk).
  bool check_invariants = false;      // Run the full dO check after every update (slow; tests;
                                      // the job key of the same name).
  bool filtered_walk = true;          // Rays are walked from their vertex with double-precision
                                      // tests on terms cached per vertex, CGAL's exact walk
                                      // where a test is within rounding: the same cells as
                                      // CGAL's walk. false: CGAL's walk for every ray.
  bool planned_moves = true;          // kExact: a keyframe's moves are planned on the engine's
                                      // threads (what each does to its cells, read only) and
                                      // committed in order; false: each made with CGAL's vertex
                                      // removal and insertion (the same cells and weights).
  ForgetMode forget = ForgetMode::kAuto;  // Long drives (DESIGN.md section 10): the part of
                                      // the triangulation that no live camera, ray or point can
                                      // reach any more is final: its part of dO is handed out
                                      // (TakeFinalParts) and its cells, rays and points are
                                      // freed, so memory stays flat in the drive's length.
                                      // kAuto: so once the cameras travel (Engine::forgetting).
  double forget_distance = 0.0;       // A cell is final once it lies this far (metres) behind
                                      // every one of the last `window` cameras; 0: derived
                                      // from the options (ForgetDistance).
  double forget_step = 0.0;           // Forgetting runs each time the newest camera has moved
                                      // this far (metres) since it last ran; 0: derived
                                      // (2 x steiner_spacing).
  int num_threads = 0;                // Threads casting rays and planning moves (kExact): 0 =
                                      // every core of the process's affinity mask. The mesh is
                                      // the same for any number (results are applied in one
                                      // fixed order).

  // Empty when every field is usable; otherwise which field and why (the validator shape of
  // every options struct of imr).
  std::string Check() const;
  // forget_distance, or when 0 what a live change can reach behind the cameras: a ray carves
  // max_ray_length, the Steiner grid reaches steiner_margin further, shrink takes cells within
  // shrink_radius of a point, and a cell spans about a grid step.
  double ForgetDistance() const;
  // forget_step, or when 0 two grid steps (a step scans the vertices behind; rays are freed
  // at steps, so a longer one keeps more of them: four steps held ~15-40 MB more on the dense
  // street for ~10 % less forgetting time).
  double ForgetStep() const;
  // min_component_area in square metres: that many steiner_spacing^2.
  double MinComponentArea() const;
  // Nodes of the Steiner grid one camera's rays can reach at most (rays in every direction): a
  // cube of 2 (max_ray_length + steiner_margin) / steiner_spacing + 2 nodes a side.
  double SteinerNodesPerCamera() const;
  // Empty when that grid has at most kMaxSteinerNodesPerCamera nodes, else its size, the
  // memory it would take and the options to change. Apart from Check: the lengths a job gives
  // may be scaled to the scene before they are used (pipeline/scale.h). The engine refuses to
  // start with such options.
  std::string CheckSteinerGrid() const;
};

struct Camera {
  uint64_t id = 0;
  Vec3 center{};  // Camera centre in world coordinates: the start of its viewing rays.
  // Not used by the engine (rays need only the centre); carried for callers and future use.
  std::array<double, 9> rotation{1, 0, 0, 0, 1, 0, 0, 0, 1};  // World -> camera, row-major.
  std::array<double, 4> intrinsics{};                        // fx, fy, cx, cy (0 = unknown).
};

struct NewPoint {
  uint64_t id = 0;
  Vec3 position{};
  std::vector<uint64_t> camera_ids;  // Observing cameras, known already or in the same update.
};

struct MovedPoint {
  uint64_t id = 0;
  Vec3 position{};                   // The new estimate.
  std::vector<uint64_t> camera_ids;  // Extra observing cameras since the last update (optional).
};

// What the refiner delivers at one keyframe.
struct KeyframeUpdate {
  std::vector<Camera> cameras;
  std::vector<NewPoint> new_points;
  std::vector<MovedPoint> moved_points;
  std::vector<uint64_t> removed_points;
  // No update follows (a source that knows its end says so: an SfM model, a SLAM file). No cell
  // is destroyed after it, so kExact casts its rays as weights only, without listing them in
  // the cells they cross (the same weights and surface; a model's one batch of long rays took
  // 8 bytes per cell crossed, 300 MB). ApplyUpdate refuses any update after it.
  bool last = false;
};

struct Mesh {
  std::vector<double> vertices;    // Packed xyz.
  std::vector<uint32_t> faces;     // 3 per triangle, oriented: normals toward free space (O).
  std::vector<int64_t> point_ids;  // Per vertex: the point id, -1 for a Steiner point.
};

// What the export dropped as pieces too small (EngineOptions::min_component_area).
struct DroppedComponents {
  int64_t components = 0;
  int64_t faces = 0;
  int64_t vertices = 0;
  double area = 0.0;  // square metres
};

// A piece of the exported surface, handed out while the run goes on (EngineOptions::forget,
// DESIGN.md section 10): triangles of dO that can no longer change, through the Steiner filter
// (steiner_export), with the vertices they use. Holes are not filled and pinched vertices not
// split here: both need a vertex's whole fan, which the consumer has once the vertex is completed.
// Parts share their seam vertices by key, never by index: the union of every part of a run (the
// last from Engine::FinishSurface), vertices merged by key, is the run's filtered dO, and after
// SplitPinchedVertices, FillSmallHoles and SmoothTaubin it is what ExtractMesh would return.
struct SurfacePart {
  std::vector<double> vertices;    // Packed xyz, per vertex of this part.
  std::vector<int64_t> keys;       // Per vertex: its key, unique within the run, the same (at the
                                   // same position) in every part that names the vertex.
  std::vector<int64_t> point_ids;  // Per vertex: the point id, -1 for a Steiner point.
  std::vector<uint32_t> faces;     // 3 per triangle, indices into this part's vertices, oriented
                                   // as Mesh::faces (normals toward free space).
  std::vector<int64_t> completed;  // Keys of vertices that no later part names (every triangle
                                   // around them, filtered or not, has been handed out), among
                                   // the vertices this part or an earlier one named.
  int64_t update = 0;              // Updates applied when it was handed out.
};

struct PhaseTimes {
  double steiner = 0.0;  // Growing the Steiner grid (seconds).
  double shrink = 0.0;
  double move = 0.0;     // Moves, without their ray casting.
  double insert = 0.0;   // Insertions and removals of points, without ray casting.
  double cast = 0.0;     // All ray casting (forward, backward, re-casting).
  double threaded = 0.0;  // Of cast and move, kExact: the keyframe's two ray batches and the
                          // moves' plans, which run on the engine's threads (the rest of a
                          // keyframe runs on one).
  double scan = 0.0;     // kRays: whole-triangulation scans removing a moved point's rays.
  double grow = 0.0;
  double extract = 0.0;  // ExtractMesh.
  double forget = 0.0;   // forget: finding what became final, handing it out, rebuilding.
  double rebuild = 0.0;  // Of forget, rebuilding the triangulation without what it forgot.
  double total = 0.0;    // ApplyUpdate wall time.
};

struct EngineStats {
  PhaseTimes time;                       // Accumulated over all updates.
  std::vector<double> keyframe_seconds;  // ApplyUpdate wall time per update.
  int64_t updates = 0;
  int64_t rays_cast = 0;              // Forward casts (including re-casts).
  int64_t rays_cast_backward = 0;
  int64_t rays_skipped_too_long = 0;  // Longer than max_ray_length (cast whole: none of them).
  int64_t rays_truncated_to_camera = 0;  // Of those, cast over max_ray_length next to the camera.
  int64_t rays_truncated = 0;         // Hit max_cells_per_ray or a traversal failure.
  int64_t rays_uncast_listed = 0;     // kExact: of rays_cast_backward, taken out of the cells
                                      // their cast listed, without a walk.
  int64_t rays_rewalked = 0;          // kExact: rays walked again through the new cells of a hole.
  int64_t rays_rewalked_exact = 0;    // kExact: of those, walked with exact predicates (near an
                                      // edge or vertex, or no entry facet known).
  int64_t rays_walked_exact = 0;      // Rays walked with CGAL's traverser rather than the
                                      // filtered walk (undecided, not starting at their vertex,
                                      // the camera on a facet; or filtered_walk off).
  int64_t cells_rewalked = 0;         // kExact: new cells those walks gave a ray.
  int64_t ray_mismatches = 0;         // kExact: a ray not found where a walk expected it (or
                                      // found where no walk reaches): degenerate traversals.
  int64_t cells_traversed = 0;        // Cells of T over all rays.
  int64_t cells_weighted = 0;         // Cells of T, N1 and N2 over all rays.
  int64_t points_inserted = 0;
  int64_t points_moved = 0;
  int64_t moves_skipped = 0;          // Move refused: its cells could not be shrunk out of O.
  int64_t points_dropped = 0;         // New point dropped (conflict zone met O after shrink).
  int64_t points_duplicate = 0;       // New point onto an existing vertex: not inserted.
  int64_t moves_duplicate = 0;        // Move onto an existing vertex: refused (moves_skipped).
  int64_t moves_in_place = 0;         // kExact moves that kept the cells (the vertex stayed inside
                                      // its star and no facet flipped): no re-insertion.
  int64_t moves_planned_ahead = 0;    // kExact: moves planned on the engine's threads ahead of
                                      // their turn (planned_moves, more than one thread).
  int64_t moves_replanned = 0;        // Of those, planned again at their turn: an earlier move of
                                      // the same batch had changed their cells.
  int64_t moves_below_min = 0;        // Moves shorter than min_move_fraction of the local
                                      // spacing: not made.
  int64_t points_reentered = 0;       // Points refused at insertion that entered at a later move.
  int64_t points_removed = 0;
  int64_t observations_over_limit = 0;  // Observations of a point beyond its 65,535th camera:
                                        // not kept (their rays are not cast).
  int64_t steiner_points = 0;
  int64_t steiner_dropped = 0;
  int64_t cells_grown = 0;
  int64_t cells_opened = 0;           // Cells that joined O on the camera path (camera_path).
  int64_t camera_regrowths = 0;       // Cameras whose cell was outside O after grow: O peeled
                                      // around them and grown again (camera_path_radius).
  int64_t camera_cells_regrown = 0;   // Of those, the cells in O after it.
  int64_t cells_shrunk = 0;
  int64_t policy_calls = 0;
  int64_t rays_scan_cells = 0;        // kRays: cells visited by the whole-triangulation scans.
  int64_t vertices = 0;               // Current finite vertices (points + Steiner).
  int64_t cells = 0;                  // Current finite cells.
  int64_t cells_in_o = 0;
  // Each keyframe's new cameras, after the update (or, for a camera that came before O existed,
  // after the first update that has an O): how many, and how many have their centre in a
  // cell of O (free space). A camera inside matter means the surface closes over the path the
  // cameras took (issue 34: the camera path should be free space).
  int64_t cameras_checked = 0;
  int64_t cameras_in_o = 0;
  // forget (EngineOptions::forget):
  int64_t forget_steps = 0;           // Steps run (the newest camera moved forget_step).
  // kAuto: the update (1-based) from which the engine forgets, 0 while it does not (kOn: 1);
  // the steps that had cells to make final but kept them live (the cameras did not travel);
  // and what the rule measured at the last of its looks (camera_spread 0: not measured).
  int64_t forget_on_update = 0;
  int64_t forget_steps_held = 0;
  double forget_camera_spread = 0.0;  // Spread of the camera centres (median distance from
  double forget_point_spread = 0.0;   // their per-axis median), of the points likewise
  double forget_camera_step = 0.0;    // The median distance between consecutive cameras
  int64_t cells_finalized = 0;        // Cells that became final.
  int64_t cells_final = 0;            // Current cells that are final (finite and infinite).
  int64_t rebuilds = 0;               // Triangulations rebuilt without forgotten vertices.
  int64_t rebuilds_abandoned = 0;     // Rebuilds dropped: a live cell was not in the rebuilt
                                      // triangulation (not expected: a degenerate case).
  int64_t vertices_forgotten = 0;     // Vertices the rebuilds left out.
  int64_t points_forgotten = 0;       // Points retired (their updates are ignored since).
  int64_t point_records_freed = 0;    // Of those, records freed (no live cell held their rays).
  int64_t updates_of_forgotten_points = 0;  // Moves and removals of retired points: ignored.
  int64_t changes_refused_final = 0;  // Insertions, moves and removals refused: they would
                                      // have destroyed or reshaped a final cell in O or next
                                      // to O.
  int64_t points_refused_final = 0;   // Of those, new points: points in space already handed
                                      // out (the cameras came back to it); not inserted.
  int64_t shrinks_blocked_final = 0;  // Moves and insertions whose cells could not leave O
                                      // with a final cell of O next to them (it stays: the
                                      // surface handed out); skipped or dropped (counted in
                                      // moves_skipped, points_dropped too).
  int64_t components_started = 0;     // Components of O grown from a camera's cell that
                                      // touched no O (the cameras came back where O was
                                      // forgotten).
  int64_t final_cells_replaced = 0;   // Final cells with no part in the surface destroyed by a
                                      // change (a grid growing sideways at a bend).
  int64_t parts = 0;                  // SurfaceParts handed out (FinishSurface's included).
  int64_t part_triangles = 0;         // Their triangles.
  // At each step: the update, the live (not final) cells, the points kept, the vertices.
  struct LiveSample {
    int64_t update = 0, live_cells = 0, points = 0, vertices = 0;
  };
  std::vector<LiveSample> live_samples;
};

// Where the engine's memory is (Engine::Memory), in bytes: the sizes of its structures and the
// capacities of their containers, without the allocator's own overhead (RSS is larger).
struct EngineMemory {
  int64_t cells = 0;             // CGAL's cell storage with the cells' infos (capacity).
  int64_t vertices = 0;          // CGAL's vertex storage (capacity).
  int64_t ray_entries = 0;       // kExact, kRays: the cells' ray lists (capacity).
  int64_t ray_entries_used = 0;  // Of those, entries held (live or stale).
  int64_t ray_entries_live = 0;  // kExact: of those, the current casts of their rays.
  int64_t points = 0;            // Point records with their per-ray vectors, the id index and
                                 // the ids of points forgotten.
  int64_t ray_batch_lists = 0;   // kExact: the last cast batch's cell lists (un-cast next).
  int64_t steiner_nodes = 0;     // The Steiner grid's placed nodes.
  int64_t cameras = 0;           // Cameras and their index.
  int64_t Total() const {
    return cells + vertices + ray_entries + points + ray_batch_lists + steiner_nodes + cameras;
  }
};

struct ManifoldCheckResult {
  bool ok = true;
  std::string message;          // First problem found, empty when ok.
  int64_t boundary_triangles = 0;
  int64_t boundary_vertices = 0;
  int64_t cells_in_o = 0;
};

namespace internal {
class EngineInternals;  // Benchmark and diagnostic hooks (engine_internal.h); not public API.
}

class Engine {
 public:
  // The policy is not owned and must outlive the engine; it may be null in kRays mode.
  Engine(const EngineOptions& options, WeightTransferPolicy* policy);
  ~Engine();
  Engine(const Engine&) = delete;
  Engine& operator=(const Engine&) = delete;

  // Options or policy unusable: every ApplyUpdate returns this error.
  const Status& init_status() const;

  // One keyframe: cameras, removed points, moves, new points, then growing. A bad update (NaN,
  // unknown camera or point id, ...) is refused as a whole before anything changes.
  Status ApplyUpdate(const KeyframeUpdate& update);

  // The exported surface: dO filtered by options().steiner_export, finished (FinishExportedMesh;
  // `dropped`, optional, gets the small components it dropped).
  Mesh ExtractMesh(DroppedComponents* dropped = nullptr) const;
  // dO itself, unfiltered (a closed 2-manifold).
  Mesh ExtractBoundary() const;

  // The parts of the surface that became final since the last call (SurfacePart; empty unless
  // options().forget), in the order they became final.
  std::vector<SurfacePart> TakeFinalParts();
  // The rest of the surface, as the run's last part: every triangle of the filtered dO not handed
  // out yet, every vertex completed. Without forgetting it is the whole filtered dO. Call it once,
  // after the last update.
  SurfacePart FinishSurface();
  // The surface not handed out yet, as a part (its vertices keyed, none completed): merged with
  // the parts taken so far and finished (FinishExportedMesh), the whole surface now, in the
  // middle of a run that forgets (the Python module's mesh). The run goes on unchanged.
  SurfacePart LiveSurface();

  const EngineStats& Stats() const;
  // What the engine's structures take now (walks every cell: milliseconds on a large scene).
  EngineMemory Memory() const;
  const EngineOptions& options() const;
  // Whether the engine forgets now: options().forget is kOn, or kAuto and the cameras have
  // been seen to travel (once on, it stays on). Before it is on, no part is handed out.
  bool forgetting() const;

  // Polled in the update's long loops (the Steiner grid): when it returns true, ApplyUpdate
  // stops and returns an error starting "stopped"; the engine is then not to be used further.
  // A signal handler's flag, or a deadline. Empty (the default): never stops.
  void SetStopCheck(std::function<bool()> stop_requested);

  // Full check of dO (not the local test): every edge in exactly two boundary triangles with
  // opposite orientations, every vertex one fan, no infinite cell in O, Delaunay valid.
  ManifoldCheckResult CheckInvariants() const;

  // --- Lower-level access, for tests and the benchmark. ---
  // Casts (sign +1) or casts backward (sign -1) the rays from the given cameras to a point.
  Status CastPointRays(uint64_t point_id, const std::vector<uint64_t>& camera_ids, int sign);
  // Weight of every finite cell as integer units, in a deterministic order (by sorted vertices).
  std::vector<std::pair<std::array<int64_t, 4>, int64_t>> CellWeights() const;
  // Current position of a point in the triangulation; false if absent (dropped or removed).
  bool PointPosition(uint64_t point_id, Vec3* position) const;
  size_t NumPoints() const;  // Points currently in the triangulation.

 private:
  friend class internal::EngineInternals;
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Puts a mesh in a canonical order that depends only on its geometry and point ids (faces sorted,
// each starting at its smallest vertex, orientation kept; vertices numbered by first use), so the
// same surface is written identically by every run. ExtractMesh and ExtractBoundary return
// canonical meshes. `new_index` (optional) receives each old vertex's new index.
void CanonicalizeMesh(Mesh* mesh, std::vector<uint32_t>* new_index = nullptr);

// Closes every boundary loop of at most `max_edges` edges and `max_perimeter` in length with a
// fan of triangles around a new vertex (point id -1) at its centroid; a 2-manifold with boundary
// stays one. Returns the holes closed.
int FillSmallHoles(Mesh* mesh, double max_perimeter, int max_edges = 64);
// Taubin's lambda|mu smoothing (`iterations` pairs of steps toward the neighbours' mean): noise
// is smoothed without the shrinking of plain Laplacian steps. Boundary vertices stay; faces and
// topology are unchanged.
void SmoothTaubin(Mesh* mesh, int iterations, double lambda = 0.5, double mu = -0.53);
// Drops every connected component (triangles joined through a shared vertex) whose area is
// under `min_area`, and the vertices no face names any more; the order of what stays is kept.
// Whole components go, so a 2-manifold stays one. Adds what it dropped to `dropped` (optional).
void DropSmallComponents(Mesh* mesh, double min_area, DroppedComponents* dropped = nullptr);
// Drops the faces whose `drop` entry (one per face) is non-zero; then a vertex left with several
// fans gets a copy per extra fan (SplitPinchedVertices), vertices no face names go, and so do the
// components under `min_area` (DropSmallComponents, adding to `dropped`). A 2-manifold with
// boundary stays one; the order of what stays is kept. Returns the faces dropped by `drop` (none:
// the mesh is left as it was).
int64_t DropFaces(Mesh* mesh, const std::vector<uint8_t>& drop, double min_area,
                  DroppedComponents* dropped = nullptr);

// steiner_export open_steiner on a mesh filtered by all_steiner: the triangles with a Steiner
// vertex (point id -1), joined across shared edges whose two triangles' normals differ by at most
// `crease_deg` (180: every shared edge), form regions; a region whose rim has fewer edges shared
// with triangles between points than edges bordering anything else (nothing, only dropped
// all-Steiner triangles, or another region) goes. Returns the triangles dropped; vertices no face
// names go too. Pinches it leaves are split by FinishExportedMesh, which calls it.
int64_t DropOpenSteinerRegions(Mesh* mesh, double crease_deg = 180.0);

// What ExtractMesh does after taking dO through the Steiner filter: open_steiner's regions dropped,
// pinched vertices split (unless the rule is kNone), small holes filled and Taubin smoothing as the
// options say, small components dropped (`dropped`, optional, gets what went), canonical order.
void FinishExportedMesh(Mesh* mesh, const EngineOptions& options, DroppedComponents* dropped = nullptr);
// The union of a run's parts (SurfacePart) as one mesh, vertices merged by key, before
// FinishExportedMesh. Empty string, or why the parts do not fit together (a key at two positions,
// a face index out of range).
std::string MergeSurfaceParts(const std::vector<SurfacePart>& parts, Mesh* merged);

// Checks an exported mesh: every edge in one or two triangles (two with opposite orientation),
// every vertex one closed or open fan. closed = true also requires every edge in two triangles.
ManifoldCheckResult CheckMesh(const Mesh& mesh, bool closed);

}  // namespace imr::engine
