// `imr submit`: a job as a Slurm array. Writes two readable sbatch scripts into the batch folder
// (imr-batch/slurm/): an array whose tasks each run `imr run` on their share of the sequences
// (the shard comes from SLURM_ARRAY_TASK_ID/COUNT/MIN), and a reduce job that runs
// `imr report RUN_DIR` once every task has ended, however it ended (--dependency=afterany).
// The sequence list is frozen in imr-batch/sequences.txt so every task shards the same set.
#pragma once

#include "host/pipeline/run.h"

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace imr::batch {

struct SubmitOptions {
  int tasks = 1;                 // array tasks (capped at the number of sequences)
  std::string partition;         // --partition; empty: the cluster's default
  std::string time;              // --time per task, e.g. "2:00:00"; empty: the partition's default
  std::string mem;               // --mem per task, e.g. "8G"; empty: the default
  int cpus_per_task = 1;         // --cpus-per-task
  int jobs = 0;                  // sequences at once in a task (imr run --jobs); 0: cpus_per_task
  std::string account, qos;      // --account, --qos; empty: not given
  std::vector<std::string> sbatch_args;  // more sbatch options, verbatim (e.g. "--constraint=x")
  uint64_t max_rss = 0;          // imr run --max-rss for the tasks (bytes; 0: none)
  bool force = false;            // imr run --force for the tasks
  bool dry_run = false;          // write the scripts, print the sbatch commands, submit nothing
  std::string executable;        // the imr the tasks run (this one)
  std::string sbatch = "sbatch"; // the sbatch program

  // Empty when usable, else what is wrong, naming the option. Every value that reaches a script
  // is checked: --time and --mem as Slurm reads them, no control character anywhere (a newline
  // would end an #SBATCH line and make the rest a command), --sbatch-arg an option ("-...").
  std::string Check() const;
};

// Empty when Slurm can take a job whose batch folder is `batch_directory`, else why not (a
// control character in the path: the #SBATCH --output of the tasks' logs cannot hold it).
std::string CheckScriptPaths(const std::filesystem::path& batch_directory);

struct SubmitResult {
  std::filesystem::path batch_directory;
  std::filesystem::path array_script, reduce_script, log_directory;
  int tasks = 0;
  std::string array_job_id, reduce_job_id;  // empty for a dry run
  std::vector<std::string> array_command, reduce_command;  // the sbatch command lines
};

// Writes the scripts and (unless a dry run) submits them. Throws std::runtime_error with
// sbatch's message when a submission fails, std::invalid_argument when CheckScriptPaths fails.
// Paths in the scripts' comments are written on one line (OneLine), words of their commands
// quoted for bash (ANSI-C quoting when they hold a control character).
SubmitResult Submit(const pipeline::ValidatedJob& job, const plugin::PluginRegistry& registry,
                    const pipeline::RunOptions& run_options, const SubmitOptions& options);

}  // namespace imr::batch
