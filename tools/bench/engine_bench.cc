// imr-bench engine: the reconstruction engine on the synthetic street stream, in every visibility
// mode, with and without moving points (the paper's cost model: per-move overhead = (T_mov - T_nonmov) / N_mov).
// Accuracy both ways on the mesh of real-point triangles: the mean distance of its triangles to
// the true scene (acc_real), and the paper's figure, the mean distance from ground truth (points
// sampled on the surfaces the cameras saw, independently of the stream) to it (gt2m_real). Then
// the real-time check: the dense street stream (about 1,250 observations per frame, every
// point moving at each keyframe while it is tracked), nearest, in engine frames per second
// (target >= 10). Prints tables, then one JSON object as the last line.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <sstream>
#include <string>
#include <vector>

#include <malloc.h>
#include <sys/resource.h>

#include "host/engine/engine.h"
#include "host/engine/testing/run_stream.h"
#include "tools/bench/common/bench_util.h"
#include "tools/bench/common/engine_modes.h"
#include "tools/bench/common/frame.h"

namespace imr::bench {
namespace {

using engine::Engine;
using engine::EngineOptions;
using engine::EngineStats;

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
  SceneAccuracy truth_real;               // Ground truth -> the real-point mesh (paper's figure).
  double observations_per_frame = 0.0;
};

// The paper's engine, measured on the whole scene (forgetting has its own bench: drive).
EngineOptions g_base_options = [] {
  EngineOptions o;
  o.forget = engine::ForgetMode::kOff;
  return o;
}();

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
  int64_t observations = 0;
  const engine::Status s = engine::testing::RunStream(
      &stream, &eng, [&](const synthetic::StreamKeyframe& kf) {
        ++done;
        for (const auto& p : kf.new_points) observations += static_cast<int64_t>(p.camera_ids.size());
        for (const auto& p : kf.moved_points) observations += static_cast<int64_t>(p.camera_ids.size());
        if (kf.index % 50 == 0)
          std::fprintf(stderr, "[%s%s %d/%d] %.3f s\n", mode.c_str(), frozen ? " frozen" : "",
                       done, total_kf, eng.Stats().keyframe_seconds.back());
        return true;
      });
  r.ok = s.ok();
  r.error = s.message();
  r.observations_per_frame = static_cast<double>(observations) / std::max(1, so.frames);
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
    r.truth_real = EvaluateAgainstScene(
        stream.scene(), real.vertices, real.faces,
        SampleSeenSurfaces(stream, so.frames, 1, 200, so.seed + 1000), 0.25, 0);
  }
  return r;
}


struct EngineArgs {
  synthetic::StreamOptions so;
  std::vector<std::string> modes = {"exact", "nearest", "mean", "weighted_mean", "rays5", "rays1"};
  int dense_frames = -1;  // -1: as many as --frames; 0: no real-time check.
  bool dense_only = false;
};

bool ParseEngineArgs(int argc, char** argv, EngineArgs* a, int* status) {
  a->so.scene = synthetic::SceneKind::kStreet;
  a->so.frames = 1000;
  a->so.points_per_keyframe = 150;
  a->so.noise_at_10m = 0.1;
  Options o("imr-bench engine",
            "usage: imr-bench engine [--frames N] [--seed S] [--quick] [--points P]\n"
            "         [--modes exact,nearest,mean,weighted_mean,rays5,rays1] [--shrink-radius R]\n"
            "         [--window W] [--steiner-jitter J] [--transfer-on-insert]\n"
            "         [--no-camera-side] [--negative-weights]   (the engine before issue 8)\n"
            "         [--dense-frames N (0: none)] [--dense-only]\n");
  o.Int("--frames", &a->so.frames).Uint64("--seed", &a->so.seed);
  o.Int("--points", &a->so.points_per_keyframe).Action("--quick", [a] { a->so.frames = 200; });
  o.Double("--shrink-radius", &g_base_options.shrink_radius).Int("--window", &g_base_options.window);
  o.Double("--steiner-jitter", &g_base_options.steiner_jitter);
  o.Flag("--transfer-on-insert", &g_base_options.transfer_on_insert);
  o.Flag("--no-camera-side", &g_base_options.transfer_camera_side, false);
  o.Flag("--negative-weights", &g_base_options.nonnegative_weights, false);
  o.Int("--dense-frames", &a->dense_frames).Flag("--dense-only", &a->dense_only);
  o.List("--modes", &a->modes);
  if (!o.Parse(argc, argv, status)) return false;
  *status = 2;
  if (const std::string option_error = g_base_options.Check(); !option_error.empty()) {
    std::fprintf(stderr, "imr-bench engine: %s\n", option_error.c_str());
    return false;
  }
  if (a->so.frames < 10 || a->so.points_per_keyframe < 1) {
    std::fprintf(stderr, "imr-bench engine: --frames must be >= 10 and --points >= 1\n");
    return false;
  }
  if (!KnownModes(a->modes, "engine")) return false;
  if (a->dense_frames < 0) a->dense_frames = a->so.frames;
  if (a->dense_only) a->modes.clear();
  *status = 0;
  return true;
}

