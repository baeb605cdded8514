#include "host/python/session.h"

#include "host/batch/manifest.h"
#include "host/eval/evaluate.h"
#include "host/io/engine_options.h"
#include "host/io/input_formats.h"
#include "host/io/schema.h"
#include "host/pipeline/job_validation.h"
#include "host/pipeline/report.h"
#include "host/pipeline/run.h"
#include "host/pipeline/stage_watch.h"
#include "host/plugin/host_services.h"
#include "host/util/atomic_file.h"
#include "host/util/write_rule.h"
#include "host/util/log.h"

#include <algorithm>
#include <cctype>

namespace imr::python {
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

json ParseObject(const std::string& text, const std::string& what) {
  json j;
  try {
    j = json::parse(text);
  } catch (const std::exception& e) {
    throw OptionError(what + ": not JSON (" + std::string(e.what()) + ")");
  }
  if (!j.is_object()) throw OptionError(what + ": expected an object, got " + io::Describe(j));
  return j;
}

std::string Joined(const std::vector<io::Problem>& problems) {
  std::string s;
  for (const io::Problem& p : problems) s += (s.empty() ? "" : "; ") + p.ToString();
  return s;
}

// The engine-option problems as a job's validation words them, with each option's bounds.
void CheckEngineOptions(const json& j, engine::EngineOptions* options) {
  std::vector<io::Problem> problems;
  if (!io::EngineOptionsFromJson(j, options, &problems)) throw OptionError(Joined(problems));
}

plugin::PluginRegistry& ScannedRegistry(plugin::PluginRegistry* registry) {
  if (registry->searched().empty()) {
    registry->Scan(plugin::PluginRegistry::DefaultSearchPaths());
    for (const auto& r : registry->refusals()) LogWarning("plugin refused: " + r.ToString());
  }
  return *registry;
}

// A plugin of `kind` by id, as a job's stage names it (the same message for an unknown id).
const plugin::PluginInfo& FindPlugin(plugin::PluginRegistry& registry, const std::string& id,
                                     const std::string& kind, const std::string& path) {
  const plugin::PluginInfo* info = registry.Find(id);
  if (info == nullptr) {
    auto known = registry.Ids(kind);
    throw OptionError(path + ": unknown plugin id " + io::Describe(id) + " (known " + kind +
                      " plugins: " + (known.empty() ? std::string("none") : io::JoinAlternatives(known)) +
                      "; run `imr plugins` to see what was found and refused)");
  }
  if (info->kind() != kind)
    throw OptionError(path + ": plugin " + info->id() + " (" + info->file.string() + ") is a " +
                      info->kind() + " plugin, expected a " + kind + " plugin");
  return *info;
}

// The source of keyframes the caller builds: it knows no more of a camera than the keyframe says
// (the exports take its centre and rotation) and no colours.
class CallerSource : public io::KeyframeSource {
 public:
  bool Next(engine::KeyframeUpdate*, io::KeyframeInfo*) override { return false; }
};

}  // namespace

void SetPluginDirectory(const fs::path& directory) {
  plugin::PluginRegistry::SetInstalledPluginDirectory(directory);
}

// --- Reader ---

Reader::Reader(const std::string& format, const std::string& path, const std::string& options_json)
    : format_(format) {
  const io::InputFormat* f = io::FindInputFormat(format);
  if (f == nullptr || f->needs_front_end) {
    std::vector<std::string> names;
    for (const io::InputFormat& x : io::InputFormats())
      if (!x.needs_front_end) names.push_back(x.name);
    throw OptionError("input.format: expected " + io::JoinAlternatives(names) + ", got " +
                      io::Describe(format) +
                      (f != nullptr ? " (an image format: run it as a job, imr.run)" : ""));
  }
  const json options = ParseObject(options_json, "input.options");
  std::vector<io::Problem> problems;
  io::ValidateAgainstSchema(f->options_schema, options, "input.options", &problems);
  const json with_defaults = io::WithDefaults(f->options_schema, options);
  if (problems.empty() && f->check)
    for (std::string& m : f->check(with_defaults)) problems.push_back({"input.options", std::move(m)});
  if (!problems.empty()) throw OptionError(Joined(problems));
  const std::string source =
      f->sequences_are_paths ? fs::absolute(path).lexically_normal().string() : path;
  if (f->sequences_are_paths && !fs::exists(source))
    throw std::runtime_error(source + ": no such file or folder");
  source_ = f->open(source, with_defaults);
}

