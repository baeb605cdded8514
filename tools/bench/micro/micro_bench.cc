// imr-microbench: the engine's hot paths one at a time (Google Benchmark), on the triangulation
// that a synthetic street stream (100 frames, 150 new points per keyframe, points moving) leaves
// behind: ray traversal per cell, a full cast (T + N1 + N2 weighted) per cell, the weight
// transfer of each policy on the conflict zones the engine really met, the local manifold test,
// and growing per cell. Time per unit is in the "per_*" counters (seconds, Google Benchmark's
// inverted rate). Internal hooks: host/engine/engine_internal.h.
//
//   build/bin/imr-microbench                       # all, about 30 s
//   build/bin/imr-microbench --benchmark_filter=Transfer
#include <benchmark/benchmark.h>

#include <cstdio>
#include <memory>
#include <utility>
#include <vector>

#include "host/engine/engine.h"
#include "host/engine/engine_internal.h"
#include "host/engine/testing/run_stream.h"

namespace imr::bench {
namespace {

using engine::Engine;
using engine::internal::EngineInternals;

// An engine after a street stream, the (point, camera) pairs of its viewing rays in the
// window, and the transfers the policy was called with during the second half of the stream.
struct Scene {
  synthetic::StreamOptions so;
  std::unique_ptr<engine::WeightTransferPolicy> policy;
  std::unique_ptr<Engine> engine;
  std::vector<std::pair<uint64_t, uint64_t>> rays;
  std::vector<engine::Vec3> points;
  std::vector<engine::internal::RecordedTransfer> transfers;
};

std::unique_ptr<Scene> BuildScene() {
  auto s = std::make_unique<Scene>();
  s->so.scene = synthetic::SceneKind::kStreet;
  s->so.frames = 100;
  s->so.points_per_keyframe = 150;
  s->so.noise_at_10m = 0.1;
  engine::EngineOptions eo;
  eo.forget = engine::ForgetMode::kOff;  // the micro benches probe the whole scene
  engine::testing::ConfigureMode("nearest", &eo, &s->policy);
  s->engine = std::make_unique<Engine>(eo, s->policy.get());
  synthetic::SyntheticStream stream(s->so);
  std::vector<uint64_t> ids;
  const engine::Status st = engine::testing::RunStream(
      &stream, s->engine.get(), [&](const synthetic::StreamKeyframe& kf) {
        for (const auto& p : kf.new_points) ids.push_back(p.id);
        if (kf.index == stream.keyframe_count() / 2)
          EngineInternals::RecordTransfers(*s->engine, true, 20000);
        return true;
      });
  if (!st.ok()) std::fprintf(stderr, "imr-microbench: stream failed: %s\n", st.message().c_str());
  s->transfers = EngineInternals::RecordedTransfers(*s->engine);
  EngineInternals::RecordTransfers(*s->engine, false);
  for (uint64_t id : ids) {
    engine::Vec3 p;
    if (!s->engine->PointPosition(id, &p)) continue;
    s->points.push_back(p);
    for (uint64_t c : EngineInternals::WindowCameras(*s->engine, id)) s->rays.push_back({id, c});
  }
  return s;
}

Scene& SharedScene() {
  static std::unique_ptr<Scene> scene = BuildScene();
  return *scene;
}

// Segment traversal alone: cells crossed from the point's vertex toward a camera.
void BM_RayTraversal(benchmark::State& state) {
  Scene& s = SharedScene();
  size_t i = 0;
  int64_t cells = 0, rays = 0;
  for (auto _ : state) {
    const auto& r = s.rays[i++ % s.rays.size()];
    cells += EngineInternals::TraverseOnly(*s.engine, r.first, r.second);
    ++rays;
  }
  state.counters["cells_per_ray"] = static_cast<double>(cells) / std::max<int64_t>(1, rays);
  state.counters["per_cell"] = benchmark::Counter(static_cast<double>(cells),
                                                  benchmark::Counter::kIsRate |
                                                      benchmark::Counter::kInvert);
}
BENCHMARK(BM_RayTraversal);

// A full cast: traversal, the two neighbour rings, weights; cast forward then backward (which
// restores every weight), so the scene is unchanged.
void BM_CastRay(benchmark::State& state) {
  Scene& s = SharedScene();
  size_t i = 0;
  int64_t weighted = 0, casts = 0;
  for (auto _ : state) {
    const auto& r = s.rays[i++ % s.rays.size()];
    weighted += EngineInternals::CastRay(*s.engine, r.first, r.second, +1);
    weighted += EngineInternals::CastRay(*s.engine, r.first, r.second, -1);
    casts += 2;
  }
  state.counters["weighted_cells_per_ray"] =
      static_cast<double>(weighted) / std::max<int64_t>(1, casts);
  state.counters["per_weighted_cell"] = benchmark::Counter(
      static_cast<double>(weighted), benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
  state.counters["per_ray"] = benchmark::Counter(
      static_cast<double>(casts), benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}
BENCHMARK(BM_CastRay);

// The policy on the conflict zones the engine met (removed cells R -> new cells A).
void BM_Transfer(benchmark::State& state, const char* name) {
  Scene& s = SharedScene();
  auto policy = engine::testing::MakePolicy(name);
  if (s.transfers.empty()) {
    state.SkipWithError("no transfers recorded");
    return;
  }
  std::vector<double> out;
  size_t i = 0;
  int64_t pairs = 0, calls = 0, removed = 0, added = 0;
  for (auto _ : state) {
    const auto& t = s.transfers[i++ % s.transfers.size()];
    engine::TransferInput in;
    in.removed_centroids = t.removed_centroids.data();
    in.removed_weights = t.removed_weights.data();
    in.removed_count = t.removed_weights.size();
    in.new_centroids = t.new_centroids.data();
    in.new_count = t.new_centroids.size() / 3;
    out.resize(in.new_count);
    policy->Transfer(in, out.data());
    benchmark::DoNotOptimize(out.data());
    pairs += static_cast<int64_t>(in.removed_count * in.new_count);
    removed += static_cast<int64_t>(in.removed_count);
    added += static_cast<int64_t>(in.new_count);
    ++calls;
  }
  state.counters["removed_cells"] = static_cast<double>(removed) / std::max<int64_t>(1, calls);
  state.counters["new_cells"] = static_cast<double>(added) / std::max<int64_t>(1, calls);
  state.counters["per_call"] = benchmark::Counter(
      static_cast<double>(calls), benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
  state.counters["per_new_cell"] = benchmark::Counter(
      static_cast<double>(added), benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}
BENCHMARK_CAPTURE(BM_Transfer, nearest, "nearest");
BENCHMARK_CAPTURE(BM_Transfer, mean, "mean");
BENCHMARK_CAPTURE(BM_Transfer, weighted_mean, "weighted_mean");

// The local manifold test on cells next to dO (the test growing and shrinking run per cell):
// the engine's combinatorial form, and the reference form that rebuilds each vertex's link.
void BM_ManifoldTest(benchmark::State& state, bool by_links) {
  Scene& s = SharedScene();
  const size_t n = EngineInternals::CollectBoundaryCells(*s.engine, 20000);
  int64_t tests = 0, kept = 0;
  for (auto _ : state) {
    kept += EngineInternals::TestCollectedCells(*s.engine, by_links);
    tests += static_cast<int64_t>(n);
  }
  state.counters["cells"] = static_cast<double>(n);
  state.counters["share_manifold"] = static_cast<double>(kept) / std::max<int64_t>(1, tests);
  state.counters["per_test"] = benchmark::Counter(
      static_cast<double>(tests), benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}
BENCHMARK_CAPTURE(BM_ManifoldTest, combinatorial, false);
BENCHMARK_CAPTURE(BM_ManifoldTest, links, true);

// Growing: take the cells around a point out of O (untimed), grow them back (timed).
void BM_Grow(benchmark::State& state) {
  Scene& s = SharedScene();
  size_t i = 0;
  int64_t grown = 0;
  for (auto _ : state) {
    state.PauseTiming();
    const engine::Vec3& p = s.points[(i++ * 7919) % s.points.size()];
    EngineInternals::ShrinkAround(*s.engine, p, 3.0);
    state.ResumeTiming();
    grown += EngineInternals::Grow(*s.engine);
  }
  state.counters["cells_grown"] = static_cast<double>(grown) / std::max<int64_t>(1, state.iterations());
  state.counters["per_cell"] = benchmark::Counter(
      static_cast<double>(grown), benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}
BENCHMARK(BM_Grow)->Iterations(300);

}  // namespace
}  // namespace imr::bench

BENCHMARK_MAIN();
