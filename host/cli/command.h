// The imr executable's commands, as a table (main.cc) of groups (one file each: batch_commands.cc,
// job_commands.cc, evaluate_command.cc, render_command.cc), and what the commands share: option
// parsing with -h/-q/-v, loading a job with its --set overrides, the run flags, the exit statuses
// of host/util/exit_status.h.
#pragma once

#include "host/pipeline/job_validation.h"
#include "host/pipeline/run.h"
#include "host/plugin/registry.h"

#include <boost/program_options.hpp>

#include <filesystem>
#include <string>
#include <vector>

namespace imr::cli {

namespace po = boost::program_options;

struct Command {
  std::string name;     // "run"
  std::string usage;    // how the overview shows it: "run JOB.json"
  std::string summary;  // the overview's description ('\n' between its lines)
  int (*run)(const std::vector<std::string>& args);  // the arguments after the name
  bool hidden = false;  // internal (the children of `imr run`): not in the overview
};

// The groups, in the overview's order.
std::vector<Command> BatchCommands();     // run, submit, report, mesh (and the hidden child)
std::vector<Command> JobCommands();       // validate, options, plugins
std::vector<Command> EvaluateCommands();  // evaluate
std::vector<Command> RenderCommands();    // render
std::vector<Command> TilesCommands();     // tiles merge

// Parses a command's options after adding -h, -q and -v; returns false (after printing the
// help, status 0, or the error and the usage, status 64) when the command should stop.
// `missing_hint` replaces Boost's message when a required option is missing, keyed by the
// option's name (e.g. {"job", "needs a job file: imr run JOB.json"}).
bool ParseCommand(const std::string& name, const std::string& synopsis,
                  po::options_description& opts, po::positional_options_description& pos,
                  const std::vector<std::string>& args, po::variables_map* vm, int* status,
                  const std::vector<std::pair<std::string, std::string>>& missing_hint = {});

// --set KEY=VALUE (repeatable): the job's values overridden on the command line.
void AddJobOverrideFlag(po::options_description& opts);
std::vector<std::string> JobOverrides(const po::variables_map& vm);

// Loads the plugins a job can see and validates the job with its overrides; prints every
// problem when it is invalid.
bool LoadJob(const std::filesystem::path& job, const std::vector<std::string>& overrides,
             plugin::PluginRegistry* registry, pipeline::ValidatedJob* v);
void PrintProblems(const std::filesystem::path& job, const std::vector<io::Problem>& problems);

// The flags of pipeline::RunOptions (host/batch/run_flags.h), for run and submit.
void AddRunOptionFlags(po::options_description& opts);
bool ReadRunOptions(const po::variables_map& vm, const char* cmd, pipeline::RunOptions* o);

// This executable, for the child processes and the Slurm scripts.
std::string SelfPath();
void SetArgv0(const char* argv0);

// Ctrl-C, kill and a closed terminal all stop a run the same way: no new sequence starts, the
// running ones are stopped, the summary is written.
void HandleStopSignals();

}  // namespace imr::cli