std::optional<Keyframe> Reader::Next() {
  Keyframe k;
  if (!source_->Next(&k.update, &k.info)) return std::nullopt;
  k.format = format_;
  k.source = source_;
  return k;
}

// --- Session ---

Session::Session(const std::string& engine_json, const std::string& policy,
                 const std::string& policy_params)
    : engine_json_(ParseObject(engine_json, "engine")) {
  CheckEngineOptions(engine_json_, &base_options_);
  for (const auto& item : engine_json_.items()) explicit_keys_.insert(item.key());
  options_ = base_options_;
  // The Steiner grid's size, as a job's validation checks it once the lengths are known: here
  // with the lengths as given (metric scale, the default for keyframes built by the caller) unless
  // engine.scale is "auto" and a length is left to it; then when the first keyframes set them.
  if (engine_json_.value("scale", "") != "auto" ||
      (engine_json_.contains("steiner_spacing") && engine_json_.contains("steiner_margin") &&
       engine_json_.contains("max_ray_length")))
    if (const std::string grid = base_options_.CheckSteinerGrid(); !grid.empty())
      throw OptionError("engine: " + grid);
  sources_.push_back(std::make_shared<CallerSource>());
  export_context_.source = sources_.back().get();
  const json params = ParseObject(policy_params, "weight_policy_params");
  if (!policy.empty()) {
    plugin::PluginRegistry& registry = ScannedRegistry(&registry_);
    const plugin::PluginInfo& info = FindPlugin(registry, policy, "weight_policy", "weight_policy");
    std::vector<io::Problem> problems;
    io::ValidateAgainstSchema(info.params_schema, params, "weight_policy_params", &problems);
    if (!problems.empty()) throw OptionError(Joined(problems));
    policy_.emplace(plugin::CreateInstance(info, io::WithDefaults(info.params_schema, params)), info.id());
    if (base_options_.visibility_mode == engine::VisibilityMode::kRays)
      throw OptionError("weight_policy: visibility_mode 'rays' does not use a weight_policy; remove it");
  } else if (!params.empty()) {
    throw OptionError("weight_policy_params: given without a weight_policy");
  } else if (base_options_.visibility_mode == engine::VisibilityMode::kWeights) {
    throw OptionError("weight_policy: visibility_mode 'weights' needs a weight_policy plugin "
                      "(e.g. weight_policy=\"org.imr.policy.nearest\")");
  }
}

Session::~Session() = default;

void Session::Add(Keyframe k) {
  if (k.format.empty()) k.info = {keyframes_ + static_cast<int>(early_.size()), keyframes_ + static_cast<int>(early_.size())};
  // What the readers check of their cameras, positions and ids, before the keyframe is held or
  // applied: a bad one is refused here, whatever engine.scale holds back.
  if (const std::string p = check_.Check(&k.update, k.info.index); !p.empty())
    throw OptionError("keyframe " + std::to_string(k.info.index) + " (frame " + std::to_string(k.info.frame) +
                      "): " + p);
  if (!scale_mode_) {
    scale_mode_ = pipeline::ScaleModeOf(engine_json_, k.format);
    if (*scale_mode_ == pipeline::ScaleMode::kMetric)
      if (const std::string grid = base_options_.CheckSteinerGrid(); !grid.empty()) {
        scale_mode_.reset();
        throw OptionError("engine: " + grid);
      }
  }
  if (k.source && std::find(sources_.begin(), sources_.end(), k.source) == sources_.end()) {
    sources_.push_back(k.source);
    export_context_.source = k.source.get();  // its points' colours, as a job's run gives them
  }
  if (!engine_ && *scale_mode_ == pipeline::ScaleMode::kAuto) {
    // As the run does: the first keyframes decide the scene's scale before the engine starts.
    probe_.Add(k.update);
    early_.push_back(std::move(k));
    if (probe_.Enough()) Start();
    return;
  }
  if (!engine_) Start();
  Apply(std::move(k));
}