double MaxOf(const std::vector<double>& k) {
  return k.empty() ? 0.0 : *std::max_element(k.begin(), k.end());
}

// Per-move overhead (T_mov - T_nonmov) / N_mov of a mode; 0 when it did not run.
double Overhead(const std::vector<RunResult>& moving, const std::vector<RunResult>& frozen,
                const std::string& m) {
  for (size_t i = 0; i < moving.size(); ++i)
    if (moving[i].mode == m)
      return (moving[i].total - frozen[i].total) /
             static_cast<double>(std::max<int64_t>(1, moving[i].stats.points_moved));
  return 0.0;
}

const RunResult* Find(const std::vector<RunResult>& moving, const std::string& m) {
  for (const auto& r : moving)
    if (r.mode == m) return &r;
  return nullptr;
}

void PrintModes(const std::vector<RunResult>& moving, const std::vector<RunResult>& frozen) {
  if (!moving.empty())
    std::printf("\n%-14s %9s %9s %9s %9s %9s %8s %9s %10s %8s %8s %8s %8s %9s %8s\n", "mode",
                "kf_med_ms", "kf_p90_ms", "kf_max_ms", "T_mov_s", "T_nonmov", "N_mov", "move_us",
                "late/early", "dropped", "cells/ray", "acc_m", "acc_real", "gt2m_real", "compl");
  for (size_t i = 0; i < moving.size(); ++i) {
    const RunResult& r = moving[i];
    const RunResult& f = frozen[i];
    const auto& k = r.stats.keyframe_seconds;
    const double nmov = static_cast<double>(std::max<int64_t>(1, r.stats.points_moved));
    const double rays = static_cast<double>(
        std::max<int64_t>(1, r.stats.rays_cast + r.stats.rays_cast_backward));
    std::printf("%-14s %9.2f %9.2f %9.2f %9.2f %9.2f %8lld %9.1f %10.2f %8lld %8.1f %8.3f %8.3f "
                "%9.3f %8.2f%s\n",
                r.mode.c_str(), 1e3 * Median(k), 1e3 * Quantile(k, 0.9), 1e3 * MaxOf(k), r.total,
                f.total, static_cast<long long>(r.stats.points_moved),
                1e6 * (r.total - f.total) / nmov, r.late_vs_early,
                static_cast<long long>(r.stats.points_dropped), r.stats.cells_traversed / rays,
                r.accuracy.mean_mesh_to_scene, r.accuracy_real.mean_mesh_to_scene,
                r.truth_real.truth_to_mesh_mean, r.accuracy_real.completeness,
                r.ok && f.ok ? "" : "  ERROR");
    if (!r.ok) std::printf("  error: %s\n", r.error.c_str());
    if (!f.ok) std::printf("  error (frozen): %s\n", f.error.c_str());
  }
}

// Phase breakdown and cost per traversed cell.
void PrintPhases(const std::vector<RunResult>& moving) {
  if (!moving.empty())
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
}

// The paper's comparison on the modes: overhead and accuracy of nearest against rays5, memory.
struct Summary {
  double ratio = 0.0, acc_ratio = 0.0, gt2m_ratio = 0.0, bytes_per_vertex = 0.0;
  long peak = 0;
  const RunResult* nearest = nullptr;
};

