// imr-bench peers: imr against COLMAP's Delaunay mesher (`colmap delaunay_mesher --input_type
// sparse`) on identical input. imr runs the whole pipeline on imr-synth's street and writes the
// points and their visibility as a COLMAP sparse text model (--export-colmap); COLMAP meshes that
// model in one batch. Compared: accuracy against the known scene (imr evaluate, both directions),
// time (imr's total incremental engine time against COLMAP's one batch run, wall), and whether
// each output is a manifold (host/eval mesh statistics). COLMAP with CGAL comes from
// tools/bench/peers/build_colmap.sh (Debian's binary package has no Delaunay meshing); without it
// the bench says how to get it and stops. Benchmark only, never in CI. Prints a Markdown table
// and ends with one JSON line.
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "host/eval/mesh_io.h"
#include "host/eval/mesh_stats.h"
#include "tools/bench/common/bench_util.h"
#include "tools/bench/common/frame.h"
#include "tools/bench/common/subprocess.h"
#include "tools/bench/peers/colmap.h"

namespace imr::bench {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

struct MesherResult {
  std::string name;
  bool ok = false;
  std::string error;
  double seconds = 0.0;  // imr: total incremental engine time; COLMAP: the batch run (wall).
  json accuracy;
  eval::MeshStatistics stats;
};

bool Evaluate(const fs::path& mesh, const std::string& truth_args, const fs::path& out,
              MesherResult* r) {
  const int rc = Sh(Quote((ExeDir() / "imr").string()) + " evaluate " + Quote(mesh.string()) +
                    " " + truth_args + " --tau 0.2 -q -o " + Quote(out.string()) + " >" +
                    Quote(fs::path(out).replace_extension(".log").string()) + " 2>&1");
  r->accuracy = ReadJson(out);
  if (rc != 0 || r->accuracy.is_null()) {
    r->error = "imr evaluate failed";
    return false;
  }
  try {
    const eval::TriangleMesh m = eval::ReadMesh(mesh);
    std::vector<double> xyz;
    std::vector<uint32_t> faces;
    for (const auto& v : m.vertices) xyz.insert(xyz.end(), v.begin(), v.end());
    for (const auto& t : m.triangles) faces.insert(faces.end(), t.begin(), t.end());
    r->stats = eval::ComputeMeshStatistics(xyz, faces);
  } catch (const std::exception& e) {
    r->error = std::string("reading the mesh: ") + e.what();
    return false;
  }
  return true;
}


json ImrJobOn(const std::string& description, const fs::path& sequence, const std::string& format,
              const std::string& steiner_export, json pipeline, const fs::path& out) {
  return {{"description", description},
          {"sequences", {sequence.string()}},
          {"input", {{"format", format}, {"options", json::object()}}},
          {"engine", {{"window", 15}, {"steiner_export", steiner_export}}},
          {"pipeline", std::move(pipeline)},
          {"output", {{"directory", out.string()}, {"formats", {"ply"}}}}};
}

// imr's whole pipeline (the default job's settings) on imr-synth's street: its mesh, its model
// for COLMAP (work/colmap-model) and its engine input (work/stream.json). Null on a failure.
json RunImrPipeline(const fs::path& work, const fs::path& seq, int frames) {
  if (Sh(Quote((ExeDir() / "imr-synth").string()) + " --out " + Quote(seq.string()) +
         " --frames " + std::to_string(frames) + " --no-lidar --force -q") != 0) {
    std::fprintf(stderr, "imr-bench peers: imr-synth failed\n");
    return nullptr;
  }
  const json pipeline = {{{"kind", "features"}, {"plugin", "org.imr.features.edge_klt"}},
                         {{"kind", "refiner"}, {"plugin", "org.imr.refiner.ceres"},
                          {"params", {{"max_distance", 30.0}}}},
                         {{"kind", "weight_policy"}, {"plugin", "org.imr.policy.nearest"}},
                         {{"kind", "exporter"}, {"plugin", "org.imr.exporter.assimp"}}};
  ImrJob how;
  how.job_file = work / "job.json";
  how.log = work / "imr.log";
  how.extra = "--export-colmap " + Quote((work / "colmap-model").string()) + " --export-stream " +
              Quote((work / "stream.json").string());
  const ImrJobResult r = RunImrJob(
      ImrJobOn("imr-bench peers", seq, "kitti_odometry", "any_steiner", pipeline, work / "imr"), how);
  if (r.status != 0) {
    std::fprintf(stderr, "imr-bench peers: imr run failed (%s)\n", r.log.c_str());
    return nullptr;
  }
  return r.report.is_null() ? json::object() : r.report;
}

// The same engine input replayed with the all_steiner export rule (the engine's default: only
// triangles of three Steiner points left out), closer to COLMAP's complete surface.
MesherResult ReplayAllSteiner(const fs::path& work, const std::string& truth_args) {
  MesherResult r;
  r.name = "imr, all_steiner export";
  const fs::path out = work / "imr-all-steiner";
  const json pipeline = {{{"kind", "weight_policy"}, {"plugin", "org.imr.policy.nearest"}},
                         {{"kind", "exporter"}, {"plugin", "org.imr.exporter.assimp"}}};
  ImrJob how;
  how.job_file = work / "replay.json";
  const ImrJobResult run = RunImrJob(ImrJobOn("imr-bench peers: replay", work / "stream.json",
                                              "slam_json", "all_steiner", pipeline, out),
                                     how);
  if (run.status != 0) {
    r.error = "imr run (replay) failed";
    return r;
  }
  r.seconds = run.report["engine"]["seconds"].value("total", 0.0);
  r.ok = Evaluate(out / "mesh.ply", truth_args, work / "evaluate-imr-all.json", &r);
  return r;
}

// COLMAP's Delaunay mesher on imr's model, one batch run (wall time, process included).
MesherResult RunColmap(const std::string& colmap, const fs::path& work,
                       const std::string& truth_args) {
  MesherResult r;
  r.name = "COLMAP delaunay_mesher (batch)";
  const fs::path mesh = work / "colmap-mesh.ply";
  const auto t0 = std::chrono::steady_clock::now();
  const int rc = Sh(Quote(colmap) + " delaunay_mesher --input_path " +
                    Quote((work / "colmap-model").string()) + " --input_type sparse --output_path " +
                    Quote(mesh.string()) + " >" + Quote((work / "colmap.log").string()) + " 2>&1");
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (rc != 0 || !fs::exists(mesh))
    r.error = "colmap delaunay_mesher failed (" + (work / "colmap.log").string() + ")";
  else
    r.ok = Evaluate(mesh, truth_args, work / "evaluate-colmap.json", &r);
  return r;
}

// One mesher's row and its JSON object.
json PrintMesher(const MesherResult& m) {
  if (!m.ok) {
    std::printf("| %s | failed: %s | | | | | |\n", m.name.c_str(), m.error.c_str());
    return {{"ok", false}, {"error", m.error}};
  }
  const json& a = m.accuracy;
  std::printf("| %s | %.2f | %.3f / %.3f | %.3f / %.3f | %.2f / %.2f | %lld | %s (%lld / "
              "%lld) |\n",
              m.name.c_str(), m.seconds, a["truth_to_mesh"].value("mean", 0.0),
              a["truth_to_mesh"].value("median", 0.0), a["mesh_to_truth"].value("mean", 0.0),
              a["mesh_to_truth"].value("median", 0.0), a["completeness"][0].get<double>(),
              a["precision"][0].get<double>(), static_cast<long long>(m.stats.faces),
              m.stats.manifold ? "yes" : "no", static_cast<long long>(m.stats.nonmanifold_edges),
              static_cast<long long>(m.stats.nonmanifold_vertices));
  return {{"ok", true},
          {"seconds", m.seconds},
          {"truth_to_mesh_mean_m", a["truth_to_mesh"].value("mean", 0.0)},
          {"truth_to_mesh_median_m", a["truth_to_mesh"].value("median", 0.0)},
          {"mesh_to_truth_mean_m", a["mesh_to_truth"].value("mean", 0.0)},
          {"mesh_to_truth_median_m", a["mesh_to_truth"].value("median", 0.0)},
          {"completeness", a["completeness"][0]},
          {"precision", a["precision"][0]},
          {"triangles", m.stats.faces},
          {"manifold", m.stats.manifold},
          {"nonmanifold_edges", m.stats.nonmanifold_edges},
          {"nonmanifold_vertices", m.stats.nonmanifold_vertices}};
}

}  // namespace