void Session::Start() {
  options_ = base_options_;
  if (scale_mode_ == pipeline::ScaleMode::kAuto) {
    scale_ = probe_.Estimate();
    std::string line;
    options_ = pipeline::AutoScaledOptions(base_options_, scale_, explicit_keys_, &line);
    (scale_.rays == 0 ? LogWarning : LogInfo)(line);
  }
  engine_.emplace(options_, policy_ ? &*policy_ : nullptr);
  if (!engine_->init_status().ok()) {
    const std::string message = engine_->init_status().message();
    engine_.reset();
    throw std::runtime_error("engine: " + message);
  }
  // Ctrl-C (module.cc turns it into a cancel request) reaches the engine's long loops.
  engine_->SetStopCheck([] { return plugin::CancelRequested(); });
  while (!early_.empty()) {
    Keyframe k = std::move(early_.front());
    early_.pop_front();
    Apply(std::move(k));
  }
}

void Session::Apply(Keyframe k) {
  if (k.source) in_front_.Add(k.update, *k.source);
  canonical_.Apply(&k.update);
  // A reader's last keyframe is not the engine's: the module's user may add keyframes after it
  // (another reader's, their own), so its rays are kept as every other keyframe's.
  k.update.last = false;
  const engine::Status st = engine_->ApplyUpdate(k.update);
  if (!st.ok())
    throw std::runtime_error("keyframe " + std::to_string(k.info.index) + " (frame " +
                             std::to_string(k.info.frame) + "): " + st.message());
  if (policy_ && policy_->failed())
    throw std::runtime_error("keyframe " + std::to_string(k.info.index) + ": weight policy " +
                             policy_->error());
  export_context_.Add(k.update, k.info, nullptr);
  ++keyframes_;
  // engine.forget (auto: once the cameras travel): what became final leaves the engine; the
  // session keeps it, a mesh far smaller than the engine's state, for Mesh().
  for (engine::SurfacePart& part : engine_->TakeFinalParts()) final_parts_.push_back(std::move(part));
}

engine::Mesh Session::Mesh() {
  if (!engine_) Start();
  if (final_parts_.empty()) return engine_->ExtractMesh();
  std::vector<engine::SurfacePart> parts = final_parts_;
  parts.push_back(engine_->LiveSurface());
  engine::Mesh mesh;
  if (const std::string e = engine::MergeSurfaceParts(parts, &mesh); !e.empty())
    throw std::runtime_error("the surface's parts do not fit together: " + e);
  engine::FinishExportedMesh(&mesh, engine_->options());
  return mesh;
}

json Session::Stats() {
  json j = pipeline::EngineStatsJson(engine_ ? engine_->Stats() : engine::EngineStats{});
  j["keyframes_held"] = early_.size();  // waiting for engine.scale auto
  j["scale"] = pipeline::ScaleJson(scale_mode_.value_or(pipeline::ScaleMode::kMetric), scale_,
                                   options_, explicit_keys_);
  return j;
}

json Session::Options() const { return io::EngineOptionsToJson(options_); }

void Session::Write(const fs::path& file) {
  std::string format = file.extension().string();
  for (char& c : format) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (format != ".ply" && format != ".obj" && format != ".gltf" && format != ".glb")
    throw OptionError("write: expected a file ending in .ply, .obj, .gltf or .glb, got '" +
                      file.filename().string() + "'");
  format = format.substr(1);
  CheckWriteTarget(fs::absolute(file));  // the write rule of every command (write_rule.h)
  const engine::Mesh mesh = Mesh();
  plugin::PluginRegistry& registry = ScannedRegistry(&registry_);
  const plugin::PluginInfo& info = FindPlugin(registry, "org.imr.exporter.assimp", "exporter", "exporter");
  io::StageSpec stage;
  stage.kind = "exporter";
  stage.plugin = info.id();
  stage.json_path = "exporter";
  pipeline::Exporters exporters;
  exporters.emplace_back(&stage, plugin::CreateInstance(info, io::WithDefaults(info.params_schema, json::object())));
  pipeline::StageWatch watch;
  // Staged and renamed into place, as imr run writes its outputs: no half-written mesh.
  const fs::path directory = fs::absolute(file).parent_path();
  StagingDirectory staging(directory);
  pipeline::ExportMesh(mesh, export_context_, {format}, exporters, staging.path(), file.stem().string(),
                       watch, 0.0);
  staging.Commit();
}

// --- imr run, imr evaluate ---

