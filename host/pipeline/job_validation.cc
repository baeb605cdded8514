#include "host/pipeline/job_validation.h"

#include "host/io/batch_folder.h"
#include "host/io/engine_options.h"
#include "host/io/input_formats.h"
#include "host/pipeline/scale.h"
#include "host/pipeline/tiles.h"
#include "host/util/input_file.h"
#include "host/util/json_text.h"
#include "host/util/log.h"

#include "imr/sdk/params_schema.hpp"

#include <glob.h>

#include <algorithm>
#include <map>
#include <set>

namespace imr::pipeline {
namespace fs = std::filesystem;
using io::Problem;
using nlohmann::json;

namespace {

bool HasGlobChars(const std::string& s) { return s.find_first_of("*?[") != std::string::npos; }

std::vector<std::string> Components(const std::string& path) {
  std::vector<std::string> out;
  for (std::size_t pos = 0; pos <= path.size();) {
    const std::size_t slash = std::min(path.find('/', pos), path.size());
    if (slash > pos) out.push_back(path.substr(pos, slash - pos));
    pos = slash + 1;
  }
  return out;
}

// The name of a path given without wildcards: its last component ("data/00/" -> "00").
std::string PathName(const std::string& path) {
  const auto c = Components(path);
  return c.empty() ? path : c.back();
}

// "data/00/" -> "data/00": sources are named the same however the folder was written.
std::string StripSlash(std::string path) {
  while (path.size() > 1 && path.back() == '/') path.pop_back();
  return path;
}

// The name of a glob match: the parts the wildcards matched, joined by '-', so that
// "seqs/*/sfm_data.json" names its matches after their folders ("seqs/dino/sfm_data.json" ->
// "dino") and "seqs/*/" after themselves; "seqs/*.json" keeps the file name, as before.
std::string GlobMatchName(const std::string& pattern, const std::string& match) {
  const auto p = Components(pattern), m = Components(match);
  if (p.size() != m.size()) return PathName(match);
  std::string name;
  for (std::size_t i = 0; i < p.size(); ++i)
    if (HasGlobChars(p[i])) name += (name.empty() ? "" : "-") + m[i];
  return name.empty() ? PathName(match) : name;
}

// Each sequence writes its own folder inside the batch folder: two sharing one would overwrite
// each other, and "." or ".." (a glob ".*/" matches them) would write into the batch folder or
// above it. `owners`: the output folders seen so far, with their sequences.
void CheckOutputFolder(const SequenceRef& s, const std::string& path, const fs::path& batch,
                       std::map<fs::path, std::string>* owners, ValidatedJob* v) {
  const io::JobSpec& job = v->job;
  fs::path out = fs::absolute(job.OutputDirectory(s.name)).lexically_normal();
  if (out.has_relative_path() && out.filename().empty()) out = out.parent_path();
  const std::string who = "sequence '" + JsonText(s.name) + "': its output folder " + out.string();
  if (job.output.directory.find("{sequence}") != std::string::npos) {
    const fs::path rel = out.lexically_relative(batch);
    if (rel.empty() || rel == ".") {
      v->problems.push_back({path, who + " is the batch folder itself (where the summary and " +
                                       "imr-batch/ go)"});
      return;
    }
    if (*rel.begin() == "..") {
      v->problems.push_back({path, who + " is outside the batch folder " + batch.string()});
      return;
    }
    // imr's own entries of the batch folder: the summary, the viewer page, imr-batch/.
    if (io::IsBatchFolderEntry(rel.begin()->string())) {
      v->problems.push_back({path, who + " is the batch folder's " + rel.begin()->string() +
                                       ", which imr run writes (the batch summary, the viewer "
                                       "page or its records); rename the sequence, or put text "
                                       "around {sequence} in output.directory (e.g. "
                                       "\"runs/{sequence}_mesh\")"});
      return;
    }
    if (s.name == "." || s.name == "..") {
      v->problems.push_back({path, "a sequence named '" + s.name + "': not a folder name for " +
                                       "{sequence} in output.directory"});
      return;
    }
  }
  const auto [it, first] = owners->emplace(out, s.name);
  if (!first)
    v->problems.push_back({"output.directory", "sequences '" + JsonText(it->second) + "' and '" +
                                                   JsonText(s.name) + "' would both write to " +
                                                   out.string()});
}

// A glob over the folder the outputs go to matches them on the next run (sequences "cm/*/" and
// output "cm/{sequence}_mesh": cm/A_mesh, cm/imr-batch, cm/assets), and the batch would grow
// with every run. Matches that are imr's own entries of the batch folder, or the output folder
// of another match (or inside one), are left out, with an info line naming them.
void LeaveOutOwnOutputs(const std::string& path, const io::JobSpec& job, const fs::path& batch,
                        std::vector<SequenceRef>* found) {
  auto normal = [](const fs::path& p) {
    fs::path n = fs::absolute(p).lexically_normal();
    if (n.has_relative_path() && n.filename().empty()) n = n.parent_path();
    return n;
  };
  auto inside = [](const fs::path& p, const fs::path& dir) {
    const fs::path rel = p.lexically_relative(dir);
    return !rel.empty() && *rel.begin() != "..";
  };
  // Output folder -> its sequence; only those strictly inside the batch folder (the others are
  // refused by CheckOutputFolder, and must not hide a match).
  std::map<fs::path, std::string> outputs;
  if (job.output.directory.find("{sequence}") != std::string::npos)
    for (const SequenceRef& s : *found) {
      const fs::path out = normal(job.OutputDirectory(s.name));
      if (out != batch && inside(out, batch)) outputs.emplace(out, s.name);
    }
  std::vector<SequenceRef> kept;
  std::string left_out;
  for (SequenceRef& s : *found) {
    const fs::path source = normal(s.source);
    std::string why;
    for (const char* e : io::kBatchFolderEntries)
      if (inside(source, batch / e) && io::ForeignBatchEntry(batch, e).empty())
        why = "the batch folder's";
    for (const auto& [out, owner] : outputs)
      if (why.empty() && owner != s.name && inside(source, out))
        why = "the output folder of '" + JsonText(owner) + "'";
    if (why.empty()) {
      kept.push_back(std::move(s));
      continue;
    }
    left_out += (left_out.empty() ? "" : ", ") + source.string() + " (" + why + ")";
  }
  if (!left_out.empty())
    LogInfo(path + ": left out what imr wrote: " + left_out);
  *found = std::move(kept);
}

void ExpandSequences(const io::InputFormat& format, ValidatedJob* v) {
  const io::JobSpec& job = v->job;
  const fs::path batch = job.BatchDirectory();
  std::map<fs::path, std::string> owners;
  std::set<std::string> seen_names;
  for (std::size_t i = 0; i < job.sequences.size(); ++i) {
    const std::string path = "sequences[" + std::to_string(i) + "]";
    const std::string& entry = job.sequences[i];
    std::vector<SequenceRef> found;
    if (!format.sequences_are_paths) {
      if (std::find(format.sequence_names.begin(), format.sequence_names.end(), entry) ==
          format.sequence_names.end()) {
        v->problems.push_back({path, "input format '" + format.name + "' takes the names " +
                                         io::JoinAlternatives(format.sequence_names) +
                                         ", got " + io::Describe(entry)});
        continue;
      }
      found.push_back({entry, entry});
    } else if (HasGlobChars(entry)) {
      const std::string pattern = job.Resolve(entry).string();
      glob_t g{};
      const int rc = ::glob(pattern.c_str(), 0, nullptr, &g);
      if (rc == 0)
        for (std::size_t k = 0; k < g.gl_pathc; ++k)
          found.push_back({GlobMatchName(pattern, g.gl_pathv[k]), StripSlash(g.gl_pathv[k])});
      ::globfree(&g);
      LeaveOutOwnOutputs(path, job, batch, &found);
      if (found.empty()) v->problems.push_back({path, "pattern matches nothing: " + pattern});
      std::sort(found.begin(), found.end(),
                [](const SequenceRef& a, const SequenceRef& b) { return a.source < b.source; });
    } else {
      const fs::path p = job.Resolve(entry);
      std::error_code ec;
      if (!fs::exists(p, ec)) {
        v->problems.push_back({path, "no such file or folder: " + p.string()});
        continue;
      }
      found.push_back({PathName(p.string()), StripSlash(p.string())});
    }
    for (auto& s : found) {
      if (!seen_names.insert(s.name).second) {
        v->problems.push_back({path, "two sequences are named '" + JsonText(s.name) +
                                         "': their outputs would collide"});
        continue;
      }
      CheckOutputFolder(s, path, batch, &owners, v);
      v->sequences.push_back(std::move(s));
    }
  }
  // A pattern can stand for several sequences; the parser only saw one entry.
  if (job.sequences.size() == 1 && v->sequences.size() > 1 &&
      job.output.directory.find("{sequence}") == std::string::npos)
    v->problems.push_back({"output.directory", "sequences[0] matches " +
                                                   std::to_string(v->sequences.size()) +
                                                   " sequences, which would share one folder: "
                                                   "put {sequence} in the template"});
}

void ValidateStages(const io::InputFormat* format, const plugin::PluginRegistry& registry,
                    ValidatedJob* v) {
  const io::JobSpec& job = v->job;
  std::map<std::string, int> count;
  std::vector<std::string> exporter_formats;
  bool unknown_exporter = false;  // its formats are unknown: do not call every format unwritten
  for (std::size_t i = 0; i < job.pipeline.size(); ++i) {
    const io::StageSpec& stage = job.pipeline[i];
    nlohmann::json params = stage.params;
    ++count[stage.kind];
    const plugin::PluginInfo* info = registry.Find(stage.plugin);
    if (info == nullptr) {
      unknown_exporter |= stage.kind == "exporter";
      auto known = registry.Ids(stage.kind);
      v->problems.push_back(
          {stage.json_path + ".plugin",
           "unknown plugin id " + io::Describe(stage.plugin) + " (known " + stage.kind +
               " plugins: " + (known.empty() ? std::string("none") : io::JoinAlternatives(known)) +
               "; run `imr plugins` to see what was found and refused)"});
      v->stage_params.push_back(params);
      continue;
    }
    if (info->kind() != stage.kind) {
      v->problems.push_back({stage.json_path + ".plugin",
                             "plugin " + info->id() + " (" + info->file.string() + ") is a " +
                                 info->kind() + " plugin, the stage's kind is " + stage.kind});
    }
    io::ValidateAgainstSchema(info->params_schema, params, stage.json_path + ".params",
                              &v->problems);
    v->stage_params.push_back(io::WithDefaults(info->params_schema, params));
    if (info->kind() == "exporter" && info->descriptor->exporter->formats) {
      std::string list = info->descriptor->exporter->formats;
      for (std::size_t pos = 0; pos <= list.size();) {
        const std::size_t comma = std::min(list.find(',', pos), list.size());
        if (comma > pos) exporter_formats.push_back(list.substr(pos, comma - pos));
        pos = comma + 1;
      }
    }
  }
  if (format != nullptr && !format->needs_front_end) {
    for (const char* kind : {"features", "refiner", "dense"})
      if (count[kind] > 0)
        v->problems.push_back({"pipeline", std::string("input format '") + format->name +
                                               "' delivers 3D points: a " + kind +
                                               " stage has nothing to do; remove it"});
  }
  if (format != nullptr && format->needs_front_end) {
    for (const char* kind : {"features", "refiner"})
      if (count[kind] != 1)
        v->problems.push_back({"pipeline", std::string("input format '") + format->name +
                                               "' needs exactly one " + kind + " stage, found " +
                                               std::to_string(count[kind])});
  }
  // weights: one policy; rays: none; exact: none needed, one allowed (jobs written for the
  // weights mode run unchanged; the run says the policy is not called).
  const engine::VisibilityMode mode = v->engine_options.visibility_mode;
  if (mode == engine::VisibilityMode::kWeights && count["weight_policy"] != 1)
    v->problems.push_back({"pipeline", "visibility_mode 'weights' needs exactly one "
                                       "weight_policy stage, found " +
                                           std::to_string(count["weight_policy"])});
  if (mode == engine::VisibilityMode::kRays && count["weight_policy"] > 0)
    v->problems.push_back({"pipeline", "visibility_mode 'rays' does not use a weight_policy "
                                       "stage; remove it"});
  if (mode == engine::VisibilityMode::kExact && count["weight_policy"] > 1)
    v->problems.push_back({"pipeline", "at most one weight_policy stage, found " +
                                           std::to_string(count["weight_policy"])});
  if (count["exporter"] == 0)
    v->problems.push_back({"pipeline", "no exporter stage: nothing would be written"});
  if (count["dense"] > 1)
    v->problems.push_back({"pipeline", "at most one dense stage, found " +
                                           std::to_string(count["dense"])});
  if (count["mesh_refiner"] > 1)
    v->problems.push_back({"pipeline", "at most one mesh_refiner stage, found " +
                                           std::to_string(count["mesh_refiner"])});
  // Tiles are GLB (3D Tiles 1.1 content), written through the first exporter that writes glb.
  if (!v->tiles.is_null() && count["exporter"] > 0 && !unknown_exporter &&
      std::find(exporter_formats.begin(), exporter_formats.end(), "glb") == exporter_formats.end())
    v->problems.push_back({"output.tiles", "tiles are GLB files: no exporter stage writes glb (they "
                                           "write " + io::JoinAlternatives(exporter_formats) + ")"});
  for (std::size_t i = 0; i < job.output.formats.size(); ++i) {
    const std::string& f = job.output.formats[i];
    if (count["exporter"] > 0 && !unknown_exporter &&
        std::find(exporter_formats.begin(), exporter_formats.end(), f) == exporter_formats.end())
      v->problems.push_back({"output.formats[" + std::to_string(i) + "]",
                             io::Describe(f) + " is not written by any exporter stage (they write " +
                                 io::JoinAlternatives(exporter_formats) + ")"});
  }
}

}  // namespace

ValidatedJob LoadAndValidateJob(const fs::path& job_file, plugin::PluginRegistry* registry,
                                const std::vector<std::string>& overrides) {
  return ValidateParsedJob(io::ParseJobFile(job_file, overrides), registry);
}

ValidatedJob LoadAndValidateJobText(const std::string& text, const fs::path& job_file,
                                    plugin::PluginRegistry* registry,
                                    const std::vector<std::string>& overrides) {
  return ValidateParsedJob(io::ParseJobText(text, job_file, overrides), registry);
}

ValidatedJob ValidateParsedJob(io::JobParseResult parsed, plugin::PluginRegistry* registry) {
  ValidatedJob v;
  v.job = std::move(parsed.job);
  v.problems = std::move(parsed.problems);
  if (v.job.input.format.empty() && v.job.sequences.empty() && !v.problems.empty() &&
      v.problems[0].path.empty())
    return v;  // unreadable or malformed: nothing more to say

  std::vector<fs::path> paths = v.job.plugin_paths;
  for (const auto& p : plugin::PluginRegistry::DefaultSearchPaths()) paths.push_back(p);
  registry->Scan(paths);
  // A refused library is not fatal (the job may not need it) but must not pass unnoticed.
  for (const auto& r : registry->refusals()) LogWarning("plugin refused: " + r.ToString());
  for (std::size_t i = 0; i < v.job.plugin_paths.size(); ++i) {
    std::error_code ec;
    if (!fs::exists(v.job.plugin_paths[i], ec))
      v.problems.push_back({"plugin_paths[" + std::to_string(i) + "]",
                            "no such file or folder: " + v.job.plugin_paths[i].string()});
  }

  const io::InputFormat* format = nullptr;
  if (!v.job.input.format.empty()) {
    format = io::FindInputFormat(v.job.input.format);
    if (format == nullptr) {
      std::vector<std::string> names;
      for (const auto& f : io::InputFormats()) names.push_back(f.name);
      v.problems.push_back({"input.format", "unknown format " + io::Describe(v.job.input.format) +
                                                " (expected " + io::JoinAlternatives(names) + ")"});
    } else {
      const size_t before = v.problems.size();
      io::ValidateAgainstSchema(format->options_schema, v.job.input.options, "input.options",
                                &v.problems);
      v.input_options = io::WithDefaults(format->options_schema, v.job.input.options);
      if (format->check && v.problems.size() == before)
        for (std::string& m : format->check(v.input_options))
          v.problems.push_back({"input.options", std::move(m)});
      // A poses file named in the job is relative to the job's folder, like every other path.
      if (v.input_options.contains("poses") && v.input_options["poses"].is_string() &&
          !v.input_options["poses"].get<std::string>().empty())
        v.input_options["poses"] = v.job.Resolve(v.input_options["poses"].get<std::string>()).string();
      ExpandSequences(*format, &v);
    }
  }
  // {job} is the job file's stem: "...json" gives "..", which would climb out of the folder.
  if (v.job.output.directory.find("{job}") != std::string::npos &&
      (v.job.Name() == "." || v.job.Name() == ".." || v.job.Name().empty()))
    v.problems.push_back({"output.directory",
                          "{job} would be '" + v.job.Name() + "' (the job file " +
                              v.job.file.filename().string() + "): not a folder name; rename the "
                              "job file"});
  bool spacing_known = false;  // the Steiner spacing the run will use (not scaled per sequence)
  if (io::EngineOptionsFromJson(v.job.engine, &v.engine_options, &v.problems)) {
    // The Steiner grid's size, once its lengths are known: in metric mode, or when the job gives
    // all three; auto scaling sets the others per sequence, and the run checks them then.
    bool known = ScaleModeOf(v.job.engine, v.job.input.format) == ScaleMode::kMetric;
    spacing_known = known || (v.job.engine.is_object() && v.job.engine.contains("steiner_spacing"));
    if (!known && v.job.engine.is_object())
      known = v.job.engine.contains("steiner_spacing") && v.job.engine.contains("steiner_margin") &&
              v.job.engine.contains("max_ray_length");
    if (known)
      if (const std::string grid = v.engine_options.CheckSteinerGrid(); !grid.empty())
        v.problems.push_back({"engine", grid});
  }
  if (!v.job.evaluation.is_null()) {
    io::ValidateAgainstSchema(EvaluationSchema(), v.job.evaluation, "evaluation", &v.problems);
    v.evaluation = io::WithDefaults(EvaluationSchema(), v.job.evaluation);
    const std::string truth = v.evaluation.value("truth", "");
    const bool kitti = format != nullptr &&
                       (format->name == "kitti_raw" || format->name == "kitti_odometry");
    if (truth == "velodyne" && !kitti)
      v.problems.push_back({"evaluation.truth", "\"velodyne\" needs a KITTI input format "
                                                "(kitti_raw or kitti_odometry), the job's is " +
                                                    io::Describe(v.job.input.format)});
    else if (truth.empty())
      v.problems.push_back({"evaluation.truth", "expected \"velodyne\" or a ground-truth file "
                                                "(point cloud .ply/.xyz or reference mesh)"});
    else if (truth != "velodyne") {
      const fs::path p = v.job.Resolve(truth);
      // The open rule's words: a FIFO or a folder is named as what it is, not as missing.
      if (const std::string why = InputFileProblem(p, "a ground-truth file (point cloud .ply/.xyz or "
                                                      "reference mesh)");
          !why.empty())
        v.problems.push_back({"evaluation.truth", p.string() + ": " + why});
      v.evaluation["truth"] = p.string();
    }
  }
  const json& tiles = v.job.output.tiles;
  if (tiles.is_object() || tiles == json(true)) {
    const json given = tiles.is_object() ? tiles : json::object();
    // "origin" is an object of its own (TilesOriginSchema): checked apart, kept in v.tiles.
    json flat = given;
    flat.erase("origin");
    // Named among the keys an unknown one is told (never checked here: erased above).
    json keys = TilesSchema();
    keys["origin"] = {{"type", "string"}};
    io::ValidateAgainstSchema(keys, flat, "output.tiles", &v.problems);
    if (const auto origin = given.find("origin"); origin != given.end()) {
      if (!origin->is_object()) {
        v.problems.push_back({"output.tiles.origin", "expected an object {\"latitude\": degrees, "
                                                     "\"longitude\": degrees, \"height\": metres, "
                                                     "\"heading\": degrees}, got " + io::Describe(*origin)});
      } else {
        io::ValidateAgainstSchema(TilesOriginSchema(), *origin, "output.tiles.origin", &v.problems);
        for (const auto& [key, spec] : TilesOriginSchema().items())
          if (!origin->contains(key))
            v.problems.push_back({"output.tiles.origin." + key,
                                  "missing: expected " + imr::sdk::ExpectedValue(spec) + " (" +
                                      spec["unit"].get<std::string>() + "; required with an origin)"});
      }
    }
    v.tiles = io::WithDefaults(TilesSchema(), given);
    // The cells against the Steiner spacing, when the job fixes it (else the run checks).
    TilesOptions o;
    if (spacing_known && v.tiles["size"].is_number() && v.tiles["size"].get<double>() > 0.0) {
      o.size = v.tiles["size"].get<double>();
      if (const std::string e = o.CheckSize(v.engine_options.steiner_spacing); !e.empty())
        v.problems.push_back({"output.tiles.size", e});
    }
  }
  ValidateStages(format, *registry, &v);
  return v;
}

nlohmann::json EvaluationSchema() {
  return {{"truth", {{"type", "string"}, {"default", ""},
                     {"description", "\"velodyne\" (the KITTI sequence's scans) or a point cloud "
                                     "(.ply/.xyz) or reference mesh file, relative to the job"}}},
          {"tau", {{"type", "number"}, {"default", 0.2}, {"minimum", 1e-9},
                   {"description", "completeness/precision threshold the summary shows (scene "
                                   "units); the report has 0.05, 0.1, 0.2, 0.5 and this"}}},
          {"max_ray_length", {{"type", "number"}, {"default", 30.0}, {"minimum", 0.0},
                              {"description", "crop: ground truth within this of a camera that "
                                              "sees it (0: no range limit)"}}},
          {"scan_step", {{"type", "integer"}, {"default", 5}, {"minimum", 1},
                         {"description", "velodyne: every n-th frame's scan"}}},
          {"crop", {{"type", "boolean"}, {"default", true},
                    {"description", "crop ground truth to what the cameras saw"}}}};
}

}  // namespace imr::pipeline
