#include "host/eval/evaluate.h"

#include "host/eval/distance.h"
#include "host/eval/parallel.h"
#include "host/eval/synthetic_truth.h"
#include "host/util/atomic_file.h"
#include "host/util/clock.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace imr::eval {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

double Share(std::size_t part, std::size_t whole) {
  return whole == 0 ? std::numeric_limits<double>::quiet_NaN()
                    : static_cast<double>(part) / static_cast<double>(whole);
}

json StatsJson(const DistanceStats& s) {
  if (s.count == 0) return json{{"count", 0}};
  return {{"count", s.count}, {"mean", s.mean}, {"median", s.median}, {"rms", s.rms},
          {"p90", s.p90},     {"max", s.max}};
}

json CropJson(const CropCounts& c) {
  return {{"input", c.input},
          {"kept", c.kept},
          {"beyond_range", c.beyond_range},
          {"outside_frustum", c.outside_frustum}};
}

// The frames' cameras of a sequence.
std::vector<io::CameraGeometry> Cameras(const io::ImageSequence& seq) {
  std::vector<io::CameraGeometry> out;
  out.reserve(seq.frames.size());
  for (const auto& f : seq.frames) out.push_back(f.camera);
  return out;
}

void WritePerPoint(const fs::path& path, const std::vector<double>& d) {
  std::string text;
  text.reserve(d.size() * 13);
  char buf[32];
  for (double x : d) {
    const int n = std::isnan(x) ? std::snprintf(buf, sizeof buf, "nan\n")
                                : std::snprintf(buf, sizeof buf, "%.10g\n", x);
    text.append(buf, static_cast<std::size_t>(n));
  }
  WriteFileAtomically(path, text);
}

}  // namespace

std::vector<double> SharesWithin(const std::vector<double>& d, const std::vector<double>& taus) {
  std::vector<double> out;
  for (double tau : taus)
    out.push_back(Share(static_cast<std::size_t>(std::count_if(d.begin(), d.end(),
                                                                [&](double x) { return x <= tau; })),
                        d.size()));
  return out;
}

std::string EvaluationOptions::Check() const {
  if (taus.empty()) return "no tau given";
  for (double t : taus)
    if (!(t > 0.0) || !std::isfinite(t)) return "tau " + std::to_string(t) + " is not a positive number";
  if (!std::isfinite(max_ray_length)) return "max_ray_length must be finite (<= 0: no range limit)";
  if (!(truth_density > 0.0) || !std::isfinite(truth_density))
    return "truth density must be a positive number";
  if (precision_samples == 0) return "precision samples must be at least 1";
  if (threads < 0) return "threads must be >= 0 (0: all cores)";
  return "";
}

DistanceStats Summarize(std::vector<double> v) {
  DistanceStats s;
  s.count = v.size();
  if (v.empty()) return s;
  std::sort(v.begin(), v.end());
  double sum = 0.0, sum2 = 0.0;
  for (double x : v) {
    sum += x;
    sum2 += x * x;
  }
  const double n = static_cast<double>(v.size());
  s.mean = sum / n;
  s.rms = std::sqrt(sum2 / n);
  s.max = v.back();
  auto percentile = [&](double q) {
    const double h = q * (n - 1.0);
    const std::size_t lo = static_cast<std::size_t>(std::floor(h));
    const std::size_t hi = std::min(lo + 1, v.size() - 1);
    return v[lo] + (h - static_cast<double>(lo)) * (v[hi] - v[lo]);
  };
  s.median = percentile(0.5);
  s.p90 = percentile(0.9);
  return s;
}

