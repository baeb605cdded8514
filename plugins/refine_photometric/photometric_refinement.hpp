// Photometric refinement of a triangle mesh from calibrated images: the core of the plugin
// org.imr.refine.photometric, with no SDK types (the plugin converts), so it is tested alone.
//
// Each vertex searches along its normal for the offset whose small tangent-plane patch looks
// the same (ZNCC) in the keyframes that see it, coarse to fine; an umbrella (Laplace-Beltrami)
// term keeps the sheet smooth where the images say nothing. A vertex no camera sees moves by the
// regulariser only. No move may flip a triangle or make the surface cross itself: such a step is
// undone (halved, then dropped).
#pragma once

#include <opencv2/core.hpp>

#include <Eigen/Core>

#include <array>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace imr::photometric {

// A keyframe: pinhole, world -> camera x_cam = R * X + t, pixel = K * x_cam (pixel centres at
// integer coordinates), and its image as 8-bit gray (CV_8UC1), the size the camera says.
struct View {
  Eigen::Matrix3d K = Eigen::Matrix3d::Identity();
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  cv::Mat gray;
};

struct RefineOptions {
  int levels = 3;                  // coarse-to-fine rounds; the search range halves each round
  int iterations_per_level = 3;    // search + update passes per round
  double search_range = 0.5;       // metres along the normal searched in the first round, +-
  int search_steps = 9;            // candidate offsets per side of the search range
  int patch_size = 7;              // patch samples per side (odd)
  double patch_pixels = 1.5;       // patch sample spacing, in pixels of the reference view
  int image_scale_levels = 2;      // image pyramid levels (coarse rounds use the coarse images)
  double min_zncc = 0.5;           // a match must score at least this to move a vertex
  double min_gain = 0.0;           // ... and beat the vertex's own position by this much
  int normal_smoothing = 0;        // 1-ring averagings of the normals the patches lie on
  int max_views = 5;               // views per vertex (the most frontal ones that see it)
  double max_view_angle_deg = 75;  // a view further from the normal than this does not count
  double step = 0.5;               // fraction of the way to the matched offset taken per pass
  double smoothness = 0.2;         // umbrella step (fraction of the Laplacian) per pass
  bool smooth_along_normal = false;  // the umbrella step projected on the vertex normal
  bool smooth_matched = true;      // false: only vertices without a photometric match smoothed
  double flatten_spikes = 0.0;     // > 0: an unmatched vertex farther than this many times its
                                   // neighbours' plane-fit residual from their plane goes onto it
  double max_move = 1.0;           // metres a vertex may move in total from its input position
  // Planarizing after the photometric passes: a vertex whose 2-ring lies on one plane (a robust
  // fit holding planarize_min_share of it within planarize_tolerance) goes onto that plane; a
  // corner stays. Rounds of it (0: off).
  int planarize = 0;
  double planarize_tolerance = 0.1;   // metres (the plugin gives it in median edge lengths)
  double planarize_min_share = 0.7;   // share of the 2-ring the plane must hold
  bool planarize_matched = true;      // false: vertices the images placed are not moved by it
  int depth_map_scale = 4;         // occlusion z-buffer at 1/scale of each view's resolution
  int threads = 1;                 // threads for the per-vertex search (joined before return)
  bool Check(std::string* error) const;  // false and a message naming the field when invalid
};

struct RefineStats {
  int64_t vertices = 0;             // vertices of the mesh
  int64_t vertices_active = 0;      // vertices the call was asked to refine
  int64_t vertices_seen = 0;        // active vertices at least two views see
  int64_t vertices_moved = 0;       // vertices whose final position differs from the input
  int64_t vertices_matched = 0;     // vertices a match placed in some pass (min_zncc, min_gain)
  int64_t moves_undone = 0;         // steps undone (fold-over or self-intersection)
  double mean_zncc_before = 0.0;    // mean best score at the input positions (seen vertices)
  double mean_zncc_after = 0.0;     // the same at the output positions
  double mean_move = 0.0;           // mean distance moved over moved vertices, metres
  int64_t vertices_planarized = 0;  // vertices the planarizing moved
  int64_t vertices_on_plane = 0;    // active vertices whose 2-ring held a plane (first round)
  double roughness_before = 0.0;    // mean angle between neighbouring face normals (degrees) over
  double roughness_after = 0.0;     // the interior edges of faces with an active vertex
  double seconds = 0.0;
};

// Refines `vertices` in place. `faces` index `vertices`, oriented counter-clockwise seen from the
// side the normal points to (free space, where the cameras are). `active[v]` non-zero: v may move
// and is refined; zero: v stays where it is (a seam vertex, a part no recent keyframe sees) but
// still bounds its neighbours. Empty `active`: every vertex is active. `views` are the keyframes;
// visibility (occlusion) is computed from the mesh itself. `cancelled`, when given, is polled
// between passes; returning true stops the refinement with the positions reached so far
// (consistent: no fold-over), and Refine returns false.
bool Refine(const std::vector<View>& views, const std::vector<std::array<uint32_t, 3>>& faces,
            const std::vector<uint8_t>& active, const RefineOptions& options,
            std::vector<Eigen::Vector3d>* vertices, RefineStats* stats,
            const std::function<bool()>& cancelled = {});

}  // namespace imr::photometric
