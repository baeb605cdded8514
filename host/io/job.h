// Job files: which sequences, read how, through which plugins, written where. Parsing checks the
// structure (types, required and unknown keys) and collects every problem with its JSON path;
// checks that need the plugins (ids, kinds, params) are done by pipeline/job_validation.
#pragma once

#include "host/io/schema.h"

#include <nlohmann/json.hpp>

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace imr::io {

// The largest job file read (a job is a few kB; /dev/zero is not one).
inline constexpr std::uintmax_t kMaxJobFileBytes = 64u << 20;

// Longest accepted stage timeout: a year. Longer is surely a typo, and keeps deadlines finite.
inline constexpr double kMaxStageTimeoutSeconds = 365.0 * 24 * 3600;

// One stage of the pipeline: a plugin of a given kind with its params.
struct StageSpec {
  std::string kind;       // "features", "refiner", "dense", "weight_policy", "mesh_refiner"
                           // or "exporter"
  std::string plugin;     // plugin id, e.g. "org.imr.policy.nearest"
  nlohmann::json params = nlohmann::json::object();  // as written in the job
  std::string json_path;  // "pipeline[2]", for messages
  // A call into the plugin that takes longer fails the sequence (a hung plugin cannot be
  // stopped otherwise); 0: imr run's --stage-timeout, whose default is none.
  double timeout_seconds = 0.0;
  // mesh_refiner only: refine every this many keyframes as the run goes (0: only at the end,
  // which every mesh refiner stage does, before the exports).
  int every_keyframes = 0;
};

struct InputSpec {
  std::string format;                                 // see input_formats.h
  nlohmann::json options = nlohmann::json::object();  // format-specific, as written
};

struct OutputSpec {
  // Folder per sequence; placeholders {sequence} (sequence name) and {job} (job file stem).
  // Relative paths are relative to the job file's folder.
  std::string directory = "runs/{sequence}";
  std::string stem = "mesh";                           // output file name without extension
  std::vector<std::string> formats = {"obj", "ply", "glb"};  // handed to the exporter stage(s)
  // Also write the mesh every this many keyframes, as snapshots/<stem>_kf<NNNNNN>.<format>
  // (watching a reconstruction grow; the paper's Figure 3). 0: no snapshots.
  int snapshot_every = 0;
  // "tiles": the surface also as OGC 3D Tiles (tileset.json, tiles/*.glb) written as the run
  // goes (host/pipeline/tiles.h; an object of options, or true); null: none. With tiles,
  // `formats` may be empty: tiles only.
  nlohmann::json tiles;
};

struct JobSpec {
  std::filesystem::path file;      // the job file
  std::filesystem::path base_dir;  // its folder: relative paths are resolved against it
  std::string description;
  std::vector<std::string> sequences;  // paths, globs, or names (format decides)
  InputSpec input;
  nlohmann::json engine = nlohmann::json::object();  // engine options, as written
  std::vector<StageSpec> pipeline;
  OutputSpec output;
  std::vector<std::filesystem::path> plugin_paths;  // resolved against base_dir
  // Accuracy against ground truth for every sequence's report (issue 6): {"truth": "velodyne" or
  // a point cloud / reference mesh file, "tau", "max_ray_length", "scan_step", "crop"}; null when
  // the job has none. Checked against pipeline::EvaluationSchema() by validation.
  nlohmann::json evaluation;
  // The job's values overridden on the command line (imr run --set KEY=VALUE), as given and in
  // order; already applied to the fields above. Recorded in each report and in the resume hash.
  std::vector<std::string> overrides;

  std::string Name() const { return file.stem().string(); }
  std::filesystem::path Resolve(const std::string& p) const;
  // The output folder of one sequence, template expanded and resolved.
  std::filesystem::path OutputDirectory(const std::string& sequence_name) const;
  // The batch folder (absolute): the part of output.directory before its first component with
  // {sequence} ("runs/{sequence}" -> "runs", "out/{job}/{sequence}/mesh" -> "out/<job>"); the
  // output folder itself for a template without {sequence}.
  std::filesystem::path BatchDirectory() const;
};

// `tmpl` with each placeholder ("{sequence}", ...) replaced by its value, in one pass over the
// template: a value that holds a placeholder ("x{job}", a folder named "{sequence}") is text.
std::string ExpandTemplate(const std::string& tmpl,
                           const std::vector<std::pair<std::string, std::string>>& values);

struct JobParseResult {
  JobSpec job;
  std::vector<Problem> problems;  // empty when the structure is valid
  bool ok() const { return problems.empty(); }
};

// Reads and structurally checks a job file, with `overrides` applied to its JSON first. Never
// throws for bad input: an unreadable file, malformed JSON (with line and column) or an override
// that does not apply is reported as a problem.
JobParseResult ParseJobFile(const std::filesystem::path& file,
                            const std::vector<std::string>& overrides = {});
// The same from text (for tests); `file` names the source in messages and anchors relative paths.
JobParseResult ParseJobText(const std::string& text, const std::filesystem::path& file,
                            const std::vector<std::string>& overrides = {});

// Applies overrides "KEY=VALUE" to a job's JSON: KEY is a path of object keys and array indices
// ("engine.steiner_spacing", "pipeline[1].params.max_distance", "pipeline.1.params"); missing
// objects on the way are created; VALUE is read as JSON, else taken as a string ("2" is a
// number, "[\"ply\"]" an array, "street" a string). Problems name the override ("--set ...").
void ApplyJobOverrides(const std::vector<std::string>& overrides, nlohmann::json* job,
                       std::vector<Problem>* problems);

// Known stage kinds, in pipeline order.
const std::vector<std::string>& StageKinds();

// Checks an output directory template's placeholders; returns problems at `path`.
std::vector<Problem> CheckOutputTemplate(const std::string& tmpl, const std::string& path);

}  // namespace imr::io
