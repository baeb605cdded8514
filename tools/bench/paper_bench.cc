// imr-bench paper: the comparison of Romanoni & Matteucci (section 4, Fig. 3) reproduced. For the
// efficient policies (nearest, mean, weighted_mean) and the straightforward baseline of Lovi et
// al. (rays, K = 5 and K = 1), on identical input:
//   - accuracy against ground truth: the paper's figure, the mean distance from each ground-truth
//     point to the mesh (CloudCompare's cloud-to-mesh; host/eval/README.md), with its median, and the other
//     direction (mesh -> true surface) with completeness and precision;
//   - per-move overhead (T_mov - T_nonmov) / N_mov (the paper's cost model), T_nonmov from the same stream
//     with every point frozen at its first estimate, N_mov every move the input delivers;
//   - total engine time, points moved, moves refused, points dropped.
// Sequences: the synthetic street and room streams (engine in process, exact ground truth), the
// image pipeline on imr-synth's street (imr run once with moving and once with frozen points,
// --export-stream, then every mode replays those streams: identical input), and the real KITTI
// raw sample the same way (accuracy against its Velodyne scans through imr evaluate).
// Prints Markdown tables, writes the paper's two figures as PNG (tools/bench/paper_plots.py) and
// ends with one JSON line.
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "host/engine/engine.h"
#include "host/engine/testing/run_stream.h"
#include "tools/bench/common/bench_util.h"
#include "tools/bench/common/engine_modes.h"
#include "tools/bench/common/frame.h"
#include "tools/bench/common/subprocess.h"

