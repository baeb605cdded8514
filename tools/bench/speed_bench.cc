// imr-bench speed (issue 18): the engine on ../shared/data/street-stream with every view a
// keyframe (slam_json views_per_keyframe 1: each track's estimate moves at each of its views),
// the quality issue's default settings, pinned to one core (taskset) and on two. Engine time only
// (report.json's engine.seconds): frames per second = views / engine seconds; the phases beside
// it (where the time goes). The engine's threads follow the affinity mask, so the two-core run
// casts on two threads; its mesh must be byte-identical to the one-core run's. This machine's
// cores slow down for minutes at a time (other work shares them), so the one- and two-core runs
// alternate --rounds times, the one-core run on core 0 and core 1 in turn, and the fastest of
// each is the figure (every run's time printed beside it). The nearest policy (weights mode)
// runs beside the default for reference, and --before runs an earlier build on one core. Then
// two one-core runs at once, one per core: whether the machine gives two engines twice the
// throughput of one (the limit is then the engine's serial part, which the bench prints: the
// two-core run's steps outside the threaded parts, Amdahl's bound they set on two perfect cores
// and at the machine's ratio, and each phase's speed-up). Prints the targets, then one JSON
// object as the last line.
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "tools/bench/common/bench_util.h"
#include "tools/bench/common/frame.h"
#include "tools/bench/common/subprocess.h"

