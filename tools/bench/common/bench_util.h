// Shared helpers of the imr-bench subcommands (engine, paper, scaling): quantiles, memory and
// machine figures, and accuracy against a known synthetic scene in both directions with medians
// (host/eval/README.md: the paper's figure is the mean distance from each ground-truth point to the mesh).
// Header-only; no CGAL.
#pragma once

#include <malloc.h>
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <limits>
#include <random>
#include <sstream>
#include <string>
#include <unordered_map>
#include <vector>

#include "host/synthetic/evaluation.h"
#include "host/synthetic/scene.h"
#include "host/synthetic/stream.h"

namespace imr::bench {

inline double Quantile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const double pos = q * static_cast<double>(v.size() - 1);
  const size_t i = static_cast<size_t>(pos);
  const double f = pos - static_cast<double>(i);
  return i + 1 < v.size() ? v[i] * (1 - f) + v[i + 1] * f : v[i];
}
inline double Median(std::vector<double> v) { return Quantile(std::move(v), 0.5); }
inline double Mean(const std::vector<double>& v) {
  double s = 0.0;
  for (double x : v) s += x;
  return v.empty() ? 0.0 : s / static_cast<double>(v.size());
}

// Bytes allocated and in use on the heap (glibc), independent of memory kept by the allocator.
inline long HeapInUseBytes() { return static_cast<long>(mallinfo2().uordblks); }

inline long PeakRssKb() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_maxrss;
}

// The 1-minute load average, as /proc/loadavg has it ("1.93").
inline std::string LoadAverage() {
  std::ifstream in("/proc/loadavg");
  std::string a;
  in >> a;
  return a.empty() ? "?" : a;
}

// "Intel(R) Xeon(R) ... , 2 cores" from /proc/cpuinfo.
inline std::string MachineLine() {
  std::ifstream in("/proc/cpuinfo");
  std::string line, model;
  while (std::getline(in, line))
    if (line.rfind("model name", 0) == 0) {
      model = line.substr(line.find(':') + 2);
      break;
    }
  std::ostringstream s;
  s << (model.empty() ? "unknown CPU" : model) << ", " << sysconf(_SC_NPROCESSORS_ONLN)
    << " cores";
  return s.str();
}

inline std::string Num(double v) {
  if (!std::isfinite(v)) return "null";
  char b[64];
  std::snprintf(b, sizeof b, "%.6g", v);
  return b;
}

inline std::string JsonString(const std::string& s) {
  std::string o = "\"";
  for (char c : s) {
    if (c == '"' || c == '\\') o += '\\';
    if (static_cast<unsigned char>(c) < 0x20) continue;
    o += c;
  }
  return o + "\"";
}

// ---------------------------------------------------------------------------------------------
// Ground truth of a synthetic run: a "synthetic Velodyne", points of the true surfaces that the
// cameras saw, sampled independently of the stream's own points. From every `frame_step`-th
// frame, `rays_per_frame` random directions around the viewing direction hit the scene; a hit is
// kept when that camera sees it (within max_range, inside the field of view, not hidden).
inline std::vector<synthetic::Vec3> SampleSeenSurfaces(const synthetic::SyntheticStream& stream,
                                                       int frames, int frame_step,
                                                       int rays_per_frame, uint64_t seed) {
  using synthetic::Vec3;
  std::vector<Vec3> out;
  std::mt19937_64 rng(seed * 0x2545F4914F6CDD1Dull + 3);
  std::uniform_real_distribution<double> uh(-1.2, 1.2), uv(-0.8, 0.8);
  const double range = stream.options().max_range;
  const Vec3 up{0.0, 0.0, 1.0};
  for (int f = 0; f < frames; f += std::max(1, frame_step)) {
    const Vec3 c = stream.CameraCenter(f), fw = stream.CameraForward(f);
    const Vec3 right = synthetic::Normalized(synthetic::Cross(fw, up));
    const Vec3 u = synthetic::Cross(right, fw);
    for (int i = 0; i < rays_per_frame; ++i) {
      const Vec3 dir = synthetic::Normalized(synthetic::Add(
          fw, synthetic::Add(synthetic::Scale(right, std::tan(uh(rng))),
                             synthetic::Scale(u, std::tan(uv(rng))))));
      double t;
      if (!stream.scene().Intersect(c, dir, range, &t)) continue;
      const Vec3 x = synthetic::Add(c, synthetic::Scale(dir, t * (1.0 - 1e-9)));
      if (stream.Sees(f, x)) out.push_back(x);
    }
  }
  return out;
}

