// What the Python module (module.cc) drives, without Python: an engine fed keyframe by keyframe
// as `imr run` feeds it (the job's options and their checks, engine.scale, the weight policy
// plugin, the canonical order of each update), the readers as keyframe streams, a job run in
// this process, `imr evaluate`. Errors are exceptions carrying the CLI's messages: OptionError
// for options (Python's ValueError), std::runtime_error for the rest.
#pragma once

#include "host/engine/engine.h"
#include "host/eval/mesh_io.h"
#include "host/io/keyframe_source.h"
#include "host/io/slam_json.h"
#include "host/io/update_check.h"
#include "host/pipeline/in_front_check.h"
#include "host/pipeline/mesh_export.h"
#include "host/pipeline/scale.h"
#include "host/plugin/policy_adapter.h"
#include "host/plugin/registry.h"

#include <nlohmann/json.hpp>

#include <cstdint>
#include <deque>
#include <filesystem>
#include <memory>
#include <optional>
#include <set>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace imr::python {

// Bad options: the problems as `imr validate` words them ("engine.window: expected ...").
class OptionError : public std::invalid_argument {
 public:
  using std::invalid_argument::invalid_argument;
};

// One keyframe as a reader delivers it, with the reader (its cameras, its points' colours) kept
// alive for the exports of the engine that takes it.
struct Keyframe {
  engine::KeyframeUpdate update;
  io::KeyframeInfo info;
  std::string format;                          // the input format, "" when built by the caller
  std::shared_ptr<io::KeyframeSource> source;  // null when built by the caller
};

// A reader of an input format (colmap, slam_json, openmvg, ...) as a stream of keyframes.
class Reader {
 public:
  // `options_json`: the format's input.options as a JSON object (checked against its schema:
  // OptionError naming the option); the reader's errors are std::runtime_error, as the CLI's.
  Reader(const std::string& format, const std::string& path, const std::string& options_json);
  // The next keyframe, or nullopt at the end.
  std::optional<Keyframe> Next();
  int KeyframeCount() const { return source_->KeyframeCount(); }
  const std::string& format() const { return format_; }

 private:
  std::string format_;
  std::shared_ptr<io::KeyframeSource> source_;
};

class Session {
 public:
  // `engine_json`: the job's "engine" object; `policy`: a weight_policy plugin id ("" none) with
  // its params (JSON object text). Throws OptionError for bad options, unknown plugins or params.
  Session(const std::string& engine_json, const std::string& policy, const std::string& policy_params);
  ~Session();

  // One keyframe, as the job's run applies it. Throws OptionError ("keyframe 3 (frame 3): camera 0:
  // the rotation is not a rotation: ...") for what a reader would refuse (io::UpdateCheck: cameras,
  // coordinates, ids), std::runtime_error when the engine refuses it.
  void Add(Keyframe keyframe);
  // The exported mesh now (ExtractMesh). Keyframes held back to decide the scale (engine.scale
  // auto) are applied first, with the scale they give.
  engine::Mesh Mesh();
  // The report's "engine" object, with "scale" (how the lengths were chosen) beside it.
  nlohmann::json Stats();
  // The options in use (after engine.scale), as a job would write them.
  nlohmann::json Options() const;
  // Writes the mesh as `imr run` does (org.imr.exporter.assimp; the format from the extension).
  void Write(const std::filesystem::path& file);
  int keyframes() const { return keyframes_; }

 private:
  void Start();
  void Apply(Keyframe keyframe);

  nlohmann::json engine_json_;
  engine::EngineOptions base_options_, options_;
  std::set<std::string> explicit_keys_;
  std::optional<pipeline::ScaleMode> scale_mode_;  // decided by the first keyframe
  pipeline::ScaleProbe probe_;
  pipeline::ScaleEstimate scale_;
  std::deque<Keyframe> early_;
  plugin::PluginRegistry registry_;
  std::optional<plugin::PluginWeightPolicy> policy_;
  std::optional<engine::Engine> engine_;
  pipeline::InFrontCheck in_front_;  // points behind their cameras fail as the run fails
  io::CanonicalOrder canonical_;
  io::UpdateCheck check_;  // cameras, positions and ids as the readers check theirs
  pipeline::ExportContext export_context_;
  std::vector<std::shared_ptr<io::KeyframeSource>> sources_;  // for the exports
  int keyframes_ = 0;
  std::vector<engine::SurfacePart> final_parts_;  // handed out by the engine (engine.forget)
};

// `imr run` of a job (a file, or JSON text anchored at `job_file`), each sequence in this process
// through the runner of imr run's children: its outputs and report.json as imr run writes them
// (no manifest, no batch summary). Returns each sequence's report by name; a failing sequence
// throws SequenceError with the message imr run prints for it; an invalid job OptionError with
// the problems as imr validate lists them.
class SequenceError : public std::runtime_error {
 public:
  SequenceError(std::string sequence, const std::string& message)
      : std::runtime_error(message), sequence_(std::move(sequence)) {}
  const std::string& sequence() const { return sequence_; }

 private:
  std::string sequence_;
};
// Before running, each sequence's output folder is checked as imr run checks it
// (batch::ForeignOutputs): a report.json or manifest.json this job's sequence did not write throws
// SequenceError, and nothing is written. `job_name` (e.g. "the job (a dict)") replaces job_file in
// the messages when the job has no file of its own.
nlohmann::json RunJob(const std::string& job_file, const std::string* job_text,
                      const std::vector<std::string>& overrides, int threads,
                      const std::string& job_name = "");

// `imr evaluate MESH --truth TRUTH` (or --velodyne-seq) with the options as JSON ("tau",
// "max_ray_length", "crop", "truth_density", "precision_samples", "seed", "threads",
// "velodyne_seq"): its JSON report.
// `mesh_data` / `truth_points`, when given, are evaluated in memory (nothing written to disk);
// `mesh` / `truth` then name them ("<arrays>") in messages and the report.
nlohmann::json Evaluate(const std::string& mesh, const std::string& truth, const std::string& options_json,
                        const eval::TriangleMesh* mesh_data = nullptr,
                        const std::vector<Vec3>* truth_points = nullptr);

// Where the module's plugins are (the installed plugin folder of a host that is not imr).
void SetPluginDirectory(const std::filesystem::path& directory);

}  // namespace imr::python