namespace imr::bench {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

struct SpeedArgs {
  std::string shared, work, before, before_label = "before";
  int views_per_keyframe = 1, rounds = 3;
};

struct SpeedRow {
  std::string label;
  std::string cores;  // taskset -c list
  bool ok = false;
  double wall = 0.0, engine = 0.0, fps = 0.0, rss_mb = 0.0;
  json phases;  // engine.seconds of report.json
  std::string note;
  std::string name;             // its output folder under the work directory
  std::vector<double> engines;  // every round's engine seconds (the row is the fastest)
  int failed = 0;               // rounds that failed (their logs kept with --work)
};

// One imr run: its job, its cores, the build, the table's row it is a round of.
struct Run {
  std::string name, mode, cores, imr;
  std::size_t row;
};

// What the runs share: the stream, its views, the work folder.
struct SpeedInput {
  fs::path stream, work;
  std::size_t views = 0;
  int views_per_keyframe = 1;
};

bool ParseSpeedArgs(int argc, char** argv, SpeedArgs* a, int* status) {
  Options o(
      "imr-bench speed",
      "usage: imr-bench speed [--shared DIR] [--work DIR] [--views-per-keyframe N]\n"
      "       [--rounds N]   one- and two-core runs alternated N times (3); fastest\n"
      "       [--before IMR [--before-label LABEL]]   an earlier build, one core\n");
  o.String("--shared", &a->shared).String("--work", &a->work);
  o.Int("--views-per-keyframe", &a->views_per_keyframe).Int("--rounds", &a->rounds);
  o.String("--before", &a->before).String("--before-label", &a->before_label);
  if (!o.Parse(argc, argv, status)) return false;
  if (a->views_per_keyframe < 1 || a->rounds < 1) {
    std::fprintf(stderr, "imr-bench speed: --views-per-keyframe and --rounds must be >= 1\n");
    *status = 2;
    return false;
  }
  return true;
}

// The rows of the table and the runs that fill them: one- and two-core rounds alternated, the
// nearest policy, the earlier build, and the pair of one-core runs last. The engine's threads
// default to the cores of the affinity mask: taskset picks them.
std::vector<Run> PlanRuns(const SpeedArgs& a, std::vector<SpeedRow>* rows) {
  const std::string imr = (ExeDir() / "imr").string();
  rows->assign(3, SpeedRow());
  (*rows)[0].label = "exact (default), one core", (*rows)[0].cores = "0";
  (*rows)[1].label = "exact (default), two cores", (*rows)[1].cores = "0,1";
  (*rows)[2].label = "nearest (weights mode), one core", (*rows)[2].cores = "0";
  std::vector<Run> runs;
  for (int k = 0; k < a.rounds; ++k) {
    const std::string n = std::to_string(k);
    runs.push_back({"exact-1-" + n, "exact", k % 2 == 0 ? "0" : "1", imr, 0});
    runs.push_back({"exact-2-" + n, "exact", "0,1", imr, 1});
  }
  runs.push_back({"weights-1", "weights", "0", imr, 2});
  if (!a.before.empty()) {
    rows->push_back({});
    rows->back().label = "exact, " + a.before_label + ", one core";
    runs.push_back({"before-1", "exact", "0", a.before, rows->size() - 1});
  }
  // Two one-core runs at the same time, on cores 0 and 1: their engine times against the lone
  // one-core run's.
  rows->push_back({});
  rows->back().label = "exact, one core, beside another on core 1";
  runs.push_back({"pair-0", "exact", "0", imr, rows->size() - 1});
  return runs;
}

json SpeedJob(const SpeedInput& in, const std::string& mode, const fs::path& out) {
  json pipeline = json::array();
  if (mode == "weights")
    pipeline.push_back({{"kind", "weight_policy"}, {"plugin", "org.imr.policy.nearest"}});
  pipeline.push_back({{"kind", "exporter"}, {"plugin", "org.imr.exporter.assimp"}});
  return {{"description", "imr-bench speed"},
          {"sequences", {in.stream.string()}},
          {"input", {{"format", "slam_json"},
                     {"options", {{"views_per_keyframe", in.views_per_keyframe}}}}},
          {"engine", {{"visibility_mode", mode}}},
          {"pipeline", pipeline},
          {"output", {{"directory", out.string()}, {"formats", {"ply"}}}}};
}

// The command of one run; the pair's starts the same job on core 1 (its own output folder) first.
std::string SpeedCommand(const SpeedInput& in, const Run& run, const json& job) {
  const fs::path job_file = in.work / (run.name + ".json");
  WriteJson(job_file, job);
  const std::string command = "taskset -c " + run.cores + " " + Quote(run.imr) +
                              " run -q --force " + Quote(job_file.string());
  if (run.name != "pair-0") return command;
  json job1 = job;
  job1["output"]["directory"] = (in.work / "pair-1").string();
  WriteJson(in.work / "pair-1.json", job1);
  return "/bin/sh -c " + Quote("taskset -c 1 " + Quote(run.imr) + " run -q --force " +
                               Quote((in.work / "pair-1.json").string()) + " > " +
                               Quote((in.work / "pair-1.log").string()) + " 2>&1 & " + command +
                               "; s=$?; wait $! || s=1; exit $s");
}

SpeedRow RunOnce(const SpeedInput& in, const Run& run, const std::string& label) {
  SpeedRow r;
  r.label = label;
  r.cores = run.cores;
  r.name = run.name;
  const std::string command = SpeedCommand(in, run, SpeedJob(in, run.mode, in.work / run.name));
  const TimedRun t = RunTimed(command, in.work / (run.name + ".log"));
  r.wall = t.seconds;
  r.rss_mb = t.peak_rss_mb;
  if (t.status != 0) {
    r.note = "imr run failed (" + (in.work / (run.name + ".log")).string() + ")";
    return r;
  }
  const json rep = ReadJson(in.work / run.name / "report.json");
  if (rep.is_object() && rep.contains("engine")) {
    r.phases = rep["engine"]["seconds"];
    r.engine = r.phases.value("total", 0.0);
    r.fps = r.engine > 0.0 ? static_cast<double>(in.views) / r.engine : 0.0;
    r.ok = true;
  } else {
    r.note = "no report.json";
  }
  return r;
}

// The row is its fastest round (a failed round only when none succeeds); every round's time kept.
void KeepFastest(SpeedRow r, SpeedRow* row) {
  std::vector<double> engines = std::move(row->engines);
  const int failed = row->failed + (r.ok ? 0 : 1);
  if (r.ok) engines.push_back(r.engine);
  if (!row->ok || (r.ok && r.engine < row->engine)) *row = std::move(r);
  row->engines = std::move(engines);
  row->failed = failed;
}

json PrintRows(const SpeedInput& in, const std::vector<SpeedRow>& rows) {
  std::printf("\nstreet stream, %zu views, views_per_keyframe %d (a keyframe every %d view(s); "
              "every tracked point moves at each)\n\n",
              in.views, in.views_per_keyframe, in.views_per_keyframe);
  MarkdownHeader({"run", "wall s", "engine s", "frames/s (engine)", "RSS MB", "cast", "move",
                  "insert", "shrink", "grow", "steiner"});
  json out_rows = json::array();
  for (const SpeedRow& r : rows) {
    if (!r.ok) {
      std::printf("| %s | %s | | | | | | | | | |\n", r.label.c_str(), r.note.c_str());
      out_rows.push_back({{"run", r.label}, {"ok", false}, {"note", r.note}});
      continue;
    }
    auto ph = [&](const char* k) { return r.phases.value(k, 0.0); };
    std::printf("| %s | %.1f | %.1f | %.1f | %.0f | %.1f (%.0f %%) | %.1f (%.0f %%) | %.1f | %.1f | "
                "%.1f | %.1f |\n",
                r.label.c_str(), r.wall, r.engine, r.fps, r.rss_mb, ph("cast"),
                100.0 * ph("cast") / r.engine, ph("move"), 100.0 * ph("move") / r.engine,
                ph("insert"), ph("shrink"), ph("grow"), ph("steiner"));
    out_rows.push_back({{"run", r.label}, {"ok", true}, {"cores", r.cores}, {"wall_s", r.wall},
                        {"engine_s", r.engine}, {"fps", r.fps}, {"rss_mb", r.rss_mb},
                        {"phases", r.phases}, {"engine_s_rounds", r.engines}});
  }
  return out_rows;
}

// Every round, so that the fastest is seen against the others.
void PrintRounds(const std::vector<SpeedRow>& rows) {
  auto list = [](const SpeedRow& r) {
    std::string t;
    for (double e : r.engines) t += Format("%s%.2f", t.empty() ? "" : ", ", e);
    if (r.failed > 0) t += (t.empty() ? "" : ", ") + std::to_string(r.failed) + " failed";
    return t;
  };
  std::printf("\nengine s of each round (the rows above are the fastest; one core on cores 0 and "
              "1 in turn): one core %s; two cores %s\n",
              list(rows[0]).c_str(), list(rows[1]).c_str());
}

// Bit-identical meshes for any thread count: every one- and two-core run's PLY file.
bool SameMeshes(const SpeedInput& in, const std::vector<SpeedRow>& rows,
                const std::vector<Run>& runs, int* meshes) {
  const std::string mesh1 =
      rows[0].ok ? ReadFileBytes(in.work / rows[0].name / "mesh.ply") : std::string();
  bool same = rows[0].ok && rows[1].ok && !mesh1.empty();
  *meshes = 0;
  for (const Run& run : runs)
    if (run.row <= 1) {
      same = same && ReadFileBytes(in.work / run.name / "mesh.ply") == mesh1;
      ++*meshes;
    }
  return same;
}

void PrintTargets(const SpeedArgs& a, const std::vector<SpeedRow>& rows, bool same, int meshes) {
  const double one = rows[0].ok ? rows[0].fps : 0.0, two = rows[1].ok ? rows[1].fps : 0.0;
  std::printf("\ntarget: one core >= 10 frames/s — reached %.1f: %s\n", one,
              one >= 10.0 ? "met" : "NOT met");
  std::printf("target: two cores >= 1.8x one core — reached %.2fx: %s\n",
              one > 0.0 ? two / one : 0.0, one > 0.0 && two / one >= 1.8 ? "met" : "NOT met");
  std::printf("target: the same mesh bytes on one and two cores — %s (%d runs)\n",
              same ? "met (mesh.ply identical)" : "NOT met", meshes);
  if (!a.before.empty() && rows[3].ok && rows[3].fps > 0.0)
    std::printf("one core against %s: %.2fx the frames/s\n", a.before_label.c_str(),
                one / rows[3].fps);
}

// Whether the machine bounds the two-core speed-up: two one-core runs at once against one alone.
void PairLimits(const SpeedInput& in, const std::vector<SpeedRow>& rows, json* limits) {
  const SpeedRow& pair0 = rows.back();
  const json rep1 = ReadJson(in.work / "pair-1" / "report.json");
  const double pair1 = rep1.is_object() && rep1.contains("engine")
                           ? rep1["engine"]["seconds"].value("total", 0.0)
                           : 0.0;
  if (!rows[0].ok || !pair0.ok || pair1 <= 0.0) return;
  const double throughput = rows[0].engine / pair0.engine + rows[0].engine / pair1;
  std::printf("two one-core runs at once (cores 0 and 1): engine %.1f s and %.1f s against "
              "%.1f s alone: %.2fx the throughput of one run\n",
              pair0.engine, pair1, rows[0].engine, throughput);
  (*limits)["pair_engine_s"] = {pair0.engine, pair1};
  (*limits)["pair_throughput"] = throughput;
}

// Amdahl's bound for two cores, taking the one-thread part's one-core cost as its two-core wall
// time S: the rest (T1 - S of the one-core run) at best halves, or shrinks by the machine's own
// ratio for two independent runs (pair_throughput, when measured).
// T2 >= S + (T1 - S) / c, so T1 / T2 <= T1 / (S + (T1 - S) / c).
void AmdahlLimits(const SpeedRow& one, const SpeedRow& two, json* limits) {
  // On two cores the moves are planned on the threads (engine.planned_moves) and made in order on
  // one; engine.seconds.threaded is the wall time of the parts on the threads (the plans, the
  // un-cast and cast batches), the rest of the two-core run is one thread.
  const double total1 = one.engine, total2 = two.engine;
  const double threaded1 = one.phases.value("threaded", 0.0);
  const double threaded2 = two.phases.value("threaded", 0.0), serial2 = total2 - threaded2;
  const double budget = total1 / 1.8 - serial2;
  std::printf("two cores: %.1f s of the engine's %.1f s on one thread (the moves made in order "
              "with their shrink and refill, insertions, Steiner points, growing: each changes "
              "what the next reads), %.1f s on both (the moves' plans and the ray batches; on "
              "one core the batches alone took %.1f s and the moves ran CGAL's removal and "
              "insertion); 1.8x needs the threaded parts in %.1f s\n",
              serial2, total2, threaded2, threaded1, budget);
  const double rest1 = total1 - serial2;
  auto bound = [&](double ratio) { return total1 / (serial2 + rest1 / ratio); };
  const double reached = total2 > 0.0 ? total1 / total2 : 0.0;
  const double threaded_x = threaded2 > 0.0 ? rest1 / threaded2 : 0.0;
  const double machine = limits->value("pair_throughput", 0.0);
  std::printf("Amdahl: with %.1f s on one thread, two cores reach at most %.2fx if the other %.1f "
              "s of the one-core run halve", serial2, bound(2.0), rest1);
  // Two cores cannot give more than 2x: a larger ratio means the one-core run alone was slowed
  // by other work on the host, and the run's ratios are not to be trusted.
  if (machine > 2.0)
    std::printf(" (the machine's %.2fx for two independent runs is above 2: the one-core run "
                "was slowed, compare other rounds)", machine);
  else if (machine > 0.0)
    std::printf(", %.2fx at this machine's %.2fx for two independent runs", bound(machine),
                machine);
  // The one-thread seconds 1.8x leaves: S + (T1 - S) / c <= T1 / 1.8, solved for S.
  const bool at_machine = machine > 1.0 && machine <= 2.0;
  const double c = at_machine ? machine : 2.0;
  const double allowed = std::max(0.0, (total1 / 1.8 - total1 / c) / (1.0 - 1.0 / c));
  std::printf("; reached %.2fx, the threaded parts %.2fx faster than the same work on one core "
              "(%.1f -> %.1f s); 1.8x %s allows %.1f s on one thread\n",
              reached, threaded_x, rest1, threaded2,
              at_machine ? "at this machine's ratio" : "on two perfect cores", allowed);
  (*limits)["serial_two_cores_s"] = serial2;
  (*limits)["threaded_s"] = {threaded1, threaded2};
  (*limits)["two_core_bound_serial"] = serial2 > 0.0 ? total1 / serial2 : 0.0;
  (*limits)["two_core_bound_perfect"] = bound(2.0);
  if (at_machine) (*limits)["two_core_bound_machine"] = bound(machine);
  (*limits)["threaded_speedup"] = threaded_x;
  (*limits)["threaded_budget_for_target_s"] = budget;
}

// Phase by phase: which parts the second core speeds up.
void PhaseLimits(const SpeedRow& one, const SpeedRow& two, json* limits) {
  const char* keys[3] = {"cast", "move", "shrink"};
  double one_s[4], two_s[4];
  for (int i = 0; i < 3; ++i) {
    one_s[i] = one.phases.value(keys[i], 0.0);
    two_s[i] = two.phases.value(keys[i], 0.0);
  }
  one_s[3] = one.engine - one_s[0] - one_s[1] - one_s[2];
  two_s[3] = two.engine - two_s[0] - two_s[1] - two_s[2];
  auto x = [](double a, double b) { return b > 0.0 ? a / b : 0.0; };
  std::printf("phase by phase, one core -> two cores: cast (the un-cast and cast batches) "
              "%.2f -> %.2f s (%.2fx); moves without their shrink %.2f -> %.2f s (%.2fx: on two "
              "cores planned on both threads, committed in order on one); shrink %.2f -> %.2f s "
              "(%.2fx); the rest (insertions, Steiner points, growing) %.2f -> %.2f s (%.2fx)\n",
              one_s[0], two_s[0], x(one_s[0], two_s[0]), one_s[1], two_s[1],
              x(one_s[1], two_s[1]), one_s[2], two_s[2], x(one_s[2], two_s[2]), one_s[3],
              two_s[3], x(one_s[3], two_s[3]));
  json by_phase = json::object();
  const char* names[4] = {"cast", "move", "shrink", "rest"};
  for (int i = 0; i < 4; ++i) by_phase[names[i]] = {one_s[i], two_s[i]};
  (*limits)["phase_s_one_two_cores"] = by_phase;
}

}  // namespace