Summary PrintSummary(const std::vector<RunResult>& moving, const std::vector<RunResult>& frozen) {
  Summary s;
  s.nearest = Find(moving, "nearest");
  const RunResult* nearest = s.nearest;
  const RunResult* rays5 = Find(moving, "rays5");
  s.ratio = rays5 && nearest && Overhead(moving, frozen, "nearest") > 0
                ? Overhead(moving, frozen, "rays5") / Overhead(moving, frozen, "nearest")
                : 0.0;
  s.peak = PeakRssKb();
  s.bytes_per_vertex = nearest && nearest->stats.vertices > 0
                           ? static_cast<double>(nearest->heap_bytes) /
                                 static_cast<double>(nearest->stats.vertices)
                           : 0.0;
  std::printf("\noverhead_ratio_rays5_vs_nearest %.2f (target >= 10)\n", s.ratio);
  if (nearest)
    std::printf("late_vs_early_keyframe_time (nearest) %.2f (target <= 1.5)\n",
                nearest->late_vs_early);
  if (nearest && rays5 && rays5->accuracy_real.mean_mesh_to_scene > 0 &&
      rays5->truth_real.truth_to_mesh_mean > 0) {
    s.acc_ratio =
        nearest->accuracy_real.mean_mesh_to_scene / rays5->accuracy_real.mean_mesh_to_scene;
    s.gt2m_ratio = nearest->truth_real.truth_to_mesh_mean / rays5->truth_real.truth_to_mesh_mean;
    std::printf("accuracy nearest / rays5 (target <= 1.10): ground truth -> mesh (the paper's "
                "figure) %.2f; mesh -> scene %.2f\n",
                s.gt2m_ratio, s.acc_ratio);
  }
  if (!moving.empty())
    std::printf("peak RSS %.1f MB; %.0f heap bytes per triangulation vertex (nearest: %lld "
                "vertices)\n",
                s.peak / 1024.0, s.bytes_per_vertex,
                static_cast<long long>(nearest ? nearest->stats.vertices : 0));
  return s;
}

// Real-time check: the dense stream (720 new points per keyframe: about 1,250 observations per
// frame; every point moves at each keyframe while it is tracked), engine alone: the default mode
// (exact), and nearest (the paper's; the default before issue 14) beside it.
struct Dense {
  synthetic::StreamOptions so;
  RunResult exact, nearest;
  double exact_fps = 0.0, nearest_fps = 0.0;
};

void RunDense(Dense* d) {
  for (const std::string mode : {"exact", "nearest"}) {
    RunResult& r = mode == "exact" ? d->exact : d->nearest;
    double& fps = mode == "exact" ? d->exact_fps : d->nearest_fps;
    r = Run(mode, false, d->so, false);
    fps = r.total > 0 ? d->so.frames / r.total : 0.0;
    const auto& k = r.stats.keyframe_seconds;
    std::printf("\nreal-time check: dense street stream, %d frames, %d new points per keyframe, "
                "%.0f observations per frame, %lld moves; %s\n"
                "  keyframe median / p90 / max %.1f / %.1f / %.1f ms; total %.2f s; engine "
                "%.1f frames/s (target >= 10, i.e. a keyframe in <= 0.5 s); late/early %.2f%s\n",
                d->so.frames, d->so.points_per_keyframe, r.observations_per_frame,
                static_cast<long long>(r.stats.points_moved), mode.c_str(), 1e3 * Median(k),
                1e3 * Quantile(k, 0.9), 1e3 * MaxOf(k), r.total, fps, r.late_vs_early,
                r.ok ? "" : "  ERROR");
    if (!r.ok) std::printf("  error: %s\n", r.error.c_str());
  }
  if (d->exact_fps > 0.0)
    std::printf("exact / nearest time on the dense stream: %.2fx (issue 14: at most 1.5x)\n",
                d->nearest_fps / d->exact_fps);
}

// One mode's figures in the JSON line.
void ModeJson(std::ostringstream& j, const RunResult& r, const RunResult& f, double overhead) {
  const auto& k = r.stats.keyframe_seconds;
  j << "\"" << r.mode << "\":{\"ok\":" << (r.ok && f.ok ? "true" : "false")
    << ",\"keyframe_s_median\":" << Num(Median(k)) << ",\"keyframe_s_p90\":"
    << Num(Quantile(k, 0.9)) << ",\"keyframe_s_max\":" << Num(MaxOf(k))
    << ",\"t_mov_s\":" << Num(r.total) << ",\"t_nonmov_s\":" << Num(f.total)
    << ",\"n_mov\":" << r.stats.points_moved << ",\"per_move_overhead_s\":" << Num(overhead)
    << ",\"late_vs_early_keyframe_time\":" << Num(r.late_vs_early)
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
    << ",\"ground_truth_to_real_mesh_mean_m\":" << Num(r.truth_real.truth_to_mesh_mean)
    << ",\"ground_truth_to_real_mesh_median_m\":" << Num(r.truth_real.truth_to_mesh_median)
    << ",\"truth_to_mesh_mean_m\":" << Num(r.accuracy.mean_truth_to_mesh) << "}";
}

