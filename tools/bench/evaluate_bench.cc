// imr-bench evaluate: the cost of `imr evaluate` (issue 6 target: 1 M ground-truth points against
// a 500 k-triangle mesh in seconds). A bumpy height field of the requested size and noisy points
// over it; times the AABB tree build, the point-to-triangle queries on 1 thread and on all, and a
// whole Evaluate (crop off: distances both ways, completeness and precision). Prints a few lines,
// then one JSON object as the last line.
#include "host/eval/distance.h"
#include "host/eval/evaluate.h"
#include "host/eval/parallel.h"
#include "tools/bench/common/frame.h"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <random>
#include <string>
#include <vector>

namespace imr::bench {
namespace {

using eval::TriangleMesh;
using eval::Vec3;

double Now() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

double Height(double x, double y) { return 2.0 * std::sin(x / 7.0) * std::cos(y / 5.0) + 0.3 * std::sin(x) * std::sin(1.3 * y); }

// An n x n grid of cells over [0, size]^2, two triangles per cell.
TriangleMesh HeightField(int n, double size) {
  TriangleMesh m;
  const double h = size / n;
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) m.vertices.push_back({i * h, j * h, Height(i * h, j * h)});
  auto id = [&](int i, int j) { return static_cast<uint32_t>(j * (n + 1) + i); };
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      m.triangles.push_back({id(i, j), id(i + 1, j), id(i + 1, j + 1)});
      m.triangles.push_back({id(i, j), id(i + 1, j + 1), id(i, j + 1)});
    }
  return m;
}

// Uniform over the square, height = surface + Gaussian noise (sigma 0.2).
std::vector<Vec3> NoisyPoints(std::size_t count, double size, uint64_t seed) {
  std::mt19937_64 g(seed);
  std::uniform_real_distribution<double> u(0.0, size);
  std::normal_distribution<double> noise(0.0, 0.2);
  std::vector<Vec3> p(count);
  for (auto& q : p) {
    const double x = u(g), y = u(g);
    q = {x, y, Height(x, y) + noise(g)};
  }
  return p;
}

}  // namespace

int RunEvaluateBench(int argc, char** argv) {
  uint64_t points = 1000000, triangles = 500000;
  int threads = 0;
  uint64_t seed = 1;
  Options args("imr-bench evaluate",
            "usage: imr-bench evaluate [--points N] [--triangles N] [--threads N] [--seed S] [--quick]\n");
  args.Uint64("--points", &points).Uint64("--triangles", &triangles).Int("--threads", &threads);
  args.Uint64("--seed", &seed).Action("--quick", [&] { points = 100000, triangles = 50000; });
  if (int status = 0; !args.Parse(argc, argv, &status)) return status;
  threads = eval::ResolveThreads(threads);
  const int n = std::max(1, static_cast<int>(std::lround(std::sqrt(triangles / 2.0))));
  const double size = 100.0;
  double t = Now();
  const TriangleMesh mesh = HeightField(n, size);
  const std::vector<Vec3> truth = NoisyPoints(points, size, seed);
  std::printf("scene: %zu triangles (height field %d x %d over %.0f m), %zu points (noise 0.2 m); %.2f s to make\n",
              mesh.triangles.size(), n, n, size, truth.size(), Now() - t);

  t = Now();
  const eval::MeshDistance md(mesh);
  const double build = Now() - t;
  t = Now();
  const std::vector<double> d1 = md.Distances(truth, 1);
  const double query1 = Now() - t;
  t = Now();
  const std::vector<double> dn = md.Distances(truth, threads);
  const double queryn = Now() - t;
  if (d1 != dn) {
    std::fprintf(stderr, "imr-bench evaluate: 1-thread and %d-thread distances differ\n", threads);
    return 1;
  }
  std::printf("AABB tree build:        %.2f s\n", build);
  std::printf("queries, 1 thread:      %.2f s (%.2f us/point)\n", query1, 1e6 * query1 / truth.size());
  std::printf("queries, %d threads:     %.2f s (%.2f us/point, speed-up %.2f)\n", threads, queryn,
              1e6 * queryn / truth.size(), query1 / queryn);

  eval::EvaluationOptions o;
  o.threads = threads;
  o.precision_samples = points;
  t = Now();
  const eval::Evaluation e = eval::Evaluate(mesh, truth, {}, o);
  const double whole = Now() - t;
  std::printf("Evaluate, %d threads:    %.2f s (truth -> mesh %.2f incl. build, mesh -> truth %.2f for %zu samples)\n",
              threads, whole, e.seconds_truth_to_mesh, e.seconds_mesh_to_truth, e.precision_samples);
  std::printf("mean distance %.4f m (vertical noise sigma 0.2: at most 0.16 on slopes), completeness@0.2 %.3f\n",
              e.truth_to_mesh.mean, e.completeness[2]);
  std::printf(
      "{\"bench\":\"evaluate\",\"points\":%zu,\"triangles\":%zu,\"threads\":%d,\"build_s\":%.3f,"
      "\"query_1thread_s\":%.3f,\"query_threads_s\":%.3f,\"evaluate_s\":%.3f,"
      "\"truth_to_mesh_s\":%.3f,\"mesh_to_truth_s\":%.3f,\"mean_distance\":%.5f}\n",
      truth.size(), mesh.triangles.size(), threads, build, query1, queryn, whole,
      e.seconds_truth_to_mesh, e.seconds_mesh_to_truth, e.truth_to_mesh.mean);
  return 0;
}

}  // namespace imr::bench