Evaluation Evaluate(const TriangleMesh& mesh, const std::vector<Vec3>& truth,
                    const std::vector<io::CameraGeometry>& cameras,
                    const EvaluationOptions& options, bool per_point,
                    const std::vector<ScannerView>* scanner_views) {
  const std::string problem = options.Check();
  if (!problem.empty()) throw std::invalid_argument(problem);
  Evaluation e;
  e.threads = ResolveThreads(options.threads);
  e.mesh_vertices = mesh.vertices.size();
  e.mesh_triangles = mesh.triangles.size();
  e.mesh_area = MeshArea(mesh);
  e.truth_points = truth.size();
  e.taus = options.taus;
  e.cameras = cameras.size();

  // The crop: the same rule for truth points and for precision's mesh samples.
  e.cropped = options.crop && !cameras.empty();
  if (e.cropped) {
    e.crop_note = "kept points inside the frustum of a camera and within max_ray_length of that "
                  "camera's centre";
  } else {
    e.crop_note = options.crop ? "not cropped: no cameras (give an image sequence to crop to the "
                                 "region the cameras saw)"
                               : "not cropped: cropping turned off";
  }
  auto crop = [&](const std::vector<Vec3>& points, CropCounts* counts) {
    std::vector<uint8_t> keep;
    if (e.cropped) {
      keep = CropToCameras(points, cameras, options.max_ray_length, e.threads, counts);
    } else {
      keep.assign(points.size(), 1);
      *counts = {points.size(), points.size(), 0, 0};
    }
    return keep;
  };

  auto t0 = std::chrono::steady_clock::now();
  const std::vector<uint8_t> keep = crop(truth, &e.truth_crop);
  std::vector<Vec3> kept;
  kept.reserve(e.truth_crop.kept);
  for (std::size_t i = 0; i < truth.size(); ++i)
    if (keep[i]) kept.push_back(truth[i]);
  e.seconds_crop = SecondsSince(t0);
  if (kept.empty())
    throw std::runtime_error(
        "no ground-truth point left" +
        (e.cropped ? " after the crop (" + std::to_string(e.truth_crop.beyond_range) +
                         " beyond max_ray_length of every camera, " +
                         std::to_string(e.truth_crop.outside_frustum) + " outside every frustum)"
                   : std::string(" (none given)")));

  // Ground truth -> mesh: the paper's measure.
  t0 = std::chrono::steady_clock::now();
  const MeshDistance to_mesh(mesh);  // throws when no triangle has an area
  e.degenerate_triangles = to_mesh.degenerate();
  std::vector<double> d = to_mesh.Distances(kept, e.threads);
  e.seconds_truth_to_mesh = SecondsSince(t0);
  e.completeness = SharesWithin(d, e.taus);
  if (per_point) {
    e.per_point.assign(truth.size(), std::numeric_limits<double>::quiet_NaN());
    for (std::size_t i = 0, k = 0; i < truth.size(); ++i)
      if (keep[i]) e.per_point[i] = d[k++];
  }
  e.truth_to_mesh = Summarize(std::move(d));

  // Mesh -> ground truth: samples uniform by area, cropped as the truth, nearest truth point.
  t0 = std::chrono::steady_clock::now();
  e.precision_samples = options.precision_samples;
  std::vector<Vec3> samples = SampleSurface(mesh, options.precision_samples, options.seed);
  const std::vector<uint8_t> keep_samples = crop(samples, &e.sample_crop);
  std::size_t n = 0;
  for (std::size_t i = 0; i < samples.size(); ++i)
    if (keep_samples[i]) samples[n++] = samples[i];
  samples.resize(n);
  const PointSetDistance to_truth(kept);
  std::vector<double> ds = to_truth.Distances(samples, e.threads);
  e.precision = SharesWithin(ds, e.taus);
  if (scanner_views != nullptr && !scanner_views->empty()) {
    // Only the samples some scan could have measured: a scanner sees a band of elevations.
    std::vector<uint8_t> in_view(samples.size(), 0);
    ParallelFor(samples.size(), e.threads, [&](std::size_t begin, std::size_t end) {
      for (std::size_t i = begin; i < end; ++i) in_view[i] = InScannerView(*scanner_views, samples[i]);
    });
    std::vector<double> seen;
    for (std::size_t i = 0; i < samples.size(); ++i)
      if (in_view[i]) seen.push_back(ds[i]);
    e.scanner_view = true;
    e.samples_in_scanner_view = seen.size();
    e.precision_in_scanner_view = SharesWithin(seen, e.taus);
  }
  e.mesh_to_truth = Summarize(std::move(ds));
  e.seconds_mesh_to_truth = SecondsSince(t0);
  return e;
}

