// imr-bench scaling: does a keyframe cost the same at frame 2000 as at frame 50 (the paper's cost model: the
// efficient policy's keyframe cost must not grow with F)? The synthetic street of 250 / 500 /
// 1000 / 2000 frames (points moving), each length in its own process so that peak RSS is its
// own: per-keyframe time (median, p90) against frame index, total time, peak RSS, heap bytes
// per triangulation vertex, and the fitted exponent b of total time ~ frames^b (target <= 1.1).
// Prints a Markdown table, writes scaling.json and scaling.png (tools/bench/scaling_plot.py) and
// ends with one JSON line.
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <ctime>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "host/engine/engine.h"
#include "host/engine/testing/run_stream.h"
#include "tools/bench/common/bench_util.h"
#include "tools/bench/common/engine_modes.h"
#include "tools/bench/common/frame.h"

namespace imr::bench {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

struct ScalingArgs {
  std::vector<int> frames = {250, 500, 1000, 2000};
  std::vector<std::string> modes = {"nearest"};
  int points = 150;
  double noise = 0.1;
  uint64_t seed = 1;
  std::string out = "scaling-figures";
};

double ThreadCpuSeconds() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

// One run, in a child process: the figures as JSON.
json RunOne(const std::string& mode, int frames, const ScalingArgs& a) {
  synthetic::StreamOptions so;
  so.scene = synthetic::SceneKind::kStreet;
  so.frames = frames;
  so.points_per_keyframe = a.points;
  so.noise_at_10m = a.noise;
  so.seed = a.seed;
  synthetic::SyntheticStream stream(so);
  engine::EngineOptions eo;
  eo.forget = engine::ForgetMode::kOff;  // memory and time of the whole scene (forgetting: drive)
  std::unique_ptr<engine::WeightTransferPolicy> policy;
  engine::testing::ConfigureMode(mode, &eo, &policy);
  const long heap0 = HeapInUseBytes();
  const long rss0 = PeakRssKb();
  engine::Engine eng(eo, policy.get());
  std::vector<int> kf_frame;
  int64_t observations = 0;
  // The stream's keyframes one by one; engine CPU time (this thread) beside its wall time, so
  // that figures taken while other processes share the cores can be compared.
  double cpu = 0.0;
  engine::Status s;
  synthetic::StreamKeyframe kf;
  while (stream.Next(&kf)) {
    const engine::KeyframeUpdate u = engine::testing::ToUpdate(kf);
    const double c0 = ThreadCpuSeconds();
    s = eng.ApplyUpdate(u);
    cpu += ThreadCpuSeconds() - c0;
    if (!s.ok()) break;
    kf_frame.push_back(kf.frame);
    for (const auto& p : kf.new_points) observations += static_cast<int64_t>(p.camera_ids.size());
    for (const auto& p : kf.moved_points) observations += static_cast<int64_t>(p.camera_ids.size());
    if (kf.index % 100 == 0)
      std::fprintf(stderr, "[scaling %s %d] keyframe %d: %.3f s\n", mode.c_str(), frames, kf.index,
                   eng.Stats().keyframe_seconds.back());
  }
  const engine::EngineStats& st = eng.Stats();
  const long heap = HeapInUseBytes() - heap0;
  const auto& k = st.keyframe_seconds;
  const size_t n = k.size(), fifth = std::max<size_t>(1, n / 5);
  double total = 0.0;
  for (double t : k) total += t;
  json j = {{"mode", mode},
            {"frames", frames},
            {"ok", s.ok()},
            {"error", s.message()},
            {"keyframes", n},
            {"keyframe_s_median", Median(k)},
            {"keyframe_s_p90", Quantile(k, 0.9)},
            {"keyframe_s_max", k.empty() ? 0.0 : *std::max_element(k.begin(), k.end())},
            {"total_s", total},
            {"engine_cpu_s", cpu},
            {"frames_per_second", total > 0 ? frames / total : 0.0},
            {"observations_per_frame", static_cast<double>(observations) / frames},
            {"peak_rss_mb", PeakRssKb() / 1024.0},
            {"rss_at_start_mb", rss0 / 1024.0},
            {"heap_mb", heap / 1048576.0},
            {"vertices", st.vertices},
            {"cells", st.cells},
            {"bytes_per_vertex", st.vertices > 0 ? static_cast<double>(heap) / st.vertices : 0.0},
            {"points_moved", st.points_moved},
            {"keyframe_frame", kf_frame},
            {"keyframe_s", k}};
  if (n >= 5) {
    const double early = Median(std::vector<double>(k.begin(), k.begin() + fifth));
    const double late = Median(std::vector<double>(k.end() - fifth, k.end()));
    j["late_vs_early_keyframe_time"] = early > 0 ? late / early : 0.0;
  }
  return j;
}

// Runs RunOne in a fresh process (fork) and reads its JSON back through a pipe.
json RunInChild(const std::string& mode, int frames, const ScalingArgs& a) {
  int fd[2];
  if (pipe(fd) != 0) return {{"ok", false}, {"error", "pipe failed"}};
  std::fflush(stdout);
  std::fflush(stderr);
  const pid_t pid = fork();
  if (pid == 0) {
    close(fd[0]);
    std::string out;
    try {
      out = RunOne(mode, frames, a).dump();
    } catch (const std::exception& e) {
      out = json{{"ok", false}, {"error", e.what()}}.dump();
    }
    size_t off = 0;
    while (off < out.size()) {
      const ssize_t w = write(fd[1], out.data() + off, out.size() - off);
      if (w <= 0) break;
      off += static_cast<size_t>(w);
    }
    close(fd[1]);
    _exit(0);
  }
  close(fd[1]);
  std::string buf;
  char tmp[65536];
  ssize_t r;
  while ((r = read(fd[0], tmp, sizeof tmp)) > 0) buf.append(tmp, static_cast<size_t>(r));
  close(fd[0]);
  int status = 0;
  waitpid(pid, &status, 0);
  try {
    return json::parse(buf);
  } catch (...) {
    return {{"ok", false}, {"error", "child failed (status " + std::to_string(status) + ")"},
            {"mode", mode}, {"frames", frames}};
  }
}

// Least squares of log(y) on log(x): the exponent b of y ~ x^b.
double FitExponent(const std::vector<double>& x, const std::vector<double>& y) {
  const size_t n = x.size();
  if (n < 2) return 0.0;
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  for (size_t i = 0; i < n; ++i) {
    const double lx = std::log(x[i]), ly = std::log(y[i]);
    sx += lx;
    sy += ly;
    sxx += lx * lx;
    sxy += lx * ly;
  }
  const double d = n * sxx - sx * sx;
  return d != 0 ? (n * sxy - sx * sy) / d : 0.0;
}

bool ParseScalingArgs(int argc, char** argv, ScalingArgs* a, int* status) {
  Options o("imr-bench scaling",
            "usage: imr-bench scaling [--frames 250,500,1000,2000] [--modes nearest,...]\n"
            "         [--points P] [--noise S] [--seed S] [--out DIR] [--quick]\n");
  o.IntList("--frames", &a->frames, 10);
  o.List("--modes", &a->modes).Int("--points", &a->points).Double("--noise", &a->noise);
  o.Uint64("--seed", &a->seed).String("--out", &a->out);
  o.Action("--quick", [a] { a->frames = {100, 200, 400}; });
  if (!o.Parse(argc, argv, status)) return false;
  *status = 2;  // when a mode is unknown
  return KnownModes(a->modes, "scaling");
}

// Every mode at every length, a row each (a child process per run); the growth exponent of total
// time in frames per mode. False when a run failed.
bool RunAll(const ScalingArgs& a, json* runs, json* exponents) {
  std::printf("\n");
  MarkdownHeader({"mode", "frames", "obs/frame", "keyframe median / p90 / max (ms)", "late/early",
                  "total wall / CPU (s)", "frames/s", "peak RSS (MB)", "bytes/vertex", "vertices"});
  bool ok = true;
  for (const std::string& mode : a.modes) {
    std::vector<double> xs, ys;
    for (int f : a.frames) {
      json r = RunInChild(mode, f, a);
      runs->push_back(r);
      if (!r.value("ok", false)) {
        ok = false;
        std::printf("| %s | %d | failed: %s | | | | | | | |\n", mode.c_str(), f,
                    r.value("error", std::string("?")).c_str());
        continue;
      }
      xs.push_back(f);
      ys.push_back(r["total_s"].get<double>());
      std::printf("| %s | %d | %.0f | %.1f / %.1f / %.1f | %.2f | %.2f / %.2f | %.1f | %.1f | %.0f "
                  "| %lld |\n",
                  mode.c_str(), f, r["observations_per_frame"].get<double>(),
                  1e3 * r["keyframe_s_median"].get<double>(),
                  1e3 * r["keyframe_s_p90"].get<double>(), 1e3 * r["keyframe_s_max"].get<double>(),
                  r.value("late_vs_early_keyframe_time", 0.0), r["total_s"].get<double>(),
                  r["engine_cpu_s"].get<double>(), r["frames_per_second"].get<double>(), r["peak_rss_mb"].get<double>(),
                  r["bytes_per_vertex"].get<double>(),
                  static_cast<long long>(r["vertices"].get<int64_t>()));
      std::fflush(stdout);
    }
    (*exponents)[mode] = FitExponent(xs, ys);
  }
  return ok;
}

// The figure from the data file, when python3 with matplotlib is there.
void Figure(const ScalingArgs& a, const json& result) {
  fs::create_directories(a.out);
  const fs::path data = fs::path(a.out) / "scaling.json";
  std::ofstream(data) << result.dump() << "\n";
  const fs::path script = fs::path(__FILE__).parent_path() / "scaling_plot.py";
  const std::string py = FindPython();
  if (!py.empty() && fs::exists(script) &&
      std::system((py + " '" + script.string() + "' '" + data.string() + "' '" + a.out + "'")
                      .c_str()) == 0)
    std::printf("figure: %s (data: %s)\n", (fs::path(a.out) / "scaling.png").c_str(),
                data.c_str());
  else
    std::printf("figure: skipped (no python3 with matplotlib, or the script failed)\n");
}

}  // namespace

