// imr-bench quality (issue 14): the surface imr makes, input by input, beside other meshers fed
// the same input in the same run, all evaluated by the same code (host/eval, what `imr evaluate`
// runs). Per mesher: completeness / precision / F at 0.2 and 0.5 m, truth -> mesh mean and
// median, mesh -> truth mean, wall time and peak RSS of its process, whether its mesh is a
// manifold (closed, or with boundary), and its roughness (mean angle between neighbouring faces).
// Each image job (synth, kitti) also runs with and without a mesh_refiner stage (issue 34:
// org.imr.refine.photometric every 10 keyframes), with the refinement's seconds per call.
//
// Inputs (each skipped with a message when absent):
//   street   ../shared/data/street-stream: an independent generator's SLAM JSON stream, fed to
//            imr (slam_json) and to the Piazza mesher as it is; completeness against
//            gt_points.ply, precision against scene_mesh.ply (the team's measure, data README).
//            The limit the stream's points allow (../shared/tools/oracle_mesh.py) beside it.
//   synth    imr-synth's street through the default image job; completeness and precision against
//            the exact scene (scene.ply, cropped to what the cameras saw), and the road alone.
//   kitti    the KITTI raw sample (../shared/data) against its Velodyne scans (camera 2).
//   stream   imr's own synthetic observation stream (the street), against its analytic scene.
//   middlebury  the temple and dino rings (not by default): no ground truth, a look before and
//            after the refinement (renders of frame 5 in --work).
// Peers: the Piazza et al. 2018 mesher (tools/bench/peers/build_piazza.sh) on street directly
// and on the others through the stream `imr run --export-stream` writes; COLMAP's
// delaunay_mesher (tools/bench/peers/build_colmap.sh) on imr's final points
// (`--export-colmap`). With --openmvs BIN_DIR (tools/bench/peers/build_openmvs.sh), OpenMVS's
// RefineMesh on synth and kitti: the unrefined run's mesh and its images (the run's COLMAP
// export, through InterfaceCOLMAP), refined by OpenMVS and scored by the same code as imr's own
// refinement; and OpenMVS's whole pipeline (issue 45: InterfaceCOLMAP on the run's COLMAP export,
// the keyframes' images -> DensifyPointCloud -> ReconstructMesh -> RefineMesh; --openmvs-rows,
// --openmvs-resolution-level) as its own row. Per input and mesher, a second table: roughness
// over all edges and on the true planes (imr-synth), the share of the visible surface seen from
// behind over every 10th keyframe, components under 0.5 % of the area (tools/bench/common/
// surface_figures.h). --config-set KEY=VALUE / --variant-job INPUT=FILE: one more imr row per
// image input (a job variant beside the config); --renders DIR: the same frames of every
// mesher's mesh drawn by `imr render`. Benchmark only, never in CI. Prints Markdown tables with
// the targets, then one JSON object as the last line.
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <unordered_map>
#include <vector>

#include <nlohmann/json.hpp>

#include "host/engine/edge_flips.h"
#include "host/engine/normal_filter.h"
#include "host/engine/plane_retriangulation.h"
#include "host/eval/distance.h"
#include "host/eval/evaluate.h"
#include "host/eval/mesh_io.h"
#include "host/eval/mesh_stats.h"
#include "host/eval/synthetic_truth.h"
#include "host/io/colmap_model.h"
#include "host/synthetic/stream.h"
#include "tools/bench/common/bench_util.h"
#include "tools/bench/common/frame.h"
#include "tools/bench/common/surface_figures.h"
#include "tools/bench/common/subprocess.h"
#include "tools/bench/peers/colmap.h"
#include "tools/bench/peers/openmvs.h"
#include "tools/bench/peers/piazza.h"