Truth LoadTruth(const std::string& path, const io::ImageSequence* sequence, int scan_step,
                const EvaluationOptions& options) {
  Truth truth;
  json& t = truth.description;
  if (!path.empty()) {
    TriangleMesh g = ReadGeometry(path);
    t = {{"path", path}, {"format", GeometryFormat(path)}};
    if (g.triangles.empty()) {
      t["source"] = "point_cloud";
      truth.points = std::move(g.vertices);
    } else {
      const double area = MeshArea(g);
      const double count = std::round(area * options.truth_density);
      if (count > 2e8)
        throw std::runtime_error(path + ": a reference mesh of area " + std::to_string(area) +
                                 " at density " + std::to_string(options.truth_density) +
                                 " gives more than 2e8 samples; lower the truth density");
      truth.points = SampleSurface(g, static_cast<std::size_t>(count), options.seed ^ 0x5eedu);
      t["source"] = "mesh_samples";
      t["reference_triangles"] = g.triangles.size();
      t["reference_area"] = area;
      t["density"] = options.truth_density;
      t["seed"] = options.seed;
    }
  } else {
    if (sequence == nullptr)
      throw std::runtime_error("Velodyne ground truth: no sequence with Velodyne scans given");
    VelodyneTruth v = LoadVelodyneTruth(*sequence, scan_step);
    truth.points = std::move(v.points);
    truth.scanner_views = std::move(v.views);
    t = {{"source", "velodyne"},
         {"path", sequence->root},
         {"layout", sequence->layout},
         {"scans", v.scans},
         {"scan_step", scan_step},
         {"frames_without_scan", v.frames_without_scan}};
  }
  t["points"] = truth.points.size();
  if (truth.points.empty())
    throw std::runtime_error((path.empty() && sequence != nullptr ? sequence->root : path) +
                             ": no ground-truth point");
  return truth;
}

