// Remeshing for the photometric refinement: the crust on real imagery is in which triangles the
// carving chose between sparse points, not only where the vertices are, so the stage may change
// triangles. Edges longer than a bound are split at their midpoint (longest first), then edges
// are flipped where the flip lowers the total dihedral angle of the five edges it touches
// (Dyn, Hormann, Kim & Levin 2001: "Optimizing 3D triangulations using discrete curvature
// analysis"). No edge is collapsed: the mesh_refiner contract refuses fewer vertices than the
// host sent, and an unreferenced vertex would reach the exports (docs/refinement.md).
//
// What never changes: a boundary edge (so the boundary loops and their vertices), a locked
// vertex's faces (a FIXED vertex, or one whose fan the caller does not hold), a crease (an edge
// whose faces meet at more than corner_deg stays, and no flip brings a crease beside it below
// that). A flip never folds (each new face within max_turn_deg of both faces it replaces),
// never makes a degenerate face or an edge that exists already, and never shows a camera more
// back sides than the faces it replaces did (no more surface seen from behind).
#pragma once

#include <Eigen/Core>

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace imr::photometric {

struct RemeshOptions {
  double max_edge = 0.0;        // split interior edges longer than this (0: no splits)
  int64_t max_new_vertices = -1;  // at most this many splits (-1: as many faces as the input)
  int flip_passes = 10;         // sweeps over the edges queued for a flip (each sweep re-queues
                                // the edges around a flip)
  double corner_deg = 60.0;     // an edge whose faces meet at more than this is a crease: kept
  double fold_deg = 180.0;      // ... unless they meet at more than this: a fold (the sheet turns
                                // back on itself, its two faces overlapping), flipped when the
                                // two new faces agree with each other and with one of the old
                                // (180: no fold is flipped)
  double max_turn_deg = 75.0;   // a new face's normal within this of both faces it replaces
  double min_quality = 0.05;    // a flip's new faces at least this shaped (1: equilateral, 0:
                                // degenerate), unless they are no worse than the old ones
  double min_gain_deg = 0.5;    // a flip must lower the five edges' total dihedral by this much
  bool Check(std::string* error) const;  // false and a message naming the field when invalid
};

// A camera centre, and how far from it the surface counts as seen by it (infinity: everywhere).
struct Viewpoint {
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  double range = 0.0;
};

struct RemeshStats {
  int64_t edges_split = 0;
  int64_t edges_flipped = 0;
  int64_t creases_kept = 0;      // flips refused because the edge or one beside it is a crease
  int64_t folds_flipped = 0;     // of edges_flipped, folds (fold_deg) taken out
  int64_t flips_refused = 0;     // flips that would lower the dihedral but fold or degenerate
  int64_t flips_facing_away = 0;  // ... or show a viewpoint more back sides than before
  double total_dihedral_before = 0.0;  // sum over interior edges of the dihedral angle, degrees
  double total_dihedral_after = 0.0;
  int64_t interior_edges_before = 0;   // the edges those sums run over
  int64_t interior_edges_after = 0;
  bool changed() const { return edges_split > 0 || edges_flipped > 0; }
};

// Remeshes `faces` (counter-clockwise seen from free space, a 2-manifold with boundary; indices
// into `vertices`) in place. `viewpoints`: the cameras that see no more back sides after it. `locked[v]` non-zero: no face of v changes (empty: none locked).
// New vertices (midpoints) are appended to `vertices`, to `locked` (unlocked) when it is not
// empty, and their parent edge's ends to `parents` when given. An edge in more than two faces or
// a repeated directed edge (not a manifold) locks its ends rather than failing.
RemeshStats Remesh(const RemeshOptions& options, const std::vector<Viewpoint>& viewpoints,
                   std::vector<Eigen::Vector3d>* vertices,
                   std::vector<std::array<uint32_t, 3>>* faces, std::vector<uint8_t>* locked,
                   std::vector<std::array<uint32_t, 2>>* parents = nullptr);

// The dihedral angle (degrees) between the faces of each interior edge, summed and counted:
// the remesh's objective, and the roughness figure's numerator (mean = sum / count).
double TotalDihedralDeg(const std::vector<Eigen::Vector3d>& vertices,
                        const std::vector<std::array<uint32_t, 3>>& faces, int64_t* interior_edges = nullptr);

}  // namespace imr::photometric
