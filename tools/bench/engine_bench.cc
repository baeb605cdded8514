// imr-bench engine: the reconstruction engine on the synthetic street stream, in every visibility
// mode, with and without moving points (DESIGN §4: per-move overhead = (T_mov - T_nonmov) / N_mov).
// Prints a table, then one JSON object as the last line.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <sstream>
#include <string>
#include <vector>

#include <malloc.h>
#include <sys/resource.h>

#include "host/engine/engine.h"
#include "host/engine/testing/run_stream.h"

namespace imr::bench {
namespace {

using engine::Engine;
using engine::EngineOptions;
using engine::EngineStats;

double Quantile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const double pos = q * (v.size() - 1);
  const size_t i = static_cast<size_t>(pos);
  const double f = pos - i;
  return i + 1 < v.size() ? v[i] * (1 - f) + v[i + 1] * f : v[i];
}

double Median(std::vector<double> v) { return Quantile(std::move(v), 0.5); }

// Bytes allocated and in use on the heap (glibc), independent of memory kept by the allocator.
long HeapInUseBytes() { return static_cast<long>(mallinfo2().uordblks); }

long PeakRssKb() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_maxrss;
}

struct RunResult {
  std::string mode;
  bool frozen = false;
  bool ok = true;
  std::string error;
  EngineStats stats;
  double total = 0.0;
  double late_vs_early = 0.0;
  long heap_bytes = 0;  // Heap in use by the engine (and the stream) at the end of the run.
  synthetic::MeshAccuracy accuracy;
  synthetic::MeshAccuracy accuracy_real;  // Only triangles of real points.
};

EngineOptions g_base_options;

RunResult Run(const std::string& mode, bool frozen, const synthetic::StreamOptions& base,
              bool evaluate) {
  RunResult r;
  r.mode = mode;
  r.frozen = frozen;
  synthetic::StreamOptions so = base;
  so.frozen = frozen;
  synthetic::SyntheticStream stream(so);
  EngineOptions eo = g_base_options;
  std::unique_ptr<engine::WeightTransferPolicy> policy;
  engine::testing::ConfigureMode(mode, &eo, &policy);
  const long heap0 = HeapInUseBytes();
  Engine eng(eo, policy.get());
  const int total_kf = stream.keyframe_count();
  int done = 0;
  const engine::Status s = engine::testing::RunStream(
      &stream, &eng, [&](const synthetic::StreamKeyframe& kf) {
        ++done;
        if (kf.index % 50 == 0)
          std::fprintf(stderr, "[%s%s %d/%d] %.3f s\n", mode.c_str(), frozen ? " frozen" : "",
                       done, total_kf, eng.Stats().keyframe_seconds.back());
        return true;
      });
  r.ok = s.ok();
  r.error = s.message();
  r.heap_bytes = HeapInUseBytes() - heap0;
  r.stats = eng.Stats();
  for (double t : r.stats.keyframe_seconds) r.total += t;
  const auto& k = r.stats.keyframe_seconds;
  const size_t n = k.size(), fifth = std::max<size_t>(1, n / 5);
  if (n >= 5) {
    const double early = Median(std::vector<double>(k.begin(), k.begin() + fifth));
    const double late = Median(std::vector<double>(k.end() - fifth, k.end()));
    r.late_vs_early = early > 0 ? late / early : 0.0;
  }
  if (evaluate) {
    const engine::Mesh m = eng.ExtractMesh();
    r.accuracy = engine::testing::Accuracy(stream, m, 0.25);
    engine::Mesh real = eng.ExtractBoundary();
    std::vector<uint32_t> faces;
    for (size_t t = 0; t < real.faces.size(); t += 3) {
      bool steiner = false;
      for (int j = 0; j < 3; ++j) steiner = steiner || real.point_ids[real.faces[t + j]] < 0;
      if (!steiner) faces.insert(faces.end(), real.faces.begin() + t, real.faces.begin() + t + 3);
    }
    real.faces = faces;
    r.accuracy_real = engine::testing::Accuracy(stream, real, 0.25);
  }
  return r;
}

std::string Num(double v) {
  char b[64];
  std::snprintf(b, sizeof b, "%.6g", v);
  return b;
}

}  // namespace

