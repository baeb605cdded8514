#include "host/pipeline/run.h"

#include "host/eval/evaluate.h"
#include "host/eval/ground_truth.h"
#include "host/eval/mesh_stats.h"
#include "host/io/engine_options.h"
#include "host/pipeline/scale.h"
#include "host/pipeline/front_end.h"
#include "host/pipeline/stage_watch.h"
#include "host/plugin/host_services.h"
#include "host/plugin/keyframe_images.h"
#include "host/plugin/policy_adapter.h"
#include "host/io/input_formats.h"
#include "host/io/slam_json.h"
#include "host/util/atomic_file.h"
#include "host/util/json_text.h"
#include "host/util/clock.h"
#include "host/util/sha256.h"
#include "host/util/log.h"

#include <unistd.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <deque>
#include <cmath>
#include <fstream>
#include <map>
#include <optional>
#include <set>

namespace imr::pipeline {
namespace fs = std::filesystem;
using nlohmann::json;

const char* Version() { return IMR_VERSION; }

int BatchResult::failed() const {
  int n = 0;
  for (const auto& s : sequences) n += s.ok ? 0 : 1;
  return n;
}

namespace {

json PluginJson(const plugin::PluginInfo& info, const json& params) {
  return {{"id", info.id()},     {"version", info.version()}, {"kind", info.kind()},
          {"abi", info.abi()},   {"file", info.file.string()}, {"params", params}};
}

json StatsJson(const engine::EngineStats& s) {
  const auto& t = s.time;
  // Every counter engine::EngineStats keeps (REPORT.md lists them).
  return {{"seconds", {{"steiner", t.steiner}, {"shrink", t.shrink}, {"move", t.move},
                       {"insert", t.insert}, {"cast", t.cast}, {"scan", t.scan},
                       {"grow", t.grow}, {"extract", t.extract}, {"total", t.total}}},
          {"keyframes", s.updates},
          {"rays_cast", s.rays_cast},
          {"rays_cast_backward", s.rays_cast_backward},
          {"rays_skipped_too_long", s.rays_skipped_too_long},
          {"rays_truncated_to_camera", s.rays_truncated_to_camera},
          {"rays_truncated", s.rays_truncated},
          {"rays_rewalked", s.rays_rewalked},
          {"rays_rewalked_exact", s.rays_rewalked_exact},
          {"cells_rewalked", s.cells_rewalked},
          {"ray_mismatches", s.ray_mismatches},
          {"cells_traversed", s.cells_traversed},
          {"cells_weighted", s.cells_weighted},
          {"points_inserted", s.points_inserted},
          {"points_moved", s.points_moved},
          {"moves_skipped", s.moves_skipped},
          {"points_dropped", s.points_dropped},
          {"points_duplicate", s.points_duplicate},
          {"moves_duplicate", s.moves_duplicate},
          {"moves_in_place", s.moves_in_place},
          {"points_reentered", s.points_reentered},
          {"points_removed", s.points_removed},
          {"steiner_points", s.steiner_points},
          {"steiner_dropped", s.steiner_dropped},
          {"cells_grown", s.cells_grown},
          {"cells_shrunk", s.cells_shrunk},
          {"policy_calls", s.policy_calls},
          {"rays_scan_cells", s.rays_scan_cells},
          {"vertices", s.vertices},
          {"cells", s.cells},
          {"cells_in_o", s.cells_in_o}};
}

// When most points never entered the triangulation (all at one position, at a camera, or cut
// off by the reconstructed volume), the mesh rests on a few points and is mostly the Steiner
// grid's: "ok" alone would hide it. Empty when a half or less was refused (points refused at
// first and entered later, as they moved, count as entered).
std::string RefusedPointsWarning(const engine::EngineStats& s, const engine::Mesh& mesh) {
  const int64_t entered = s.points_inserted + s.points_reentered;
  const int64_t refused = s.points_dropped + s.points_duplicate - s.points_reentered;
  if (refused <= 0 || 2 * refused <= entered + refused) return {};
  std::size_t steiner_only = 0;
  if (mesh.point_ids.size() * 3 == mesh.vertices.size())
    for (std::size_t f = 0; f + 2 < mesh.faces.size(); f += 3)
      if (mesh.point_ids[mesh.faces[f]] < 0 && mesh.point_ids[mesh.faces[f + 1]] < 0 &&
          mesh.point_ids[mesh.faces[f + 2]] < 0)
        ++steiner_only;
  return "most points never entered the mesh: " + std::to_string(s.points_duplicate) +
         " new points were at the position of a point already in it and " +
         std::to_string(s.points_dropped) +
         " were dropped (their conflict zone met the reconstructed volume); " +
         std::to_string(s.points_reentered) + " of them entered later, as they moved, against " +
         std::to_string(s.points_inserted) + " inserted at once; " + std::to_string(steiner_only) +
         " of the mesh's " + std::to_string(mesh.faces.size() / 3) +
         " triangles touch no data point (Steiner grid only). Are the points' positions right?";
}

using Exporters = std::vector<std::pair<const io::StageSpec*, plugin::LoadedInstance>>;

// This process's resident memory (bytes), from /proc/self/statm; 0 when unreadable.
uint64_t ResidentBytes() {
  std::ifstream statm("/proc/self/statm");
  uint64_t pages_total = 0, pages_resident = 0;
  if (!(statm >> pages_total >> pages_resident)) return 0;
  return pages_resident * static_cast<uint64_t>(::sysconf(_SC_PAGESIZE));
}

// The --trace file: one JSON line per keyframe, flushed as it goes (a long run can be watched),
// under <path>.partial until the sequence ends, then renamed: a killed run never leaves a trace
// that looks complete.
class TraceFile {
 public:
  explicit TraceFile(fs::path path) : path_(std::move(path)), partial_(path_) {
    partial_ += ".partial";
    if (path_.has_parent_path()) fs::create_directories(path_.parent_path());
    out_.open(partial_, std::ios::trunc);
    if (!out_) throw std::runtime_error(partial_.string() + ": cannot write the trace");
  }
  ~TraceFile() { Finish(); }
  void Write(const json& line) {
    out_ << DumpJson(line) << '\n';
    out_.flush();
    if (!out_) throw std::runtime_error(partial_.string() + ": cannot write the trace");
  }
  const fs::path& Finish() {
    if (out_.is_open()) {
      out_.close();
      std::error_code ec;
      fs::rename(partial_, path_, ec);
      if (ec) LogWarning(path_.string() + ": cannot finish the trace: " + ec.message());
    }
    return path_;
  }

