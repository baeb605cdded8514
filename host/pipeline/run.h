// Running a validated job: for each sequence, input -> engine (with the policy plugin) ->
// exporter plugins, then a JSON report. A failing sequence is recorded and the others go on.
// Outputs go through a staging folder and are renamed into place; report.json comes last.
#pragma once

#include "host/pipeline/job_validation.h"

#include <nlohmann/json.hpp>

#include <filesystem>
#include <string>
#include <vector>

namespace imr::pipeline {

struct SequenceResult {
  std::string name;
  bool ok = false;
  std::string error;                        // why it failed (names the file or field)
  std::filesystem::path output_directory;
  std::vector<std::filesystem::path> files;  // written outputs, report last
  double seconds = 0.0;
  nlohmann::json report;                    // the report written as report.json
};

struct BatchResult {
  std::vector<SequenceResult> sequences;
  int failed() const;
};

BatchResult RunJob(const ValidatedJob& job, const plugin::PluginRegistry& registry);

// imr's own version, for reports and `imr --version`.
const char* Version();

}  // namespace imr::pipeline
