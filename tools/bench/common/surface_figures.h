// The figures of a surface a user sees, for `imr-bench quality` (issue 45): each computed the
// same way for every mesher's mesh (imr's, OpenMVS's, the peers'), from plain packed arrays.
//   - roughness: the mean angle between the normals of neighbouring faces, over every edge, and
//     over the edges whose two faces lie on one true plane only (imr-synth's planes and boxes:
//     a flat façade meshed flat gives 0° there, whatever the corners between planes do);
//   - seen from behind: report.json's mesh.back_facing (render::MeasureBackFacing), on any mesh,
//     from the cameras of every 10th keyframe of a run's COLMAP export;
//   - small components: how many connected pieces each hold under 0.5 % of the mesh's area, and
//     their share of it (floating specks and curtains).
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <vector>

#include "host/eval/mesh_stats.h"
#include "host/eval/synthetic_truth.h"
#include "host/io/colmap_model.h"
#include "host/render/rasterizer.h"
#include "host/util/geometry.h"

namespace imr::bench {

// The mean angle, in degrees, between the normals of the two faces of each edge that has exactly
// two (a plane meshed flat: 0; the spikes of a surface through noisy points: tens). 0 when no
// edge has two faces.
double Roughness(const std::vector<double>& xyz, const std::vector<uint32_t>& faces);

struct PlaneRoughness {
  double degrees = 0.0;      // mean angle over the counted edges (0 when none)
  int64_t edges = 0;         // edges whose two faces are on one true plane
  double face_share = 0.0;   // share of the faces with all three vertices on one true plane
};
// Which true plane a point lies on: its id (>= 0), or -1 when it is on none or near two.
using PlaneOf = std::function<int(const Vec3&)>;
// The roughness over the edges whose two faces have all their vertices on the same plane
// (plane_of), i.e. away from the true surface's corners and from what is not near it at all.
PlaneRoughness RoughnessOnPlanes(const std::vector<double>& xyz, const std::vector<uint32_t>& faces,
                                 const PlaneOf& plane_of);
// imr-synth's scene (world frame): a point is on a plane when the rects within `tolerance` of it
// (host/synthetic/scene.h) all lie in one plane (coplanar rects share an id); near two planes (a
// box's edge, a kerb) or none: -1. The returned function keeps its own copy of `truth`.
PlaneOf SyntheticPlanes(const eval::SyntheticTruth& truth, double tolerance);

struct SmallComponents {
  int64_t components = 0;  // connected components (through shared vertices)
  int64_t small = 0;       // of those, each under `share` of the whole area
  double area_share = 0.0; // their summed area over the whole area
};
// From ComputeMeshStatistics's per-component areas; `share` in (0, 1) (the 0.5 %: 0.005).
SmallComponents SmallComponentsOf(const eval::MeshStatistics& stats, double share = 0.005);

// The cameras of every `every`-th keyframe of a run's COLMAP export (images by id; keyframe k is
// the image of rank k * keyframe_every, as PrepareOpenMvsColmap and the front end choose them),
// as render cameras. PINHOLE and SIMPLE_PINHOLE only (imr exports those); throws
// std::runtime_error naming the camera otherwise.
std::vector<render::Camera> KeyframeViews(const io::ColmapModel& model, int keyframe_every,
                                          int every = 10);

// The share of the visible surface seen from behind in `cameras` (drawn at `scale` of their
// size, as report.json's figure), on any mesh. Throws as render::MeasureBackFacing does.
render::BackFacing SeenFromBehind(const std::vector<double>& xyz, const std::vector<uint32_t>& faces,
                                  const std::vector<render::Camera>& cameras, double scale = 0.25);

}  // namespace imr::bench