 private:
  fs::path path_, partial_;
  std::ofstream out_;
};

// What an export carries beside the mesh (SDK 1.1): the keyframes so far, their image files
// (inputs with images) and the source, which may know the points' colours.
struct ExportContext {
  std::vector<imr_camera> keyframes;
  std::vector<std::string> image_paths;  // one per keyframe, or empty: no images
  const io::KeyframeSource* source = nullptr;

  // Records the cameras of a keyframe update: the keyframe's own camera for image inputs (the
  // update also carries the frames between keyframes), every new camera for the others.
  void Add(const engine::KeyframeUpdate& update, const io::KeyframeInfo& kf,
           const ImageFrontEndSource* front_end) {
    auto camera_of = [&](const engine::Camera& c) {
      if (const io::CameraGeometry* g = source->Camera(c.id); g != nullptr)
        return ToPluginCamera(*g, g->intrinsics.width, g->intrinsics.height);
      io::CameraGeometry g;  // only the centre and rotation the engine got
      g.id = c.id;
      for (int r = 0; r < 3; ++r)
        for (int k = 0; k < 3; ++k) g.rotation[r][k] = c.rotation[3 * r + k];
      io::SetFromCenter(g.rotation, c.center, &g);
      return ToPluginCamera(g, 0, 0);
    };
    if (front_end != nullptr) {
      for (const engine::Camera& c : update.cameras) {
        if (c.id != static_cast<uint64_t>(kf.frame)) continue;
        keyframes.push_back(camera_of(c));
        image_paths.push_back(front_end->sequence().frames.at(c.id).image_path);
      }
      return;
    }
    for (const engine::Camera& c : update.cameras)
      if (seen_.insert(c.id).second) keyframes.push_back(camera_of(c));
  }