int RunEngineBench(int argc, char** argv) {
  synthetic::StreamOptions so;
  so.scene = synthetic::SceneKind::kStreet;
  so.frames = 1000;
  so.points_per_keyframe = 150;
  so.noise_at_10m = 0.1;
  std::vector<std::string> modes = {"nearest", "mean", "weighted_mean", "rays5", "rays1"};
  for (int i = 0; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> const char* {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "imr-bench engine: %s needs a value\n", a.c_str());
        std::exit(2);
      }
      return argv[++i];
    };
    if (a == "--frames") so.frames = std::atoi(next());
    else if (a == "--seed") so.seed = std::strtoull(next(), nullptr, 10);
    else if (a == "--points") so.points_per_keyframe = std::atoi(next());
    else if (a == "--quick") so.frames = 200;
    else if (a == "--shrink-radius") g_base_options.shrink_radius = std::atof(next());
    else if (a == "--window") g_base_options.window = std::atoi(next());
    else if (a == "--transfer-on-insert") g_base_options.transfer_on_insert = true;
    else if (a == "--modes") {
      modes.clear();
      std::stringstream ss(next());
      std::string m;
      while (std::getline(ss, m, ',')) modes.push_back(m);
    } else {
      std::fprintf(stderr,
                   "usage: imr-bench engine [--frames N] [--seed S] [--quick] [--points P] "
                   "[--modes nearest,mean,weighted_mean,rays5,rays1] [--shrink-radius R] [--window W] "
                   "[--transfer-on-insert]\n");
      return 2;
    }
  }
  std::string option_error;
  if (!g_base_options.Check(&option_error)) {
    std::fprintf(stderr, "imr-bench engine: %s\n", option_error.c_str());
    return 2;
  }
  if (so.frames < 10 || so.points_per_keyframe < 1) {
    std::fprintf(stderr, "imr-bench engine: --frames must be >= 10 and --points >= 1\n");
    return 2;
  }
  for (const auto& m : modes) {
    EngineOptions eo;
    std::unique_ptr<engine::WeightTransferPolicy> p;
    if (!engine::testing::ConfigureMode(m, &eo, &p)) {
      std::fprintf(stderr, "imr-bench engine: unknown mode '%s'\n", m.c_str());
      return 2;
    }
  }
  std::printf("imr-bench engine: street stream, %d frames (%d keyframes), %d new points per "
              "keyframe, seed %llu\n",
              so.frames, so.frames / so.keyframe_every, so.points_per_keyframe,
              static_cast<unsigned long long>(so.seed));
  std::vector<RunResult> moving, frozen;
  for (const auto& m : modes) {
    frozen.push_back(Run(m, true, so, false));
    moving.push_back(Run(m, false, so, true));
  }
  std::printf("\n%-14s %9s %9s %9s %9s %9s %8s %9s %10s %8s %8s %8s %8s %8s\n", "mode", "kf_med_ms",
              "kf_p90_ms", "kf_max_ms", "T_mov_s", "T_nonmov", "N_mov", "move_us", "late/early",
              "dropped", "cells/ray", "acc_m", "acc_real", "compl");
  for (size_t i = 0; i < moving.size(); ++i) {
    const RunResult& r = moving[i];
    const RunResult& f = frozen[i];
    const auto& k = r.stats.keyframe_seconds;
    const double nmov = static_cast<double>(std::max<int64_t>(1, r.stats.points_moved));
    const double rays = static_cast<double>(
        std::max<int64_t>(1, r.stats.rays_cast + r.stats.rays_cast_backward));
    std::printf("%-14s %9.2f %9.2f %9.2f %9.2f %9.2f %8lld %9.1f %10.2f %8lld %8.1f %8.3f %8.3f %8.2f%s\n",
                r.mode.c_str(), 1e3 * Median(k), 1e3 * Quantile(k, 0.9),
                1e3 * (k.empty() ? 0.0 : *std::max_element(k.begin(), k.end())), r.total, f.total,
                static_cast<long long>(r.stats.points_moved), 1e6 * (r.total - f.total) / nmov,
                r.late_vs_early, static_cast<long long>(r.stats.points_dropped),
                r.stats.cells_traversed / rays, r.accuracy.mean_mesh_to_scene,
                r.accuracy_real.mean_mesh_to_scene, r.accuracy_real.completeness,
                r.ok && f.ok ? "" : "  ERROR");
    if (!r.ok) std::printf("  error: %s\n", r.error.c_str());
    if (!f.ok) std::printf("  error (frozen): %s\n", f.error.c_str());
  }
  // Phase breakdown and cost per traversed cell.
  std::printf("\n%-14s %8s %8s %8s %8s %8s %8s %8s %8s %10s %11s\n", "mode", "steiner",
              "shrink", "move", "insert", "cast", "scan", "grow", "total", "rays", "ns/cell");
  for (const RunResult& r : moving) {
    const auto& t = r.stats.time;
    const double cells = static_cast<double>(std::max<int64_t>(1, r.stats.cells_weighted));
    std::printf("%-14s %8.2f %8.2f %8.2f %8.2f %8.2f %8.2f %8.2f %8.2f %10lld %11.1f\n",
                r.mode.c_str(), t.steiner, t.shrink, t.move, t.insert, t.cast, t.scan, t.grow,
                t.total,
                static_cast<long long>(r.stats.rays_cast + r.stats.rays_cast_backward),
                1e9 * t.cast / cells);
  }
  auto find = [&](const std::string& m) -> const RunResult* {
    for (const auto& r : moving)
      if (r.mode == m) return &r;
    return nullptr;
  };
  auto overhead = [&](const std::string& m) -> double {
    for (size_t i = 0; i < moving.size(); ++i)
      if (moving[i].mode == m)
        return (moving[i].total - frozen[i].total) /
               static_cast<double>(std::max<int64_t>(1, moving[i].stats.points_moved));
    return 0.0;
  };
  const RunResult* nearest = find("nearest");
  const double ratio = find("rays5") && nearest && overhead("nearest") > 0
                           ? overhead("rays5") / overhead("nearest")
                           : 0.0;
  const long peak = PeakRssKb();
  const double bytes_per_vertex =
      nearest && nearest->stats.vertices > 0
          ? static_cast<double>(nearest->heap_bytes) /
                static_cast<double>(nearest->stats.vertices)
          : 0.0;
  std::printf("\noverhead_ratio_rays5_vs_nearest %.2f (target >= 10)\n", ratio);
  if (nearest)
    std::printf("late_vs_early_keyframe_time (nearest) %.2f (target <= 1.5)\n",
                nearest->late_vs_early);
  std::printf("peak RSS %.1f MB; %.0f heap bytes per triangulation vertex (nearest: %lld "
              "vertices)\n",
              peak / 1024.0, bytes_per_vertex,
              static_cast<long long>(nearest ? nearest->stats.vertices : 0));
  // The JSON object, last line.
  std::ostringstream j;
  j << "{\"bench\":\"engine\",\"scene\":\"street\",\"frames\":" << so.frames
    << ",\"seed\":" << so.seed << ",\"points_per_keyframe\":" << so.points_per_keyframe
    << ",\"modes\":{";
  for (size_t i = 0; i < moving.size(); ++i) {
    const RunResult& r = moving[i];
    const auto& k = r.stats.keyframe_seconds;
    if (i) j << ",";
    j << "\"" << r.mode << "\":{\"ok\":" << (r.ok && frozen[i].ok ? "true" : "false")
      << ",\"keyframe_s_median\":" << Num(Median(k)) << ",\"keyframe_s_p90\":"
      << Num(Quantile(k, 0.9))
      << ",\"keyframe_s_max\":" << Num(k.empty() ? 0.0 : *std::max_element(k.begin(), k.end()))
      << ",\"t_mov_s\":" << Num(r.total) << ",\"t_nonmov_s\":" << Num(frozen[i].total)
      << ",\"n_mov\":" << r.stats.points_moved << ",\"per_move_overhead_s\":"
      << Num(overhead(r.mode)) << ",\"late_vs_early_keyframe_time\":" << Num(r.late_vs_early)
      << ",\"points_inserted\":" << r.stats.points_inserted
      << ",\"points_dropped\":" << r.stats.points_dropped
      << ",\"moves_skipped\":" << r.stats.moves_skipped << ",\"rays_cast\":"
      << r.stats.rays_cast + r.stats.rays_cast_backward
      << ",\"cells_traversed\":" << r.stats.cells_traversed
      << ",\"cast_ns_per_weighted_cell\":"
      << Num(1e9 * r.stats.time.cast /
             static_cast<double>(std::max<int64_t>(1, r.stats.cells_weighted)))
      << ",\"vertices\":" << r.stats.vertices
      << ",\"accuracy_mean_m\":" << Num(r.accuracy.mean_mesh_to_scene)
      << ",\"accuracy_real_mean_m\":" << Num(r.accuracy_real.mean_mesh_to_scene)
      << ",\"completeness_real\":" << Num(r.accuracy_real.completeness)
      << ",\"truth_to_mesh_mean_m\":" << Num(r.accuracy.mean_truth_to_mesh) << "}";
  }
  j << "},\"overhead_ratio_rays5_vs_nearest\":" << Num(ratio)
    << ",\"late_vs_early_keyframe_time\":" << Num(nearest ? nearest->late_vs_early : 0.0)
    << ",\"peak_rss_mb\":" << Num(peak / 1024.0)
    << ",\"bytes_per_vertex\":" << Num(bytes_per_vertex) << "}";
  std::printf("%s\n", j.str().c_str());
  bool all_ok = true;
  for (size_t i = 0; i < moving.size(); ++i) all_ok = all_ok && moving[i].ok && frozen[i].ok;
  return all_ok ? 0 : 1;
}

}  // namespace imr::bench