int RunSpeedBench(int argc, char** argv) {
  SpeedArgs a;
  if (int status = 0; !ParseSpeedArgs(argc, argv, &a, &status)) return status;
  SpeedInput in;
  in.stream = SharedDir(a.shared) / "data/street-stream/slam.json";
  in.views_per_keyframe = a.views_per_keyframe;
  std::printf("imr-bench speed: %s; load average at start %s\n", MachineLine().c_str(),
              LoadAverage().c_str());
  if (!fs::exists(in.stream)) {
    std::printf("skipped: %s not found\n", in.stream.c_str());
    return 0;
  }
  const json views = json::parse(std::ifstream(in.stream), nullptr, false);
  in.views = views.is_object() && views.contains("views") ? views["views"].size() : 0;
  const WorkFolder work(a.work, "speed");
  in.work = work.path();

  std::vector<SpeedRow> rows;
  const std::vector<Run> runs = PlanRuns(a, &rows);
  for (const Run& run : runs) KeepFastest(RunOnce(in, run, rows[run.row].label), &rows[run.row]);

  const json out_rows = PrintRows(in, rows);
  if (a.rounds > 1) PrintRounds(rows);
  int meshes = 0;
  const bool same = SameMeshes(in, rows, runs, &meshes);
  PrintTargets(a, rows, same, meshes);
  json limits = json::object();
  PairLimits(in, rows, &limits);
  if (rows[0].ok && rows[1].ok) {
    AmdahlLimits(rows[0], rows[1], &limits);
    PhaseLimits(rows[0], rows[1], &limits);
  }
  std::printf("load average at end %s\n", LoadAverage().c_str());
  work.Finish();
  const double one = rows[0].ok ? rows[0].fps : 0.0, two = rows[1].ok ? rows[1].fps : 0.0;
  const json result = {{"bench", "speed"},
                       {"machine", MachineLine()},
                       {"views", in.views},
                       {"views_per_keyframe", a.views_per_keyframe},
                       {"rounds", a.rounds},
                       {"rows", out_rows},
                       {"one_core_fps", one},
                       {"same_mesh_one_and_two_cores", same},
                       {"two_core_speedup", one > 0.0 ? two / one : 0.0},
                       {"limits", limits}};
  std::printf("%s\n", result.dump().c_str());
  return 0;
}

}  // namespace imr::bench