 private:
  std::set<uint64_t> seen_;
};

// How the keyframe images were served to one export (all formats of one mesh).
struct ExportImageStats {
  plugin::KeyframeImageStoreStats store;
  int keyframes = 0;
};

// Writes `mesh` into `directory` as stem.<format> for every format, each through the first
// exporter stage that writes it, with the keyframes of `context` (their images decoded on demand
// for this export only, within a bounded cache).
ExportImageStats ExportMesh(const engine::Mesh& mesh, const ExportContext& context,
                            const std::vector<std::string>& formats, const Exporters& exporters,
                            const fs::path& directory, const std::string& stem, StageWatch& watch,
                            double stage_timeout) {
  imr_mesh_view view{};
  view.struct_size = sizeof(view);
  view.vertices = mesh.vertices.data();
  view.vertex_count = mesh.vertices.size() / 3;
  view.faces = mesh.faces.data();
  view.face_count = mesh.faces.size() / 3;
  view.point_ids = mesh.point_ids.data();
  // The points' own colours, when the input gives any (grey where it gives none).
  std::vector<uint8_t> colors;
  if (context.source != nullptr && context.image_paths.empty()) {
    bool any = false;
    colors.assign(mesh.vertices.size(), 128);
    std::array<uint8_t, 3> rgb{};
    for (std::size_t i = 0; i < mesh.point_ids.size(); ++i)
      if (mesh.point_ids[i] >= 0 &&
          context.source->PointColor(static_cast<uint64_t>(mesh.point_ids[i]), &rgb)) {
        std::copy(rgb.begin(), rgb.end(), colors.begin() + static_cast<std::ptrdiff_t>(3 * i));
        any = true;
      }
    if (!any) colors.clear();
  }
  view.vertex_colors = colors.empty() ? nullptr : colors.data();
  std::optional<plugin::KeyframeImageStore> images;
  if (!context.image_paths.empty()) images.emplace(context.image_paths);
  const plugin::ScopedKeyframeImages scope(images ? &*images : nullptr);
  std::set<std::string> written;
  const std::string dir = directory.string();
  for (const std::string& mesh_format : formats) {
    for (const auto& [stage, inst] : exporters) {
      const std::string list = std::string(",") + inst.instance.descriptor()->exporter->formats + ",";
      if (list.find("," + mesh_format + ",") == std::string::npos || written.count(mesh_format))
        continue;
      imr_export_request req{};
      req.mesh = &view;
      req.directory = dir.c_str();
      req.stem = stem.c_str();
      req.format = mesh_format.c_str();
      req.keyframes = context.keyframes.empty() ? nullptr : context.keyframes.data();
      req.keyframe_count = context.keyframes.size();
      req.keyframe_images = images ? 1 : 0;
      const WatchedStage watched = WatchedStageOf(*stage, stage_timeout);
      const StageWatch::Call call = watch.Enter(watched);
      inst.instance.ExportMesh(&req);
      written.insert(mesh_format);
      if (images) images->ReleaseAll();  // holds end with the call (plugin.h)
    }
  }
  ExportImageStats stats;
  stats.keyframes = static_cast<int>(context.keyframes.size());
  if (images) stats.store = images->stats();
  return stats;
}

// What the sequence was made from, by content: SHA-256 of each file of the source (a file, or the
// files directly in its folder: calibration, poses, times) and, for image sequences, one digest
// over every image in frame order (the hash of their hashes), so a report says which bytes it
// describes.
json InputChecksums(const std::string& source, const ImageFrontEndSource* front_end) {
  json files = json::object();
  std::error_code ec;
  const fs::path root = front_end != nullptr ? fs::path(front_end->sequence().root) : fs::path(source);
  if (fs::is_regular_file(root, ec)) {
    files[root.filename().string()] = Sha256File(root);
  } else if (fs::is_directory(root, ec)) {
    std::vector<fs::path> list;
    for (const auto& e : fs::directory_iterator(root, ec))
      if (e.is_regular_file()) list.push_back(e.path());
    std::sort(list.begin(), list.end());
    for (const auto& f : list) files[f.filename().string()] = Sha256File(f);
  }
  json j = {{"algorithm", "sha256"}, {"files", files}};
  if (front_end != nullptr) {
    Sha256 all;
    const auto& frames = front_end->sequence().frames;
    for (const io::ImageFrame& f : frames) all.Update(Sha256File(f.image_path));
    j["images"] = {{"count", frames.size()}, {"sha256_of_sha256s", all.HexDigest()}};
  }
  return j;
}

// Accuracy against the ground truth the job names (its "evaluation" section), as the report's
// "accuracy": the paper's mean distance from ground truth to the mesh, completeness and precision
// at the job's tau, and host/eval's full report under "evaluation".
json EvaluateAgainstTruth(const json& options, const engine::Mesh& mesh,
                          const ImageFrontEndSource* front_end) {
  eval::TriangleMesh m;
  for (std::size_t i = 0; i + 2 < mesh.vertices.size(); i += 3)
    m.vertices.push_back({mesh.vertices[i], mesh.vertices[i + 1], mesh.vertices[i + 2]});
  for (std::size_t i = 0; i + 2 < mesh.faces.size(); i += 3)
    m.triangles.push_back({mesh.faces[i], mesh.faces[i + 1], mesh.faces[i + 2]});
  eval::EvaluationOptions o;
  const double tau = options.at("tau").get<double>();
  if (std::find(o.taus.begin(), o.taus.end(), tau) == o.taus.end()) o.taus.push_back(tau);
  std::sort(o.taus.begin(), o.taus.end());
  o.max_ray_length = options.at("max_ray_length").get<double>();
  o.crop = options.at("crop").get<bool>();
  o.precision_samples = 200000;  // per sequence in a batch: enough for 3 digits
  const std::string truth_name = options.at("truth").get<std::string>();
  std::vector<eval::Vec3> truth;
  json t;
  if (truth_name == "velodyne") {
    if (front_end == nullptr || !front_end->sequence().has_lidar)
      throw std::runtime_error("evaluation.truth \"velodyne\": the sequence has no Velodyne scans");
    eval::VelodyneTruth vt =
        eval::LoadVelodyneTruth(front_end->sequence(), options.at("scan_step").get<int>());
    truth = std::move(vt.points);
    t = {{"source", "velodyne"}, {"scans", vt.scans}, {"scan_step", options.at("scan_step")}};
  } else {
    eval::TriangleMesh g = eval::ReadGeometry(truth_name);
    t = {{"path", truth_name}};
    if (g.triangles.empty()) {
      truth = std::move(g.vertices);
      t["source"] = "point_cloud";
    } else {
      const double count = std::round(eval::MeshArea(g) * o.truth_density);
      if (count > 2e8) throw std::runtime_error(truth_name + ": reference mesh too large to sample");
      truth = eval::SampleSurface(g, static_cast<std::size_t>(count), o.seed ^ 0x5eedu);
      t["source"] = "mesh_samples";
    }
  }
  t["points"] = truth.size();
  std::vector<io::CameraGeometry> cameras;
  if (front_end != nullptr)
    for (const io::ImageFrame& f : front_end->sequence().frames) cameras.push_back(f.camera);
  const eval::Evaluation e = eval::Evaluate(m, truth, cameras, o);
  const std::size_t k = static_cast<std::size_t>(
      std::find(e.taus.begin(), e.taus.end(), tau) - e.taus.begin());
  auto stats = [](const eval::DistanceStats& d) {
    return json{{"count", d.count}, {"mean", d.mean}, {"median", d.median},
                {"rms", d.rms}, {"p90", d.p90}, {"max", d.max}};
  };
  return {{"reference", "ground truth (" + t.value("source", std::string()) + ")"},
          {"mean_truth_to_mesh", e.truth_to_mesh.mean},
          {"median_truth_to_mesh", e.truth_to_mesh.median},
          {"tau", tau},
          {"completeness", k < e.completeness.size() ? e.completeness[k] : 0.0},
          {"precision", k < e.precision.size() ? e.precision[k] : 0.0},
          {"evaluation",
           {{"truth", t},
            {"crop", {{"applied", e.cropped}, {"rule", e.crop_note},
                      {"truth_kept", e.truth_crop.kept}, {"truth_input", e.truth_crop.input}}},
            {"truth_to_mesh", stats(e.truth_to_mesh)},
            {"mesh_to_truth", stats(e.mesh_to_truth)},
            {"taus", e.taus},
            {"completeness", e.completeness},
            {"precision", e.precision},
            {"seconds", e.seconds_crop + e.seconds_truth_to_mesh + e.seconds_mesh_to_truth}}}};
}

void RunSequence(const ValidatedJob& v, const plugin::PluginRegistry& registry,
                 const RunOptions& options, const SequenceRef& seq, SequenceResult* result) {
  const auto start = std::chrono::steady_clock::now();
  const io::JobSpec& job = v.job;
  result->output_directory = job.OutputDirectory(seq.name);

  // Plugins: one policy (weights mode) and the exporters.
  std::optional<plugin::PluginWeightPolicy> policy;
  Exporters exporters;
  std::optional<plugin::LoadedInstance> features, refiner;
  // Every call into a plugin is watched against its stage's timeout: a hung plugin fails the
  // sequence (host/pipeline/stage_watch.h). Declared before the source, the policy adapter and
  // the engine, which call plugins through it.
  StageWatch watch(options.on_stage_timeout);
  std::vector<WatchedStage> watched;
  for (const io::StageSpec& stage : job.pipeline)
    watched.push_back(WatchedStageOf(stage, options.stage_timeout));
  std::size_t policy_stage = 0, features_stage = 0, refiner_stage = 0;
  json plugins_json = json::array();
  watch.SetPosition("creating the plugin instances");
  for (std::size_t i = 0; i < job.pipeline.size(); ++i) {
    const io::StageSpec& stage = job.pipeline[i];
    const plugin::PluginInfo* info = registry.Find(stage.plugin);
    plugins_json.push_back(PluginJson(*info, v.stage_params[i]));
    auto instance = [&] {
      const StageWatch::Call call = watch.Enter(watched[i]);
      try {
        return plugin::CreateInstance(*info, v.stage_params[i]);
      } catch (const std::exception& e) {  // name the stage: its params are in the job there
        throw std::runtime_error(stage.json_path + " (" + stage.kind + "): " + e.what());
      }
    }();
    if (stage.kind == "weight_policy") {
      policy.emplace(std::move(instance), info->id());
      policy_stage = i;
    } else if (stage.kind == "exporter") {
      exporters.emplace_back(&stage, std::move(instance));
    } else if (stage.kind == "features") {
      features.emplace(std::move(instance));
      features_stage = i;
    } else if (stage.kind == "refiner") {
      refiner.emplace(std::move(instance));
      refiner_stage = i;
    }
  }

  // Input -> engine, keyframe by keyframe.
  const io::InputFormat* format = io::FindInputFormat(job.input.format);
  std::unique_ptr<io::KeyframeSource> source;
  const ImageFrontEndSource* front_end = nullptr;
  if (format->needs_front_end) {
    // Images: the features and refiner plugins make the points (validation checked both exist).
    FrontEndOptions fo;
    fo.keyframe_every = io::ImageSequenceOptionsFromJson(v.input_options).keyframe_every;
    auto fe = std::make_unique<ImageFrontEndSource>(format->open_images(seq.source, v.input_options),
                                                    features->instance, refiner->instance, fo);
    fe->Watch(&watch, &watched[features_stage], &watched[refiner_stage]);
    front_end = fe.get();
    source = std::move(fe);
  } else {
    source = format->open(seq.source, v.input_options);
  }
  std::optional<WatchedPolicy> watched_policy;
  if (policy) watched_policy.emplace(&*policy, &watch, watched[policy_stage]);
  if (policy && v.engine_options.visibility_mode == engine::VisibilityMode::kExact)
    LogInfo("[" + seq.name + "] visibility_mode 'exact' keeps exact weights: the weight_policy "
            "stage (" + job.pipeline[policy_stage].plugin + ") is not called");
  // The scene's scale (scale.h): in auto mode the first keyframes are read, measured and kept
  // for the engine, which starts with the lengths they give.
  const ScaleMode scale_mode = ScaleModeOf(job.engine, job.input.format);
  std::set<std::string> explicit_keys;
  if (job.engine.is_object())
    for (const auto& item : job.engine.items()) explicit_keys.insert(item.key());
  ScaleProbe probe;
  ScaleEstimate scale;
  engine::EngineOptions engine_options = v.engine_options;
  std::deque<std::pair<engine::KeyframeUpdate, io::KeyframeInfo>> early;
  if (scale_mode == ScaleMode::kAuto) {
    while (!probe.Enough()) {
      if (plugin::CancelRequested()) throw std::runtime_error("cancelled (signal)");
      engine::KeyframeUpdate u;
      io::KeyframeInfo i;
      if (!source->Next(&u, &i)) break;
      probe.Add(u);
      early.emplace_back(std::move(u), i);
    }
    scale = probe.Estimate();
    if (scale.rays == 0) {
      LogWarning("[" + JsonText(seq.name) + "] engine.scale auto: no ray to measure in the first " +
                 std::to_string(scale.keyframes) + " keyframes; the metric defaults are kept");
    } else {
      engine_options = ScaledOptions(v.engine_options, scale, explicit_keys);
      std::string error;
      if (!engine_options.Check(&error))
        throw std::runtime_error("engine.scale auto (median ray " + std::to_string(scale.median_ray) +
                                 ") gives unusable options: " + error +
                                 "; set the engine's lengths in the job, or engine.scale \"metric\"");
      LogInfo("[" + JsonText(seq.name) + "] " + ScaleLogLine(scale, engine_options, explicit_keys));
    }
  }
  engine::Engine engine(engine_options, watched_policy ? &*watched_policy : nullptr);
  if (!engine.init_status().ok()) throw std::runtime_error("engine: " + engine.init_status().message());
  engine::KeyframeUpdate update;
  io::KeyframeInfo kf;
  // The keyframes read to decide the scale first, then the rest.
  auto next = [&](engine::KeyframeUpdate* u, io::KeyframeInfo* i) {
    if (early.empty()) return source->Next(u, i);
    *u = std::move(early.front().first);
    *i = early.front().second;
    early.pop_front();
    return true;
  };
  io::CanonicalOrder canonical;
  ExportContext export_context;
  export_context.source = source.get();
  std::optional<io::StreamRecorder> recorder;
  if (!options.export_stream.empty() || !options.export_colmap.empty())
    recorder.emplace(source.get(), std::string("imr ") + Version() + ", job " + job.Name() +
                                       ", sequence " + seq.name);
  std::optional<TraceFile> trace;
  if (!options.trace.empty()) trace.emplace(ExpandExportPath(options.trace, v, seq.name));
  int keyframes = 0, checks = 0;
  double engine_seconds = 0.0, snapshot_seconds = 0.0, check_seconds = 0.0;
  json snapshots = json::array();
  const int total_keyframes = source->KeyframeCount();
  const std::string of_total = total_keyframes > 0 ? "/" + std::to_string(total_keyframes) : "";
  while (next(&update, &kf)) {
    if (plugin::CancelRequested()) throw std::runtime_error("cancelled (signal)");
    if (scale_mode == ScaleMode::kMetric && !probe.Enough()) probe.Add(update);
    canonical.Apply(&update);
    watch.SetPosition("keyframe " + std::to_string(kf.index) + ", frame " + std::to_string(kf.frame));
    const auto engine_start = std::chrono::steady_clock::now();
    engine::Status st = engine.ApplyUpdate(update);
    const double keyframe_seconds = SecondsSince(engine_start);
    engine_seconds += keyframe_seconds;
    if (!st.ok())
      throw std::runtime_error("keyframe " + std::to_string(kf.index) + " (frame " +
                               std::to_string(kf.frame) + "): " + st.message());
    if (policy && policy->failed())
      throw std::runtime_error("keyframe " + std::to_string(kf.index) + ": weight policy " +
                               policy->error());
    if (recorder) recorder->Record(update, kf);
    export_context.Add(update, kf, front_end);
    ++keyframes;
    double this_check = -1.0;
    if (options.check_invariants_every > 0 && keyframes % options.check_invariants_every == 0) {
      const auto check_start = std::chrono::steady_clock::now();
      const engine::ManifoldCheckResult r = engine.CheckInvariants();
      this_check = SecondsSince(check_start);
      check_seconds += this_check;
      ++checks;
      if (!r.ok)
        throw std::runtime_error("keyframe " + std::to_string(kf.index) + " (frame " +
                                 std::to_string(kf.frame) + "): invariant check failed: " +
                                 r.message);
    }
    if (trace) {
      const engine::EngineStats& es = engine.Stats();
      json line = {{"keyframe", keyframes},       {"frame", kf.frame},
                   {"points", engine.NumPoints()}, {"vertices", es.vertices},
                   {"cells", es.cells},            {"cells_in_o", es.cells_in_o},
                   {"rss_bytes", ResidentBytes()}, {"engine_seconds", keyframe_seconds}};
      if (this_check >= 0.0) line["check_seconds"] = this_check;
      trace->Write(line);
    }
    if (job.output.snapshot_every > 0 && keyframes % job.output.snapshot_every == 0) {
      // Each snapshot is committed at once (whole files), so a running job can be watched.
      const auto snap_start = std::chrono::steady_clock::now();
      const engine::Mesh snap = engine.ExtractMesh();
      if (!snap.faces.empty()) {
        char stem[64];
        std::snprintf(stem, sizeof(stem), "_kf%06d", keyframes);
        StagingDirectory dir(result->output_directory / "snapshots");
        watch.SetPosition("snapshot after keyframe " + std::to_string(kf.index));
        ExportMesh(snap, export_context, job.output.formats, exporters, dir.path(),
                   job.output.stem + stem, watch, options.stage_timeout);
        for (auto& f : dir.Commit()) result->extra_files.push_back(std::move(f));
        snapshots.push_back({{"keyframe", keyframes}, {"frame", kf.frame},
                             {"stem", "snapshots/" + job.output.stem + stem},
                             {"faces", snap.faces.size() / 3}});
      }
      snapshot_seconds += SecondsSince(snap_start);
    }
    if (options.progress) options.progress({keyframes, total_keyframes, kf.frame});
    if (keyframes % 20 == 0 || keyframes == total_keyframes)
      LogInfo("[" + seq.name + "] keyframe " + std::to_string(keyframes) + of_total);
  }
  const engine::Mesh mesh = engine.ExtractMesh();
  const engine::ManifoldCheckResult boundary_check = engine.CheckInvariants();
  const engine::ManifoldCheckResult mesh_check = engine::CheckMesh(mesh, /*closed=*/false);
  if (!boundary_check.ok)
    throw std::runtime_error("invariant check failed after the last keyframe (" +
                             std::to_string(keyframes) + "): " + boundary_check.message);
  if (!mesh_check.ok) throw std::runtime_error("exported mesh check failed: " + mesh_check.message);

  // Rays longer than max_ray_length are not cast: most of them skipped usually means the
  // scene is not in metres (or is much larger or smaller than the defaults assume).
  const engine::EngineStats& stats = engine.Stats();
  // Warnings: on stderr and in report.json (the summary lists them).
  json warnings = json::array();
  auto warn = [&](const std::string& w) {
    LogWarning("[" + JsonText(seq.name) + "] " + w);
    warnings.push_back(w);
    result->warnings.push_back(w);
  };
  std::string scale_hint;
  if (stats.rays_skipped_too_long > stats.rays_cast) {
    scale_hint = std::to_string(stats.rays_skipped_too_long) + " of " +
                 std::to_string(stats.rays_skipped_too_long + stats.rays_cast) +
                 " rays were longer than engine.max_ray_length (" +
                 std::to_string(engine_options.max_ray_length) +
                 "): set max_ray_length and steiner_spacing to the scene's scale";
    warn(scale_hint);
  }
  // A metric job on a scene of another size: say so, with the values auto would choose.
  if (scale_mode == ScaleMode::kMetric) {
    const ScaleEstimate e = probe.Estimate();
    if (e.rays > 0 && (e.factor < 0.25 || e.factor > 4.0)) {
      const engine::EngineOptions proposed = ScaledOptions(engine_options, e, explicit_keys);
      std::string hint = ScaleLogLine(e, proposed, explicit_keys);
      hint.replace(0, std::string("engine.scale auto: ").size(), "");
      scale_hint = std::string("the scene is ") + (e.factor < 1.0 ? "far smaller" : "far larger") +
                   " than the engine's metric defaults assume: " + hint +
                   " would fit; set engine.scale \"auto\" (or these options) in the job";
      warn(scale_hint);
    }
  }
  if (const std::string w = RefusedPointsWarning(stats, mesh); !w.empty()) warn(w);
  if (mesh.faces.empty())
    throw std::runtime_error("no surface was reconstructed (0 triangles after " +
                             std::to_string(keyframes) + " keyframes): nothing to export" +
                             (scale_hint.empty() ? "" : "; " + scale_hint));

  // Exports first (each whole or absent), then the mesh, then the report.
  json exports = json::object();
  if (recorder && recorder->unrepresentable() > 0)
    warn(std::to_string(recorder->unrepresentable()) +
         " points entered the engine with no camera: the exported stream cannot hold them, so "
         "its replay will differ");
  if (!options.export_stream.empty()) {
    const fs::path p = ExpandExportPath(options.export_stream, v, seq.name);
    if (p.has_parent_path()) fs::create_directories(p.parent_path());
    WriteFileAtomically(p, recorder->SlamJson());
    exports["stream"] = fs::absolute(p).string();
    result->extra_files.push_back(p);
  }
  if (!options.export_colmap.empty()) {
    const fs::path p = ExpandExportPath(options.export_colmap, v, seq.name);
    StagingDirectory colmap(p);
    io::WriteColmapText(recorder->Colmap(), colmap.path());
    for (auto& f : colmap.Commit()) result->extra_files.push_back(std::move(f));
    exports["colmap"] = fs::absolute(p).string();
  }

  nlohmann::json accuracy = source->Evaluate(mesh);
  nlohmann::json known_scene;
  double evaluation_seconds = 0.0;
  if (!v.evaluation.is_null()) {
    // The job's ground truth wins the "accuracy" key (the summary's column); a known synthetic
    // scene's figures stay beside it.
    const auto eval_start = std::chrono::steady_clock::now();
    known_scene = std::move(accuracy);
    accuracy = EvaluateAgainstTruth(v.evaluation, mesh, front_end);
    evaluation_seconds = SecondsSince(eval_start);
  }

  const auto export_start = std::chrono::steady_clock::now();
  StagingDirectory staging(result->output_directory);
  watch.SetPosition("writing the mesh after the last keyframe");
  const ExportImageStats export_images =
      ExportMesh(mesh, export_context, job.output.formats, exporters, staging.path(),
                 job.output.stem, watch, options.stage_timeout);
  const std::vector<std::string> commit_last = {job.output.stem + ".gltf", "report.json"};
  const double export_seconds = SecondsSince(export_start);

  json report;
  report["imr_version"] = Version();
  report["job"] = fs::absolute(job.file).lexically_normal().string();
  report["sequence"] = {{"name", seq.name}, {"source", seq.source}};
  report["input"] = {{"format", job.input.format}, {"options", v.input_options}};
  if (format->sequences_are_paths) report["input"]["checksums"] = InputChecksums(seq.source, front_end);
  if (const json summary = source->Summary(); !summary.is_null()) report["input"]["summary"] = summary;
  report["engine_options"] = io::EngineOptionsToJson(engine_options);
  report["engine_scale"] = ScaleJson(scale_mode, scale, engine_options, explicit_keys);
  report["plugins"] = plugins_json;
  report["engine"] = StatsJson(engine.Stats());
  report["engine"]["keyframe_seconds"] = engine.Stats().keyframe_seconds;
  // Time of the move phase per moved point. The paper's per-move overhead, (T_mov - T_nonmov) /
  // N_mov, needs a second run with frozen points: imr-bench paper measures it.
  report["engine"]["move_seconds_per_moved_point"] =
      engine.Stats().points_moved > 0
          ? engine.Stats().time.move / static_cast<double>(engine.Stats().points_moved)
          : 0.0;
  report["mesh"] = {{"vertices", mesh.vertices.size() / 3},
                    {"faces", mesh.faces.size() / 3},
                    {"manifold", mesh_check.ok},
                    {"boundary_closed_manifold", boundary_check.ok},
                    {"boundary_triangles", boundary_check.boundary_triangles}};
  // Topology of what was written: components, Euler characteristic, genus, boundary loops.
  report["mesh"]["stats"] = eval::ComputeMeshStatistics(mesh.vertices, mesh.faces).ToJson();
  if (!accuracy.is_null()) report["accuracy"] = accuracy;
  if (!known_scene.is_null()) report["accuracy_known_scene"] = known_scene;
  // Wall time per stage of the chain (reader -> features -> refiner -> engine -> exporter).
  json stages = json::object();
  if (front_end != nullptr) {
    const FrontEndStats& fs_ = front_end->stats();
    stages["read_images"] = fs_.read_seconds;
    stages["features"] = fs_.features_seconds;
    stages["refiner"] = fs_.refiner_seconds;
  }
  stages["engine"] = engine_seconds;
  stages["export"] = export_seconds;
  // What the exporters were given (SDK 1.1) and how the keyframe images were served to them.
  report["export_input"] = {{"keyframes", export_images.keyframes},
                      {"keyframe_images", !export_context.image_paths.empty()}};
  if (export_images.store.requests > 0)
    report["export_input"]["image_service"] = {{"requests", export_images.store.requests},
                                         {"decodes", export_images.store.decodes},
                                         {"evictions", export_images.store.evictions},
                                         {"peak_bytes", export_images.store.peak_bytes},
                                         {"decode_seconds", export_images.store.decode_seconds}};
  if (!snapshots.empty()) stages["snapshots"] = snapshot_seconds;
  if (!v.evaluation.is_null()) stages["evaluation"] = evaluation_seconds;
  report["stage_seconds"] = stages;
  if (!snapshots.empty()) report["snapshots"] = snapshots;
  if (!exports.empty()) report["exports"] = exports;
  if (!warnings.empty()) report["warnings"] = warnings;
  if (options.check_invariants_every > 0)
    report["invariant_checks"] = {{"every", options.check_invariants_every},
                                  {"count", checks},
                                  {"seconds", check_seconds}};
  if (trace) {
    const fs::path p = trace->Finish();
    report["trace"] = fs::absolute(p).string();
    result->extra_files.push_back(p);
  }
  json files = json::array();
  for (const auto& f : staging.Staged(commit_last)) files.push_back(f.filename().string());
  report["files"] = files;
  result->seconds = SecondsSince(start);
  report["seconds"] = result->seconds;
  // report.json is staged with the meshes and moved in last: when it cannot be written (a full
  // disk) no mesh of the failed run is left under a final name either.
  WriteFileAtomically(staging.path() / "report.json", DumpJson(report, 2) + "\n");
  result->files = staging.Commit(commit_last);
  result->report = std::move(report);
  result->ok = true;
}

}  // namespace

std::vector<std::string> RunOptionsToArgs(const RunOptions& o) {
  std::vector<std::string> args;
  const std::pair<const char*, const std::string*> paths[] = {
      {"--export-stream", &o.export_stream}, {"--export-colmap", &o.export_colmap},
      {"--trace", &o.trace}};
  for (const auto& [flag, value] : paths)
    if (!value->empty()) args.insert(args.end(), {flag, *value});
  if (o.check_invariants_every > 0)
    args.insert(args.end(), {"--check-invariants-every", std::to_string(o.check_invariants_every)});
  if (o.stage_timeout > 0.0) {
    char seconds[32];
    std::snprintf(seconds, sizeof(seconds), "%.17g", o.stage_timeout);
    args.insert(args.end(), {"--stage-timeout", seconds});
  }
  return args;
}

std::vector<std::string> CheckRunOptions(const RunOptions& o, const ValidatedJob& v) {
  std::vector<std::string> problems;
  if (const std::string e = CheckStageTimeout(o.stage_timeout); !e.empty())
    problems.push_back("--stage-timeout: " + e);
  if (o.check_invariants_every < 0)
    problems.push_back("--check-invariants-every " + std::to_string(o.check_invariants_every) +
                       ": expected a number of keyframes >= 1");
  const std::pair<const char*, const std::string*> flags[] = {
      {"--export-stream", &o.export_stream}, {"--export-colmap", &o.export_colmap},
      {"--trace", &o.trace}};
  for (const auto& [flag, value] : flags) {
    if (value->empty() || v.sequences.size() < 2) continue;
    if (value->find("{sequence}") == std::string::npos && value->find("{output}") == std::string::npos)
      problems.push_back(std::string(flag) + " " + *value + ": the job has " +
                         std::to_string(v.sequences.size()) +
                         " sequences; put {sequence} or {output} in the path so that each gets "
                         "its own (e.g. '{output}/stream.json')");
  }
  // An export must not be (or hold) an output folder: a stream file where a sequence's folder
  // goes breaks that sequence on every later run.
  auto folder = [](const fs::path& p) {
    fs::path n = fs::absolute(p).lexically_normal();
    return n.has_relative_path() && n.filename().empty() ? n.parent_path() : n;
  };
  std::map<fs::path, std::string> folders;  // output folders and their parents -> a sequence
  for (const SequenceRef& s : v.sequences)
    for (fs::path p = folder(v.job.OutputDirectory(s.name)); p.has_relative_path(); p = p.parent_path())
      folders.emplace(p, s.name);
  for (const auto& [flag, value] : flags) {
    if (value->empty()) continue;
    for (const SequenceRef& s : v.sequences) {
      const fs::path p = folder(ExpandExportPath(*value, v, s.name));
      const auto it = folders.find(p);
      if (it == folders.end()) continue;
      problems.push_back(std::string(flag) + " " + *value + ": " + p.string() +
                         (p == folder(v.job.OutputDirectory(it->second))
                              ? " is the output folder of sequence '"
                              : " holds the output folder of sequence '") +
                         JsonText(it->second) + "'; name a file (or folder) of its own, e.g. " +
                         "'{output}/stream.json'");
      break;
    }
  }
  for (const auto& [a, b] : {std::pair{&o.export_stream, &o.export_colmap},
                             std::pair{&o.export_stream, &o.trace},
                             std::pair{&o.export_colmap, &o.trace}})
    if (!a->empty() && *a == *b)
      problems.push_back("two of --export-stream, --export-colmap and --trace name the same "
                         "path (" + *a + ")");
  return problems;
}

fs::path ExpandExportPath(const std::string& tmpl, const ValidatedJob& v, const std::string& sequence) {
  return io::ExpandTemplate(tmpl, {{"{sequence}", sequence},
                                   {"{job}", v.job.Name()},
                                   {"{output}", v.job.OutputDirectory(sequence).string()}});
}

SequenceResult RunOneSequence(const ValidatedJob& v, const plugin::PluginRegistry& registry,
                              const RunOptions& options, const SequenceRef& seq) {
  SequenceResult r;
  r.name = seq.name;
  const auto start = std::chrono::steady_clock::now();
  try {
    RunSequence(v, registry, options, seq, &r);
  } catch (const std::exception& e) {
    r.ok = false;
    r.error = e.what();
    r.seconds = SecondsSince(start);
    LogError("sequence " + seq.name + " failed: " + r.error);
  }
  return r;
}

BatchResult RunJob(const ValidatedJob& v, const plugin::PluginRegistry& registry,
                   const RunOptions& options) {
  BatchResult batch;
  for (std::size_t i = 0; i < v.sequences.size(); ++i) {
    const SequenceRef& seq = v.sequences[i];
    LogInfo("[" + std::to_string(i + 1) + "/" + std::to_string(v.sequences.size()) +
            "] sequence " + seq.name);
    batch.sequences.push_back(RunOneSequence(v, registry, options, seq));
  }
  return batch;
}

}  // namespace imr::pipeline