// The JSON object, last line.
std::string EngineJson(const EngineArgs& a, const std::vector<RunResult>& moving,
                       const std::vector<RunResult>& frozen, const Summary& s, const Dense& d,
                       const std::string& load_start) {
  std::ostringstream j;
  j << "{\"bench\":\"engine\",\"scene\":\"street\",\"frames\":" << a.so.frames
    << ",\"seed\":" << a.so.seed << ",\"points_per_keyframe\":" << a.so.points_per_keyframe
    << ",\"modes\":{";
  for (size_t i = 0; i < moving.size(); ++i) {
    if (i) j << ",";
    ModeJson(j, moving[i], frozen[i], Overhead(moving, frozen, moving[i].mode));
  }
  j << "},\"overhead_ratio_rays5_vs_nearest\":" << Num(s.ratio)
    << ",\"late_vs_early_keyframe_time\":" << Num(s.nearest ? s.nearest->late_vs_early : 0.0)
    << ",\"peak_rss_mb\":" << Num(s.peak / 1024.0)
    << ",\"bytes_per_vertex\":" << Num(s.bytes_per_vertex)
    << ",\"accuracy_ratio_nearest_vs_rays5\":{\"ground_truth_to_mesh\":" << Num(s.gt2m_ratio)
    << ",\"mesh_to_scene\":" << Num(s.acc_ratio) << "}";
  if (a.dense_frames >= 10)
    j << ",\"dense\":{\"ok\":" << (d.exact.ok ? "true" : "false") << ",\"frames\":" << d.so.frames
      << ",\"points_per_keyframe\":" << d.so.points_per_keyframe
      << ",\"observations_per_frame\":" << Num(d.exact.observations_per_frame)
      << ",\"points_moved\":" << d.exact.stats.points_moved
      << ",\"keyframe_s_median\":" << Num(Median(d.exact.stats.keyframe_seconds))
      << ",\"keyframe_s_p90\":" << Num(Quantile(d.exact.stats.keyframe_seconds, 0.9))
      << ",\"total_s\":" << Num(d.exact.total) << ",\"frames_per_second\":" << Num(d.exact_fps)
      << ",\"late_vs_early_keyframe_time\":" << Num(d.exact.late_vs_early)
      << ",\"mode\":\"exact\",\"nearest_frames_per_second\":" << Num(d.nearest_fps) << "}";
  j << ",\"engine_options\":{\"transfer_camera_side\":"
    << (g_base_options.transfer_camera_side ? "true" : "false") << ",\"nonnegative_weights\":"
    << (g_base_options.nonnegative_weights ? "true" : "false")
    << ",\"steiner_jitter\":" << Num(g_base_options.steiner_jitter) << "}"
    << ",\"machine\":" << JsonString(MachineLine())
    << ",\"load_average_start\":" << JsonString(load_start)
    << ",\"load_average_end\":" << JsonString(LoadAverage()) << "}";
  return j.str();
}

}  // namespace

int RunEngineBench(int argc, char** argv) {
  EngineArgs a;
  if (int status = 0; !ParseEngineArgs(argc, argv, &a, &status)) return status;
  const synthetic::StreamOptions& so = a.so;
  const std::string load_start = LoadAverage();
  std::printf("imr-bench engine: street stream, %d frames (%d keyframes), %d new points per "
              "keyframe, seed %llu; %s; load average at start %s\n",
              so.frames, so.frames / so.keyframe_every, so.points_per_keyframe,
              static_cast<unsigned long long>(so.seed), MachineLine().c_str(), load_start.c_str());
  std::vector<RunResult> moving, frozen;
  for (const auto& m : a.modes) {
    frozen.push_back(Run(m, true, so, false));
    moving.push_back(Run(m, false, so, true));
  }
  PrintModes(moving, frozen);
  PrintPhases(moving);
  const Summary s = PrintSummary(moving, frozen);
  Dense dense;
  dense.so = so;
  dense.so.frames = a.dense_frames;
  dense.so.points_per_keyframe = 720;
  if (a.dense_frames >= 10) RunDense(&dense);
  std::printf("load average at end %s\n", LoadAverage().c_str());
  std::printf("%s\n", EngineJson(a, moving, frozen, s, dense, load_start).c_str());
  bool all_ok = true;
  for (size_t i = 0; i < moving.size(); ++i) all_ok = all_ok && moving[i].ok && frozen[i].ok;
  if (a.dense_frames >= 10) all_ok = all_ok && dense.exact.ok;
  return all_ok ? 0 : 1;
}

}  // namespace imr::bench