json EvaluateFiles(const EvaluationInputs& in, const EvaluationOptions& options,
                   SequenceReader read_sequence) {
  const std::string problem = options.Check();
  if (!problem.empty()) throw std::invalid_argument(problem);
  if (in.truth.empty() && in.sequence.empty())
    throw std::invalid_argument("no ground truth: give a truth file or a sequence with Velodyne scans");
  if (in.scan_step < 1) throw std::invalid_argument("scan step must be at least 1");
  const auto start = std::chrono::steady_clock::now();

  const TriangleMesh mesh = in.mesh_data != nullptr ? *in.mesh_data : ReadMesh(in.mesh);
  json report;
  report["mesh"] = {{"path", in.mesh},
                    {"format", in.mesh_data != nullptr ? std::string("arrays") : GeometryFormat(in.mesh)}};

  io::ImageSequence seq;
  std::vector<io::CameraGeometry> cameras;
  if (!in.sequence.empty()) {
    if (!read_sequence) throw std::invalid_argument("no sequence reader given for " + in.sequence);
    seq = read_sequence(in.sequence, in.sequence_options);
    cameras = Cameras(seq);
  }

  Truth truth;
  if (in.truth_points != nullptr) {
    if (in.truth_points->empty()) throw std::runtime_error(in.truth + ": no ground-truth point");
    truth.points = *in.truth_points;
    truth.description = {{"path", in.truth}, {"format", "array"}, {"source", "point_cloud"},
                         {"points", truth.points.size()}};
  } else {
    truth = LoadTruth(in.truth, in.sequence.empty() ? nullptr : &seq, in.scan_step, options);
  }
  report["truth"] = std::move(truth.description);
  const double seconds_read = SecondsSince(start);

  const Evaluation e = Evaluate(mesh, truth.points, cameras, options, !in.per_point.empty(),
                                &truth.scanner_views);
  if (!in.per_point.empty()) WritePerPoint(in.per_point, e.per_point);

  report["mesh"]["vertices"] = e.mesh_vertices;
  report["mesh"]["triangles"] = e.mesh_triangles;
  report["mesh"]["degenerate_triangles"] = e.degenerate_triangles;
  report["mesh"]["area"] = e.mesh_area;
  json& c = report["crop"];
  c = {{"applied", e.cropped}, {"rule", e.crop_note}, {"cameras", e.cameras}};
  if (e.cropped) c["max_ray_length"] = options.max_ray_length > 0 ? json(options.max_ray_length) : json(nullptr);
  if (!in.sequence.empty()) c["sequence"] = {{"path", in.sequence}, {"layout", seq.layout}, {"frames", seq.frames.size()}};
  c["truth"] = CropJson(e.truth_crop);
  c["mesh_samples"] = CropJson(e.sample_crop);
  report["truth_to_mesh"] = StatsJson(e.truth_to_mesh);
  report["mesh_to_truth"] = StatsJson(e.mesh_to_truth);
  report["mesh_to_truth"]["samples"] = e.precision_samples;
  report["tau"] = e.taus;
  report["completeness"] = e.completeness;
  report["precision"] = e.precision;
  if (e.scanner_view)
    report["scanner_view"] = {
        {"rule", "mesh samples (kept by the crop) within some scan's elevations and range: what "
                 "the scanner could have measured at all"},
        {"samples", e.samples_in_scanner_view},
        {"share", Share(e.samples_in_scanner_view, e.sample_crop.kept)},
        {"precision", e.precision_in_scanner_view}};
  report["options"] = {{"threads", e.threads},
                       {"seed", options.seed},
                       {"precision_samples", options.precision_samples},
                       {"truth_density", options.truth_density},
                       {"max_ray_length", options.max_ray_length},
                       {"crop", options.crop}};
  if (!in.per_point.empty()) report["per_point"] = in.per_point;
  double seconds_road = 0.0;
  if (!seq.synthetic_scene.empty()) {
    const auto t0 = std::chrono::steady_clock::now();
    const RoadSurfaceEvaluation road =
        EvaluateRoadSurface(mesh, ReadSyntheticTruth(seq.synthetic_scene), cameras, options);
    report["road_surface"] = {
        {"scene", seq.synthetic_scene},
        {"samples", road.samples},
        {"crop", CropJson(road.crop)},
        {"hidden", road.hidden},
        {"truth_to_mesh", StatsJson(road.truth_to_mesh)},
        {"completeness", road.completeness},
        {"completeness_visible", road.completeness_visible}};
    seconds_road = SecondsSince(t0);
  }
  report["seconds"] = {{"read", seconds_read},
                       {"crop", e.seconds_crop},
                       {"truth_to_mesh", e.seconds_truth_to_mesh},
                       {"mesh_to_truth", e.seconds_mesh_to_truth},
                       {"road_surface", seconds_road},
                       {"total", SecondsSince(start)}};
  return report;
}

