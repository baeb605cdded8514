#include "host/eval/synthetic_truth.h"

#include "host/util/input_file.h"

#include "host/eval/distance.h"
#include "host/eval/parallel.h"
#include "host/synthetic/evaluation.h"

#include <nlohmann/json.hpp>

#include <atomic>
#include <cmath>
#include <fstream>
#include <stdexcept>

namespace imr::eval {

using nlohmann::json;

io::Vec3 SyntheticTruth::ToScene(const io::Vec3& w) const {
  return io::Mul(io::Transpose(rotation),
                 {w[0] - translation[0], w[1] - translation[1], w[2] - translation[2]});
}

io::Vec3 SyntheticTruth::ToWorld(const io::Vec3& s) const {
  const io::Vec3 r = io::Mul(rotation, s);
  return {r[0] + translation[0], r[1] + translation[1], r[2] + translation[2]};
}

SyntheticTruth ReadSyntheticTruth(const std::string& path) {
  InputStream in(path, "the synthetic scene description (JSON)");  // the open rule
  json j;
  try {
    in >> j;
  } catch (const json::exception& e) {
    throw std::runtime_error(path + ": not valid JSON (" + e.what() + ")");
  }
  auto number = [&](const char* key) {
    if (!j.contains(key) || !j[key].is_number())
      throw std::runtime_error(path + ": field '" + key + "': expected a number");
    return j[key].get<double>();
  };
  if (!j.contains("scene") || j["scene"] != "street")
    throw std::runtime_error(path + ": field 'scene': expected \"street\"");
  SyntheticTruth t;
  if (!j.contains("seed") || !j["seed"].is_number_unsigned())
    throw std::runtime_error(path + ": field 'seed': expected a non-negative integer");
  t.scene = synthetic::Scene::StreetCanyon(number("length"), j["seed"].get<uint64_t>(),
                                           number("half_width"), number("facade_height"));
  const json& m = j.contains("world_from_scene") ? j["world_from_scene"] : json();
  std::vector<double> v;
  if (m.is_array() && m.size() == 4) {
    for (const json& row : m)
      if (row.is_array())
        for (const json& x : row)
          if (x.is_number()) v.push_back(x.get<double>());
  } else if (m.is_array()) {
    for (const json& x : m)
      if (x.is_number()) v.push_back(x.get<double>());
  }
  if (v.size() != 16)
    throw std::runtime_error(path + ": field 'world_from_scene': expected a 4x4 matrix "
                             "(4 rows of 4 numbers, or 16 numbers row-major)");
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) t.rotation[r][c] = v[4 * r + c];
    t.translation[r] = v[4 * r + 3];
  }
  if (const std::string p = io::RotationProblem(t.rotation, 1e-6); !p.empty())
    throw std::runtime_error(path + ": field 'world_from_scene': rotation part " + p);
  return t;
}

RoadSurfaceEvaluation EvaluateRoadSurface(const TriangleMesh& mesh, const SyntheticTruth& truth,
                                          const std::vector<io::CameraGeometry>& cameras,
                                          const EvaluationOptions& options) {
  if (const std::string problem = options.Check(); !problem.empty())
    throw std::invalid_argument(problem);
  RoadSurfaceEvaluation e;
  e.taus = options.taus;
  std::vector<Vec3> samples =
      synthetic::SampleRoadSurface(truth.scene, options.truth_density, options.seed ^ 0x20adu);
  e.samples = samples.size();
  for (Vec3& p : samples) p = truth.ToWorld(p);

  const int threads = ResolveThreads(options.threads);
  e.cropped = options.crop && !cameras.empty();
  std::vector<uint8_t> keep;
  if (e.cropped) {
    keep = CropToCameras(samples, cameras, options.max_ray_length, threads, &e.crop);
  } else {
    keep.assign(samples.size(), 1);
    e.crop = {samples.size(), samples.size(), 0, 0};
  }
  std::vector<Vec3> kept;
  kept.reserve(e.crop.kept);
  for (std::size_t i = 0; i < samples.size(); ++i)
    if (keep[i]) kept.push_back(samples[i]);
  if (kept.empty())
    throw std::runtime_error("no road sample left after the crop (" +
                             std::to_string(e.crop.beyond_range) + " beyond max_ray_length of " +
                             "every camera, " + std::to_string(e.crop.outside_frustum) +
                             " outside every frustum)");

  // Hidden: no camera within range, with the sample in its frustum, sees it past the scene.
  std::vector<uint8_t> seen(kept.size(), 1);
  if (!cameras.empty()) {
    std::vector<io::Vec3> centers;  // scene frame, where Visible() lives
    for (const auto& c : cameras) centers.push_back(truth.ToScene(c.center));
    const bool limited = e.cropped && options.max_ray_length > 0.0;
    const double range2 = options.max_ray_length * options.max_ray_length;
    double t = 0.0;  // builds the scene's lazy index here, before the threads read it
    truth.scene.Intersect({0.0, 0.0, 0.0}, {0.0, 0.0, 1.0}, 1.0, &t);
    std::atomic<std::size_t> hidden{0};
    ParallelFor(kept.size(), threads, [&](std::size_t begin, std::size_t end) {
      std::size_t local = 0;
      for (std::size_t i = begin; i < end; ++i) {
        const io::Vec3 s = truth.ToScene(kept[i]);
        bool visible = false;
        for (std::size_t c = 0; c < cameras.size() && !visible; ++c) {
          const io::Vec3& o = centers[c];
          const double dx = s[0] - o[0], dy = s[1] - o[1], dz = s[2] - o[2];
          if (limited && dx * dx + dy * dy + dz * dz > range2) continue;
          if (e.cropped && !InFrustum(cameras[c], kept[i])) continue;
          visible = truth.scene.Visible(o, s);
        }
        if (!visible) {
          seen[i] = 0;
          ++local;
        }
      }
      hidden += local;
    }, 1024);
    e.hidden = hidden;
  }

  const MeshDistance to_mesh(mesh);  // throws when no triangle has an area
  std::vector<double> d = to_mesh.Distances(kept, threads);
  e.completeness = SharesWithin(d, e.taus);
  std::vector<double> visible;
  visible.reserve(d.size() - e.hidden);
  for (std::size_t i = 0; i < d.size(); ++i)
    if (seen[i]) visible.push_back(d[i]);
  e.completeness_visible = SharesWithin(visible, e.taus);
  e.truth_to_mesh = Summarize(std::move(d));
  return e;
}

}  // namespace imr::eval