namespace imr::bench {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

struct PaperArgs {
  int street_frames = 500;
  int room_frames = 300;
  int points = 150;
  double noise = 0.1;
  uint64_t seed = 1;
  int image_frames = 300;
  bool images = true;
  bool synth_images = true;
  bool kitti_enabled = true;
  std::string kitti;
  std::string out = "paper-figures";
  std::string work;
  double tau = 0.2;
  std::vector<std::string> modes = {"nearest", "mean", "weighted_mean", "rays5", "rays1"};
  std::vector<std::string> scenes = {"street", "room"};
};

// One mode on one sequence.
struct ModeResult {
  std::string sequence, mode;
  bool ok = false;
  std::string error;
  double t_mov = 0.0, t_nonmov = 0.0;  // Engine seconds (sum of ApplyUpdate).
  int64_t n_mov = 0;                   // Moves the input delivered.
  int64_t moved = 0, moves_skipped = 0, dropped = 0, inserted = 0;
  double keyframe_median = 0.0;
  // Accuracy (metres).
  double t2m_mean = 0.0, t2m_median = 0.0, m2t_mean = 0.0, m2t_median = 0.0;
  double completeness = 0.0, precision = 0.0;
  int64_t triangles = 0;
  double Overhead() const { return n_mov > 0 ? (t_mov - t_nonmov) / n_mov : 0.0; }
};

// ---------------------------------------------------------------------------------------------
// Synthetic streams, engine in process.

struct EngineRun {
  bool ok = false;
  std::string error;
  engine::EngineStats stats;
  int64_t moves_delivered = 0;
  engine::Mesh mesh;
};

EngineRun RunEngine(const synthetic::StreamOptions& so, const std::string& mode, bool mesh) {
  EngineRun r;
  synthetic::SyntheticStream stream(so);
  engine::EngineOptions eo;
  eo.forget = engine::ForgetMode::kOff;  // the paper's engine, measured whole (forgetting: drive)
  eo.steiner_export = engine::SteinerExportRule::kAnySteiner;  // As the default job.
  std::unique_ptr<engine::WeightTransferPolicy> policy;
  engine::testing::ConfigureMode(mode, &eo, &policy);
  engine::Engine eng(eo, policy.get());
  const engine::Status s = engine::testing::RunStream(
      &stream, &eng, [&](const synthetic::StreamKeyframe& kf) {
        r.moves_delivered += static_cast<int64_t>(kf.moved_points.size());
        return true;
      });
  r.ok = s.ok();
  r.error = s.message();
  r.stats = eng.Stats();
  if (mesh) r.mesh = eng.ExtractMesh();
  return r;
}

ModeResult RunSyntheticMode(const std::string& scene_name, const synthetic::StreamOptions& base,
                            const std::string& mode, const std::vector<synthetic::Vec3>& truth,
                            double tau) {
  ModeResult m;
  m.sequence = scene_name;
  m.mode = mode;
  synthetic::StreamOptions so = base;
  so.frozen = true;
  std::fprintf(stderr, "[paper] %s %s frozen ...\n", scene_name.c_str(), mode.c_str());
  const EngineRun frozen = RunEngine(so, mode, false);
  so.frozen = false;
  std::fprintf(stderr, "[paper] %s %s moving ...\n", scene_name.c_str(), mode.c_str());
  const EngineRun moving = RunEngine(so, mode, true);
  m.ok = frozen.ok && moving.ok;
  m.error = moving.ok ? frozen.error : moving.error;
  m.t_mov = moving.stats.time.total;
  m.t_nonmov = frozen.stats.time.total;
  m.n_mov = moving.moves_delivered;
  m.moved = moving.stats.points_moved;
  m.moves_skipped = moving.stats.moves_skipped;
  m.dropped = moving.stats.points_dropped;
  m.inserted = moving.stats.points_inserted;
  m.keyframe_median = Median(moving.stats.keyframe_seconds);
  synthetic::SyntheticStream scene_stream(base);  // Same scene (seeded), for distances.
  const SceneAccuracy a = EvaluateAgainstScene(scene_stream.scene(), moving.mesh.vertices,
                                               moving.mesh.faces, truth, tau);
  m.t2m_mean = a.truth_to_mesh_mean;
  m.t2m_median = a.truth_to_mesh_median;
  m.m2t_mean = a.mesh_to_scene_mean;
  m.m2t_median = a.mesh_to_scene_median;
  m.completeness = a.completeness;
  m.precision = a.precision;
  m.triangles = static_cast<int64_t>(a.triangles);
  return m;
}

// ---------------------------------------------------------------------------------------------
// The image pipeline (imr run as a subprocess).

json EngineSection(const std::string& mode) {
  json e = {{"window", 15}, {"steiner_spacing", 5.0}, {"steiner_export", "any_steiner"}};
  if (mode == "rays5" || mode == "rays1") {
    e["visibility_mode"] = "rays";
    e["rays_per_cell"] = mode == "rays5" ? 5 : 1;
  } else {
    e["visibility_mode"] = "weights";
  }
  return e;
}

// The whole pipeline, as configs/default.json, writing the engine's input stream. frozen: the
// refiner reports no move (min_move beyond any refinement), so points stay at their first
// estimate.
json FrontEndJob(const std::string& format, const json& input_options, const std::string& seq,
                 const fs::path& out, bool frozen) {
  json refiner = {{"max_distance", 30.0}};
  if (frozen) refiner["min_move"] = 1e9;
  return {{"description", "imr-bench paper: front end"},
          {"sequences", {seq}},
          {"input", {{"format", format}, {"options", input_options}}},
          {"engine", EngineSection("nearest")},
          {"pipeline",
           {{{"kind", "features"}, {"plugin", "org.imr.features.edge_klt"}},
            {{"kind", "refiner"}, {"plugin", "org.imr.refiner.ceres"}, {"params", refiner}},
            {{"kind", "weight_policy"}, {"plugin", "org.imr.policy.nearest"}},
            {{"kind", "exporter"}, {"plugin", "org.imr.exporter.assimp"}}}},
          {"output", {{"directory", out.string()}, {"formats", {"ply"}}}}};
}

// The engine alone on an exported stream, in one mode.
json ReplayJob(const fs::path& stream, const std::string& mode, const fs::path& out) {
  json pipeline = json::array();
  if (mode != "rays5" && mode != "rays1")
    pipeline.push_back({{"kind", "weight_policy"}, {"plugin", "org.imr.policy." + mode}});
  pipeline.push_back({{"kind", "exporter"}, {"plugin", "org.imr.exporter.assimp"}});
  return {{"description", "imr-bench paper: replay"},
          {"sequences", {stream.string()}},
          {"input", {{"format", "slam_json"}, {"options", json::object()}}},
          {"engine", EngineSection(mode)},
          {"pipeline", pipeline},
          {"output", {{"directory", out.string()}, {"formats", {"ply"}}}}};
}

// imr run on `job` (its log beside `job_file`); *report is its output folder's report.json.
bool ImrRun(const json& job, const fs::path& job_file, const std::string& extra, json* report) {
  ImrJob how;
  how.job_file = job_file;
  how.extra = extra;
  const ImrJobResult r = RunImrJob(job, how);
  *report = r.report;
  if (r.status != 0 || report->is_null()) {
    std::fprintf(stderr, "imr run failed (exit %d): see %s\n", r.status, r.log.c_str());
    return false;
  }
  return true;
}

// Moves the refiner delivered (the front end's report; the same stream for every mode).
int64_t MovesDelivered(const json& report) {
  const json& s = report["input"]["summary"];
  if (s.contains("points") && s["points"].is_object() && s["points"].contains("moved"))
    return s["points"]["moved"].get<int64_t>();
  return report["engine"].value("points_moved", int64_t{0});
}

// One image sequence: front end twice (moving, frozen), then every mode replays both streams.
std::vector<ModeResult> RunImageSequence(const std::string& name, const std::string& format,
                                         const json& input_options, const std::string& seq,
                                         const std::string& evaluate_args, const fs::path& work,
                                         const PaperArgs& a) {
  std::vector<ModeResult> out;
  const fs::path dir = work / name;
  fs::create_directories(dir);
  json report, front;
  const fs::path mov_stream = dir / "stream-moving.json", frz_stream = dir / "stream-frozen.json";
  if (!ImrRun(FrontEndJob(format, input_options, seq, dir / "front-moving", false),
              dir / "front-moving.json", "--export-stream " + Quote(mov_stream.string()), &front) ||
      !ImrRun(FrontEndJob(format, input_options, seq, dir / "front-frozen", true),
              dir / "front-frozen.json", "--export-stream " + Quote(frz_stream.string()), &report)) {
    ModeResult m;
    m.sequence = name;
    m.mode = "front end";
    m.error = "imr run (front end) failed";
    out.push_back(m);
    return out;
  }
  for (const std::string& mode : a.modes) {
    ModeResult m;
    m.sequence = name;
    m.mode = mode;
    json rm, rf;
    const fs::path om = dir / ("replay-" + mode), of = dir / ("replay-" + mode + "-frozen");
    std::fprintf(stderr, "[paper] %s %s ...\n", name.c_str(), mode.c_str());
    const bool ok_m = ImrRun(ReplayJob(mov_stream, mode, om), dir / ("replay-" + mode + ".json"),
                             "", &rm);
    const bool ok_f = ImrRun(ReplayJob(frz_stream, mode, of),
                             dir / ("replay-" + mode + "-frozen.json"), "", &rf);
    if (!ok_m || !ok_f) {
      m.error = "imr run (replay) failed";
      out.push_back(m);
      continue;
    }
    const json& e = rm["engine"];
    m.t_mov = e["seconds"].value("total", 0.0);
    m.t_nonmov = rf["engine"]["seconds"].value("total", 0.0);
    m.n_mov = MovesDelivered(front);
    m.moved = e.value("points_moved", int64_t{0});
    m.moves_skipped = e.value("moves_skipped", int64_t{0});
    m.dropped = e.value("points_dropped", int64_t{0});
    m.inserted = e.value("points_inserted", int64_t{0});
    m.keyframe_median = 0.0;
    const fs::path ev = dir / ("evaluate-" + mode + ".json");
    const int rc = Sh(Quote((ExeDir() / "imr").string()) + " evaluate " +
                      Quote((om / "mesh.ply").string()) + " " + evaluate_args + " --tau " +
                      Num(a.tau) + " -q -o " + Quote(ev.string()) + " >" +
                      Quote(fs::path(ev).replace_extension(".log").string()) + " 2>&1");
    const json r = ReadJson(ev);
    if (rc != 0 || r.is_null()) {
      m.error = "imr evaluate failed";
      out.push_back(m);
      continue;
    }
    m.t2m_mean = r["truth_to_mesh"].value("mean", 0.0);
    m.t2m_median = r["truth_to_mesh"].value("median", 0.0);
    m.m2t_mean = r["mesh_to_truth"].value("mean", 0.0);
    m.m2t_median = r["mesh_to_truth"].value("median", 0.0);
    m.completeness = r["completeness"][0].get<double>();
    m.precision = r["precision"][0].get<double>();
    m.triangles = r["mesh"].value("triangles", int64_t{0});
    m.ok = true;
    out.push_back(m);
  }
  return out;
}

// ---------------------------------------------------------------------------------------------

void PrintTable(const std::vector<ModeResult>& rs, double tau) {
  std::printf("\n| sequence | policy | truth→mesh mean / median (m) | mesh→truth mean / median (m) "
              "| completeness / precision (τ = %.2g m) | T_mov / T_nonmov (s) | N_mov | per-move "
              "overhead (µs) | moved / refused / dropped |\n",
              tau);
  std::printf("|---|---|---|---|---|---|---|---|---|\n");
  for (const ModeResult& m : rs) {
    if (!m.ok) {
      std::printf("| %s | %s | failed: %s | | | | | | |\n", m.sequence.c_str(), m.mode.c_str(),
                  m.error.c_str());
      continue;
    }
    std::printf("| %s | %s | %.3f / %.3f | %.3f / %.3f | %.2f / %.2f | %.2f / %.2f | %lld | %.1f "
                "| %lld / %lld / %lld |\n",
                m.sequence.c_str(), m.mode.c_str(), m.t2m_mean, m.t2m_median, m.m2t_mean,
                m.m2t_median, m.completeness, m.precision, m.t_mov, m.t_nonmov,
                static_cast<long long>(m.n_mov), 1e6 * m.Overhead(),
                static_cast<long long>(m.moved), static_cast<long long>(m.moves_skipped),
                static_cast<long long>(m.dropped));
  }
}

json ToJson(const ModeResult& m) {
  json j = {{"ok", m.ok}};
  if (!m.ok) {
    j["error"] = m.error;
    return j;
  }
  j["truth_to_mesh_mean_m"] = m.t2m_mean;
  j["truth_to_mesh_median_m"] = m.t2m_median;
  j["mesh_to_truth_mean_m"] = m.m2t_mean;
  j["mesh_to_truth_median_m"] = m.m2t_median;
  j["completeness"] = m.completeness;
  j["precision"] = m.precision;
  j["triangles"] = m.triangles;
  j["t_mov_s"] = m.t_mov;
  j["t_nonmov_s"] = m.t_nonmov;
  j["n_mov"] = m.n_mov;
  j["per_move_overhead_s"] = m.Overhead();
  j["points_inserted"] = m.inserted;
  j["points_moved"] = m.moved;
  j["moves_refused"] = m.moves_skipped;
  j["points_dropped"] = m.dropped;
  if (m.keyframe_median > 0) j["keyframe_s_median"] = m.keyframe_median;
  return j;
}


bool ParsePaperArgs(int argc, char** argv, PaperArgs* a, int* status) {
  Options o("imr-bench paper",
            "usage: imr-bench paper [--street-frames N] [--room-frames N] [--points P]\n"
            "         [--noise S] [--seed S] [--modes nearest,mean,weighted_mean,rays5,rays1]\n"
            "         [--scenes street,room] [--image-frames N] [--no-images]\n"
            "         [--no-synth-images] [--no-kitti]\n"
            "         [--kitti DRIVE_DIR] [--out DIR] [--work DIR] [--tau T] [--quick]\n");
  o.Int("--street-frames", &a->street_frames).Int("--room-frames", &a->room_frames);
  o.Int("--points", &a->points).Double("--noise", &a->noise).Uint64("--seed", &a->seed);
  o.Int("--image-frames", &a->image_frames).Flag("--no-images", &a->images, false);
  o.Flag("--no-kitti", &a->kitti_enabled, false).Flag("--no-synth-images", &a->synth_images, false);
  o.String("--kitti", &a->kitti).String("--out", &a->out).String("--work", &a->work);
  o.Double("--tau", &a->tau).List("--modes", &a->modes).List("--scenes", &a->scenes);
  o.Action("--quick", [a] {
    a->street_frames = 150;
    a->room_frames = 100;
    a->image_frames = 100;
  });
  if (!o.Parse(argc, argv, status)) return false;
  if (!KnownModes(a->modes, "paper")) {
    *status = 2;
    return false;
  }
  return true;
}

// 1. Synthetic streams, every mode on each scene. False on an unknown scene.
bool RunSyntheticScenes(const PaperArgs& a, std::vector<ModeResult>* all) {
  for (const std::string& scene : a.scenes) {
    synthetic::StreamOptions so;
    if (!synthetic::FromString(scene, &so.scene)) {
      std::fprintf(stderr, "imr-bench paper: unknown scene '%s'\n", scene.c_str());
      return false;
    }
    so.frames = scene == "room" ? a.room_frames : a.street_frames;
    so.points_per_keyframe = a.points;
    so.noise_at_10m = a.noise;
    so.seed = a.seed;
    synthetic::SyntheticStream gt_stream(so);
    const auto truth = SampleSeenSurfaces(gt_stream, so.frames, 1, 200, a.seed + 1000);
    std::printf("synthetic %s: %d frames, %d new points per keyframe, noise %.2f m at 10 m, "
                "ground truth %zu points sampled on the surfaces the cameras saw\n",
                scene.c_str(), so.frames, so.points_per_keyframe, so.noise_at_10m, truth.size());
    std::fflush(stdout);
    for (const std::string& mode : a.modes)
      all->push_back(RunSyntheticMode("synthetic " + scene, so, mode, truth, a.tau));
  }
  return true;
}

// 2-3. Image sequences through imr run: imr-synth's street and the KITTI raw sample. What was
// skipped, as the note under the tables says it.
std::string RunImageSequences(const PaperArgs& a, const fs::path& work,
                              std::vector<ModeResult>* all) {
  if (!a.images) return "";
  if (!fs::exists(ExeDir() / "imr") || !fs::exists(ExeDir() / "imr-synth"))
    return "imr or imr-synth not built (IMR_ENGINE_ONLY?): image sequences skipped";
  std::string note;
  fs::create_directories(work);
  const fs::path synth = work / "imr-synth-street";
  if (!a.synth_images) {
    // Skipped on request.
  } else if (Sh(Quote((ExeDir() / "imr-synth").string()) + " --out " + Quote(synth.string()) +
                " --frames " + std::to_string(a.image_frames) + " --no-lidar --force -q") == 0) {
    auto rs = RunImageSequence(
        "images street", "kitti_odometry", json::object(), synth.string(),
        "--truth " + Quote((synth / "ground_truth/scene.ply").string()) + " --velodyne-seq " +
            Quote(synth.string()),
        work, a);
    all->insert(all->end(), rs.begin(), rs.end());
  } else {
    note += "imr-synth failed; ";
  }
  // The team's data beside the checkout (IMR_SHARED_DIR, else ../shared of this source tree).
  const std::string kitti = KittiRawSample(a.kitti);
  if (a.kitti_enabled && fs::is_directory(kitti)) {
    auto rs = RunImageSequence("KITTI raw", "kitti_raw", json{{"camera", 2}}, kitti,
                               "--velodyne-seq " + Quote(kitti) + " --camera 2", work, a);
    all->insert(all->end(), rs.begin(), rs.end());
  } else if (a.kitti_enabled) {
    note += "no KITTI raw sample at " + kitti + "; ";
  }
  return note;
}

// The results by sequence (in the order they ran) and mode.
struct BySequence {
  std::map<std::string, std::map<std::string, const ModeResult*>> by_seq;
  std::vector<std::string> order;
};

// Ratios per sequence: nearest against rays5.
json PrintRatios(const std::vector<ModeResult>& all, BySequence* b) {
  for (const ModeResult& m : all) {
    if (!b->by_seq.count(m.sequence)) b->order.push_back(m.sequence);
    b->by_seq[m.sequence][m.mode] = &m;
  }
  json ratios = json::object();
  std::printf("\n");
  MarkdownHeader({"sequence", "overhead rays5 / nearest (target ≥ 10)",
                  "truth→mesh mean nearest / rays5 (target ≤ 1.10)", "mesh→truth mean nearest / rays5"});
  for (const std::string& s : b->order) {
    auto& mm = b->by_seq[s];
    const ModeResult* n = mm.count("nearest") ? mm["nearest"] : nullptr;
    const ModeResult* r = mm.count("rays5") ? mm["rays5"] : nullptr;
    if (!n || !r || !n->ok || !r->ok) continue;
    const double ov = n->Overhead() > 0 ? r->Overhead() / n->Overhead() : 0.0;
    const double acc = r->t2m_mean > 0 ? n->t2m_mean / r->t2m_mean : 0.0;
    const double prec = r->m2t_mean > 0 ? n->m2t_mean / r->m2t_mean : 0.0;
    std::printf("| %s | %.1f | %.2f | %.2f |\n", s.c_str(), ov, acc, prec);
    ratios[s] = {{"overhead_rays5_vs_nearest", ov},
                 {"truth_to_mesh_nearest_vs_rays5", acc},
                 {"mesh_to_truth_nearest_vs_rays5", prec}};
  }
  return ratios;
}

json PaperJson(const PaperArgs& a, const BySequence& b, const json& ratios,
               const std::string& load_start) {
  json result = {{"bench", "paper"},
                 {"machine", MachineLine()},
                 {"load_average_start", load_start},
                 {"load_average_end", LoadAverage()},
                 {"tau_m", a.tau},
                 {"synthetic",
                  {{"street_frames", a.street_frames},
                   {"room_frames", a.room_frames},
                   {"points_per_keyframe", a.points},
                   {"noise_at_10m", a.noise},
                   {"seed", a.seed}}},
                 {"image_frames", a.image_frames},
                 {"modes", a.modes},
                 {"sequences", json::object()},
                 {"sequence_order", b.order},
                 {"ratios", ratios}};
  for (const std::string& s : b.order) {
    json js = json::object();
    const auto& modes = b.by_seq.at(s);
    for (const std::string& mode : a.modes)
      if (modes.count(mode)) js[mode] = ToJson(*modes.at(mode));
    result["sequences"][s] = js;
  }
  return result;
}

// The paper's two figures from the data file, when python3 with matplotlib is there.
void Figures(const PaperArgs& a, json* result) {
  fs::create_directories(a.out);
  const fs::path data = fs::path(a.out) / "paper.json";
  std::ofstream(data) << result->dump(2) << "\n";
  const fs::path script = fs::path(__FILE__).parent_path() / "paper_plots.py";
  const std::string py = FindPython();
  if (py.empty() || !fs::exists(script)) {
    std::printf("\nfigures: skipped (%s)\n",
                py.empty() ? "no python3 with matplotlib" : "paper_plots.py not found");
    (*result)["figures"] = json::array();
  } else if (Sh(py + " " + Quote(script.string()) + " " + Quote(data.string()) + " " +
                Quote(a.out)) == 0) {
    const fs::path f1 = fs::path(a.out) / "paper_accuracy.png";
    const fs::path f2 = fs::path(a.out) / "paper_overhead.png";
    std::printf("\nfigures: %s, %s (data: %s)\n", f1.c_str(), f2.c_str(), data.c_str());
    (*result)["figures"] = {f1.string(), f2.string()};
  }
}

}  // namespace

