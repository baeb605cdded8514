// org.imr.refine.photometric: the surface refined from the keyframe images (SDK 1.4 mesh
// refiner). The work is photometric_refinement.cc's; this file turns the host's request into
// its inputs: which vertices to refine (all at the end; during the run, those the engine changed
// and those the recent keyframes see), which keyframes to use, their images in gray.
#include "photometric_refinement.hpp"
#include "remesh.hpp"
#include "subdivision.hpp"

#include <imr/sdk/plugin.hpp>

#include <opencv2/imgproc.hpp>

#include <Eigen/Geometry>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

namespace {

using imr::photometric::View;

// Median edge length: the mesh's own scale, so that the lengths below work in any unit.
double MedianEdge(const imr::sdk::MeshView& mesh) {
  std::vector<double> lengths;
  const std::size_t faces = mesh.face_count();
  const std::size_t step = std::max<std::size_t>(1, faces / 20000);  // a sample is enough
  for (std::size_t f = 0; f < faces; f += step)
    for (int k = 0; k < 3; ++k) {
      const double* a = &mesh.vertices[3 * mesh.faces[3 * f + k]];
      const double* b = &mesh.vertices[3 * mesh.faces[3 * f + (k + 1) % 3]];
      lengths.push_back(std::hypot(a[0] - b[0], a[1] - b[1], a[2] - b[2]));
    }
  if (lengths.empty()) return 1.0;
  std::nth_element(lengths.begin(), lengths.begin() + lengths.size() / 2, lengths.end());
  return lengths[lengths.size() / 2] > 0.0 ? lengths[lengths.size() / 2] : 1.0;
}

// The camera's centre in the world: -R^T t.
Eigen::Vector3d Center(const imr_camera& c) {
  Eigen::Vector3d x;
  for (int i = 0; i < 3; ++i) x[i] = -(c.R[i] * c.t[0] + c.R[3 + i] * c.t[1] + c.R[6 + i] * c.t[2]);
  return x;
}

bool HasIntrinsics(const imr_camera& c) { return c.K[0] > 0.0 && c.K[4] > 0.0 && c.width > 0 && c.height > 0; }

// How deep camera c refines and compares: no deeper than max_depth (0: no such limit) and no
// deeper than where an edge of `edge` spans min_edge_pixels pixels (0: no such limit). The
// second holds in any unit and at any focal length: a street camera and a ring of close-up
// views around an object both see their surface at a few tens of pixels per edge, while the
// object's ring stands ~130 edges away and the street's useful depth is ~40.
double DepthLimit(const imr_camera& c, double edge, double max_depth, double min_edge_pixels) {
  double limit = max_depth > 0.0 ? max_depth * edge : std::numeric_limits<double>::infinity();
  if (min_edge_pixels > 0.0) limit = std::min(limit, std::sqrt(c.K[0] * c.K[4]) * edge / min_edge_pixels);
  return limit;
}

// Whether world point p is in front of camera c, at most max_depth deep, and inside its image.
bool Sees(const imr_camera& c, const double* p, double max_depth) {
  double x[3];
  for (int r = 0; r < 3; ++r) x[r] = c.R[3 * r] * p[0] + c.R[3 * r + 1] * p[1] + c.R[3 * r + 2] * p[2] + c.t[r];
  if (x[2] <= 0.0 || x[2] > max_depth) return false;
  const double u = (c.K[0] * x[0] + c.K[1] * x[1] + c.K[2] * x[2]) / x[2];
  const double v = (c.K[4] * x[1] + c.K[5] * x[2]) / x[2];
  return u >= 0.0 && v >= 0.0 && u <= c.width - 1.0 && v <= c.height - 1.0;
}

// Which vertices: all at the end of a run refined only then; otherwise those the engine changed
// since the last call and those a recent keyframe sees within its depth limit (kept positions
// elsewhere).
std::vector<uint8_t> ActiveVertices(const imr::sdk::RefineRequest& r, const std::vector<double>& depth_limit) {
  const std::size_t n = r.mesh.vertex_count();
  std::vector<uint8_t> active(n, 0);
  const bool all = r.final_call && r.recent_keyframes_begin == 0;
  for (std::size_t v = 0; v < n; ++v) {
    if (r.Fixed(v)) continue;
    bool a = all || r.Changed(v);
    for (std::size_t k = r.recent_keyframes_begin; !a && k < r.keyframes.size(); ++k)
      a = HasIntrinsics(r.keyframes[k]) && Sees(r.keyframes[k], &r.mesh.vertices[3 * v], depth_limit[k]);
    active[v] = a ? 1 : 0;
  }
  return active;
}

// The part of the surface a call refines, numbered on its own.
struct LocalMesh {
  std::vector<uint32_t> global;                  // the request's vertex of each local one
  std::vector<std::array<uint32_t, 3>> faces;    // local numbering
  std::vector<std::size_t> faces_taken;          // the request's face of each local one
  std::vector<Eigen::Vector3d> vertices;
  std::vector<uint8_t> active;
};

// The part of the surface in `region` (every face with a corner in it): the active vertices,
// and around them the rest as fixed context (occluders, neighbours). The work of a call is
// bounded by what the recent keyframes see, not by the surface so far.
LocalMesh ExtractLocalMesh(const imr::sdk::MeshView& mesh, const Eigen::AlignedBox3d& region,
                           const std::vector<uint8_t>& active) {
  LocalMesh m;
  std::vector<uint32_t> local(mesh.vertex_count(), UINT32_MAX);
  for (std::size_t f = 0; f < mesh.face_count(); ++f) {
    bool inside = false;
    for (int k = 0; k < 3 && !inside; ++k) {
      const double* q = &mesh.vertices[3 * mesh.faces[3 * f + k]];
      inside = region.contains(Eigen::Vector3d(q[0], q[1], q[2]));
    }
    if (!inside) continue;
    std::array<uint32_t, 3> face;
    for (int k = 0; k < 3; ++k) {
      const uint32_t g = mesh.faces[3 * f + k];
      if (local[g] == UINT32_MAX) {
        local[g] = static_cast<uint32_t>(m.global.size());
        m.global.push_back(g);
      }
      face[k] = local[g];
    }
    m.faces.push_back(face);
    m.faces_taken.push_back(f);
  }
  m.vertices.resize(m.global.size());
  m.active.resize(m.global.size());
  for (std::size_t i = 0; i < m.global.size(); ++i) {
    const double* q = &mesh.vertices[3 * m.global[i]];
    m.vertices[i] = Eigen::Vector3d(q[0], q[1], q[2]);
    m.active[i] = active[m.global[i]];
  }
  return m;
}

// Back to the request's numbering; added vertices after the request's. With edges split, the
// faces too: the request's faces not taken, then the local ones.
void WriteBack(const imr::sdk::MeshView& mesh, const LocalMesh& m, bool split,
               imr::sdk::RefineResult* out) {
  const std::size_t n = mesh.vertex_count();
  const std::size_t added = m.vertices.size() - m.global.size();
  out->vertices.resize(3 * (n + added));
  for (std::size_t i = 0; i < m.vertices.size(); ++i) {
    const std::size_t g = i < m.global.size() ? m.global[i] : n + (i - m.global.size());
    for (int k = 0; k < 3; ++k) out->vertices[3 * g + k] = m.vertices[i][k];
  }
  if (!split) return;
  std::vector<uint8_t> taken(mesh.face_count(), 0);
  for (std::size_t f : m.faces_taken) taken[f] = 1;
  out->faces.reserve(3 * (mesh.face_count() + m.faces.size()));
  for (std::size_t f = 0; f < mesh.face_count(); ++f)
    if (!taken[f]) out->faces.insert(out->faces.end(), &mesh.faces[3 * f], &mesh.faces[3 * f] + 3);
  for (const auto& f : m.faces)
    for (uint32_t i : f)
      out->faces.push_back(i < m.global.size() ? m.global[i] : static_cast<uint32_t>(n + (i - m.global.size())));
}

class PhotometricRefiner : public imr::sdk::MeshRefiner {
 public:
  static constexpr const char* kId = "org.imr.refine.photometric";
  static constexpr const char* kVersion = "1.0.0";
  static constexpr const char* kDescription =
      "Moves the surface's vertices along their normals to where the keyframe images agree "
      "(ZNCC of tangent-plane patches, coarse to fine); spikes the images do not place go onto "
      "their neighbours' plane; no triangle flips or crosses another";
  static constexpr const char* kParamsSchema = R"json({
    "levels": {"type": "integer", "default": 3, "minimum": 1, "maximum": 8,
               "description": "coarse-to-fine rounds; the search range halves each round"},
    "iterations_per_level": {"type": "integer", "default": 2, "minimum": 1, "maximum": 50,
                             "description": "search and update passes per round"},
    "search_range": {"type": "number", "default": 0.6, "minimum": 0.001, "maximum": 100,
                     "description": "distance searched along the normal in the first round, +-, in median edge lengths of the mesh"},
    "search_steps": {"type": "integer", "default": 9, "minimum": 1, "maximum": 100,
                     "description": "candidate offsets per side of the search range"},
    "patch_size": {"type": "integer", "default": 11, "minimum": 3, "maximum": 31,
                   "description": "patch samples per side (odd)"},
    "patch_pixels": {"type": "number", "default": 3, "minimum": 0.1, "maximum": 20,
                     "description": "patch sample spacing in pixels of the reference keyframe"},
    "min_zncc": {"type": "number", "default": 0.6, "minimum": 0, "maximum": 1,
                 "description": "a vertex moves to a match only when its ZNCC reaches this"},
    "min_gain": {"type": "number", "default": 0.05, "minimum": 0, "maximum": 2,
                 "description": "a match must also beat the ZNCC at the vertex's own position by this much"},
    "normal_smoothing": {"type": "integer", "default": 2, "minimum": 0, "maximum": 100,
                         "description": "1-ring averagings of the normals the patches lie on"},
    "subdivide": {"type": "number", "default": 0, "minimum": 0, "maximum": 100,
                  "description": "split edges longer than this many median edge lengths before refining (0: none)"},
    "remesh": {"type": "boolean", "default": false,
               "description": "at the final call, after the photometric passes, change triangles: split long edges (remesh_split) and flip edges where that lowers the dihedral angles, never across a crease (remesh_corner_deg), a boundary edge or a FIXED vertex's faces, never showing a keyframe more back sides; no vertex moves; a run that writes its surface in parts (engine.forget, output.tiles) cannot take it"},
    "remesh_split": {"type": "number", "default": 0, "minimum": 0, "maximum": 100,
                     "description": "with remesh: split interior edges longer than this many median edge lengths at their midpoints, longest first (0: no splits)"},
    "remesh_corner_deg": {"type": "number", "default": 60, "minimum": 1, "maximum": 180,
                          "description": "with remesh: an edge whose faces meet at more than this angle is a crease: never flipped, and no flip beside it brings it below"},
    "remesh_fold_deg": {"type": "number", "default": 180, "minimum": 1, "maximum": 180,
                        "description": "with remesh: an edge whose faces meet at more than this is a fold (the sheet turned back on itself between noisy points), flipped when its new faces lie flat on one of the old (180: none; at least remesh_corner_deg)"},
    "max_views": {"type": "integer", "default": 5, "minimum": 2, "maximum": 64,
                  "description": "keyframes compared per vertex (the most frontal that see it)"},
    "max_view_angle_deg": {"type": "number", "default": 75, "minimum": 1, "maximum": 89,
                           "description": "a keyframe further than this from a vertex's normal does not count"},
    "step": {"type": "number", "default": 0.7, "minimum": 0.01, "maximum": 1,
             "description": "fraction of the way to the match taken per pass"},
    "smoothness": {"type": "number", "default": 0, "minimum": 0, "maximum": 1,
                   "description": "umbrella (Laplacian) step per pass (it flattens spikes and shrinks corners: precision for completeness)"},
    "smooth_along_normal": {"type": "boolean", "default": false,
                            "description": "the umbrella step projected on the vertex normal"},
    "flatten_spikes": {"type": "number", "default": 5, "minimum": 0, "maximum": 1000,
                       "description": "a vertex the images do not place, farther from its neighbours' plane than this many times their own spread about it, goes onto that plane (0: never)"},
    "planarize": {"type": "integer", "default": 3, "minimum": 0, "maximum": 100,
                  "description": "rounds of planarizing after the photometric passes: a vertex whose 2-ring lies on one plane (a robust fit holding planarize_min_share of it within planarize_tolerance) goes onto it; a corner stays (0: off)"},
    "planarize_tolerance": {"type": "number", "default": 0.15, "minimum": 0.001, "maximum": 100,
                            "description": "with planarize: how far from the plane a neighbour still counts as on it, in median edge lengths"},
    "planarize_min_share": {"type": "number", "default": 0.7, "minimum": 0.01, "maximum": 1,
                            "description": "with planarize: the share of the 2-ring the plane must hold"},
    "planarize_matched": {"type": "boolean", "default": true,
                          "description": "with planarize: false keeps the vertices the images placed where they are"},
    "max_move": {"type": "number", "default": 1.0, "minimum": 0.001, "maximum": 100,
                 "description": "how far a vertex may move in one call, in median edge lengths"},
    "max_depth": {"type": "number", "default": 0, "minimum": 0, "maximum": 100000,
                  "description": "a keyframe refines and compares what it sees up to this deep, in median edge lengths (0: no limit but min_edge_pixels)"},
    "min_edge_pixels": {"type": "number", "default": 18, "minimum": 0, "maximum": 10000,
                        "description": "a keyframe refines and compares what it sees with a median edge at least this many pixels long (depth at most focal x edge / this; 0: no limit)"},
    "threads": {"type": "integer", "default": 0, "minimum": 0, "maximum": 256,
                "description": "threads for the per-vertex search (0: one per core)"},
    "missing_image": {"type": "string", "default": "fail", "enum": ["fail", "skip"],
                      "description": "a keyframe image that cannot be read: fail the stage (naming it) or leave that keyframe out with a warning"}
  })json";

  PhotometricRefiner(const imr::sdk::Params& p, const imr::sdk::Host& host) : host_(host) {
    o_.levels = p.Get<int>("levels");
    o_.iterations_per_level = p.Get<int>("iterations_per_level");
    search_range_ = p.Get<double>("search_range");
    o_.search_steps = p.Get<int>("search_steps");
    o_.patch_size = p.Get<int>("patch_size");
    o_.patch_pixels = p.Get<double>("patch_pixels");
    o_.min_zncc = p.Get<double>("min_zncc");
    o_.min_gain = p.Get<double>("min_gain");
    o_.normal_smoothing = p.Get<int>("normal_smoothing");
    subdivide_ = p.Get<double>("subdivide");
    remesh_ = p.Get<bool>("remesh");
    remesh_options_.corner_deg = p.Get<double>("remesh_corner_deg");
    remesh_options_.fold_deg = p.Get<double>("remesh_fold_deg");
    remesh_split_ = p.Get<double>("remesh_split");
    o_.max_views = p.Get<int>("max_views");
    o_.max_view_angle_deg = p.Get<double>("max_view_angle_deg");
    o_.step = p.Get<double>("step");
    o_.smoothness = p.Get<double>("smoothness");
    o_.smooth_along_normal = p.Get<bool>("smooth_along_normal");
    o_.flatten_spikes = p.Get<double>("flatten_spikes");
    o_.planarize = p.Get<int>("planarize");
    planarize_tolerance_ = p.Get<double>("planarize_tolerance");
    o_.planarize_min_share = p.Get<double>("planarize_min_share");
    o_.planarize_matched = p.Get<bool>("planarize_matched");
    max_move_ = p.Get<double>("max_move");
    max_depth_ = p.Get<double>("max_depth");
    min_edge_pixels_ = p.Get<double>("min_edge_pixels");
    o_.threads = p.Get<int>("threads");
    if (o_.threads == 0) o_.threads = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
    skip_missing_ = p.Get<std::string>("missing_image") == "skip";
    std::string error;
    if (!o_.Check(&error)) throw imr::sdk::InvalidArgument("params: " + error);
    if (!remesh_options_.Check(&error)) throw imr::sdk::InvalidArgument("params: remesh: " + error);
  }

  void Refine(const imr::sdk::RefineRequest& r, imr::sdk::RefineResult* out) override {
    RefineCall(r, out);
    if (r.final_call) WarnIfNothingRefined();
    if (remesh_ && r.final_call) RemeshCall(r, out);
  }

 private:
  void RefineCall(const imr::sdk::RefineRequest& r, imr::sdk::RefineResult* out) {
    const std::size_t n = r.mesh.vertex_count();
    out->vertices.assign(r.mesh.vertices.begin(), r.mesh.vertices.end());
    if (n == 0 || r.keyframes.empty()) return;
    if (!r.keyframe_images)
      throw imr::sdk::InvalidArgument(
          std::string(kId) + " needs the keyframe images, and this input has none (a SLAM/SfM "
          "export or a synthetic stream): refine a run from images, or remove the stage");
    const double edge = MedianEdge(r.mesh);
    std::vector<double> depth_limit(r.keyframes.size());
    for (std::size_t k = 0; k < r.keyframes.size(); ++k)
      depth_limit[k] = DepthLimit(r.keyframes[k], edge, max_depth_, min_edge_pixels_);
    const std::vector<uint8_t> active = ActiveVertices(r, depth_limit);
    if (std::find(active.begin(), active.end(), 1) == active.end()) return;

    // The region of the work: the active vertices and the centres of the keyframes that see them.
    Eigen::AlignedBox3d region;
    for (std::size_t v = 0; v < n; ++v)
      if (active[v]) region.extend(Eigen::Vector3d(r.mesh.vertices[3 * v], r.mesh.vertices[3 * v + 1], r.mesh.vertices[3 * v + 2]));
    const std::vector<View> views = Views(r, active, depth_limit, &region);
    if (views.size() < 2) {  // nothing to compare
      if (!depth_excluded_) depth_excluded_ = DepthExcludesAll(r, active);
      return;
    }
    region.extend(region.min() - Eigen::Vector3d::Constant(2 * edge));
    region.extend(region.max() + Eigen::Vector3d::Constant(2 * edge));
    LocalMesh local = ExtractLocalMesh(r.mesh, region, active);

    imr::photometric::RefineOptions o = o_;
    o.search_range = search_range_ * edge;
    o.max_move = max_move_ * edge;
    o.planarize_tolerance = planarize_tolerance_ * edge;
    // New vertices where long edges between active vertices are split (the host checks the
    // result is a manifold with the same boundary), at the end only: the host keeps the positions
    // of its own vertices between calls, not added ones.
    imr::photometric::SubdivisionStats split;
    if (subdivide_ > 0.0 && r.final_call)
      split = imr::photometric::SubdivideLongEdges(subdivide_ * edge, 1, &local.vertices, &local.faces,
                                                   &local.active);
    imr::photometric::RefineStats stats;
    try {
      imr::photometric::Refine(views, local.faces, local.active, o, &local.vertices, &stats,
                               [this] { return host_.IsCancelled(); });
    } catch (const std::invalid_argument& e) {
      throw imr::sdk::InvalidArgument(e.what());
    }
    host_.CheckCancelled();
    ++run_.compared_calls;
    run_.active += stats.vertices_active;
    run_.seen += stats.vertices_seen;
    run_.matched += stats.vertices_matched;
    WriteBack(r.mesh, local, split.edges_split > 0, out);
    char line[320];
    std::snprintf(line, sizeof(line),
                  "%s: %lld of %lld vertices refined from %zu keyframes (%lld seen twice, %lld "
                  "moved, mean %.3g), ZNCC %.3f -> %.3f, %lld steps undone, %.2f s",
                  kId, static_cast<long long>(stats.vertices_active), static_cast<long long>(n),
                  views.size(), static_cast<long long>(stats.vertices_seen),
                  static_cast<long long>(stats.vertices_moved), stats.mean_move,
                  stats.mean_zncc_before, stats.mean_zncc_after,
                  static_cast<long long>(stats.moves_undone), stats.seconds);
    host_.Info(line);
    if (o.planarize > 0) {
      std::snprintf(line, sizeof(line),
                    "%s: planarizing moved %lld vertices (%lld on a plane of their 2-ring); roughness "
                    "%.1f -> %.1f degrees",
                    kId, static_cast<long long>(stats.vertices_planarized),
                    static_cast<long long>(stats.vertices_on_plane), stats.roughness_before,
                    stats.roughness_after);
      host_.Info(line);
    }
  }

  // The final call's whole surface, at the positions the passes left, remeshed (remesh.hpp): its
  // faces live for that mesh only, so earlier calls could not keep theirs. A FIXED vertex says
  // the run writes its surface in parts, whose faces are written already: no remesh then.
  void RemeshCall(const imr::sdk::RefineRequest& r, imr::sdk::RefineResult* out) {
    const std::size_t n = r.mesh.vertex_count();
    if (n == 0) return;
    for (std::size_t v = 0; v < n; ++v)
      if (r.Fixed(v)) {
        host_.Warning(std::string(kId) + ": remesh skipped: this run writes its surface in parts "
                      "(engine.forget or output.tiles), whose triangles are written already");
        return;
      }
    const std::size_t count = out->vertices.size() / 3;
    std::vector<Eigen::Vector3d> p(count);
    for (std::size_t v = 0; v < count; ++v)
      p[v] = Eigen::Vector3d(out->vertices[3 * v], out->vertices[3 * v + 1], out->vertices[3 * v + 2]);
    const std::vector<uint32_t>& flat = out->faces.empty()
                                            ? std::vector<uint32_t>(r.mesh.faces.begin(), r.mesh.faces.end())
                                            : out->faces;
    std::vector<std::array<uint32_t, 3>> faces(flat.size() / 3);
    for (std::size_t f = 0; f < faces.size(); ++f) faces[f] = {flat[3 * f], flat[3 * f + 1], flat[3 * f + 2]};
    const double edge = MedianEdge(r.mesh);
    imr::photometric::RemeshOptions o = remesh_options_;
    o.max_edge = remesh_split_ * edge;
    std::vector<uint8_t> locked;  // none: no vertex is FIXED here
    // The keyframes, at any distance (within their depth limit only, 0.44 % of the default job's
    // surface was seen from behind, 0.31 % without the remesh): none sees more back sides after it.
    std::vector<imr::photometric::Viewpoint> viewpoints;
    for (const imr_camera& c : r.keyframes)
      if (HasIntrinsics(c)) viewpoints.push_back({Center(c), std::numeric_limits<double>::infinity()});
    const auto start = std::chrono::steady_clock::now();
    const imr::photometric::RemeshStats s = imr::photometric::Remesh(o, viewpoints, &p, &faces, &locked);
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    host_.CheckCancelled();
    char line[320];
    std::snprintf(line, sizeof(line),
                  "%s: remesh: %lld edges flipped (%lld folds), %lld split, %lld flips kept off creases, %lld "
                  "refused (fold or sliver), %lld (a back side shown to a keyframe); mean dihedral "
                  "%.2f -> %.2f degrees, %.2f s",
                  kId, static_cast<long long>(s.edges_flipped), static_cast<long long>(s.folds_flipped),
                  static_cast<long long>(s.edges_split),
                  static_cast<long long>(s.creases_kept), static_cast<long long>(s.flips_refused),
                  static_cast<long long>(s.flips_facing_away),
                  s.total_dihedral_before / static_cast<double>(std::max<int64_t>(1, s.interior_edges_before)),
                  s.total_dihedral_after / static_cast<double>(std::max<int64_t>(1, s.interior_edges_after)),
                  seconds);
    host_.Info(line);
    if (!s.changed()) return;
    out->vertices.resize(3 * p.size());
    for (std::size_t v = count; v < p.size(); ++v)
      for (int k = 0; k < 3; ++k) out->vertices[3 * v + k] = p[v][k];
    std::vector<uint32_t> remeshed;
    remeshed.reserve(3 * faces.size());
    for (const auto& f : faces) remeshed.insert(remeshed.end(), f.begin(), f.end());
    out->faces.swap(remeshed);
  }

  // The keyframes that see an active vertex within their depth limit, their images in gray;
  // `region` grows by their centres.
  std::vector<View> Views(const imr::sdk::RefineRequest& r, const std::vector<uint8_t>& active,
                          const std::vector<double>& depth_limit, Eigen::AlignedBox3d* region) {
    std::vector<View> views;
    for (std::size_t k = 0; k < r.keyframes.size(); ++k) {
      const imr_camera& c = r.keyframes[k];
      if (!HasIntrinsics(c)) continue;
      bool useful = false;
      for (std::size_t v = 0; v < active.size() && !useful; v += 1)
        useful = active[v] && Sees(c, &r.mesh.vertices[3 * v], depth_limit[k]);
      if (!useful) continue;
      host_.CheckCancelled();
      View view;
      if (!ReadGray(k, c, &view.gray)) continue;
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) {
          view.K(i, j) = c.K[3 * i + j];
          view.R(i, j) = c.R[3 * i + j];
        }
      view.t = Eigen::Vector3d(c.t[0], c.t[1], c.t[2]);
      views.push_back(std::move(view));
      region->extend(Center(c));
    }
    return views;
  }

  // Keyframe k's image in gray; false (with a warning) when it cannot be read and
  // missing_image is "skip".
  bool ReadGray(std::size_t k, const imr_camera& c, cv::Mat* gray) {
    try {
      imr::sdk::KeyframeImage image = host_.GetKeyframeImage(k);
      if (image.width() != c.width || image.height() != c.height)
        throw std::runtime_error("keyframe " + std::to_string(k) + ": its image is " +
                                 std::to_string(image.width()) + "x" + std::to_string(image.height()) +
                                 ", its camera says " + std::to_string(c.width) + "x" +
                                 std::to_string(c.height));
      const cv::Mat wrapped(image.height(), image.width(), image.channels() == 1 ? CV_8UC1 : CV_8UC3,
                            const_cast<uint8_t*>(image.view().pixels),
                            static_cast<std::size_t>(image.view().stride_bytes));
      if (image.channels() == 1)
        wrapped.copyTo(*gray);
      else
        cv::cvtColor(wrapped, *gray, cv::COLOR_BGR2GRAY);
      return true;
    } catch (const imr::sdk::InvalidArgument&) {
      throw;
    } catch (const std::exception& e) {
      // The host's message names the keyframe and its file ("keyframe image 2: <path>: ..."):
      // passed on as it is, not prefixed again.
      if (!skip_missing_) throw std::runtime_error(e.what());
      host_.Warning(std::string(kId) + ": " + e.what() + "; that keyframe is left out");
      return false;
    }
  }

  // Whether, without the depth limit (max_depth, min_edge_pixels), two keyframes would see an
  // active vertex: the limit, not the view, left the call nothing to compare.
  bool DepthExcludesAll(const imr::sdk::RefineRequest& r, const std::vector<uint8_t>& active) const {
    if (max_depth_ <= 0.0 && min_edge_pixels_ <= 0.0) return false;
    const double unlimited = std::numeric_limits<double>::infinity();
    int seeing = 0;
    for (std::size_t k = 0; k < r.keyframes.size() && seeing < 2; ++k) {
      if (!HasIntrinsics(r.keyframes[k])) continue;
      bool sees = false;
      for (std::size_t v = 0; v < active.size() && !sees; ++v)
        sees = active[v] && Sees(r.keyframes[k], &r.mesh.vertices[3 * v], unlimited);
      seeing += sees ? 1 : 0;
    }
    return seeing >= 2;
  }

  // A run whose calls compared no patch, or matched nothing, because of the settings would leave
  // the surface as the engine made it without a word: said at the final call, naming the
  // settings. Over the whole run, not per call: a call during the run often has little new to
  // compare.
  void WarnIfNothingRefined() {
    char line[520];
    if (run_.seen == 0 && run_.compared_calls == 0 && depth_excluded_) {
      std::snprintf(line, sizeof line,
                    "%s: compared no patch: no two keyframes saw a vertex to refine within their depth "
                    "limit (max_depth %g median edges, min_edge_pixels %g pixels per median edge), "
                    "though without that limit they would; the surface is as the engine made it "
                    "(lower min_edge_pixels or raise max_depth)",
                    kId, max_depth_, min_edge_pixels_);
      host_.Warning(line);
    } else if (run_.seen == 0 && run_.active > 0) {
      std::snprintf(line, sizeof line,
                    "%s: compared no patch: none of the %lld vertices to refine was seen by two "
                    "keyframes with its whole patch inside both images (patch_size %d x patch_pixels "
                    "%g = %g pixels a side) and within max_view_angle_deg %g of its normal; the "
                    "images placed no vertex (only flatten_spikes and smoothness moved any; smaller "
                    "patches)",
                    kId, static_cast<long long>(run_.active), o_.patch_size, o_.patch_pixels,
                    o_.patch_size * o_.patch_pixels, o_.max_view_angle_deg);
      host_.Warning(line);
    } else if (run_.seen >= kFewSeen && run_.matched == 0) {
      std::snprintf(line, sizeof line,
                    "%s: no vertex found a match: of %lld vertices compared in two keyframes, none "
                    "reached min_zncc %g and beat its own position by min_gain %g (patches of "
                    "patch_size %d x patch_pixels %g); the images placed no vertex (only "
                    "flatten_spikes and smoothness moved any)",
                    kId, static_cast<long long>(run_.seen), o_.min_zncc, o_.min_gain, o_.patch_size,
                    o_.patch_pixels);
      host_.Warning(line);
    }
  }
  // A handful of vertices compared may all lack texture; more than this and none matched is the
  // settings.
  static constexpr int64_t kFewSeen = 20;

  imr::sdk::Host host_;
  imr::photometric::RefineOptions o_;
  double search_range_ = 0.6;  // in median edge lengths
  double max_move_ = 1.0;      // in median edge lengths
  double planarize_tolerance_ = 0.15;  // in median edge lengths
  double subdivide_ = 0.0;     // in median edge lengths; 0: no subdivision
  bool remesh_ = false;        // the final call's triangles changed (RemeshCall)
  double remesh_split_ = 0.0;  // in median edge lengths; 0: no splits
  imr::photometric::RemeshOptions remesh_options_;
  double max_depth_ = 0.0;         // in median edge lengths; 0: no limit
  double min_edge_pixels_ = 18.0;  // pixels a median edge spans at the deepest; 0: no limit
  bool skip_missing_ = false;
  // Over the run's calls (WarnIfNothingRefined): calls that compared (two keyframes or more),
  // and their vertices to refine, seen by two keyframes, placed by a match.
  struct RunTotals {
    int64_t compared_calls = 0, active = 0, seen = 0, matched = 0;
  } run_;
  bool depth_excluded_ = false;  // a call had nothing to compare because of the depth limit
};

}  // namespace

IMR_PLUGIN_EXPORT(PhotometricRefiner)