namespace imr::bench {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

struct QualityArgs {
  std::vector<std::string> inputs = {"street", "synth", "kitti", "stream"};
  int synth_frames = 500;      // imr-synth frames (the README's first command: 500)
  int stream_frames = 500;     // synthetic observation stream frames
  std::string work;            // scratch folder (kept when given)
  std::string shared;          // ../shared; default from the source tree
  std::string piazza, colmap;  // peer binaries (default: their build caches)
  bool peers = true;
  std::string before;          // an earlier build's imr (e.g. f69611d's): run on the same input
  std::string before_label = "f69611d";
  std::string openmvs;                    // OpenMVS's bin folder (InterfaceCOLMAP, RefineMesh)
  std::vector<std::string> openmvs_args;  // more RefineMesh arguments (--openmvs-args)
  bool openmvs_all_images = false;        // every frame's image, not only the keyframes'
  bool openmvs_refine = true;             // --openmvs-rows: RefineMesh on imr's mesh
  bool openmvs_pipeline = true;           //   and the whole pipeline
  OpenMvsPipelineOptions openmvs_pipeline_options;
  std::vector<std::string> config_sets;            // --config-set KEY=VALUE: the variant row
  std::map<std::string, std::string> variant_jobs; // --variant-job INPUT=FILE
  std::string renders;                    // --renders DIR: PNGs of every mesher's mesh
  std::vector<int> render_frames;         // --render-frames; empty: each input's own
};

// One mesher's result on one input.
struct Row {
  std::string mesher;
  bool ok = false;
  std::string note;               // why it failed, or how it was fed
  double seconds = 0.0;           // wall time of its process(es)
  double rss_mb = 0.0;            // peak resident memory of its process
  double c2 = 0.0, c5 = 0.0;      // completeness at 0.2 / 0.5 m
  double p2 = 0.0, p5 = 0.0;      // precision at 0.2 / 0.5 m
  double t2m_mean = 0.0, t2m_median = 0.0, m2t_mean = 0.0;
  std::optional<double> road;     // synth: completeness of the road alone at 0.2 m
  // A laser scanner's truth: precision at 0.2 m over the mesh area it could have measured, and
  // that area's share (eval/README.md, "in the scanner's view").
  std::optional<double> p2_scanner, scanner_share;
  double roughness = 0.0;         // mean angle between neighbouring face normals, degrees
  bool refined = false;           // the job had a mesh_refiner stage
  // imr rows, from report.json: the share of the keyframes' camera centres in O (free space)
  // after their update, and of the visible area seen from behind over the keyframe views.
  std::optional<double> cameras_in_o, back_facing;
  eval::MeshStatistics stats;
  // Issue 45's figures, the same code on every mesher's mesh (surface_figures.h).
  std::optional<PlaneRoughness> plane_roughness;  // inputs with planar truth (imr-synth)
  std::optional<double> behind;                   // seen from behind, every 10th keyframe
  SmallComponents small;                          // components under 0.5 % of the area
  fs::path mesh;                                  // the mesh scored (for --renders)
};

// What an input offers the surface figures: its true planes, its keyframe views (loaded once,
// when the first mesh is scored: from the COLMAP export of imr's first run).
struct SurfaceContext {
  PlaneOf planes;  // empty: no planar truth
  fs::path model;  // the run's COLMAP export
  int keyframe_every = 5;
  bool loaded = false;
  std::vector<render::Camera> views;
  std::string views_error;
  const std::vector<render::Camera>* Views() {
    if (!loaded) {
      loaded = true;
      try {
        views = KeyframeViews(io::ReadColmapText(model), keyframe_every, 10);
      } catch (const std::exception& e) {
        views_error = e.what();
        std::printf("seen from behind: no keyframe views (%s)\n", e.what());
      }
    }
    return views.empty() ? nullptr : &views;
  }
};

double F(double c, double p) { return c + p > 0.0 ? 2.0 * c * p / (c + p) : 0.0; }

std::string ManifoldText(const eval::MeshStatistics& s) {
  if (!s.manifold)
    return "no (" + std::to_string(s.nonmanifold_edges) + " edges, " +
           std::to_string(s.nonmanifold_vertices) + " vertices)";
  return s.closed ? "yes (closed)" : "yes (" + std::to_string(s.boundary_loops) + " holes)";
}

// A mesh file as packed coordinates and indices, with its statistics (manifoldness, holes) in
// *row; false (and row->note) when it cannot be read.
bool ReadPacked(const fs::path& mesh, Row* row, std::vector<double>* xyz,
                std::vector<uint32_t>* faces, SurfaceContext* surface = nullptr) {
  try {
    const eval::TriangleMesh m = eval::ReadMesh(mesh);
    for (const auto& v : m.vertices) xyz->insert(xyz->end(), v.begin(), v.end());
    for (const auto& t : m.triangles) faces->insert(faces->end(), t.begin(), t.end());
    row->stats = eval::ComputeMeshStatistics(*xyz, *faces);
    row->roughness = Roughness(*xyz, *faces);
    row->small = SmallComponentsOf(row->stats);
    row->mesh = mesh;
    if (surface && surface->planes) row->plane_roughness = RoughnessOnPlanes(*xyz, *faces, surface->planes);
    if (surface)
      if (const std::vector<render::Camera>* views = surface->Views(); views && !faces->empty())
        row->behind = SeenFromBehind(*xyz, *faces, *views).Share();
    return true;
  } catch (const std::exception& e) {
    row->note = std::string("reading the mesh: ") + e.what();
    return false;
  }
}

bool MeshStats(const fs::path& mesh, Row* row, SurfaceContext* surface = nullptr) {
  std::vector<double> xyz;
  std::vector<uint32_t> faces;
  return ReadPacked(mesh, row, &xyz, &faces, surface);
}

// `imr evaluate`'s code on a mesh file: completeness and truth -> mesh against `completeness`
// truth, precision and mesh -> truth against `precision` truth (the same file when equal).
bool Evaluate(const fs::path& mesh, const eval::EvaluationInputs& completeness,
              const eval::EvaluationInputs& precision, Row* row, SurfaceContext* surface = nullptr) {
  if (!MeshStats(mesh, row, surface)) return false;
  eval::EvaluationOptions o;
  o.taus = {0.2, 0.5};
  try {
    eval::EvaluationInputs c = completeness, p = precision;
    c.mesh = p.mesh = mesh.string();
    const json a = eval::EvaluateFiles(c, o, eval::ReadKittiSequence);
    row->c2 = a["completeness"][0];
    row->c5 = a["completeness"][1];
    row->t2m_mean = a["truth_to_mesh"]["mean"];
    row->t2m_median = a["truth_to_mesh"]["median"];
    // imr-synth's sequences: the road surface alone (what the image front end covers worst).
    if (a.contains("road_surface") && a["road_surface"]["completeness"].is_array() &&
        a["road_surface"]["completeness"].size() > 0 && a["road_surface"]["completeness"][0].is_number())
      row->road = a["road_surface"]["completeness"][0].get<double>();
    const json b = p.truth == c.truth && p.sequence == c.sequence
                       ? a
                       : eval::EvaluateFiles(p, o, eval::ReadKittiSequence);
    row->p2 = b["precision"][0];
    row->p5 = b["precision"][1];
    if (b.contains("scanner_view") && b["scanner_view"]["precision"][0].is_number() &&
        b["scanner_view"]["share"].is_number()) {
      row->p2_scanner = b["scanner_view"]["precision"][0].get<double>();
      row->scanner_share = b["scanner_view"]["share"].get<double>();
    }
    row->m2t_mean = b["mesh_to_truth"]["mean"];
    row->ok = true;
  } catch (const std::exception& e) {
    row->note = std::string("evaluation: ") + e.what();
  }
  return row->ok;
}

// imr run on a job (this build's imr, or `binary`); the exports the peers need. Fills time and
// memory.
bool RunImr(const json& job, const fs::path& work, const std::string& name,
            const std::string& extra_args, Row* row, const std::string& binary = "") {
  ImrJob how;
  how.job_file = work / (name + ".json");
  how.imr = binary;
  how.extra = extra_args;
  const ImrJobResult r = RunImrJob(job, how);
  row->seconds = r.seconds;
  row->rss_mb = r.peak_rss_mb;
  if (r.status != 0) {
    row->note = "imr run failed (" + r.log.string() + ")";
    return false;
  }
  // One sequence: its report.json is in the output folder.
  const json& report = r.report;
  if (report.is_object() && report.contains("engine") && report["engine"].contains("cameras_in_o"))
    row->cameras_in_o = report["engine"]["cameras_in_o"].value("share", 0.0);
  if (report.is_object() && report.contains("mesh") && report["mesh"].contains("back_facing"))
    row->back_facing = report["mesh"]["back_facing"].value("share", 0.0);
  return true;
}

json Exporter() { return {{"kind", "exporter"}, {"plugin", "org.imr.exporter.assimp"}}; }

// A job of configs/ as the README runs it, on `sequence`, its mesh as PLY into `output`.
json ConfigJob(const std::string& config, const fs::path& sequence, const fs::path& output) {
  const fs::path path = fs::path(IMR_SOURCE_DIR) / "configs" / config;
  std::ifstream in(path);
  json job = json::parse(in, nullptr, /*allow_exceptions=*/false);
  if (!job.is_object()) throw std::runtime_error(path.string() + ": cannot read the job");
  job["description"] = "imr-bench quality: " + path.string();
  job["sequences"] = {sequence.string()};
  job["output"] = {{"directory", output.string()}, {"stem", "mesh"}, {"formats", {"ply"}}};
  return job;
}

// The same job through an earlier build (--before): its engine section, its plugins' params as
// that build's configs had them (before_params, by plugin id: newer params would be refused) and
// a nearest policy stage (what that build's weights mode needs), one more row.
void RunBefore(const QualityArgs& args, json job, const json& engine, const json& before_params,
               const fs::path& work, const std::string& name, const std::string& label,
               const std::function<void(const fs::path&, Row*)>& evaluate,
               std::vector<Row>* rows) {
  if (args.before.empty()) return;
  Row r;
  r.mesher = "imr at " + args.before_label + ", " + label;
  job["engine"] = engine;
  // Plugin params that build did not know (its plugins had their own defaults then).
  for (json& stage : job["pipeline"])
    if (stage.contains("plugin") && before_params.contains(stage["plugin"].get<std::string>()))
      stage["params"] = before_params[stage["plugin"].get<std::string>()];
  bool has_policy = false;
  for (const json& stage : job["pipeline"]) has_policy |= stage["kind"] == "weight_policy";
  json pipeline = json::array();
  for (const json& stage : job["pipeline"]) {
    if (stage["kind"] == "mesh_refiner") continue;  // a kind earlier builds do not know
    if (stage["kind"] == "exporter" && !has_policy)
      pipeline.push_back({{"kind", "weight_policy"}, {"plugin", "org.imr.policy.nearest"}});
    pipeline.push_back(stage);
  }
  job["pipeline"] = pipeline;
  job["output"]["directory"] = (work / name).string();
  if (RunImr(job, work, name, "", &r, args.before)) evaluate(work / name / "mesh.ply", &r);
  rows->push_back(r);
}

// The peers on one input: Piazza on `stream` (a SLAM JSON file), COLMAP on `model`.
void RunPeers(const QualityArgs& args, const fs::path& work, const fs::path& stream,
              const fs::path& model, const std::string& fed,
              const std::function<void(const fs::path&, Row*)>& evaluate,
              std::vector<Row>* rows) {
  if (!args.peers) return;
  Row piazza;
  piazza.mesher = "Piazza et al. 2018 (KITTI config, moves on)";
  const std::string binary = FindPiazza(args.piazza);
  if (binary.empty()) {
    piazza.note = "not built (tools/bench/peers/build_piazza.sh)";
  } else if (!fs::exists(stream)) {
    piazza.note = "no stream to feed it";
  } else {
    const PiazzaResult r = RunPiazza(binary, stream.string(), (work / "piazza").string(),
                                     /*moves_on=*/true);
    piazza.seconds = r.seconds;
    piazza.rss_mb = r.peak_rss_mb;
    if (!r.ok) piazza.note = r.error;
    else evaluate(r.mesh_path, &piazza), piazza.note = fed;
  }
  rows->push_back(piazza);

  Row col;
  col.mesher = "COLMAP 3.8 delaunay_mesher (batch, final points)";
  const std::string colmap = FindColmap(args.colmap);
  if (colmap.empty()) {
    col.note = "not built (tools/bench/peers/build_colmap.sh)";
  } else if (!fs::exists(model)) {
    col.note = "no COLMAP model to feed it";
  } else {
    const fs::path mesh = work / "colmap-mesh.ply";
    const TimedRun r = RunTimed(Quote(colmap) + " delaunay_mesher --input_path " +
                                    Quote(model.string()) +
                                    " --input_type sparse --output_path " + Quote(mesh.string()),
                                work / "colmap.log");
    col.seconds = r.seconds;
    col.rss_mb = r.peak_rss_mb;
    if (r.status != 0 || !fs::exists(mesh)) col.note = "delaunay_mesher failed (colmap.log)";
    else evaluate(mesh, &col), col.note = "imr's final points (--export-colmap)";
  }
  rows->push_back(col);
}

struct Target {
  std::string what;
  double value;
  bool at_least;  // value is a minimum (else a maximum)
  double reached;
};

// Issue 45's targets common to the image inputs, on imr's row (rows[0], the config's job): no
// surface seen from behind (bench-measured), no small component, and against OpenMVS's whole
// pipeline in the same run (when it ran): at least 10x faster, and on KITTI (`f_twice`) F at
// least twice its own. The time and memory against today's (45 s, 741 MB) apply to imr-synth's
// default job only.
std::vector<Target> Issue45Targets(const std::vector<Row>& rows, bool f_twice) {
  std::vector<Target> t;
  if (rows.empty() || !rows[0].ok) return t;
  const Row& r = rows[0];
  if (r.behind) t.push_back({"issue 45: seen from behind, every 10th keyframe", 0.01, false, *r.behind});
  t.push_back({"issue 45: components under 0.5 % of the area", 0.0, false, static_cast<double>(r.small.small)});
  for (const Row& p : rows)
    if (p.ok && p.mesher.rfind("OpenMVS pipeline", 0) == 0) {
      if (f_twice)
        t.push_back({"issue 45: F 0.2 m, twice the OpenMVS pipeline's", 2.0 * F(p.c2, p.p2), true, F(r.c2, r.p2)});
      t.push_back({"issue 45: OpenMVS pipeline's wall time / imr's", 10.0, true,
                   p.seconds / std::max(r.seconds, 1e-9)});
    }
  return t;
}

// A row's figures in the JSON line.
json RowJson(const Row& r) {
  json j = {{"mesher", r.mesher}, {"ok", r.ok}, {"note", r.note}};
  if (!r.ok) return j;
  j.update({{"seconds", r.seconds},
            {"rss_mb", r.rss_mb},
            {"completeness", {r.c2, r.c5}},
            {"precision", {r.p2, r.p5}},
            {"f", {F(r.c2, r.p2), F(r.c5, r.p5)}},
            {"truth_to_mesh_mean", r.t2m_mean},
            {"truth_to_mesh_median", r.t2m_median},
            {"mesh_to_truth_mean", r.m2t_mean},
            {"manifold", r.stats.manifold},
            {"closed", r.stats.closed},
            {"boundary_loops", r.stats.boundary_loops},
            {"faces", r.stats.faces},
            {"roughness_deg", r.roughness}});
  if (r.road) j["road_completeness"] = *r.road;
  if (r.cameras_in_o) j["cameras_in_o"] = *r.cameras_in_o;
  if (r.back_facing) j["back_facing"] = *r.back_facing;
  if (r.plane_roughness)
    j["roughness_on_planes"] = {{"deg", r.plane_roughness->degrees}, {"edges", r.plane_roughness->edges},
                                {"face_share", r.plane_roughness->face_share}};
  if (r.behind) j["seen_from_behind_every_10th_keyframe"] = *r.behind;
  if (r.p2_scanner) j["precision_in_scanner_view"] = {{"p2", *r.p2_scanner}, {"area_share", *r.scanner_share}};
  j["components"] = r.small.components;
  j["small_components"] = {{"count", r.small.small}, {"area_share", r.small.area_share}};
  return j;
}

// A row's wall time and memory as the tables show them: blank for a row computed here rather
// than run (the vertex-move limits have no time of their own).
void WallAndRss(const Row& r, char (&wall)[32], char (&rss)[32]) {
  if (r.seconds > 0.0 || r.rss_mb > 0.0)
    std::snprintf(wall, sizeof(wall), "%.1f", r.seconds), std::snprintf(rss, sizeof(rss), "%.0f", r.rss_mb);
}

// The accuracy table; each row's JSON object.
json PrintAccuracy(const std::vector<Row>& rows) {
  const bool road = rows.size() && rows[0].road;
  std::printf("| mesher | wall s | RSS MB | compl. 0.2 | prec. 0.2 | F 0.2 | F 0.5 | truth→mesh "
              "mean / median (m) | mesh→truth mean (m) | manifold | roughness ° |%s\n",
              road ? " road compl. 0.2 |" : "");
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|%s\n", road ? "---|" : "");
  json list = json::array();
  for (const Row& r : rows) {
    list.push_back(RowJson(r));
    if (!r.ok) {
      std::printf("| %s | %s | | | | | | | | | |\n", r.mesher.c_str(),
                  (r.note.empty() ? std::string("failed") : r.note).c_str());
      continue;
    }
    char wall[32] = "", rss[32] = "";
    WallAndRss(r, wall, rss);
    std::printf("| %s | %s | %s | %.3f | %.3f | %.3f | %.3f | %.3f / %.3f | %.3f | %s | %.1f |",
                r.mesher.c_str(), wall, rss, r.c2, r.p2, F(r.c2, r.p2), F(r.c5, r.p5),
                r.t2m_mean, r.t2m_median, r.m2t_mean, ManifoldText(r.stats).c_str(), r.roughness);
    if (r.road) std::printf(" %.3f |", *r.road);
    std::printf("\n");
  }
  return list;
}

// Issue 45's figures of the surface a user sees, the same code on every mesh.
void PrintSurface(const std::vector<Row>& rows) {
  bool planes = false;
  for (const Row& r : rows) planes |= r.ok && r.plane_roughness.has_value();
  std::printf("\n| mesher | faces | roughness, all edges ° | roughness on the true planes ° (faces "
              "counted) | seen from behind, every 10th keyframe | components under 0.5 %% of the "
              "area (count, area share) | components | wall s | peak RSS MB |\n"
              "|---|---|---|---|---|---|---|---|---|\n");
  for (const Row& r : rows) {
    if (!r.ok) continue;
    char plane[64] = "no planar truth", behind[32] = "-", wall[32] = "", rss[32] = "";
    if (r.plane_roughness)
      std::snprintf(plane, sizeof(plane), "%.1f (%.0f %%)", r.plane_roughness->degrees,
                    100.0 * r.plane_roughness->face_share);
    if (r.behind) std::snprintf(behind, sizeof(behind), "%.2f %%", 100.0 * *r.behind);
    WallAndRss(r, wall, rss);
    std::printf("| %s | %lld | %.1f | %s | %s | %lld, %.2f %% | %lld | %s | %s |\n", r.mesher.c_str(),
                static_cast<long long>(r.stats.faces), r.roughness, plane, behind,
                static_cast<long long>(r.small.small), 100.0 * r.small.area_share,
                static_cast<long long>(r.small.components), wall, rss);
  }
  if (planes)
    std::printf("(roughness on the true planes: the mean angle between the normals of neighbouring "
                "faces whose vertices all lie within 0.2 m of one true plane and of no other; "
                "seen from behind: report.json's measure over every 10th keyframe's camera, at a "
                "quarter of its size)\n");
  else
    std::printf("(no planar truth here: roughness over all edges; seen from behind: report.json's "
                "measure over every 10th keyframe's camera, at a quarter of its size)\n");
}

// The camera path (issue 34): cameras in free space, and no surface seen from behind, with its
// targets; each row's note; imr against each peer.
void PrintNotes(const std::vector<Row>& rows, std::vector<Target>* targets) {
  for (const Row& r : rows)
    if (r.ok && r.cameras_in_o && r.back_facing)
      std::printf("%s: keyframe camera centres in O %.1f %%, visible area seen from behind "
                  "%.2f %% (keyframe views)\n",
                  r.mesher.c_str(), 100.0 * *r.cameras_in_o, 100.0 * *r.back_facing);
  if (!rows.empty() && rows[0].ok && rows[0].cameras_in_o && rows[0].back_facing) {
    targets->push_back({"keyframe camera centres in O", 1.0, true, *rows[0].cameras_in_o});
    targets->push_back({"visible area seen from behind", 0.01, false, *rows[0].back_facing});
  }
  for (const Row& r : rows)
    if (r.ok && r.p2_scanner && r.scanner_share)
      std::printf("%s: precision 0.2 m in the scanner's view %.3f, over %.1f %% of the area (the "
                  "rest above every scan's elevations or beyond its range)\n",
                  r.mesher.c_str(), *r.p2_scanner, 100.0 * *r.scanner_share);
  for (const Row& r : rows)
    if (!r.ok || r.note.empty()) continue;
    else std::printf("%s: %s\n", r.mesher.c_str(), r.note.c_str());
  if (rows.empty() || !rows[0].ok) return;
  for (size_t i = 1; i < rows.size(); ++i) {
    const Row& p = rows[i];
    if (!p.ok || p.mesher.rfind("limit", 0) == 0) continue;
    std::printf("imr / %s: completeness ×%.2f, precision ×%.2f, truth→mesh mean ×%.2f, time "
                "×%.2f, memory ×%.2f\n",
                p.mesher.c_str(), rows[0].c2 / std::max(p.c2, 1e-9),
                rows[0].p2 / std::max(p.p2, 1e-9), rows[0].t2m_mean / std::max(p.t2m_mean, 1e-9),
                rows[0].seconds / std::max(p.seconds, 1e-9),
                rows[0].rss_mb / std::max(p.rss_mb, 1e-9));
  }
}

void Print(const std::string& title, const std::vector<Row>& rows,
           std::vector<Target> targets, json* out, const std::vector<Target>& more = {}) {
  std::printf("\n### %s\n\n", title.c_str());
  (*out)["rows"] = PrintAccuracy(rows);
  PrintSurface(rows);
  PrintNotes(rows, &targets);
  targets.insert(targets.end(), more.begin(), more.end());
  json tj = json::array();
  for (const Target& t : targets) {
    const bool met = t.at_least ? t.reached >= t.value : t.reached <= t.value;
    std::printf("target: %s %s %.3g — reached %.3f: %s\n", t.what.c_str(),
                t.at_least ? ">=" : "<=", t.value, t.reached, met ? "met" : "NOT met");
    tj.push_back({{"what", t.what}, {"target", t.value}, {"reached", t.reached}, {"met", met}});
  }
  (*out)["targets"] = tj;
}

// --- street: ../shared/data/street-stream --------------------------------------------------------
json Street(const QualityArgs& args, const fs::path& work) {
  const fs::path data = fs::path(args.shared) / "data/street-stream";
  json out = {{"input", "street-stream"}};
  if (!fs::exists(data / "slam.json")) {
    std::printf("\n### street-stream: skipped, %s not found\n", (data / "slam.json").c_str());
    out["skipped"] = "no " + (data / "slam.json").string();
    return out;
  }
  fs::create_directories(work);
  eval::EvaluationInputs completeness, precision;
  completeness.truth = (data / "gt_points.ply").string();
  precision.truth = (data / "scene_mesh.ply").string();
  auto evaluate = [&](const fs::path& mesh, Row* row) {
    Evaluate(mesh, completeness, precision, row);
  };
  std::vector<Row> rows;
  Row imr;
  imr.mesher = "imr (defaults)";
  const json job = {{"description", "imr-bench quality: street-stream"},
                    {"sequences", {(data / "slam.json").string()}},
                    {"input", {{"format", "slam_json"}}},
                    {"pipeline", {Exporter()}},
                    {"output", {{"directory", (work / "imr").string()}, {"formats", {"ply"}}}}};
  if (RunImr(job, work, "imr", "--export-colmap " + Quote((work / "colmap-model").string()), &imr))
    evaluate(work / "imr/mesh.ply", &imr);
  rows.push_back(imr);
  // engine.scale: auto (the default for slam_json) must be no worse than the metric defaults here.
  Row metric;
  metric.mesher = "imr, engine.scale metric";
  json metric_job = job;
  metric_job["engine"] = {{"scale", "metric"}};
  metric_job["output"]["directory"] = (work / "imr-metric").string();
  if (RunImr(metric_job, work, "imr-metric", "", &metric)) evaluate(work / "imr-metric/mesh.ply", &metric);
  rows.push_back(metric);
  RunBefore(args, job, json::object(), json::object(), work, "before-defaults", "defaults", evaluate, &rows);
  RunBefore(args, job, {{"steiner_export", "any_steiner"}}, json::object(), work, "before-any",
            "nearest, any_steiner (issue 14's table)", evaluate, &rows);

  // The limit: the stream's points triangulated per true plane (oracle_mesh.py).
  Row limit;
  limit.mesher = "limit: the points triangulated per true plane (oracle_mesh.py, final positions)";
  const fs::path oracle = fs::path(args.shared) / "tools/oracle_mesh.py";
  if (fs::exists(oracle) && Sh("/usr/bin/python3 -c 'import open3d, scipy' 2>/dev/null") == 0) {
    const TimedRun r = RunTimed("/usr/bin/python3 " + Quote(oracle.string()) + " " +
                                    Quote(data.string()) + " " +
                                    Quote((work / "oracle.ply").string()),
                                work / "oracle.log");
    if (r.status == 0) evaluate(work / "oracle.ply", &limit);
    else limit.note = "oracle_mesh.py failed (oracle.log)";
    limit.seconds = r.seconds, limit.rss_mb = r.peak_rss_mb;
  } else {
    limit.note = "needs " + oracle.string() + " and Debian's python3-open3d, python3-scipy";
  }
  rows.push_back(limit);
  RunPeers(args, work, data / "slam.json", work / "colmap-model", "the stream as it is",
           evaluate, &rows);
  const Row& r = rows[0];
  Print("street-stream (" + data.string() + "), slam_json, every mesher fed the same stream", rows,
        {{"completeness 0.2 m", 0.80, true, r.c2},
         {"precision 0.2 m", 0.80, true, r.p2},
         {"F 0.2 m", 0.80, true, F(r.c2, r.p2)},
         {"truth→mesh mean (m)", 0.20, false, r.t2m_mean},
         {"F 0.2 m, engine.scale auto against metric (issue 16: no worse)", F(metric.c2, metric.p2),
          true, F(r.c2, r.p2)}},
        &out);
  return out;
}

// OpenMVS's RefineMesh (issue 34) on the mesh of imr's unrefined run (`unrefined`, its mesh
// `mesh`) and the keyframes' images of its COLMAP export (`model`, every frame's; the job's
// keyframe_every picks the keyframes, as imr's refinement sees them; each image looked up in
// `image_dirs`): InterfaceCOLMAP, then RefineMesh with its defaults and --openmvs-args, scored by
// `evaluate`.
// Its wall time is the unrefined run's plus OpenMVS's, as imr's refined row includes its run.
// Without --openmvs, or without the binaries, no row: one line says why.
void RunOpenMvsRow(const QualityArgs& args, const json& job, const fs::path& work,
                   const Row& unrefined, const fs::path& mesh, const fs::path& model,
                   const std::vector<fs::path>& image_dirs,
                   const std::function<void(const fs::path&, Row*)>& evaluate,
                   std::vector<Row>* rows) {
  if (args.openmvs.empty()) {
    std::printf("OpenMVS RefineMesh: no row (give --openmvs BIN_DIR, from "
                "tools/bench/peers/build_openmvs.sh)\n");
    return;
  }
  if (!args.openmvs_refine) return;
  const fs::path bin(args.openmvs);
  if (!fs::exists(bin / "InterfaceCOLMAP") || !fs::exists(bin / "RefineMesh")) {
    std::printf("OpenMVS RefineMesh: no row (no InterfaceCOLMAP and RefineMesh in %s)\n",
                bin.c_str());
    return;
  }
  Row row;
  row.mesher = "OpenMVS RefineMesh (on imr's unrefined mesh)";
  row.refined = true;
  const fs::path dir = work / "openmvs";
  fs::create_directories(dir);
  if (!unrefined.ok || !fs::exists(mesh)) {
    row.note = "no unrefined mesh to refine";
  } else if (const std::string e = PrepareOpenMvsColmap(
                 model, image_dirs, dir,
                 args.openmvs_all_images
                     ? 1
                     : job["input"].value("options", json::object()).value("keyframe_every", 5));
             !e.empty()) {
    row.note = "preparing the COLMAP model: " + e;
  } else {
    try {
      WriteOpenMvsPly(mesh, dir / "before.ply");
      const OpenMvsResult r = RunOpenMvs(bin, dir, dir / "before.ply", args.openmvs_args);
      row.seconds = unrefined.seconds + r.interface_seconds + r.refine_seconds;
      row.rss_mb = std::max(unrefined.rss_mb, r.peak_rss_mb);
      if (!r.ok) {
        row.note = r.error;
      } else {
        evaluate(r.mesh, &row);
        char note[512];
        std::snprintf(note, sizeof(note),
                      "imr's unrefined run %.1f s + InterfaceCOLMAP %.1f s + RefineMesh %.1f s "
                      "(peak %.0f MB)",
                      unrefined.seconds, r.interface_seconds, r.refine_seconds, r.peak_rss_mb);
        row.note = std::string(note) + "; " + r.refine_command;
      }
    } catch (const std::exception& error) {
      row.note = error.what();
    }
  }
  rows->push_back(row);
}

// OpenMVS's whole pipeline (issue 45) on the keyframes' images and cameras of imr's run (its COLMAP
// export `model`: the same poses and sparse points imr had; every image with
// --openmvs-all-images): InterfaceCOLMAP -> DensifyPointCloud -> ReconstructMesh -> RefineMesh,
// each nice -n 10, scored by `evaluate`. Its wall time and peak RSS are OpenMVS's four processes'
// (the poses come from imr's run, not counted).
void RunOpenMvsPipelineRow(const QualityArgs& args, const json& job, const fs::path& work,
                           const fs::path& model, const std::vector<fs::path>& image_dirs,
                           const std::function<void(const fs::path&, Row*)>& evaluate,
                           std::vector<Row>* rows) {
  if (args.openmvs.empty() || !args.openmvs_pipeline) return;
  const fs::path bin(args.openmvs);
  Row row;
  row.mesher = "OpenMVS pipeline: DensifyPointCloud → ReconstructMesh → RefineMesh";
  row.refined = true;
  for (const char* exe : {"InterfaceCOLMAP", "DensifyPointCloud", "ReconstructMesh", "RefineMesh"})
    if (!fs::exists(bin / exe)) {
      std::printf("OpenMVS pipeline: no row (no %s in %s: tools/bench/peers/build_openmvs.sh)\n",
                  exe, bin.c_str());
      return;
    }
  const int keyframe_every =
      args.openmvs_all_images ? 1 : job["input"].value("options", json::object()).value("keyframe_every", 5);
  const fs::path dir = work / "openmvs-pipeline";
  fs::create_directories(dir);
  std::printf("OpenMVS pipeline: %s; %s\n",
              keyframe_every == 1 ? "every frame's image" : ("every " + std::to_string(keyframe_every) +
                                                             "th frame's image (the keyframes)").c_str(),
              args.openmvs_pipeline_options.Describe().c_str());
  std::fflush(stdout);
  if (!fs::exists(model)) {
    row.note = "no COLMAP export of imr's run (" + model.string() + ")";
  } else if (const std::string e = PrepareOpenMvsColmap(model, image_dirs, dir, keyframe_every); !e.empty()) {
    row.note = "preparing the COLMAP model: " + e;
  } else {
    const OpenMvsPipelineResult r = RunOpenMvsPipeline(bin, dir, args.openmvs_pipeline_options);
    row.seconds = r.Seconds();
    row.rss_mb = r.PeakRssMb();
    std::string steps;
    for (const auto& step : r.steps) {
      char one[160];
      std::snprintf(one, sizeof(one), "%s%s %.1f s (%.0f MB)", steps.empty() ? "" : " + ",
                    step.name.c_str(), step.seconds, step.peak_rss_mb);
      steps += one;
    }
    if (!r.ok) row.note = r.error + "; " + steps;
    else evaluate(r.mesh, &row), row.note = steps + "; " + args.openmvs_pipeline_options.Describe();
  }
  rows->push_back(row);
}

// The job variant (--variant-job INPUT=FILE for this input, else the config's own job) with
// --config-set's KEY=VALUE through `imr run --set`: one more imr row, when either was given.
void RunVariant(const QualityArgs& args, const std::string& input, const json& job,
                const fs::path& work, const std::function<void(const fs::path&, Row*)>& evaluate,
                std::vector<Row>* rows) {
  const auto file = args.variant_jobs.find(input);
  if (file == args.variant_jobs.end() && args.config_sets.empty()) return;
  Row row;
  json variant = job;
  std::string label = "imr variant: ";
  if (file != args.variant_jobs.end()) {
    std::ifstream in(file->second);
    variant = json::parse(in, nullptr, /*allow_exceptions=*/false);
    if (!variant.is_object()) {
      row.mesher = "imr variant: " + file->second;
      row.note = file->second + ": cannot read the job (not a JSON object)";
      rows->push_back(row);
      return;
    }
    variant["sequences"] = job["sequences"];
    label += fs::path(file->second).filename().string();
  } else {
    label += "the config";
  }
  variant["output"] = job["output"];
  variant["output"]["directory"] = (work / "variant").string();
  std::string sets;
  for (const std::string& kv : args.config_sets) sets += " --set " + Quote(kv), label += " --set " + kv;
  row.mesher = label;
  for (const json& stage : variant.value("pipeline", json::array()))
    row.refined |= stage.value("kind", "") == "mesh_refiner";
  if (RunImr(variant, work, "variant", sets, &row)) evaluate(work / "variant/mesh.ply", &row);
  rows->push_back(row);
}

// Where --renders draws the meshes: a sequence, its format and the frames.
struct RenderSource {
  std::string input;  // file name prefix: synth, kitti
  fs::path sequence;
  std::string format;
  int camera = -1;  // kitti_raw's camera; -1: none
  std::vector<int> frames;
};

// Each scored mesh (not the limits, computed rather than run) drawn into the same frames with
// `imr render`: DIR/<input>-<mesher>-frame<N>.png, the list printed.
void RenderRows(const QualityArgs& args, const RenderSource& source, const std::vector<Row>& rows) {
  if (args.renders.empty()) return;
  const fs::path dir(args.renders);
  fs::create_directories(dir);
  const std::vector<int> frames = args.render_frames.empty() ? source.frames : args.render_frames;
  std::printf("\nrenders (%s, frames", source.input.c_str());
  for (int f : frames) std::printf(" %d", f);
  std::printf("):\n");
  for (const Row& r : rows) {
    if (!r.ok || r.mesh.empty() || r.mesher.rfind("limit", 0) == 0) continue;
    std::string slug;
    for (char c : r.mesher) {
      if (std::isalnum(static_cast<unsigned char>(c))) slug += static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
      else if (!slug.empty() && slug.back() != '-') slug += '-';
      if (slug.size() >= 48) break;
    }
    while (!slug.empty() && slug.back() == '-') slug.pop_back();
    for (int f : frames) {
      const fs::path png = dir / (source.input + "-" + slug + "-frame" + std::to_string(f) + ".png");
      const std::string cmd = Quote((ExeDir() / "imr").string()) + " render " + Quote(r.mesh.string()) +
                              " --sequence " + Quote(source.sequence.string()) + " --format " +
                              source.format +
                              (source.camera >= 0 ? " --camera " + std::to_string(source.camera) : "") +
                              " --frame " + std::to_string(f) + " --out " + Quote(png.string());
      const int status = Sh(cmd + " >" + Quote((dir / "render.log").string()) + " 2>&1");
      std::printf("  %s: %s\n", r.mesher.c_str(),
                  status == 0 ? png.c_str() : ("failed (" + (dir / "render.log").string() + ")").c_str());
    }
  }
}

// An image job of configs/ (`config`) through imr, writing the stream and the final points for
// the peers; the same through the --before build with the settings f69611d's configs had (weights
// mode, 5 m grid, any_steiner; `before_refiner` the refiner's params then); then the peers.
std::vector<Row> RunImageJob(const QualityArgs& args, const json& job, const std::string& config,
                             const json& before_refiner, const fs::path& work,
                             const std::vector<fs::path>& image_dirs,
                             const std::function<void(const fs::path&, Row*)>& evaluate,
                             const RenderSource& render) {
  std::vector<Row> rows;
  Row imr;
  imr.mesher = "imr (configs/" + config + ")";
  if (RunImr(job, work, "imr",
             "--export-stream " + Quote((work / "stream.json").string()) + " --export-colmap " +
                 Quote((work / "colmap-model").string()),
             &imr))
    evaluate(work / "imr/mesh.ply", &imr);
  rows.push_back(imr);
  // The same job with the photometric refinement (issue 34) when the config has none, without
  // it when it has one (configs/default.json): rows[1]. Row::refined tells which is which.
  bool has_refiner = false;
  for (const json& stage : job["pipeline"]) has_refiner |= stage["kind"] == "mesh_refiner";
  rows[0].refined = has_refiner;
  Row other;
  other.refined = !has_refiner;
  other.mesher = "imr (configs/" + config + ")" +
                 (has_refiner ? " without its mesh_refiner" : " + org.imr.refine.photometric every 10 keyframes");
  json other_job = job;
  json pipeline = json::array();
  for (const json& stage : job["pipeline"]) {
    if (stage["kind"] == "mesh_refiner") continue;
    if (stage["kind"] == "exporter" && !has_refiner && pipeline.size() + 1 == job["pipeline"].size())
      pipeline.push_back({{"kind", "mesh_refiner"}, {"plugin", "org.imr.refine.photometric"},
                          {"every_keyframes", 10}});
    pipeline.push_back(stage);
  }
  other_job["pipeline"] = pipeline;
  other_job["output"]["directory"] = (work / "other").string();
  // OpenMVS refines the unrefined run's mesh with that run's cameras and points.
  const fs::path other_colmap = work / "other-colmap";
  const std::string other_args = has_refiner && !args.openmvs.empty()
                                     ? "--export-colmap " + Quote(other_colmap.string())
                                     : "";
  if (RunImr(other_job, work, "other", other_args, &other)) evaluate(work / "other/mesh.ply", &other);
  rows.push_back(other);
  // The refinement's time per call, per tenth of the calls: bounded when it stays flat.
  const fs::path report = has_refiner ? work / "imr/report.json" : work / "other/report.json";
  std::ifstream in(report);
  const json r = json::parse(in, nullptr, /*allow_exceptions=*/false);
  if (r.is_object() && r.contains("refinement")) {
    const std::vector<double> calls = r["refinement"]["call_seconds"].get<std::vector<double>>();
    std::printf("refinement: %zu calls, %.1f s; mean seconds per call by tenth of the calls:",
                calls.size(), r["refinement"]["seconds"].get<double>());
    for (int t = 0; t < 10 && !calls.empty(); ++t) {
      const std::size_t a = calls.size() * t / 10, b = std::max(a + 1, calls.size() * (t + 1) / 10);
      double sum = 0.0;
      for (std::size_t i = a; i < b && i < calls.size(); ++i) sum += calls[i];
      std::printf(" %.2f", sum / static_cast<double>(b - a));
    }
    std::printf("\n");
  }
  RunBefore(args, job,
            {{"window", 15}, {"steiner_spacing", 5.0}, {"visibility_mode", "weights"},
             {"steiner_export", "any_steiner"}},
            {{"org.imr.refiner.ceres", before_refiner}, {"org.imr.features.edge_klt", json::object()}},
            work, "before", "configs/" + config + " then", evaluate, &rows);
  RunPeers(args, work, work / "stream.json", work / "colmap-model",
           "imr's exported stream (--export-stream)", evaluate, &rows);
  if (has_refiner)
    RunOpenMvsRow(args, job, work, rows[1], work / "other/mesh.ply", other_colmap, image_dirs,
                  evaluate, &rows);
  else
    RunOpenMvsRow(args, job, work, rows[0], work / "imr/mesh.ply", work / "colmap-model",
                  image_dirs, evaluate, &rows);
  RunOpenMvsPipelineRow(args, job, work, work / "colmap-model", image_dirs, evaluate, &rows);
  RunVariant(args, render.input, job, work, evaluate, &rows);
  RenderRows(args, render, rows);
  return rows;
}

// What a refinement that only moves vertices can reach on a mesh: each vertex put on its nearest
// point of the true surface (`truth_mesh`), as is and after one midpoint subdivision (each
// triangle split in four, so that a long triangle can bend once). The carving's choice of
// triangles bounds every refinement by these rows (issue 34's targets against them).
void VertexMoveLimits(const fs::path& unrefined, const fs::path& truth_mesh, const fs::path& work,
                      const std::function<void(const fs::path&, Row*)>& evaluate,
                      std::vector<Row>* rows) {
  for (const int subdivisions : {0, 1}) {
    Row row;
    row.mesher = subdivisions == 0
                     ? "limit of vertex moves: the unrefined mesh's vertices on the true surface"
                     : "limit of vertex moves after one midpoint subdivision (4x the triangles)";
    try {
      eval::TriangleMesh mesh = eval::ReadMesh(unrefined);
      for (int s = 0; s < subdivisions; ++s) {
        std::unordered_map<uint64_t, uint32_t> middle;
        auto mid = [&](uint32_t a, uint32_t b) {
          const uint64_t key = a < b ? (uint64_t{a} << 32 | b) : (uint64_t{b} << 32 | a);
          auto [it, added] = middle.emplace(key, static_cast<uint32_t>(mesh.vertices.size()));
          if (added) mesh.vertices.push_back(Scale(Add(mesh.vertices[a], mesh.vertices[b]), 0.5));
          return it->second;
        };
        std::vector<std::array<uint32_t, 3>> split;
        split.reserve(4 * mesh.triangles.size());
        for (const auto& t : mesh.triangles) {
          const uint32_t ab = mid(t[0], t[1]), bc = mid(t[1], t[2]), ca = mid(t[2], t[0]);
          split.push_back({t[0], ab, ca});
          split.push_back({ab, t[1], bc});
          split.push_back({ca, bc, t[2]});
          split.push_back({ab, bc, ca});
        }
        mesh.triangles.swap(split);
      }
      const eval::MeshDistance truth(eval::ReadMesh(truth_mesh));
      mesh.vertices = truth.ClosestPoints(mesh.vertices, 0);
      const fs::path out = work / ("vertex-move-limit-" + std::to_string(subdivisions) + ".off");
      std::ofstream f(out);
      f.precision(17);
      f << "OFF\n" << mesh.vertices.size() << " " << mesh.triangles.size() << " 0\n";
      for (const Vec3& v : mesh.vertices) f << v[0] << " " << v[1] << " " << v[2] << "\n";
      for (const auto& t : mesh.triangles) f << "3 " << t[0] << " " << t[1] << " " << t[2] << "\n";
      f.close();
      if (!f) throw std::runtime_error("cannot write " + out.string());
      evaluate(out, &row);
    } catch (const std::exception& e) {
      row.note = e.what();
    }
    rows->push_back(row);
  }
}

// --- synth: imr-synth's street, the default image job --------------------------------------------
json Synth(const QualityArgs& args, const fs::path& work) {
  json out = {{"input", "imr-synth street"}, {"frames", args.synth_frames}};
  fs::create_directories(work);
  const fs::path seq = work / "street";
  if (Sh(Quote((ExeDir() / "imr-synth").string()) + " --out " + Quote(seq.string()) +
         " --frames " + std::to_string(args.synth_frames) + " --color --no-lidar --force -q >" +
         Quote((work / "synth.log").string()) + " 2>&1") != 0) {
    std::printf("\n### imr-synth street: imr-synth failed (%s)\n", (work / "synth.log").c_str());
    out["skipped"] = "imr-synth failed";
    return out;
  }
  // The README's first command: configs/default.json.
  const json job = ConfigJob("default.json", seq, work / "imr");
  eval::EvaluationInputs truth;
  truth.truth = (seq / "ground_truth/scene.ply").string();
  truth.sequence = seq.string();
  SurfaceContext surface;
  surface.model = work / "colmap-model";
  surface.keyframe_every = job["input"].value("options", json::object()).value("keyframe_every", 5);
  try {
    surface.planes = SyntheticPlanes(eval::ReadSyntheticTruth((seq / "ground_truth/scene.json").string()), 0.2);
  } catch (const std::exception& e) {
    std::printf("roughness on the true planes: none (%s)\n", e.what());
  }
  auto evaluate = [&](const fs::path& mesh, Row* row) {
    Evaluate(mesh, truth, truth, row, &surface);
  };
  std::vector<Row> rows =
      RunImageJob(args, job, "default.json", {{"max_distance", 30.0}}, work, {seq / "image_2"},
                  evaluate, {"synth", seq, "kitti_odometry", -1, {200}});
  VertexMoveLimits(work / (rows[0].refined ? "other" : "imr") / "mesh.ply", truth.truth, work,
                   evaluate, &rows);
  const Row& r = rows[0];
  const Row& refined = rows[0].refined ? rows[0] : rows[1];
  const Row& plain = rows[0].refined ? rows[1] : rows[0];
  std::vector<Target> issue45 = Issue45Targets(rows, /*f_twice=*/false);
  if (r.ok) {
    issue45.push_back({"issue 45: wall time (s), twice today's 45 s", 90.0, false, r.seconds});
    issue45.push_back({"issue 45: peak RSS (MB), today's", 741.0, false, r.rss_mb});
  }
  // Issue 34's targets for the refined surface; its wall time against the same run unrefined.
  Print("imr-synth street, " + std::to_string(args.synth_frames) +
            " frames, default image job (points from imr's front end for every mesher)",
        rows,
        {{"completeness 0.2 m", 0.70, true, r.c2},
         {"precision 0.2 m", 0.75, true, r.p2},
         {"road completeness 0.2 m", 0.60, true, r.road.value_or(0.0)},
         {"refined: precision 0.2 m", 0.85, true, refined.p2},
         {"refined: completeness 0.2 m", 0.70, true, refined.c2},
         {"refined: F 0.2 m", 0.80, true, F(refined.c2, refined.p2)},
         {"refined: truth→mesh mean (m)", 0.15, false, refined.t2m_mean},
         {"refined: wall time / unrefined", 1.5, false, refined.seconds / std::max(plain.seconds, 1e-9)},
         {"refined: manifold (1 = yes)", 1.0, true, refined.stats.manifold ? 1.0 : 0.0},
         {"issue 45: F 0.2 m", 0.80, true, F(r.c2, r.p2)},
         {"issue 45: roughness on the true planes (deg)", 15.0, false,
          r.plane_roughness ? r.plane_roughness->degrees : r.roughness}},
        &out, issue45);
  return out;
}

// --- kitti: the KITTI raw sample against its Velodyne -------------------------------------------
json Kitti(const QualityArgs& args, const fs::path& work) {
  json out = {{"input", "KITTI raw sample"}};
  const fs::path root = fs::path(args.shared) / "data/kitti-raw-2011_09_26-traffic";
  const fs::path drive = root / "2011_09_26/2011_09_26_drive_unknown_sync";
  if (!fs::exists(drive)) {
    std::printf("\n### KITTI raw sample: skipped, %s not found\n", drive.c_str());
    out["skipped"] = "no " + drive.string();
    return out;
  }
  fs::create_directories(work);
  const json job = ConfigJob("kitti-raw-sample.json", drive, work / "imr");
  eval::EvaluationInputs truth;  // the Velodyne scans, cropped to camera 2's view
  truth.sequence = drive.string();
  truth.sequence_options.camera = 2;
  SurfaceContext surface;
  surface.model = work / "colmap-model";
  surface.keyframe_every = job["input"].value("options", json::object()).value("keyframe_every", 5);
  auto evaluate = [&](const fs::path& mesh, Row* row) { Evaluate(mesh, truth, truth, row, &surface); };
  const std::vector<Row> rows =
      RunImageJob(args, job, "kitti-raw-sample.json", json::object(), work,
                  {drive / "image_02/data", drive / "image_02"}, evaluate,
                  {"kitti", drive, "kitti_raw", 2, {40}});
  // The target: truth -> mesh mean at most half of what imr gave before (the --before row).
  std::vector<Target> targets;
  if (rows.size() > 2 && rows[2].ok && !args.before.empty())
    targets.push_back({"truth→mesh mean (m), half of " + args.before_label + "'s",
                       rows[2].t2m_mean / 2, false, rows[0].t2m_mean});
  // Issue 34: the refined surface better by a quarter than the same run unrefined.
  const Row& refined = rows[0].refined ? rows[0] : rows[1];
  const Row& plain = rows[0].refined ? rows[1] : rows[0];
  if (refined.ok && plain.ok) {
    targets.push_back({"refined: precision 0.2 m, 1.25 x unrefined", 1.25 * plain.p2, true, refined.p2});
    targets.push_back({"refined: truth→mesh mean (m), 0.75 x unrefined", 0.75 * plain.t2m_mean,
                       false, refined.t2m_mean});
  }
  // Issue 45 against the Velodyne (no planar truth: roughness over all edges).
  const Row& r = rows[0];
  targets.push_back({"issue 45: precision 0.2 m", 0.35, true, r.p2});
  targets.push_back({"issue 45: completeness 0.2 m", 0.45, true, r.c2});
  targets.push_back({"issue 45: truth→mesh mean (m)", 0.40, false, r.t2m_mean});
  targets.push_back({"issue 45: roughness, all edges (deg)", 20.0, false, r.roughness});
  Print("KITTI raw sample (78 frames, camera 2) against its Velodyne scans", rows, targets, &out,
        Issue45Targets(rows, /*f_twice=*/true));
  return out;
}

// --- middlebury: the temple and dino rings, for a look (no ground truth) ------------------------
// Each Middlebury ring through the image pipeline (the job `imr mesh --format middlebury` makes),
// with and without org.imr.refine.photometric (every 4 of its 16 keyframes), and the same frame
// rendered from both (the PNGs stay in --work): faces, roughness, manifold, the share of the
// visible surface seen from behind, time.
json Middlebury(const QualityArgs& args, const fs::path& work) {
  json out = {{"input", "Middlebury rings"}, {"rings", json::array()}};
  for (const std::string ring : {"templeSparseRing", "dinoSparseRing"}) {
    const fs::path data = fs::path(args.shared) / "data/middlebury" / ring;
    if (!fs::exists(data)) {
      std::printf("\n### Middlebury %s: skipped, %s not found\n", ring.c_str(), data.c_str());
      continue;
    }
    const fs::path dir = work / ring;
    fs::create_directories(dir);
    std::vector<Row> rows;
    for (const bool refine : {false, true}) {
      const std::string name = refine ? "refined" : "plain";
      json pipeline = {{{"kind", "features"}, {"plugin", "org.imr.features.edge_klt"}},
                       {{"kind", "refiner"}, {"plugin", "org.imr.refiner.ceres"}}};
      if (refine)
        pipeline.push_back({{"kind", "mesh_refiner"}, {"plugin", "org.imr.refine.photometric"},
                            {"every_keyframes", 4}});
      pipeline.push_back(Exporter());
      const json job = {{"description", "imr-bench quality: Middlebury " + ring},
                        {"sequences", {data.string()}},
                        {"input", {{"format", "middlebury"}}},
                        {"pipeline", pipeline},
                        {"output", {{"directory", (dir / name).string()}, {"stem", "mesh"}, {"formats", {"ply"}}}}};
      Row row;
      row.mesher = refine ? "imr + org.imr.refine.photometric every 4 keyframes" : "imr (imr mesh's job)";
      row.refined = refine;
      if (RunImr(job, dir, name, "", &row)) row.ok = MeshStats(dir / name / "mesh.ply", &row);
      const fs::path png = dir / (name + "_frame5.png");
      if (row.ok &&
          Sh(Quote((ExeDir() / "imr").string()) + " render " + Quote((dir / name / "mesh.ply").string()) +
             " --sequence " + Quote(data.string()) + " --format middlebury --frame 5 --out " +
             Quote(png.string()) + " >/dev/null 2>&1") == 0)
        row.note = png.string();
      rows.push_back(row);
    }
    std::printf("\n### Middlebury %s (16 images), no ground truth: a look\n\n", ring.c_str());
    std::printf("| mesher | faces | roughness (deg) | manifold | seen from behind | s | frame 5 |\n"
                "|---|---|---|---|---|---|---|\n");
    json rj = json::array();
    for (const Row& r : rows) {
      if (!r.ok) {
        std::printf("| %s | failed: %s |||||\n", r.mesher.c_str(), r.note.c_str());
        continue;
      }
      char behind[32] = "-";
      if (r.back_facing) std::snprintf(behind, sizeof(behind), "%.1f %%", 100.0 * *r.back_facing);
      std::printf("| %s | %lld | %.1f | %s | %s | %.1f | %s |\n", r.mesher.c_str(),
                  static_cast<long long>(r.stats.faces), r.roughness, ManifoldText(r.stats).c_str(),
                  behind, r.seconds, r.note.c_str());
      rj.push_back({{"mesher", r.mesher}, {"faces", r.stats.faces}, {"roughness", r.roughness},
                    {"manifold", r.stats.manifold}, {"back_facing", r.back_facing.value_or(-1.0)},
                    {"seconds", r.seconds}, {"render", r.note}});
    }
    out["rings"].push_back({{"ring", ring}, {"rows", rj}});
  }
  if (args.work.empty()) std::printf("(the renders go with the work folder: give --work to keep them)\n");
  return out;
}

// --- stream: imr's own synthetic observation stream -----------------------------------------------
json Stream(const QualityArgs& args, const fs::path& work) {
  json out = {{"input", "synthetic stream (street)"}, {"frames", args.stream_frames}};
  fs::create_directories(work);
  // The stream as the synthetic input format makes it (seed 1), and ground truth sampled
  // independently on what its cameras saw.
  synthetic::StreamOptions so;
  so.scene = synthetic::SceneKind::kStreet;
  so.frames = args.stream_frames;
  so.seed = 1;
  synthetic::SyntheticStream stream(so);
  const std::vector<synthetic::Vec3> truth =
      SampleSeenSurfaces(stream, args.stream_frames, 2, 400, 7);
  auto evaluate = [&](const fs::path& mesh_file, Row* row) {
    std::vector<double> xyz;
    std::vector<uint32_t> faces;
    if (!ReadPacked(mesh_file, row, &xyz, &faces)) return;
    const SceneAccuracy a2 = EvaluateAgainstScene(stream.scene(), xyz, faces, truth, 0.2);
    const SceneAccuracy a5 = EvaluateAgainstScene(stream.scene(), xyz, faces, truth, 0.5);
    row->c2 = a2.completeness, row->c5 = a5.completeness;
    row->p2 = a2.precision, row->p5 = a5.precision;
    row->t2m_mean = a2.truth_to_mesh_mean, row->t2m_median = a2.truth_to_mesh_median;
    row->m2t_mean = a2.mesh_to_scene_mean;
    row->ok = true;
  };
  std::vector<Row> rows;
  for (const std::string mode : {"exact", "weights"}) {
    Row r;
    r.mesher = mode == "exact" ? "imr (defaults)" : "imr, the paper's nearest policy (weights)";
    json pipeline = json::array();
    if (mode == "weights")
      pipeline.push_back({{"kind", "weight_policy"}, {"plugin", "org.imr.policy.nearest"}});
    pipeline.push_back(Exporter());
    const json job = {
        {"description", "imr-bench quality: synthetic stream"},
        {"sequences", {"street"}},
        {"input", {{"format", "synthetic"},
                   {"options", {{"frames", args.stream_frames}, {"seed", 1}}}}},
        {"engine", {{"visibility_mode", mode}}},
        {"pipeline", pipeline},
        {"output", {{"directory", (work / mode).string()}, {"formats", {"ply"}}}}};
    const std::string export_arg =
        mode == "exact" ? "--export-stream " + Quote((work / "stream.json").string()) +
                              " --export-colmap " + Quote((work / "colmap-model").string())
                        : "";
    if (RunImr(job, work, mode, export_arg, &r)) evaluate(work / mode / "mesh.ply", &r);
    rows.push_back(r);
  }
  RunPeers(args, work, work / "stream.json", work / "colmap-model",
           "imr's exported stream (--export-stream)", evaluate, &rows);
  Print("imr's synthetic observation stream, street, " + std::to_string(args.stream_frames) +
            " frames, against the analytic scene",
        rows, {}, &out);
  return out;
}

// Words of `v` appended to `list` (the OpenMVS arguments add up over repeated options).
std::function<std::string(const std::string&)> AppendWords(std::vector<std::string>* list) {
  return [list](const std::string& v) {
    std::stringstream ss(v);
    for (std::string s; ss >> s;) list->push_back(s);
    return std::string();
  };
}

const char kQualityUsage[] =
    "usage: imr-bench quality [--inputs street,synth,kitti,stream,middlebury] [--frames N]\n"
    "       [--work DIR] [--shared DIR] [--piazza PATH] [--colmap PATH] "
    "[--no-peers]\n"
    "       [--before IMR --before-label LABEL]   an earlier build's imr, same "
    "input\n"
    "       [--openmvs BIN_DIR [--openmvs-args 'ARGS'] [--openmvs-all-images]]\n"
    "           OpenMVS RefineMesh on the unrefined mesh and the keyframes' images "
    "(synth, kitti)\n"
    "         [--openmvs-rows refine,pipeline] [--openmvs-resolution-level N (1)]\n"
    "         [--openmvs-min-resolution PX (320)] [--openmvs-densify-args 'ARGS']\n"
    "         [--openmvs-reconstruct-args 'ARGS'] [--openmvs-refine-args 'ARGS']\n"
    "           and its whole pipeline on the same keyframes and images, its own row\n"
    "       [--config-set KEY=VALUE]... [--variant-job synth=FILE|kitti=FILE]...\n"
    "           one more imr row per image input: the job with imr run --set KEY=VALUE\n"
    "       [--renders DIR [--render-frames N,M]]   every mesher's mesh drawn by imr\n"
    "           render into the same frames (synth 200, kitti 40)\n";

// The options whose values are checked or go to more than one place.
void AddCheckedOptions(QualityArgs* args, Options* o) {
  o->Custom("--frames", [args](const std::string& v) {
    char* end = nullptr;
    const long n = std::strtol(v.c_str(), &end, 10);
    if (v.empty() || *end) return std::string("a whole number");
    args->synth_frames = args->stream_frames = static_cast<int>(n);
    return std::string();
  });
  o->Custom("--openmvs-rows", [args](const std::string& v) {
    args->openmvs_refine = v.find("refine") != std::string::npos;
    args->openmvs_pipeline = v.find("pipeline") != std::string::npos;
    return args->openmvs_refine || args->openmvs_pipeline ? std::string()
                                                           : "refine, pipeline or refine,pipeline";
  });
  o->Custom("--config-set", [args](const std::string& v) {
    if (v.find('=') == std::string::npos || v.front() == '=') return std::string("KEY=VALUE");
    args->config_sets.push_back(v);
    return std::string();
  });
  o->Custom("--variant-job", [args](const std::string& v) {
    const std::size_t eq = v.find('=');
    if (eq == std::string::npos || (v.substr(0, eq) != "synth" && v.substr(0, eq) != "kitti"))
      return std::string("synth=FILE or kitti=FILE");
    if (!fs::is_regular_file(v.substr(eq + 1))) return "a file (" + v.substr(eq + 1) + " is not one)";
    args->variant_jobs[v.substr(0, eq)] = fs::absolute(v.substr(eq + 1)).string();
    return std::string();
  });
  o->Custom("--renders", [args](const std::string& v) {
    args->renders = fs::absolute(v).string();
    return std::string();
  });
  o->IntList("--render-frames", &args->render_frames, 0);
}

bool ParseQualityArgs(int argc, char** argv, QualityArgs* args, int* status) {
  Options o("imr-bench quality", kQualityUsage);
  OpenMvsPipelineOptions& mvs = args->openmvs_pipeline_options;
  o.List("--inputs", &args->inputs).String("--work", &args->work).String("--shared", &args->shared);
  o.String("--piazza", &args->piazza).String("--colmap", &args->colmap);
  o.Flag("--no-peers", &args->peers, false).String("--before", &args->before);
  o.String("--before-label", &args->before_label).String("--openmvs", &args->openmvs);
  o.Flag("--openmvs-all-images", &args->openmvs_all_images);
  o.Custom("--openmvs-args", AppendWords(&args->openmvs_args));
  o.Int("--openmvs-resolution-level", &mvs.resolution_level);
  o.Int("--openmvs-min-resolution", &mvs.min_resolution);
  o.Custom("--openmvs-densify-args", AppendWords(&mvs.densify_args));
  o.Custom("--openmvs-reconstruct-args", AppendWords(&mvs.reconstruct_args));
  o.Custom("--openmvs-refine-args", AppendWords(&mvs.refine_args));
  AddCheckedOptions(args, &o);
  if (!o.Parse(argc, argv, status)) return false;
  if (const std::string e = mvs.Check(); !e.empty()) {
    std::fprintf(stderr, "imr-bench quality: the OpenMVS pipeline's options: %s\n", e.c_str());
    *status = 2;
    return false;
  }
  return true;
}

}  // namespace

