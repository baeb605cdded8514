// imr-bench pipeline: the whole image pipeline (reader -> features -> refiner -> engine ->
// exporter) as users run it — the real `imr run` on a job file — pinned to one core (or to each
// count of --cores 1,2 in turn), on the synthetic sequence from imr-synth and on the real KITTI
// raw sample when ../shared/data has it. Figures come from each sequence's report.json
// (stage_seconds, frames). Targets: the whole pipeline >= 10 frames/s at 1242x375 on one core
// (issue 5); on two cores >= 1.6x its one-core rate (issue 18: the front end overlapped with the
// engine; --no-overlap runs imr without it). Prints a table per core count and the ratios, then
// one JSON object as the last line.
#include <sched.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "tools/bench/common/frame.h"
#include "tools/bench/common/subprocess.h"
#include "host/util/clock.h"

namespace imr::bench {
namespace {
namespace fs = std::filesystem;
using nlohmann::json;

struct PipelineArgs {
  int frames = 300;             // synthetic frames
  int width = 1242, height = 375;
  std::vector<int> cores = {1};  // CPUs the run may use (pinned), one run per entry
  bool no_overlap = false;       // imr run --no-overlap
  std::string work;             // scratch folder; default under the temp folder
  std::string kitti;            // KITTI raw drive folder; default from IMR_SHARED_DIR
  bool keep = false;
};

// The settings of configs/default.json (the README's first command), one output format.
json Job(const std::string& format, const std::string& sequence, const fs::path& out) {
  return {{"description", "imr-bench pipeline"},
          {"sequences", {sequence}},
          {"input", {{"format", format}, {"options", json::object()}}},
          {"engine",
           {{"window", 15},
            {"steiner_spacing", 5.0},
            {"visibility_mode", "weights"},  // the weight policy below needs it (not the default)
            {"steiner_export", "any_steiner"}}},
          {"pipeline",
           {{{"kind", "features"}, {"plugin", "org.imr.features.edge_klt"}},
            {{"kind", "refiner"}, {"plugin", "org.imr.refiner.ceres"},
             {"params", {{"max_distance", 30.0}, {"min_keyframes", 1}}}},
            {{"kind", "weight_policy"}, {"plugin", "org.imr.policy.nearest"}},
            {{"kind", "exporter"}, {"plugin", "org.imr.exporter.assimp"}}}},
          {"output", {{"directory", out.string()}, {"formats", {"ply"}}}}};
}

struct Measured {
  std::string name;
  bool ok = false;
  int frames = 0;
  int width = 0, height = 0;
  double wall = 0.0;  // the imr process, start to exit
  json stages;        // seconds per stage from the report
  double sequence_seconds = 0.0;
  json mesh, accuracy;
};

Measured RunImr(const std::string& name, const std::string& format, const std::string& sequence,
                const fs::path& work, int cores, bool no_overlap) {
  Measured m;
  m.name = name;
  const std::string run = name + "-" + std::to_string(cores) + "core";
  const fs::path job_file = work / (run + ".json");
  const fs::path out = work / ("out-" + run);
  std::ofstream(job_file) << Job(format, sequence, out).dump(2);
  const auto start = std::chrono::steady_clock::now();
  const int rc = Sh(Quote((ExeDir() / "imr").string()) + " run --force " +
                     (no_overlap ? "--no-overlap " : "") + Quote(job_file.string()) + " 2>" +
                     Quote((work / (run + ".log")).string()));
  m.wall = SecondsSince(start);
  std::ifstream in(out / "report.json");
  if (rc != 0 || !in) {
    std::fprintf(stderr, "%s: imr run failed (exit %d); log in %s\n", name.c_str(), rc,
                 (work / (run + ".log")).c_str());
    return m;
  }
  json r;
  in >> r;
  const json& s = r["input"]["summary"];
  m.frames = s.value("frames_processed", 0);
  if (s.contains("image_size")) {
    m.width = s["image_size"][0];
    m.height = s["image_size"][1];
  }
  m.stages = r["stage_seconds"];
  m.sequence_seconds = r["seconds"];
  m.mesh = r["mesh"];
  if (r.contains("accuracy")) m.accuracy = r["accuracy"];
  m.ok = true;
  return m;
}

json Figures(const Measured& m) {
  json j = {{"ok", m.ok}};
  if (!m.ok) return j;
  json fps = json::object();
  for (const auto& [stage, seconds] : m.stages.items())
    if (seconds.get<double>() > 0.0) fps[stage] = m.frames / seconds.get<double>();
  j["frames"] = m.frames;
  j["image_size"] = {m.width, m.height};
  j["stage_seconds"] = m.stages;
  j["stage_frames_per_second"] = fps;
  j["pipeline_frames_per_second"] = m.frames / m.sequence_seconds;
  j["process_frames_per_second"] = m.frames / m.wall;
  j["mesh"] = m.mesh;
  if (!m.accuracy.is_null()) j["accuracy"] = m.accuracy;
  return j;
}

void PrintRow(const Measured& m) {
  if (!m.ok) {
    std::printf("%-10s failed\n", m.name.c_str());
    return;
  }
  auto fps = [&](const char* stage) {
    const double s = m.stages.value(stage, 0.0);
    return s > 0.0 ? m.frames / s : 0.0;
  };
  std::printf("%-10s %5d %4dx%-4d %8.1f %8.1f %8.1f %8.1f %8.1f | %6.1f fps whole (%.1f s)\n",
              m.name.c_str(), m.frames, m.width, m.height, fps("read_images"), fps("features"),
              fps("refiner"), fps("engine"), fps("export"), m.frames / m.sequence_seconds,
              m.sequence_seconds);
}

}  // namespace

// Pins this process, and so every process it starts and their threads (OpenCV, Ceres, the
// engine's pool), to the first `cores` CPUs of its original affinity mask.
void PinToCores(const cpu_set_t& allowed, int cores) {
  cpu_set_t set;
  CPU_ZERO(&set);
  int picked = 0;
  for (int c = 0; c < CPU_SETSIZE && picked < cores; ++c)
    if (CPU_ISSET(c, &allowed)) {
      CPU_SET(c, &set);
      ++picked;
    }
  if (picked < cores)
    std::fprintf(stderr, "imr-bench pipeline: only %d core(s) to run on, not %d\n", picked, cores);
  if (sched_setaffinity(0, sizeof(set), &set) != 0) std::perror("sched_setaffinity");
}

namespace {

bool ParsePipelineArgs(int argc, char** argv, PipelineArgs* a, int* status) {
  Options o("imr-bench pipeline",
            "usage: imr-bench pipeline [--frames N] [--width W --height H] [--cores C[,C...]]\n"
            "                          [--no-overlap] [--kitti DRIVE_DIR] [--work DIR] [--keep]\n");
  o.Int("--frames", &a->frames).Int("--width", &a->width).Int("--height", &a->height);
  o.IntList("--cores", &a->cores, 1);
  o.Flag("--no-overlap", &a->no_overlap).String("--work", &a->work);
  o.String("--kitti", &a->kitti).Flag("--keep", &a->keep);
  if (!o.Parse(argc, argv, status)) return false;
  if (a->frames < 10 || a->width < 64 || a->height < 32 || a->cores.empty()) {
    std::fprintf(stderr, "imr-bench pipeline: need frames >= 10, size >= 64x32, cores >= 1\n");
    *status = 2;
    return false;
  }
  return true;
}

// imr-synth's street at the bench's size, its wall time; < 0 when it failed.
double Generate(const PipelineArgs& a, const fs::path& synth) {
  const auto gen_start = std::chrono::steady_clock::now();
  const int gen_rc = Sh(Quote((ExeDir() / "imr-synth").string()) + " --out " +
                        Quote(synth.string()) + " --frames " + std::to_string(a.frames) +
                        " --width " + std::to_string(a.width) + " --height " +
                        std::to_string(a.height) + " --no-lidar --force >/dev/null");
  const double gen_seconds = SecondsSince(gen_start);
  if (gen_rc != 0) {
    std::fprintf(stderr, "imr-bench pipeline: imr-synth failed (exit %d)\n", gen_rc);
    return -1.0;
  }
  return gen_seconds;
}

// One core count's table; its figures into `result`. False when a run failed.
bool PrintCores(const PipelineArgs& a, std::size_t c, const std::vector<Measured>& runs,
                bool kitti_ran, const std::string& kitti, json* result) {
  std::printf("\nimr-bench pipeline: %d core(s)%s; frames per second of each stage and of the "
              "whole\npipeline (imr run, one sequence; target >= 10 fps at 1242x375 on one core)\n\n",
              a.cores[c], a.no_overlap ? ", --no-overlap" : "");
  std::printf("%-10s %5s %9s %8s %8s %8s %8s %8s | whole\n", "input", "frames", "size",
              "read", "features", "refiner", "engine", "export");
  json by = {{"cores", a.cores[c]}};
  bool ok = true;
  for (const Measured& m : runs) {
    PrintRow(m);
    by[m.name] = Figures(m);
    ok = ok && m.ok;
  }
  if (!kitti_ran) by["kitti_raw"] = {{"skipped", "no sample at " + kitti}};
  if (a.cores.size() == 1) result->update(by);
  else (*result)["runs"].push_back(by);
  return ok;
}

// The whole pipeline's rate on each core count against the first (issue 18: 2 cores >= 1.6x 1).
void PrintSpeedups(const PipelineArgs& a, const std::vector<std::vector<Measured>>& runs,
                   json* result) {
  for (std::size_t c = 1; c < a.cores.size(); ++c) {
    std::printf("\n%d cores / %d core(s), whole pipeline:", a.cores[c], a.cores[0]);
    for (std::size_t i = 0; i < runs[c].size(); ++i) {
      const Measured& base = runs[0][i];
      const Measured& m = runs[c][i];
      if (!m.ok || !base.ok) continue;
      const double ratio = base.sequence_seconds / m.sequence_seconds;
      std::printf("  %s %.2fx", m.name.c_str(), ratio);
      (*result)["speedup"][std::to_string(a.cores[c]) + "/" + std::to_string(a.cores[0])][m.name] = ratio;
    }
    std::printf("   (target for 2/1: >= 1.6x)\n");
  }
}

}  // namespace

int RunPipelineBench(int argc, char** argv) {
  PipelineArgs a;
  if (int status = 0; !ParsePipelineArgs(argc, argv, &a, &status)) return status;
  // Each run pinned to its cores: the affinity is inherited by imr-synth and imr and every thread
  // of theirs (OpenCV, Ceres, the engine), so "one core" holds for everything the pipeline runs.
  cpu_set_t allowed;
  sched_getaffinity(0, sizeof(allowed), &allowed);
  const WorkFolder work(a.work, "pipeline");

  // Synthetic: generated once (on the first core count), then run on each.
  PinToCores(allowed, a.cores.front());
  const fs::path synth = work.path() / "synthetic-street";
  const double gen_seconds = Generate(a, synth);
  if (gen_seconds < 0.0) return 1;

  // Real: the KITTI raw sample, when the team's data is beside the checkout.
  const std::string kitti = KittiRawSample(a.kitti);
  const bool kitti_ran = fs::is_directory(kitti);
  if (!kitti_ran)
    std::fprintf(stderr, "imr-bench pipeline: no KITTI raw sample at %s; skipped\n", kitti.c_str());

  std::vector<std::vector<Measured>> runs;  // per core count
  for (int cores : a.cores) {
    PinToCores(allowed, cores);
    runs.emplace_back();
    runs.back().push_back(RunImr("synthetic", "kitti_odometry", synth.string(), work.path(), cores, a.no_overlap));
    if (kitti_ran)
      runs.back().push_back(RunImr("kitti_raw", "kitti_raw", kitti, work.path(), cores, a.no_overlap));
  }

  json result = {{"bench", "pipeline"},
                 {"overlap", !a.no_overlap},
                 {"generator_frames_per_second", a.frames / gen_seconds}};
  bool ok = true;
  for (std::size_t c = 0; c < a.cores.size(); ++c)
    ok = PrintCores(a, c, runs[c], kitti_ran, kitti, &result) && ok;
  PrintSpeedups(a, runs, &result);
  std::printf("\nsynthetic generation (imr-synth, %d frames, no lidar, %d core(s)): %.1f s, %.1f frames/s\n",
              a.frames, a.cores.front(), gen_seconds, a.frames / gen_seconds);
  if (!a.keep && ok) fs::remove_all(work.path());  // a given --work too, as ever: --keep keeps it
  std::printf("%s\n", result.dump().c_str());
  return ok ? 0 : 1;
}

}  // namespace imr::bench