json RunJob(const std::string& job_file, const std::string* job_text,
            const std::vector<std::string>& overrides, int threads, const std::string& job_name) {
  // A dict's job has no file: its messages name what the caller gave, not the anchor path.
  const std::string name = job_name.empty() ? job_file : job_name;
  const auto named = [&](std::string s) {
    if (job_name.empty()) return s;
    for (std::size_t at = s.find(job_file); at != std::string::npos; at = s.find(job_file, at + name.size()))
      s.replace(at, job_file.size(), name);
    return s;
  };
  plugin::PluginRegistry registry;
  const pipeline::ValidatedJob v =
      job_text != nullptr ? pipeline::LoadAndValidateJobText(*job_text, job_file, &registry, overrides)
                          : pipeline::LoadAndValidateJob(job_file, &registry, overrides);
  if (!v.ok()) {  // as imr run prints them (cli/command.cc PrintProblems)
    std::string s = name + ": " + std::to_string(v.problems.size()) + " problem" +
                    (v.problems.size() == 1 ? "" : "s") + ":";
    for (const auto& p : v.problems) s += "\n  " + named(p.ToString());
    throw OptionError(s);
  }
  pipeline::RunOptions run_options;
  run_options.threads = threads;
  for (const std::string& p : pipeline::CheckRunOptions(run_options, v)) throw OptionError(named(p));
  // Before anything runs, as imr run's children check each output folder: a report.json or
  // manifest.json that this job's sequence did not write is never replaced.
  for (const pipeline::SequenceRef& seq : v.sequences)
    if (const std::string foreign = batch::ForeignOutputs(v.job.OutputDirectory(seq.name), v.job.file, seq.name);
        !foreign.empty())
      throw SequenceError(seq.name, named(foreign));
  json reports = json::object();
  for (const pipeline::SequenceRef& seq : v.sequences) {
    if (plugin::CancelRequested()) throw std::runtime_error("cancelled (signal)");
    const pipeline::SequenceResult r = pipeline::RunOneSequence(v, registry, run_options, seq);
    if (!r.ok) throw SequenceError(seq.name, named(r.error));
    reports[seq.name] = r.report;
  }
  return reports;
}

json Evaluate(const std::string& mesh, const std::string& truth, const std::string& options_json,
              const eval::TriangleMesh* mesh_data, const std::vector<Vec3>* truth_points) {
  const json o = ParseObject(options_json, "evaluate");
  eval::EvaluationInputs in;
  in.mesh = mesh;
  in.truth = truth;
  in.mesh_data = mesh_data;
  in.truth_points = truth_points;
  eval::EvaluationOptions options;
  for (const auto& [key, value] : o.items()) {
    try {
      if (key == "tau") {
        options.taus = value.is_array() ? value.get<std::vector<double>>()
                                        : std::vector<double>{value.get<double>()};
      } else if (key == "max_ray_length") {
        options.max_ray_length = value.get<double>();
      } else if (key == "crop") {
        options.crop = value.get<bool>();
      } else if (key == "truth_density") {
        options.truth_density = value.get<double>();
      } else if (key == "precision_samples") {
        options.precision_samples = value.get<std::size_t>();
      } else if (key == "seed") {
        options.seed = value.get<uint64_t>();
      } else if (key == "threads") {
        options.threads = value.get<int>();
      } else if (key == "velodyne_seq") {
        in.sequence = value.get<std::string>();
      } else if (key == "scan_step") {
        in.scan_step = value.get<int>();
      } else {
        throw OptionError("evaluate: unknown option '" + key + "' (expected tau, max_ray_length, "
                          "crop, truth_density, precision_samples, seed, threads, velodyne_seq or "
                          "scan_step)");
      }
    } catch (const json::exception&) {
      throw OptionError("evaluate: " + key + ": unexpected value " + io::Describe(value));
    }
  }
  if (in.truth.empty() && in.sequence.empty())
    throw OptionError("evaluate: no ground truth: give truth (a file or points) or velodyne_seq");
  if (in.scan_step < 1) throw OptionError("evaluate: scan_step must be at least 1");
  if (const std::string p = options.Check(); !p.empty()) throw OptionError("evaluate: " + p);
  return eval::EvaluateFiles(in, options, in.sequence.empty() ? nullptr : &eval::ReadKittiSequence);
}

}  // namespace imr::python
