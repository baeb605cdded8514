// The flags of pipeline::RunOptions, declared once: `imr run` and `imr submit` offer them (with
// this help), the batch hands them on to its child processes and Slurm tasks (RunOptionsToArgs),
// and a child reads them back, strictly. A new run option is one row in run_flags.cc.
#pragma once

#include "host/pipeline/run.h"

#include <functional>
#include <optional>
#include <string>
#include <vector>

namespace imr::batch {

struct RunFlag {
  std::string name;        // without "--": "stage-timeout"
  std::string value_name;  // "SECONDS"; empty: a switch (takes no value)
  std::string help;        // one line for `imr run --help`
  // Sets the flag in *options from its text ("" for a switch). Returns "" when it is usable,
  // else what is wrong, for "imr run: --stage-timeout: <what>".
  std::function<std::string(const std::string& text, pipeline::RunOptions* options)> parse;
  // The text to hand on for `options`; nullopt: not handed on (at its default, or carried by
  // another flag, as --check-invariants by --check-invariants-every 1). Empty for a switch.
  std::function<std::optional<std::string>(const pipeline::RunOptions& options)> value;
};

// Every flag, in the order of the help.
const std::vector<RunFlag>& RunFlags();
// The flag called `name` (without "--"); nullptr when none.
const RunFlag* FindRunFlag(const std::string& name);

// The options (all but the callbacks) as flags, for child processes and Slurm scripts: parsing
// them back gives the same options.
std::vector<std::string> RunOptionsToArgs(const pipeline::RunOptions& options);

// "--set KEY=VALUE" for each of a job's overrides (io::JobSpec::overrides), for the same: a
// child or a Slurm task loads the job file with them.
std::vector<std::string> JobOverrideArgs(const std::vector<std::string>& overrides);

}  // namespace imr::batch
