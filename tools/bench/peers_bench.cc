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

}  // namespace

int RunPeersBench(int argc, char** argv) {
  int frames = 300;
  std::string colmap_arg, work_arg;
  for (int i = 0; i < argc; ++i) {
    const std::string k = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "imr-bench peers: %s needs a value\n", k.c_str());
        std::exit(2);
      }
      return argv[++i];
    };
    if (k == "--frames") frames = std::atoi(value().c_str());
    else if (k == "--colmap") colmap_arg = value();
    else if (k == "--work") work_arg = value();
    else {
      std::fprintf(stderr, "usage: imr-bench peers [--frames N] [--colmap PATH] [--work DIR]\n");
      return 2;
    }
  }
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
  const fs::path work = work_arg.empty() ? fs::temp_directory_path() /
                                               ("imr-bench-peers-" + std::to_string(getpid()))
                                         : fs::path(work_arg);
  fs::create_directories(work);
  // Input: imr-synth's street, through imr's whole pipeline (the default job's settings).
  const fs::path seq = work / "street";
  if (Sh(Quote((ExeDir() / "imr-synth").string()) + " --out " + Quote(seq.string()) +
         " --frames " + std::to_string(frames) + " --no-lidar --force -q") != 0) {
    std::fprintf(stderr, "imr-bench peers: imr-synth failed\n");
    return 1;
  }
  const fs::path out = work / "imr", model = work / "colmap-model";
  const json job = {
      {"description", "imr-bench peers"},
      {"sequences", {seq.string()}},
      {"input", {{"format", "kitti_odometry"}, {"options", json::object()}}},
      {"engine", {{"window", 15}, {"steiner_export", "any_steiner"}}},
      {"pipeline",
       {{{"kind", "features"}, {"plugin", "org.imr.features.edge_klt"}},
        {{"kind", "refiner"}, {"plugin", "org.imr.refiner.ceres"},
         {"params", {{"max_distance", 30.0}}}},
        {{"kind", "weight_policy"}, {"plugin", "org.imr.policy.nearest"}},
        {{"kind", "exporter"}, {"plugin", "org.imr.exporter.assimp"}}}},
      {"output", {{"directory", out.string()}, {"formats", {"ply"}}}}};
  std::ofstream(work / "job.json") << job.dump(2);
  if (Sh(Quote((ExeDir() / "imr").string()) + " run -q " + Quote((work / "job.json").string()) +
         " --export-colmap " + Quote(model.string()) + " --export-stream " +
         Quote((work / "stream.json").string()) + " >" +
         Quote((work / "imr.log").string()) + " 2>&1") != 0) {
    std::fprintf(stderr, "imr-bench peers: imr run failed (%s)\n", (work / "imr.log").c_str());
    return 1;
  }
  const json report = ReadJson(out / "report.json");
  const std::string truth_args = "--truth " + Quote((seq / "ground_truth/scene.ply").string()) +
                                 " --velodyne-seq " + Quote(seq.string());
  MesherResult imr;
  imr.name = "imr (nearest, incremental)";
  imr.seconds = report["engine"]["seconds"].value("total", 0.0);
  imr.ok = Evaluate(out / "mesh.ply", truth_args, work / "evaluate-imr.json", &imr);

  // The same engine input replayed with the all_steiner export rule (the engine's default:
  // only triangles of three Steiner points left out), closer to COLMAP's complete surface.
  MesherResult imr_all;
  imr_all.name = "imr, all_steiner export";
  {
    const fs::path out2 = work / "imr-all-steiner";
    const json replay = {
        {"description", "imr-bench peers: replay"},
        {"sequences", {(work / "stream.json").string()}},
        {"input", {{"format", "slam_json"}, {"options", json::object()}}},
        {"engine", {{"window", 15}, {"steiner_export", "all_steiner"}}},
        {"pipeline",
         {{{"kind", "weight_policy"}, {"plugin", "org.imr.policy.nearest"}},
          {{"kind", "exporter"}, {"plugin", "org.imr.exporter.assimp"}}}},
        {"output", {{"directory", out2.string()}, {"formats", {"ply"}}}}};
    std::ofstream(work / "replay.json") << replay.dump(2);
    if (Sh(Quote((ExeDir() / "imr").string()) + " run -q " +
           Quote((work / "replay.json").string()) + " >" +
           Quote((work / "replay.log").string()) + " 2>&1") == 0) {
      imr_all.seconds = ReadJson(out2 / "report.json")["engine"]["seconds"].value("total", 0.0);
      imr_all.ok = Evaluate(out2 / "mesh.ply", truth_args, work / "evaluate-imr-all.json", &imr_all);
    } else {
      imr_all.error = "imr run (replay) failed";
    }
  }

  MesherResult col;
  col.name = "COLMAP delaunay_mesher (batch)";
  const fs::path col_mesh = work / "colmap-mesh.ply";
  const auto t0 = std::chrono::steady_clock::now();
  const int rc = Sh(Quote(colmap) + " delaunay_mesher --input_path " + Quote(model.string()) +
                    " --input_type sparse --output_path " + Quote(col_mesh.string()) + " >" +
                    Quote((work / "colmap.log").string()) + " 2>&1");
  col.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (rc != 0 || !fs::exists(col_mesh)) {
    col.error = "colmap delaunay_mesher failed (" + (work / "colmap.log").string() + ")";
  } else {
    col.ok = Evaluate(col_mesh, truth_args, work / "evaluate-colmap.json", &col);
  }

  std::printf("\ninput: imr-synth street, %d frames; %s points in the model\n", frames,
              report["engine"].contains("points_inserted")
                  ? std::to_string(report["engine"]["points_inserted"].get<int64_t>()).c_str()
                  : "?");
  std::printf("\n| mesher | time (s) | truth→mesh mean / median (m) | mesh→truth mean / median (m) "
              "| completeness / precision (τ = 0.2 m) | triangles | manifold (non-manifold edges "
              "/ vertices) |\n|---|---|---|---|---|---|---|\n");
  json result = {{"bench", "peers"}, {"machine", MachineLine()}, {"frames", frames},
                 {"load_average_start", load_start}};
  auto key = [&](const MesherResult* m) {
    return m == &imr ? "imr" : m == &imr_all ? "imr_all_steiner" : "colmap";
  };
  for (const MesherResult* m : {&imr, &imr_all, &col}) {
    if (!m->ok) {
      std::printf("| %s | failed: %s | | | | | |\n", m->name.c_str(), m->error.c_str());
      result[key(m)] = {{"ok", false}, {"error", m->error}};
      continue;
    }
    const json& a = m->accuracy;
    std::printf("| %s | %.2f | %.3f / %.3f | %.3f / %.3f | %.2f / %.2f | %lld | %s (%lld / "
                "%lld) |\n",
                m->name.c_str(), m->seconds, a["truth_to_mesh"].value("mean", 0.0),
                a["truth_to_mesh"].value("median", 0.0), a["mesh_to_truth"].value("mean", 0.0),
                a["mesh_to_truth"].value("median", 0.0), a["completeness"][0].get<double>(),
                a["precision"][0].get<double>(), static_cast<long long>(m->stats.faces),
                m->stats.manifold ? "yes" : "no",
                static_cast<long long>(m->stats.nonmanifold_edges),
                static_cast<long long>(m->stats.nonmanifold_vertices));
    result[key(m)] = {
        {"ok", true},
        {"seconds", m->seconds},
        {"truth_to_mesh_mean_m", a["truth_to_mesh"].value("mean", 0.0)},
        {"truth_to_mesh_median_m", a["truth_to_mesh"].value("median", 0.0)},
        {"mesh_to_truth_mean_m", a["mesh_to_truth"].value("mean", 0.0)},
        {"mesh_to_truth_median_m", a["mesh_to_truth"].value("median", 0.0)},
        {"completeness", a["completeness"][0]},
        {"precision", a["precision"][0]},
        {"triangles", m->stats.faces},
        {"manifold", m->stats.manifold},
        {"nonmanifold_edges", m->stats.nonmanifold_edges},
        {"nonmanifold_vertices", m->stats.nonmanifold_vertices}};
  }
  std::printf("\nimr's time is its engine's total over all keyframes (incremental, points "
              "moving); COLMAP's is one batch run on the final points (wall, process included).\n"
              "imr's first row is the default job's export (any_steiner: no triangle touching a "
              "Steiner point).\nload average at end %s\n",
              LoadAverage().c_str());
  result["load_average_end"] = LoadAverage();
  result["colmap"]["binary"] = colmap;
  if (imr.ok && imr_all.ok && col.ok && work_arg.empty()) fs::remove_all(work);
  std::printf("%s\n", result.dump().c_str());
  return imr.ok && imr_all.ok && col.ok ? 0 : 1;
}

}  // namespace imr::bench
