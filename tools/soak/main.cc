// imr-soak (issue 9): a long run of the real `imr run` with the full invariant check every K
// keyframes and the per-keyframe trace (--trace), then whether the resident memory grows only with
// the points kept. Heavy by design (minutes): ctest runs only its plumbing, on 40 frames
// (tools/soak_smoke). Figures and commands: tools/soak/README.md.
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "tools/bench/common/bench_util.h"
#include "tools/bench/common/subprocess.h"
#include "tools/soak/trace.h"
#include "host/util/clock.h"

namespace {
namespace fs = std::filesystem;
using nlohmann::json;
using imr::SecondsSince;
using imr::bench::ExeDir;
using imr::bench::LoadAverage;
using imr::bench::Quote;
using imr::bench::Sh;  // imr-synth; the imr runs go through ShPeak
namespace soak = imr::soak;

const char kUsage[] =
    "usage: imr-soak [--frames N] [--seed S] [--points-per-keyframe P] [--check-every K]\n"
    "                [--no-baseline] [--no-contrast] [--images [--width W] [--height H]]\n"
    "                [--out DIR] [--results FILE] [--imr PATH]\n"
    "       imr-soak --analyse TRACE [--baseline-trace TRACE]\n"
    "                [--contrast-trace SPARSE --contrast-trace COARSE] [--results FILE]\n"
    "\n"
    "Runs `imr run JOB --check-invariants-every K --trace FILE` on a long synthetic sequence and\n"
    "analyses the trace: totals, invariant checks, RSS, and whether memory follows the points\n"
    "kept.\n"
    "  --frames N          frames (default 5000)\n"
    "  --seed S            the synthetic scene's seed (default 1)\n"
    "  --points-per-keyframe P   new points per keyframe of the stream (default 150)\n"
    "  --check-every K     full manifold + weight check every K keyframes (default 50)\n"
    "  --no-baseline       skip the same run without the periodic check (the engine's own memory,\n"
    "                      without what the check leaves with malloc)\n"
    "  --no-contrast       skip the two contrast runs without checks (half the points per\n"
    "                      keyframe; twice the Steiner spacing) that, with the baseline, separate\n"
    "                      growth with the points kept, with the Steiner grid and with keyframes\n"
    "  --images            images instead of the observation stream: imr-synth renders N frames\n"
    "                      (--width/--height, default 621x188), then the image pipeline of\n"
    "                      configs/default.json (edge KLT, Ceres refiner) runs on them (no\n"
    "                      contrast runs)\n"
    "  --out DIR           work folder (default: BUILD/soak beside bin/); jobs, logs, traces\n"
    "  --results FILE      also write the printed analysis there (default DIR/soak_results.txt)\n"
    "  --imr PATH          the imr executable (default: beside imr-soak)\n"
    "  --analyse TRACE     analyse existing traces only (the main run's; the baseline's; the\n"
    "                      sparse and coarse contrast runs', for the decomposition)\n"
    "Exit status: 0 memory follows the points kept and every check passed; 1 not, or a run\n"
    "failed; 2 bad usage.\n";

struct Args {
  int frames = 5000;
  int seed = 1;
  int points_per_keyframe = 150;
  int check_every = 50;
  bool baseline = true;
  bool contrast = true;
  bool images = false;
  int width = 621, height = 188;
  std::string out, results, imr, analyse, baseline_trace;
  std::vector<std::string> contrast_traces;
};

// What a run is for: the soak itself, the same without periodic checks, and the two contrasts.
enum class Role { kMain, kBaseline, kSparse, kCoarse };

struct Run {
  Role role = Role::kMain;
  std::string name;
  std::string what;  // what differs from the main run
  std::string command;
  int rc = -1;
  double wall = 0.0;
  long child_peak_kb = 0;  // the imr process tree's peak RSS (wait4)
  std::vector<soak::TraceRecord> records;
  std::string trace_note;
  json report;  // the sequence's report.json (null when the run failed)
  fs::path log;
};

std::string Fixed(double v, int decimals) {
  char b[64];
  std::snprintf(b, sizeof b, "%.*f", decimals, v);
  return b;
}

// 1234567 -> "1 234 567" (README style for counts).
std::string Count(int64_t v) {
  std::string s = std::to_string(v < 0 ? -v : v), out;
  for (size_t i = 0; i < s.size(); ++i) {
    if (i > 0 && (s.size() - i) % 3 == 0) out += ' ';
    out += s[i];
  }
  return (v < 0 ? "-" : "") + out;
}

// First line printed by a command (imr --version), or "" when it fails.
std::string FirstLine(const std::string& command) {
  FILE* p = popen(command.c_str(), "r");
  if (!p) return "";
  char b[512] = {0};
  const bool got = std::fgets(b, sizeof b, p) != nullptr;
  pclose(p);
  std::string s = got ? b : "";
  while (!s.empty() && (s.back() == '\n' || s.back() == '\r')) s.pop_back();
  return s;
}

// bench_util.h's machine line, with the memory.
std::string Machine() {
  return imr::bench::MachineLine() + ", " +
         Fixed(static_cast<double>(sysconf(_SC_PHYS_PAGES)) * sysconf(_SC_PAGESIZE) / (1 << 30),
               0) +
         " GiB";
}

std::string Today() {
  const std::time_t t = std::time(nullptr);
  char b[32];
  std::strftime(b, sizeof b, "%Y-%m-%d %H:%M", std::localtime(&t));
  return b;
}

// The job: configs/engine-synthetic.json's engine and policy on one long street (stream mode),
// or configs/default.json's image pipeline on imr-synth's rendering (images mode).
json Job(const Args& a, int points_per_keyframe, double steiner_spacing, const fs::path& images,
         const fs::path& out) {
  json pipeline = json::array();
  json input;
  json sequences;
  if (images.empty()) {
    sequences = {"street"};
    input = {{"format", "synthetic"},
             {"options", {{"frames", a.frames}, {"seed", a.seed},
                          {"points_per_keyframe", points_per_keyframe}}}};
  } else {
    sequences = {images.string()};
    input = {{"format", "kitti_odometry"}, {"options", {{"keyframe_every", 5}}}};
    pipeline.push_back({{"kind", "features"}, {"plugin", "org.imr.features.edge_klt"}});
    pipeline.push_back({{"kind", "refiner"}, {"plugin", "org.imr.refiner.ceres"},
                        {"params", {{"max_distance", 30.0}}}});
  }
  pipeline.push_back({{"kind", "weight_policy"}, {"plugin", "org.imr.policy.nearest"}});
  pipeline.push_back({{"kind", "exporter"}, {"plugin", "org.imr.exporter.assimp"}});
  return {{"description", "imr-soak: a long run with invariant checks and a per-keyframe trace"},
          {"sequences", sequences},
          {"input", input},
          {"engine", {{"window", 15}, {"steiner_spacing", steiner_spacing},
                      {"visibility_mode", "weights"},
                      {"steiner_export", "any_steiner"}}},
          {"pipeline", pipeline},
          {"output", {{"directory", out.string()}, {"stem", "mesh"}, {"formats", {"ply"}}}}};
}

// Sh (tools/bench/common/subprocess.h) with this command's own peak RSS: wait4 gives the largest
// of its process tree (imr and its sequence child), where getrusage(RUSAGE_CHILDREN) would only
// give the largest child so far.
int ShPeak(const std::string& command, long* peak_kb) {
  std::fprintf(stderr, "+ %s\n", command.c_str());
  std::fflush(nullptr);
  const pid_t pid = fork();
  if (pid < 0) return 128;
  if (pid == 0) {
    execl("/bin/sh", "sh", "-c", command.c_str(), static_cast<char*>(nullptr));
    _exit(127);
  }
  int status = 0;
  rusage u{};
  while (wait4(pid, &status, 0, &u) < 0)
    if (errno != EINTR) return 128;
  *peak_kb = u.ru_maxrss;
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128;
}

// check_every 0: no periodic check (imr still checks after the last keyframe).
Run RunImr(const Args& a, Role role, const std::string& name, const std::string& what,
           int check_every, const json& job, const fs::path& work) {
  Run r;
  r.role = role;
  r.name = name;
  r.what = what;
  const fs::path job_file = work / (name + ".json");
  const fs::path trace = work / (name + ".trace.jsonl");
  r.log = work / (name + ".log");
  std::ofstream(job_file) << job.dump(2) << "\n";
  fs::remove(trace);  // a stale trace must not pass for this run's
  fs::remove(fs::path(trace.string() + ".partial"));
  r.command = Quote(a.imr) + " run " + Quote(job_file.string()) + " --force" +
              (check_every > 0 ? " --check-invariants-every " + std::to_string(check_every) : "") +
              " --trace " + Quote(trace.string());
  const auto start = std::chrono::steady_clock::now();
  r.rc = ShPeak(r.command + " 2>" + Quote(r.log.string()), &r.child_peak_kb);
  r.wall = SecondsSince(start);
  // imr renames <trace>.partial into place when the sequence ends; a killed run leaves only that.
  fs::path read = trace;
  if (!fs::exists(read) && fs::exists(fs::path(trace.string() + ".partial")))
    read = trace.string() + ".partial";
  std::string error;
  if (!soak::ReadTrace(read.string(), &r.records, &r.trace_note, &error))
    std::fprintf(stderr, "imr-soak: %s\n", error.c_str());
  else if (read != trace)
    r.trace_note = "only " + read.string() + " (the run did not end)" +
                   (r.trace_note.empty() ? "" : "; " + r.trace_note);
  r.report = imr::bench::ReadJson(fs::path(job["output"]["directory"].get<std::string>()) /
                                  "report.json");
  return r;
}

// The lines of a failed run's log that say why (the last few).
std::string LogTail(const fs::path& log, int lines) {
  std::ifstream in(log);
  std::vector<std::string> all;
  std::string line;
  while (std::getline(in, line)) all.push_back(line);
  std::string out;
  for (size_t i = all.size() > static_cast<size_t>(lines) ? all.size() - lines : 0;
       i < all.size(); ++i)
    out += "    | " + all[i] + "\n";
  return out;
}

// One run's figures, as printed and written; the verdict is left to the caller.
void Describe(std::ostringstream& o, const Run& run, const soak::SoakFigures& f) {
  const soak::TraceRecord& last = f.last;
  o << "  frames " << Count(f.frames) << ", keyframes " << Count(f.keyframes);
  if (run.wall > 0.0)
    o << ", wall " << Fixed(run.wall, 1) << " s (" << Fixed(f.frames / run.wall, 1)
      << " frames/s, whole imr run)";
  o << "; engine " << Fixed(f.engine_total_s, 1) << " s ("
    << Fixed(f.engine_total_s > 0 ? f.frames / f.engine_total_s : 0.0, 1) << " frames/s)\n";
  o << "  at the end: points kept " << Count(last.points) << ", vertices "
    << Count(last.vertices) << " (" << Count(last.vertices - last.points)
    << " Steiner), cells " << Count(last.cells) << ", cells in O " << Count(last.cells_in_o)
    << "\n";
  if (run.report.is_object() && run.report.contains("engine")) {
    const json& e = run.report["engine"];
    o << "  engine counters: points inserted " << Count(e.value("points_inserted", 0L))
      << ", moved " << Count(e.value("points_moved", 0L)) << ", dropped "
      << Count(e.value("points_dropped", 0L)) << ", removed "
      << Count(e.value("points_removed", 0L)) << "\n";
  }
  o << "  invariant checks during the run: " << f.checks;
  if (f.checks > 0)
    o << ", total " << Fixed(f.check_total_s, 2) << " s, mean "
      << Fixed(f.check_total_s / f.checks, 3) << " s, max " << Fixed(f.check_max_s, 3) << " s";
  if (!run.command.empty() && run.rc == 0)
    o << "; all passed, and the check after the last keyframe";
  o << "\n";
  o << "  RSS: start " << soak::Mib(f.rss_start) << " MiB (keyframe " << f.first.keyframe
    << "), end " << soak::Mib(f.rss_end) << ", peak " << soak::Mib(f.rss_peak) << " (keyframe "
    << f.rss_peak_keyframe << ")";
  if (run.child_peak_kb > 0)
    o << "; the process's peak (wait4: between keyframes, final check and export too) "
      << soak::Mib(run.child_peak_kb * 1024.0);
  o << "\n";
  o << "  fit rss = a + b*points kept (whole run): a " << soak::Mib(f.fit_points.a)
    << " MiB, b " << Fixed(f.fit_points.b, 0) << " bytes per point kept; residual RMS "
    << soak::Mib(f.fit_points.rms) << " MiB, max " << soak::Mib(f.fit_points.max_abs)
    << " MiB\n";
  o << "  context (same fit against other counts): " << Fixed(f.fit_vertices.b, 0)
    << " bytes per vertex, " << Fixed(f.fit_cells.b, 0) << " bytes per cell\n";
  if (f.checks > 0)
    o << "  RSS growth on the " << f.checks << " check keyframes: "
      << Fixed(100.0 * f.growth_at_checks, 1)
      << " % of the run's (what the check's working memory leaves with malloc)\n";
  const int predicted = f.holdout_at_checks ? f.checks - f.fit_first_half.n
                                            : f.keyframes - f.fit_first_half.n;
  const std::string samples = f.holdout_at_checks ? " check keyframes" : " keyframes";
  o << "  holdout: fit on the first " << f.fit_first_half.n << samples << " (a "
    << soak::Mib(f.fit_first_half.a) << " MiB, b " << Fixed(f.fit_first_half.b, 0)
    << " bytes per point), predicting the other " << predicted << ": worst keyframe "
    << f.holdout_worst_keyframe << ", measured - predicted "
    << (f.holdout_max_dev >= 0 ? "+" : "") << soak::Mib(f.holdout_max_dev) << " MiB ("
    << (f.holdout_max_dev_pct >= 0 ? "+" : "") << Fixed(f.holdout_max_dev_pct, 2)
    << " % of its RSS); tolerance " << Fixed(100 * soak::kHoldoutTolerance, 0) << " %: "
    << (f.follows_points ? "within" : "EXCEEDED") << "\n";
  if (!run.trace_note.empty()) o << "  trace: " << run.trace_note << "\n";
}

bool ParseArgs(int argc, char** argv, Args* a) {
  for (int i = 1; i < argc; ++i) {
    const std::string k = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) throw std::runtime_error(k + " needs a value");
      return argv[++i];
    };
    auto integer = [&](int min) {
      const std::string v = value();
      char* end = nullptr;
      const long n = std::strtol(v.c_str(), &end, 10);
      if (v.empty() || *end != '\0' || n < min || n > 10000000)
        throw std::runtime_error(k + ": expected an integer >= " + std::to_string(min) +
                                 ", got '" + v + "'");
      return static_cast<int>(n);
    };
    if (k == "--frames") a->frames = integer(20);
    else if (k == "--seed") a->seed = integer(0);
    else if (k == "--points-per-keyframe") a->points_per_keyframe = integer(2);
    else if (k == "--check-every") a->check_every = integer(1);
    else if (k == "--no-contrast") a->contrast = false;
    else if (k == "--no-baseline") a->baseline = false;
    else if (k == "--images") a->images = true;
    else if (k == "--width") a->width = integer(64);
    else if (k == "--height") a->height = integer(32);
    else if (k == "--out") a->out = value();
    else if (k == "--results") a->results = value();
    else if (k == "--imr") a->imr = value();
    else if (k == "--analyse") a->analyse = value();
    else if (k == "--baseline-trace") a->baseline_trace = value();
    else if (k == "--contrast-trace") a->contrast_traces.push_back(value());
    else if (k == "--help" || k == "-h") {
      std::cout << kUsage;
      std::exit(0);
    } else {
      throw std::runtime_error("unknown option " + k);
    }
  }
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  Args a;
  try {
    ParseArgs(argc, argv, &a);
    if (!a.contrast_traces.empty() && (a.contrast_traces.size() != 2 || a.baseline_trace.empty()))
      throw std::runtime_error("--contrast-trace: give both (sparse, then coarse) and "
                               "--baseline-trace");
  } catch (const std::exception& e) {
    std::cerr << "imr-soak: " << e.what() << "\n" << kUsage;
    return 2;
  }
  std::string command_line = "imr-soak";
  for (int i = 1; i < argc; ++i) command_line += " " + Quote(argv[i]);

  std::ostringstream o;
  std::vector<Run> runs;  // the main run first
  const std::string load_start = LoadAverage();
  const std::string sparse_what =
      std::to_string(std::max(1, a.points_per_keyframe / 2)) + " points per keyframe, no check";

  if (!a.analyse.empty()) {
    const std::pair<Role, std::string> given[] = {
        {Role::kMain, a.analyse},
        {Role::kBaseline, a.baseline_trace},
        {Role::kSparse, a.contrast_traces.empty() ? "" : a.contrast_traces[0]},
        {Role::kCoarse, a.contrast_traces.empty() ? "" : a.contrast_traces[1]}};
    const char* what[] = {"", "no periodic check", "half the points per keyframe",
                          "Steiner spacing doubled"};
    for (const auto& [role, path] : given) {
      if (path.empty()) continue;
      Run r;
      r.role = role;
      r.name = path;
      r.what = what[static_cast<int>(role)];
      r.rc = 0;
      std::string error;
      if (!soak::ReadTrace(path, &r.records, &r.trace_note, &error)) {
        std::cerr << "imr-soak: " << error << "\n";
        return 1;
      }
      runs.push_back(std::move(r));
    }
    o << "imr-soak: analysis of " << command_line << "\n\n";
  } else {
    if (a.imr.empty()) a.imr = (ExeDir() / "imr").string();
    const fs::path work =
        fs::absolute(a.out.empty() ? ExeDir().parent_path() / "soak" : fs::path(a.out));
    fs::create_directories(work);
    if (a.results.empty()) a.results = (work / "soak_results.txt").string();
    fs::path images;
    double synth_seconds = 0.0;
    if (a.images) {
      images = work / "images-street";
      const auto start = std::chrono::steady_clock::now();
      const int rc = Sh(Quote((ExeDir() / "imr-synth").string()) + " --out " +
                        Quote(images.string()) + " --frames " + std::to_string(a.frames) +
                        " --seed " + std::to_string(a.seed) + " --width " +
                        std::to_string(a.width) + " --height " + std::to_string(a.height) +
                        " --no-lidar --force -q");
      synth_seconds = SecondsSince(start);
      if (rc != 0) {
        std::cerr << "imr-soak: imr-synth failed (exit " << rc << ")\n";
        return 1;
      }
    }
    o << "imr-soak (" << Today() << "): " << command_line << "\n";
    o << "machine: " << Machine() << "; load average " << load_start << " at the start; "
      << FirstLine(Quote(a.imr) + " --version 2>&1") << "\n";
    if (a.images)
      o << "input: imr-synth street, " << a.frames << " frames at " << a.width << "x" << a.height
        << " (rendered in " << Fixed(synth_seconds, 1)
        << " s), image pipeline of configs/default.json (edge KLT, Ceres, nearest)\n";
    else
      o << "input: synthetic observation stream over the street, " << a.frames
        << " frames, seed " << a.seed << ", " << a.points_per_keyframe
        << " new points per keyframe; engine and policy of configs/engine-synthetic.json\n";
    o << "\n";

    const std::string base = a.images ? "images" : "stream";
    const int ppk = a.points_per_keyframe;
    runs.push_back(RunImr(a, Role::kMain, base, "", a.check_every,
                          Job(a, ppk, 5.0, images, work / ("out-" + base)), work));
    if (a.baseline)
      runs.push_back(RunImr(a, Role::kBaseline, base + "-nocheck", "no periodic check", 0,
                            Job(a, ppk, 5.0, images, work / ("out-" + base + "-nocheck")), work));
    // The contrasts: the same cameras with half the points (so the same Steiner grid), and the
    // same points with a coarser grid; with the baseline they tell the three growths apart.
    if (a.baseline && a.contrast && !a.images) {
      runs.push_back(RunImr(a, Role::kSparse, "stream-sparse", sparse_what, 0,
                            Job(a, std::max(1, ppk / 2), 5.0, images, work / "out-stream-sparse"),
                            work));
      runs.push_back(RunImr(a, Role::kCoarse, "stream-coarse",
                            "Steiner spacing 10 m instead of 5, no check", 0,
                            Job(a, ppk, 10.0, images, work / "out-stream-coarse"), work));
    }
  }

  // Analysis. The verdict needs every run to succeed (a failed invariant check fails its run),
  // the holdout to pass on the main run and the baseline, and the decomposition's growth with
  // keyframes alone to stay within its tolerance.
  bool verdict = true;
  std::vector<soak::SoakFigures> figures(runs.size());
  const Run* main_run = nullptr;
  const Run* baseline = nullptr;
  for (size_t i = 0; i < runs.size(); ++i) {
    const Run& r = runs[i];
    verdict = verdict && r.rc == 0;
    o << "run " << r.name << (r.what.empty() ? "" : " (" + r.what + ")");
    if (!r.command.empty()) o << ": " << r.command << " (exit " << r.rc << ")";
    o << "\n";
    if (r.rc != 0) o << "  FAILED; the end of " << r.log.string() << ":\n" << LogTail(r.log, 6);
    std::string error;
    if (!soak::Analyse(r.records, &figures[i], &error)) {
      o << "  no analysis: " << error << "\n";
      verdict = false;
      continue;
    }
    Describe(o, r, figures[i]);
    if (r.role == Role::kMain) main_run = &r;
    if (r.role == Role::kBaseline) baseline = &r;
    if (r.role == Role::kMain || r.role == Role::kBaseline)
      verdict = verdict && figures[i].follows_points;
  }
  if (main_run && baseline) {
    const double extra = main_run->records.back().rss_bytes - baseline->records.back().rss_bytes;
    o << "the periodic check's cost in RSS at the end: " << soak::Mib(extra) << " MiB ("
      << Fixed(100.0 * extra / baseline->records.back().rss_bytes, 1)
      << " % over the baseline's)\n";
  }
  std::vector<const std::vector<soak::TraceRecord>*> decomposed;
  for (Role role : {Role::kBaseline, Role::kSparse, Role::kCoarse})
    for (const Run& r : runs)
      if (r.role == role && r.records.size() >= 4) decomposed.push_back(&r.records);
  const bool decompose = decomposed.size() == 3;
  if (decompose) {
    const soak::Decomposition d = soak::Decompose(decomposed);
    o << "decomposition over the baseline and the two contrasts: rss = a + p*points kept + "
         "s*Steiner points + c*keyframe";
    if (!d.ok) {
      o << ": singular (the runs do not vary points and Steiner points independently)\n";
      verdict = false;
    } else {
      const double pct = d.growth != 0.0 ? 100.0 * d.growth_keyframes / d.growth : 0.0;
      const bool ok = std::fabs(pct) <= 100 * soak::kKeyframeGrowthTolerance;
      auto share = [&](double g) {
        return soak::Mib(g) + " MiB (" + Fixed(d.growth != 0.0 ? 100.0 * g / d.growth : 0.0, 1) +
               " %)";
      };
      o << "\n  a " << soak::Mib(d.a) << " MiB, p " << Fixed(d.per_point, 0)
        << " bytes per point kept, s " << Fixed(d.per_steiner, 0) << " bytes per Steiner point, c "
        << Fixed(d.per_keyframe, 0) << " bytes per keyframe; residual RMS " << soak::Mib(d.rms)
        << " MiB, max " << soak::Mib(d.max_abs) << " MiB\n";
      o << "  the baseline's RSS growth, " << soak::Mib(d.growth) << " MiB: points kept "
        << share(d.growth_points) << ", Steiner grid " << share(d.growth_steiner)
        << ", keyframes alone " << share(d.growth_keyframes) << "; tolerance for the last +-"
        << Fixed(100 * soak::kKeyframeGrowthTolerance, 0) << " %: "
        << (ok ? "within" : "EXCEEDED") << "\n";
      verdict = verdict && ok;
    }
  }
  o << "\ncriterion: every run succeeds (invariant checks included); fit rss = a + b*points kept "
       "on the first half of the main run"
    << (baseline ? " and of the baseline" : "") << ", every sample of the second half within "
    << Fixed(100 * soak::kHoldoutTolerance, 0) << " % of the prediction"
    << (decompose ? "; the decomposition's growth with keyframes alone within +-" +
                        Fixed(100 * soak::kKeyframeGrowthTolerance, 0) + " % of the RSS growth"
                  : "")
    << "\n";
  o << "memory follows the points kept: " << (verdict ? "yes" : "no") << "\n";
  if (a.analyse.empty()) o << "load average at the end: " << LoadAverage() << "\n";

  std::cout << o.str();
  if (!a.results.empty()) {
    std::ofstream out(a.results);
    out << o.str();
    if (!out) {
      std::cerr << "imr-soak: cannot write " << a.results << "\n";
      return 1;
    }
    std::cerr << "imr-soak: analysis written to " << a.results << "\n";
  }
  return verdict ? 0 : 1;
}
