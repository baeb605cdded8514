// Everything `imr validate` checks beyond structure: input format and its options, sequences
// that exist, plugin ids and kinds, params against each plugin's schema, stages the format needs,
// output formats some exporter writes, engine options. Every problem is reported, not the first.
#pragma once

#include "host/engine/engine.h"
#include "host/io/job.h"
#include "host/plugin/registry.h"

#include <filesystem>
#include <string>
#include <vector>

namespace imr::pipeline {

// One sequence to process: its name (for the output template) and source (path or name).
struct SequenceRef {
  std::string name;
  std::string source;
};

struct ValidatedJob {
  io::JobSpec job;
  std::vector<SequenceRef> sequences;   // expanded, in a deterministic order
  nlohmann::json input_options;         // with defaults
  engine::EngineOptions engine_options;
  std::vector<nlohmann::json> stage_params;  // per stage, with defaults
  nlohmann::json evaluation;                 // the job's "evaluation" with defaults; null: none
  nlohmann::json tiles;                      // "output.tiles" with defaults; null: none
  std::vector<io::Problem> problems;
  bool ok() const { return problems.empty(); }
};

// The options of a job's "evaluation" section (accuracy against ground truth in every report).
nlohmann::json EvaluationSchema();

// Loads the plugins the job can see (its plugin_paths, then the default search path) into
// `registry` and validates the job, with `overrides` applied (io::ApplyJobOverrides), against
// them.
ValidatedJob LoadAndValidateJob(const std::filesystem::path& job_file,
                                plugin::PluginRegistry* registry,
                                const std::vector<std::string>& overrides = {});
// The same for a job given as text (the Python module's job dicts): `job_file` names it in
// messages and anchors its relative paths; it need not exist.
ValidatedJob LoadAndValidateJobText(const std::string& text, const std::filesystem::path& job_file,
                                    plugin::PluginRegistry* registry,
                                    const std::vector<std::string>& overrides = {});
// What both do after parsing.
ValidatedJob ValidateParsedJob(io::JobParseResult parsed, plugin::PluginRegistry* registry);

}  // namespace imr::pipeline