// Accuracy of a mesh against a known scene, both directions (host/eval/README.md).
struct SceneAccuracy {
  size_t triangles = 0;
  double area = 0.0;
  size_t truth_points = 0;
  double truth_to_mesh_mean = 0.0;    // The paper's figure (CloudCompare cloud-to-mesh).
  double truth_to_mesh_median = 0.0;
  double truth_to_mesh_p90 = 0.0;
  double completeness = 0.0;          // Share of truth within tau of the mesh.
  double mesh_to_scene_mean = 0.0;    // Mesh samples (uniform by area) to the true surface.
  double mesh_to_scene_median = 0.0;
  double precision = 0.0;             // Share of mesh area within tau of the true surface.
  double tau = 0.0;
  double cap = 0.0;                   // Truth -> mesh distances are capped here (no mesh near).
};

// vertices: packed xyz; faces: 3 indices per triangle.
inline SceneAccuracy EvaluateAgainstScene(const synthetic::Scene& scene,
                                          const std::vector<double>& vertices,
                                          const std::vector<uint32_t>& faces,
                                          const std::vector<synthetic::Vec3>& truth, double tau,
                                          int mesh_samples = 200000, double cap = 20.0,
                                          uint64_t seed = 1) {
  using synthetic::Vec3;
  SceneAccuracy r;
  r.tau = tau;
  r.cap = cap;
  r.triangles = faces.size() / 3;
  r.truth_points = truth.size();
  auto vert = [&](uint32_t i) -> Vec3 {
    return {vertices[3 * i], vertices[3 * i + 1], vertices[3 * i + 2]};
  };
  // Mesh -> scene: samples uniform by area.
  std::vector<double> cum(r.triangles, 0.0);
  for (size_t t = 0; t < r.triangles; ++t) {
    const Vec3 a = vert(faces[3 * t]), b = vert(faces[3 * t + 1]), c = vert(faces[3 * t + 2]);
    r.area += 0.5 * synthetic::Norm(synthetic::Cross(synthetic::Sub(b, a), synthetic::Sub(c, a)));
    cum[t] = r.area;
  }
  if (r.area > 0.0 && mesh_samples > 0) {
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<double> u01(0.0, 1.0);
    std::vector<double> d;
    d.reserve(mesh_samples);
    for (int s = 0; s < mesh_samples; ++s) {
      const double x = u01(rng) * r.area;
      const size_t t = std::min<size_t>(
          r.triangles - 1, static_cast<size_t>(std::lower_bound(cum.begin(), cum.end(), x) -
                                               cum.begin()));
      double p = u01(rng), q = u01(rng);
      if (p + q > 1.0) {
        p = 1.0 - p;
        q = 1.0 - q;
      }
      const Vec3 a = vert(faces[3 * t]), b = vert(faces[3 * t + 1]), c = vert(faces[3 * t + 2]);
      const Vec3 pt = synthetic::Add(
          a, synthetic::Add(synthetic::Scale(synthetic::Sub(b, a), p),
                            synthetic::Scale(synthetic::Sub(c, a), q)));
      d.push_back(scene.Distance(pt));
    }
    r.mesh_to_scene_mean = Mean(d);
    r.mesh_to_scene_median = Median(d);
    r.precision = static_cast<double>(std::count_if(d.begin(), d.end(),
                                                    [&](double v) { return v <= tau; })) /
                  static_cast<double>(d.size());
  }
  if (truth.empty()) return r;
  // Truth -> mesh (the same code as EvaluateMesh's): 2 m cells, triangles up to 400 m.
  const std::vector<double> dist = synthetic::TruthToMeshDistances(vertices, faces, truth, cap, 2.0, 200);
  r.truth_to_mesh_mean = Mean(dist);
  r.truth_to_mesh_median = Median(dist);
  r.truth_to_mesh_p90 = Quantile(dist, 0.9);
  r.completeness = static_cast<double>(std::count_if(dist.begin(), dist.end(),
                                                     [&](double v) { return v <= tau; })) /
                   static_cast<double>(dist.size());
  return r;
}

}  // namespace imr::bench