int RunQualityBench(int argc, char** argv) {
  QualityArgs args;
  if (int status = 0; !ParseQualityArgs(argc, argv, &args, &status)) return status;
  args.shared = SharedDir(args.shared).string();
  const WorkFolder work_folder(args.work, "quality");
  const fs::path& work = work_folder.path();
  std::printf("imr-bench quality: %s; load average at start %s; work folder %s\n",
              MachineLine().c_str(), LoadAverage().c_str(), work.c_str());
  json result = {{"bench", "quality"}, {"machine", MachineLine()},
                 {"load_average_start", LoadAverage()}, {"inputs", json::array()}};
  for (const std::string& in : args.inputs) {
    json r;
    if (in == "street") r = Street(args, work / "street");
    else if (in == "synth") r = Synth(args, work / "synth");
    else if (in == "kitti") r = Kitti(args, work / "kitti");
    else if (in == "stream") r = Stream(args, work / "stream");
    else if (in == "middlebury") r = Middlebury(args, work / "middlebury");
    else {
      std::fprintf(stderr, "imr-bench quality: unknown input '%s'\n", in.c_str());
      return 2;
    }
    result["inputs"].push_back(r);
  }
  result["load_average_end"] = LoadAverage();
  std::printf("\nload average at end %s\n", LoadAverage().c_str());
  work_folder.Finish();
  std::printf("%s\n", result.dump().c_str());
  return 0;
}

}  // namespace imr::bench

