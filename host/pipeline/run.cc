#include "host/pipeline/run.h"

#include "host/io/engine_options.h"
#include "host/plugin/host_services.h"
#include "host/plugin/policy_adapter.h"
#include "host/io/input_formats.h"
#include "host/util/atomic_file.h"
#include "host/util/log.h"

#include <chrono>
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

double Seconds(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

json PluginJson(const plugin::PluginInfo& info, const json& params) {
  return {{"id", info.id()},     {"version", info.version()}, {"kind", info.kind()},
          {"abi", info.abi()},   {"file", info.file.string()}, {"params", params}};
}

json StatsJson(const engine::EngineStats& s) {
  const auto& t = s.time;
  return {{"seconds", {{"steiner", t.steiner}, {"shrink", t.shrink}, {"move", t.move},
                       {"insert", t.insert}, {"cast", t.cast}, {"grow", t.grow},
                       {"extract", t.extract}, {"total", t.total}}},
          {"keyframes", s.updates},
          {"rays_cast", s.rays_cast},
          {"rays_cast_backward", s.rays_cast_backward},
          {"rays_skipped_too_long", s.rays_skipped_too_long},
          {"rays_truncated", s.rays_truncated},
          {"cells_traversed", s.cells_traversed},
          {"points_inserted", s.points_inserted},
          {"points_moved", s.points_moved},
          {"moves_skipped", s.moves_skipped},
          {"points_dropped", s.points_dropped},
          {"points_removed", s.points_removed},
          {"steiner_points", s.steiner_points},
          {"cells_grown", s.cells_grown},
          {"cells_shrunk", s.cells_shrunk},
          {"vertices", s.vertices},
          {"cells", s.cells},
          {"cells_in_o", s.cells_in_o}};
}

void RunSequence(const ValidatedJob& v, const plugin::PluginRegistry& registry,
                 const SequenceRef& seq, SequenceResult* result) {
  const auto start = std::chrono::steady_clock::now();
  const io::JobSpec& job = v.job;
  result->output_directory = job.OutputDirectory(seq.name);

  // Plugins: one policy (weights mode) and the exporters.
  std::optional<plugin::PluginWeightPolicy> policy;
  std::vector<std::pair<const io::StageSpec*, plugin::LoadedInstance>> exporters;
  json plugins_json = json::array();
  for (std::size_t i = 0; i < job.pipeline.size(); ++i) {
    const io::StageSpec& stage = job.pipeline[i];
    const plugin::PluginInfo* info = registry.Find(stage.plugin);
    plugins_json.push_back(PluginJson(*info, v.stage_params[i]));
    auto instance = plugin::CreateInstance(*info, v.stage_params[i]);
    if (stage.kind == "weight_policy")
      policy.emplace(std::move(instance), info->id());
    else if (stage.kind == "exporter")
      exporters.emplace_back(&stage, std::move(instance));
  }

  // Input -> engine, keyframe by keyframe.
  const io::InputFormat* format = io::FindInputFormat(job.input.format);
  std::unique_ptr<io::KeyframeSource> source = format->open(seq.source, v.input_options);
  engine::Engine engine(v.engine_options, policy ? &*policy : nullptr);
  if (!engine.init_status().ok()) throw std::runtime_error("engine: " + engine.init_status().message());
  engine::KeyframeUpdate update;
  io::KeyframeInfo kf;
  int keyframes = 0;
  const int total_keyframes = source->KeyframeCount();
  const std::string of_total = total_keyframes > 0 ? "/" + std::to_string(total_keyframes) : "";
  while (source->Next(&update, &kf)) {
    if (plugin::CancelRequested()) throw std::runtime_error("cancelled (signal)");
    engine::Status st = engine.ApplyUpdate(update);
    if (!st.ok())
      throw std::runtime_error("keyframe " + std::to_string(kf.index) + " (frame " +
                               std::to_string(kf.frame) + "): " + st.message());
    if (policy && policy->failed())
      throw std::runtime_error("keyframe " + std::to_string(kf.index) + ": weight policy " +
                               policy->error());
    ++keyframes;
    if (keyframes % 20 == 0 || keyframes == total_keyframes)
      LogInfo("[" + seq.name + "] keyframe " + std::to_string(keyframes) + of_total);
  }
  const engine::Mesh mesh = engine.ExtractMesh();
  const engine::ManifoldCheckResult boundary_check = engine.CheckInvariants();
  const engine::ManifoldCheckResult mesh_check = engine::CheckMesh(mesh, /*closed=*/false);
  if (!boundary_check.ok) throw std::runtime_error("manifold check failed: " + boundary_check.message);
  if (!mesh_check.ok) throw std::runtime_error("exported mesh check failed: " + mesh_check.message);

  if (mesh.faces.empty())
    throw std::runtime_error("no surface was reconstructed (0 triangles after " +
                             std::to_string(keyframes) + " keyframes): nothing to export");

  const nlohmann::json accuracy = source->Evaluate(mesh);

  // Export every requested format once, through the first exporter stage that writes it.
  StagingDirectory staging(result->output_directory);
  imr_mesh_view view{};
  view.struct_size = sizeof(view);
  view.vertices = mesh.vertices.data();
  view.vertex_count = mesh.vertices.size() / 3;
  view.faces = mesh.faces.data();
  view.face_count = mesh.faces.size() / 3;
  view.point_ids = mesh.point_ids.data();
  std::set<std::string> written;
  for (const std::string& format : job.output.formats) {
    for (auto& [stage, inst] : exporters) {
      const std::string list = std::string(",") + inst.instance.descriptor()->exporter->formats + ",";
      if (list.find("," + format + ",") == std::string::npos || written.count(format)) continue;
      imr_export_request req{};
      req.mesh = &view;
      const std::string dir = staging.path().string();
      req.directory = dir.c_str();
      req.stem = job.output.stem.c_str();
      req.format = format.c_str();
      inst.instance.ExportMesh(&req);
      written.insert(format);
    }
  }
  result->files = staging.Commit(job.output.stem + ".gltf");

  json report;
  report["imr_version"] = Version();
  report["job"] = fs::absolute(job.file).string();
  report["sequence"] = {{"name", seq.name}, {"source", seq.source}};
  report["input"] = {{"format", job.input.format}, {"options", v.input_options}};
  report["engine_options"] = io::EngineOptionsToJson(v.engine_options);
  report["plugins"] = plugins_json;
  report["engine"] = StatsJson(engine.Stats());
  report["mesh"] = {{"vertices", mesh.vertices.size() / 3},
                    {"faces", mesh.faces.size() / 3},
                    {"manifold", mesh_check.ok},
                    {"boundary_closed_manifold", boundary_check.ok},
                    {"boundary_triangles", boundary_check.boundary_triangles}};
  if (!accuracy.is_null()) report["accuracy"] = accuracy;
  json files = json::array();
  for (const auto& f : result->files) files.push_back(f.filename().string());
  report["files"] = files;
  result->seconds = Seconds(start);
  report["seconds"] = result->seconds;
  const fs::path report_path = result->output_directory / "report.json";
  WriteFileAtomically(report_path, report.dump(2) + "\n");
  result->files.push_back(report_path);
  result->report = std::move(report);
  result->ok = true;
}

}  // namespace

BatchResult RunJob(const ValidatedJob& v, const plugin::PluginRegistry& registry) {
  BatchResult batch;
  for (std::size_t i = 0; i < v.sequences.size(); ++i) {
    const SequenceRef& seq = v.sequences[i];
    LogInfo("[" + std::to_string(i + 1) + "/" + std::to_string(v.sequences.size()) +
            "] sequence " + seq.name);
    SequenceResult r;
    r.name = seq.name;
    const auto start = std::chrono::steady_clock::now();
    try {
      RunSequence(v, registry, seq, &r);
    } catch (const std::exception& e) {
      r.ok = false;
      r.error = e.what();
      r.seconds = Seconds(start);
      LogError("sequence " + seq.name + " failed: " + r.error);
    }
    batch.sequences.push_back(std::move(r));
  }
  return batch;
}

}  // namespace imr::pipeline