std::string FormatReport(const json& r) {
  std::ostringstream o;
  char buf[512];
  auto num = [](const json& j, const char* fmt) -> std::string {
    if (!j.is_number()) return "-";
    char b[64];
    std::snprintf(b, sizeof b, fmt, j.get<double>());
    return b;
  };
  const json& m = r["mesh"];
  std::snprintf(buf, sizeof buf, "mesh           %s: %zu triangles, %zu vertices, area %.6g\n",
                m.value("path", "").c_str(), m.value("triangles", std::size_t{0}),
                m.value("vertices", std::size_t{0}), m.value("area", 0.0));
  o << buf;
  const json& t = r["truth"];
  o << "ground truth   " << t.value("path", "") << ": " << t.value("points", std::size_t{0})
    << " points (" << t.value("source", "") << ")\n";
  const json& c = r["crop"];
  if (c.value("applied", false)) {
    std::snprintf(buf, sizeof buf,
                  "crop           kept %zu of %zu points (%zu beyond range, %zu outside every "
                  "frustum): inside a camera's frustum and within %s of its centre, %zu cameras\n",
                  c["truth"].value("kept", std::size_t{0}), c["truth"].value("input", std::size_t{0}),
                  c["truth"].value("beyond_range", std::size_t{0}),
                  c["truth"].value("outside_frustum", std::size_t{0}),
                  num(c["max_ray_length"], "%g").c_str(), c.value("cameras", std::size_t{0}));
    o << buf;
  } else {
    o << "crop           " << c.value("rule", "") << "\n";
  }
  auto stats = [&](const char* name, const json& s, const char* unit) {
    std::snprintf(buf, sizeof buf, "%-14s %zu %s: mean %s  median %s  rms %s  p90 %s  max %s\n",
                  name, s.value("count", std::size_t{0}), unit, num(s["mean"], "%.6g").c_str(),
                  num(s["median"], "%.6g").c_str(), num(s["rms"], "%.6g").c_str(),
                  num(s["p90"], "%.6g").c_str(), num(s["max"], "%.6g").c_str());
    o << buf;
  };
  stats("truth -> mesh", r["truth_to_mesh"], "points");
  stats("mesh -> truth", r["mesh_to_truth"], "samples");
  // Completeness: share of the (cropped) ground truth within tau of the mesh (truth -> mesh);
  // precision: share of the mesh samples within tau of the ground truth (mesh -> truth).
  o << "tau                                 ";
  for (const json& x : r["tau"]) o << " " << num(x, "%8g");
  o << "\ncompleteness (truth -> mesh <= tau) ";
  for (const json& x : r["completeness"]) o << " " << num(x, "%8.4f");
  o << "\nprecision    (mesh -> truth <= tau) ";
  for (const json& x : r["precision"]) o << " " << num(x, "%8.4f");
  o << "\n";
  if (r.contains("scanner_view")) {
    // The share of the mesh a laser scanner could judge, and precision over it.
    const json& sv = r["scanner_view"];
    o << "  in the scanner's view            ";
    for (const json& x : sv["precision"]) o << " " << num(x, "%8.4f");
    o << "   (" << num(sv["share"].is_number() ? json(100.0 * sv["share"].get<double>()) : sv["share"], "%.1f")
      << " % of the samples: the rest above or below every scan's elevations, or beyond its range)\n";
  }
  if (r.contains("road_surface")) {
    const json& rs = r["road_surface"];
    std::snprintf(buf, sizeof buf,
                  "road surface   %zu of %zu samples kept (%zu hidden from every camera): mean %s\n",
                  rs["crop"].value("kept", std::size_t{0}), rs.value("samples", std::size_t{0}),
                  rs.value("hidden", std::size_t{0}), num(rs["truth_to_mesh"]["mean"], "%.6g").c_str());
    o << buf << "road complete ";
    for (const json& x : rs["completeness"]) o << " " << num(x, "%8.4f");
    o << "\n  (not hidden)";
    for (const json& x : rs["completeness_visible"]) o << " " << num(x, "%8.4f");
    o << "\n";
  }
  const json& s = r["seconds"];
  std::snprintf(buf, sizeof buf,
                "time           %.2f s on %d threads (read %.2f, crop %.2f, truth -> mesh %.2f, "
                "mesh -> truth %.2f)\n",
                s.value("total", 0.0), r["options"].value("threads", 1), s.value("read", 0.0),
                s.value("crop", 0.0), s.value("truth_to_mesh", 0.0), s.value("mesh_to_truth", 0.0));
  o << buf;
  return o.str();
}

}  // namespace imr::eval