int RunPeersBench(int argc, char** argv) {
  int frames = 300;
  std::string colmap_arg, work_arg;
  Options o("imr-bench peers", "usage: imr-bench peers [--frames N] [--colmap PATH] [--work DIR]\n");
  o.Int("--frames", &frames).String("--colmap", &colmap_arg).String("--work", &work_arg);
  if (int status = 0; !o.Parse(argc, argv, &status)) return status;
  const std::string load_start = LoadAverage();
  std::printf("imr-bench peers: imr vs COLMAP delaunay_mesher on identical input; %s; load "
              "average at start %s\n",
              MachineLine().c_str(), load_start.c_str());
  const std::string colmap = FindColmap(colmap_arg);
  if (colmap.empty() || !fs::exists(colmap)) {
    std::printf("no COLMAP with CGAL found (--colmap PATH, IMR_COLMAP, or the cache of "
                "tools/bench/peers/build_colmap.sh); build it with:\n"
                "  tools/bench/peers/build_colmap.sh      # about 10 minutes on 2 cores\n");
    std::printf("%s\n", json{{"bench", "peers"}, {"skipped", "no COLMAP with CGAL"}}.dump().c_str());
    return 1;
  }
  const WorkFolder work(work_arg, "peers");
  const fs::path seq = work.path() / "street";
  json report = RunImrPipeline(work.path(), seq, frames);  // not const: a missing key reads as null
  if (report.is_null()) return 1;
  const std::string truth_args = "--truth " + Quote((seq / "ground_truth/scene.ply").string()) +
                                 " --velodyne-seq " + Quote(seq.string());
  MesherResult imr;
  imr.name = "imr (nearest, incremental)";
  imr.seconds = report["engine"]["seconds"].value("total", 0.0);
  imr.ok = Evaluate(work.path() / "imr/mesh.ply", truth_args, work.path() / "evaluate-imr.json", &imr);
  const MesherResult imr_all = ReplayAllSteiner(work.path(), truth_args);
  const MesherResult col = RunColmap(colmap, work.path(), truth_args);

  std::printf("\ninput: imr-synth street, %d frames; %s points in the model\n", frames,
              report["engine"].contains("points_inserted")
                  ? std::to_string(report["engine"]["points_inserted"].get<int64_t>()).c_str()
                  : "?");
  std::printf("\n");
  MarkdownHeader({"mesher", "time (s)", "truth→mesh mean / median (m)",
                  "mesh→truth mean / median (m)", "completeness / precision (τ = 0.2 m)",
                  "triangles", "manifold (non-manifold edges / vertices)"});
  json result = {{"bench", "peers"}, {"machine", MachineLine()}, {"frames", frames},
                 {"load_average_start", load_start}};
  result["imr"] = PrintMesher(imr);
  result["imr_all_steiner"] = PrintMesher(imr_all);
  result["colmap"] = PrintMesher(col);
  std::printf("\nimr's time is its engine's total over all keyframes (incremental, points "
              "moving); COLMAP's is one batch run on the final points (wall, process included).\n"
              "imr's first row is the default job's export (any_steiner: no triangle touching a "
              "Steiner point).\nload average at end %s\n",
              LoadAverage().c_str());
  result["load_average_end"] = LoadAverage();
  result["colmap"]["binary"] = colmap;
  work.Finish(imr.ok && imr_all.ok && col.ok);
  std::printf("%s\n", result.dump().c_str());
  return imr.ok && imr_all.ok && col.ok ? 0 : 1;
}

}  // namespace imr::bench