int RunScalingBench(int argc, char** argv) {
  ScalingArgs a;
  if (int status = 0; !ParseScalingArgs(argc, argv, &a, &status)) return status;
  const std::string load_start = LoadAverage();
  std::printf("imr-bench scaling: synthetic street, %d new points per keyframe, noise %.2f m at "
              "10 m, points moving; %s; load average at start %s\n",
              a.points, a.noise, MachineLine().c_str(), load_start.c_str());
  json runs = json::array();
  json exponents = json::object();
  const bool ok = RunAll(a, &runs, &exponents);
  std::printf("\n");
  for (const auto& [mode, b] : exponents.items())
    std::printf("growth exponent of total time in frames (%s): %.3f (target <= 1.1)\n",
                mode.c_str(), b.get<double>());
  const std::string load_end = LoadAverage();
  json result = {{"bench", "scaling"},
                 {"machine", MachineLine()},
                 {"load_average_start", load_start},
                 {"load_average_end", load_end},
                 {"points_per_keyframe", a.points},
                 {"noise_at_10m", a.noise},
                 {"seed", a.seed},
                 {"growth_exponent", exponents},
                 {"runs", runs}};
  Figure(a, result);
  std::printf("load average at end %s\n", load_end.c_str());
  // Last line: the summary without the per-keyframe series (those are in scaling.json).
  for (auto& r : result["runs"]) {
    r.erase("keyframe_frame");
    r.erase("keyframe_s");
  }
  std::printf("%s\n", result.dump().c_str());
  return ok ? 0 : 1;
}

}  // namespace imr::bench