int RunPaperBench(int argc, char** argv) {
  PaperArgs a;
  if (int status = 0; !ParsePaperArgs(argc, argv, &a, &status)) return status;
  const std::string load_start = LoadAverage();
  const auto wall0 = std::chrono::steady_clock::now();
  std::printf("imr-bench paper: %s; load average at start %s\n", MachineLine().c_str(),
              load_start.c_str());
  std::vector<ModeResult> all;
  if (!RunSyntheticScenes(a, &all)) return 2;
  const fs::path work = a.work.empty() ? fs::temp_directory_path() /
                                             ("imr-bench-paper-" + std::to_string(getpid()))
                                       : fs::path(a.work);
  const std::string image_note = RunImageSequences(a, work, &all);

  std::printf("\nAccuracy against ground truth (exported mesh, any_steiner rule as the default job;"
              " truth->mesh is the paper's figure), per-move overhead (T_mov - T_nonmov) / N_mov "
              "with engine time only:\n");
  PrintTable(all, a.tau);
  BySequence b;
  const json ratios = PrintRatios(all, &b);
  if (!image_note.empty()) std::printf("\nnote: %s\n", image_note.c_str());
  json result = PaperJson(a, b, ratios, load_start);
  result["wall_s"] =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
  Figures(a, &result);
  std::printf("load average at end %s\n", LoadAverage().c_str());
  bool ok = true;
  for (const ModeResult& m : all) ok = ok && m.ok;
  if (ok && a.work.empty() && fs::exists(work)) fs::remove_all(work);
  std::printf("%s\n", result.dump().c_str());
  return ok ? 0 : 1;
}

}  // namespace imr::bench
