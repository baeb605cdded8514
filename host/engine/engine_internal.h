// Internal hooks into the engine for the micro-benchmarks (tools/bench/micro) and diagnostics:
// the hot paths one at a time (ray traversal, weight transfer, the manifold test, growing) on
// an engine that a stream has already built. Not public API: only the engine and the benchmarks
// include this header; it stays CGAL-free (cells are addressed through the engine's own lists).
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "host/engine/engine.h"

namespace imr::engine::internal {

// One weight transfer as the engine performed it (a copy of the policy's input).
struct RecordedTransfer {
  std::vector<double> removed_centroids;
  std::vector<double> removed_weights;
  std::vector<double> new_centroids;
};

// A facet of dO seen from both sides (diagnostics).
struct BoundaryFacetProbe {
  std::array<int64_t, 3> point_ids{};  // External point ids; -1 for a Steiner vertex.
  std::array<Vec3, 3> vertices{};
  double weight_in_o = 0.0;            // Weight of the cell of O.
  double weight_outside = 0.0;         // Weight of the cell outside O.
  bool outside_free = false;           // The outside cell is free space (weight > T_w).
  bool outside_hull_adjacent = false;  // It touches the convex hull (never joins O).
};

// A finite cell as the labelling sees it (diagnostics: its place against a known scene).
struct CellProbe {
  std::array<Vec3, 4> vertices{};
  std::array<int64_t, 4> point_ids{};  // External point ids; -1 for a Steiner vertex.
  double weight = 0.0;
  bool in_o = false;
  bool free = false;                   // weight > T_w
};

class EngineInternals {
 public:
  // --- Ray casting (paper §2.1). ---
  // Walks the segment point -> camera from the point's vertex and counts the cells it crosses,
  // without weighting anything: the traversal alone.
  static int64_t TraverseOnly(Engine& e, uint64_t point_id, uint64_t camera_id);
  // One full cast (T, N1, N2 weighted with sign +1 or -1); returns the cells weighted.
  static int64_t CastRay(Engine& e, uint64_t point_id, uint64_t camera_id, int sign);
  // The last `window` cameras of a point (external ids), as a move re-casts them.
  static std::vector<uint64_t> WindowCameras(const Engine& e, uint64_t point_id);

  // --- Weight transfer. ---
  // While on, every policy call stores a copy of its input (up to `limit` of them).
  static void RecordTransfers(Engine& e, bool on, size_t limit = 100000);
  static const std::vector<RecordedTransfer>& RecordedTransfers(const Engine& e);

  // --- Manifold test. ---
  // Collects up to `limit` cells next to dO (outside O with a facet on it, and cells of O with a
  // facet on it): the cells that growing and shrinking test. Returns how many.
  static size_t CollectBoundaryCells(Engine& e, size_t limit);
  // Runs the local manifold test (toggle one cell in or out of O) on every collected cell;
  // returns how many keep dO manifold. by_links: the reference form (each vertex's link rebuilt)
  // instead of the combinatorial one the engine uses.
  static int64_t TestCollectedCells(Engine& e, bool by_links = false);
  // While on, every manifold test runs in both forms and differences are counted (and make
  // CheckInvariants fail).
  static void CrossCheckManifoldTest(Engine& e, bool on);
  static int64_t ManifoldTestMismatches(const Engine& e);

  // --- Planned moves. ---
  // While on, every planned fill takes the exact apexes (no floating-point fill first).
  static void ExactFillOnly(Engine& e, bool on);
  // Fills made so far: {floating-point fills that passed the check, exact fills}.
  static std::array<int64_t, 2> FillCounts(const Engine& e);

  // --- Batches of rays (kExact). ---
  // A cast or un-cast batch is walked `group_rays` rays at a time, and a cast batch keeps its
  // walks as lists while they hold at most `listed_cells` cells (tests: the bounds' paths on
  // small inputs). 0 keeps the engine's own bound.
  static void SetBatchBounds(Engine& e, size_t group_rays, size_t listed_cells);

  // --- Growing. ---
  // Takes out of O (keeping dO manifold) the cells with a vertex within `radius` of `centre`;
  // they and their neighbours become seeds of the next grow. Returns the cells taken out.
  static int64_t ShrinkAround(Engine& e, const Vec3& centre, double radius);
  // Grows O from the current seeds (as at the end of a keyframe); returns the cells added.
  static int64_t Grow(Engine& e);

  // --- Diagnostics. ---
  static std::vector<BoundaryFacetProbe> ProbeBoundary(const Engine& e);
  static std::vector<CellProbe> ProbeCells(const Engine& e);
  // kExact: walks every cast ray again (exact predicates) and checks that each cell it crosses
  // holds it, and that no cell holds a ray that does not cross it. Empty when all agree, else
  // what disagreed first. Costs a re-cast of every ray (tests).
  static std::string CheckRaySets(Engine& e);
  // Forgets every weight and O, re-casts every point's rays (all its cameras) through today's
  // triangulation and grows O again: the labelling a batch run would give on the same cells.
  static void RecastAllAndRegrow(Engine& e);
  // kExact: forgets the cells each ray's cast listed, so that the next un-casts walk (the rays'
  // cells and weights stay).
  static void DropRayLists(Engine& e);
  // Empties O and grows it again from the best cell (weights kept).
  static void Regrow(Engine& e);

  // --- Breaking invariants on purpose (tests of CheckInvariants). ---
  // Toggles the first collected cell whose toggle would break dO's manifoldness, skipping the
  // test (counters kept in sync). Returns false when no collected cell would break it.
  static bool ForceNonManifoldToggle(Engine& e);
  // Sets a collected cell's weight without the engine's bookkeeping.
  static void OverwriteCollectedWeight(Engine& e, size_t index, double weight);
  // kExact: takes one cell out of a listed ray's list while the cell still holds the ray (what a
  // cell change that forgot Unlist would leave). Returns the point's id, or -1 when no ray is
  // listed.
  static int64_t UnlistOneCell(Engine& e);
};

}  // namespace imr::engine::internal