namespace imr::bench {

// --- planes: engine.retriangulate_planes on one mesh, per tolerance -----------------------------
// The pass as a whole-mesh run makes it (a forgetting run makes it per released piece, with its
// seams kept: fewer regions), scored as the quality bench scores imr-synth: completeness and
// precision at 0.2 m against the scene, roughness over all edges and on the true planes, and
// the share seen from behind over every 10th keyframe when the sequence has its COLMAP model.
int RunPlanesBench(int argc, char** argv) {
  std::string mesh_file, sequence, out = "/tmp/imr-planes";
  std::vector<std::string> tolerances = {"0", "0.1", "0.2", "0.4"};
  int min_faces = engine::PlaneRetriangulationOptions().min_faces;
  engine::EdgeFlipOptions fo;  // --flips: fo.enabled
  engine::NormalFilterOptions nfo;  // --filter-normals N: nfo.iterations
  std::string colmap;
  Options o("imr-bench planes",
            "usage: imr-bench planes --mesh MESH --sequence IMR_SYNTH_SEQ [--tolerance 0,0.1,0.2]\n"
            "       [--min-faces N] [--flips [--flip-gain DEG] [--flip-min-angle DEG]] [--out DIR]\n"
            "       [--filter-normals N [--filter-range R] [--filter-spatial S] [--filter-passes N]\n"
            "        [--filter-steps N] [--filter-max-turn DEG]] [--colmap MODEL_DIR]\n"
            "  --flips: engine.flip_edges after the planes (each row)\n"
            "  --filter-normals: engine.filter_normals after the flips (each row)\n"
            "  --colmap: the run's --export-colmap model: the share seen from behind over every\n"
            "            10th keyframe (default: SEQUENCE/colmap-model when it is there)\n");
  o.String("--mesh", &mesh_file).String("--sequence", &sequence).String("--out", &out);
  o.String("--colmap", &colmap);
  o.List("--tolerance", &tolerances).Int("--min-faces", &min_faces).Flag("--flips", &fo.enabled);
  o.Double("--flip-gain", &fo.min_gain_degrees).Double("--flip-min-angle", &fo.min_angle_degrees);
  o.Int("--filter-normals", &nfo.iterations).Double("--filter-range", &nfo.sigma_range);
  o.Double("--filter-spatial", &nfo.sigma_spatial).Int("--filter-passes", &nfo.normal_passes);
  o.Int("--filter-steps", &nfo.vertex_steps).Double("--filter-max-turn", &nfo.max_turn_degrees);
  if (int status = 0; !o.Parse(argc, argv, &status)) return status;
  if (mesh_file.empty() || sequence.empty()) {
    std::fprintf(stderr, "imr-bench planes: --mesh and --sequence are required\n");
    return 2;
  }
  fs::create_directories(out);
  const eval::TriangleMesh read = eval::ReadMesh(mesh_file);
  eval::EvaluationInputs truth;
  truth.truth = (fs::path(sequence) / "ground_truth/scene.ply").string();
  truth.sequence = sequence;
  SurfaceContext surface;
  surface.planes = SyntheticPlanes(eval::ReadSyntheticTruth((fs::path(sequence) / "ground_truth/scene.json").string()), 0.2);
  surface.model = colmap.empty() ? fs::path(sequence) / "colmap-model" : fs::path(colmap);
  std::printf("| tolerance (median edges) | regions | refused | faces in regions | vertices moved | flips | "
              "seconds | compl. 0.2 m | prec. 0.2 m | F | roughness ° | on the true planes ° | seen from behind |\n"
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  for (const std::string& t : tolerances) {
    engine::Mesh m;
    for (const auto& v : read.vertices) m.vertices.insert(m.vertices.end(), v.begin(), v.end());
    for (const auto& f : read.triangles) m.faces.insert(m.faces.end(), f.begin(), f.end());
    m.point_ids.assign(read.vertices.size(), -1);
    engine::PlaneRetriangulationOptions po;
    po.tolerance = std::stod(t);
    po.min_faces = min_faces;
    const auto start = std::chrono::steady_clock::now();
    const engine::PlaneRetriangulationStats s = engine::RetriangulatePlanes(&m, po);

    const engine::EdgeFlipStats fs = engine::FlipEdges(&m, fo);
    const engine::NormalFilterStats ns = engine::FilterNormals(&m, nfo);
    if (nfo.enabled())
      std::fprintf(stderr, "filter_normals: %lld vertices moved, %lld moves reverted, max move %.3f\n",
                   static_cast<long long>(ns.vertices_moved), static_cast<long long>(ns.moves_reverted), ns.max_move);
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    const fs::path file = fs::path(out) / ("planes-" + t + ".off");
    {
      std::ofstream f(file);
      f.precision(10);
      f << "OFF\n" << m.vertices.size() / 3 << " " << m.faces.size() / 3 << " 0\n";
      for (std::size_t i = 0; i < m.vertices.size(); i += 3)
        f << m.vertices[i] << " " << m.vertices[i + 1] << " " << m.vertices[i + 2] << "\n";
      for (std::size_t i = 0; i < m.faces.size(); i += 3)
        f << "3 " << m.faces[i] << " " << m.faces[i + 1] << " " << m.faces[i + 2] << "\n";
    }
    Row row;
    Evaluate(file, truth, truth, &row, &surface);
    char behind[32] = "";
    if (row.behind) std::snprintf(behind, sizeof(behind), "%.2f %%", 100.0 * *row.behind);
    std::printf("| %s | %lld | %lld | %lld | %lld | %lld | %.2f | %.4f | %.4f | %.4f | %.1f | %.1f | %s |\n", t.c_str(),
                static_cast<long long>(s.regions), static_cast<long long>(s.regions_refused),
                static_cast<long long>(s.faces), static_cast<long long>(s.vertices_moved),
                static_cast<long long>(fs.flips), seconds,
                row.c2, row.p2, F(row.c2, row.p2), row.roughness,
                row.plane_roughness ? row.plane_roughness->degrees : 0.0, behind);
    std::fflush(stdout);
  }
  std::printf("meshes: %s/planes-*.off\n", out.c_str());
  return 0;
}

}  // namespace imr::bench
