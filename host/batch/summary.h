// The batch folder and its summary. A job's batch folder (RUN_DIR) is the part of its
// output.directory template before the first component with {sequence} ("runs/{sequence}" ->
// "runs", "out/{job}/{sequence}/mesh" -> "out/<job>"); for a template without {sequence} it is
// the output folder itself. It holds:
//   summary.json, summary.md     the batch summary (one row per sequence)
//   imr-batch/batch.json         the job and its sequences (name, source, output folder, hash)
//   imr-batch/status/<name>.json the latest outcome of each sequence (running, ok, skipped,
//                                failed + cause, interrupted); StatusFileName makes the name
//                                fit
//   imr-batch/sequences.txt      the frozen sequence list of `imr submit`
//   imr-batch/slurm/             the sbatch scripts of `imr submit` and the tasks' logs
// The summary is built from these files and the sequences' manifests and reports only, so
// `imr report RUN_DIR` can write it after array tasks on other machines have finished.
#pragma once

#include "host/io/batch_folder.h"
#include "host/io/job.h"

#include <nlohmann/json.hpp>

#include <filesystem>
#include <string>
#include <vector>

namespace imr::batch {

using io::kBatchSubdir;

std::filesystem::path BatchDirectory(const io::JobSpec& job);

// One sequence of the job as the batch folder records it. batch.json stores names and paths as
// bytes (host/util/json_text.h), the output relative to the batch folder when inside it.
struct BatchSequence {
  std::string name;
  std::string source;
  std::filesystem::path output;  // absolute (resolved against the batch folder when read)
  std::string job_hash;          // manifest hash its outputs must carry
};

struct BatchInfo {
  std::filesystem::path job_file;  // absolute
  std::string job_name;
  std::string output_stem;         // the meshes' file stem, to tell mesh files from the rest
  std::vector<BatchSequence> sequences;  // every sequence of the job, in its order
};

void WriteBatchInfo(const std::filesystem::path& batch_dir, const BatchInfo& info);
// Throws std::runtime_error naming the file when it is missing or unreadable.
BatchInfo ReadBatchInfo(const std::filesystem::path& batch_dir);

// The latest outcome of one sequence, as `imr run` records it.
struct StatusRecord {
  std::string sequence;
  std::string status;  // "running" (started, not ended), "ok", "skipped" (manifest matched),
                       // "failed", or "interrupted" (stopped by a signal to the batch)
  double seconds = 0.0;
  std::string error;   // failed: the cause, one line
  int exit_code = -1;  // failed: the child's exit status, -1 when it did not exit
  std::string signal;  // failed: "SIGSEGV" when a signal ended it
  std::vector<std::string> log_tail;  // failed: its last log lines
  std::string host;    // where it ran
  std::string finished_at;  // UTC, ISO 8601; empty while running
  std::string started_at;   // UTC, ISO 8601; running only
  std::vector<std::string> warnings;  // failed: warnings given before it failed
};

// The file name of a sequence's status record: "<name>.json" for plain short names, else a
// readable prefix and a hash of the name (any name, of any bytes and length, fits).
std::string StatusFileName(const std::string& sequence);
void WriteStatusRecord(const std::filesystem::path& batch_dir, const StatusRecord& r);
// Builds the summary from the batch folder: per sequence the status ("ok", "failed",
// "interrupted" (stopped by a signal to the batch, or started and never ended: killed, a time
// limit, a lost node) or "not run"), whether an earlier run made it ("reused"), time, frames,
// keyframes, mesh size, accuracy (the report's "accuracy" object), the report's warnings, and
// for failures the error, exit code or signal and last log lines. Outputs whose manifest no
// longer matches count as failed, saying why. Rows give the output folder relative to the batch
// folder when inside it.
nlohmann::json BuildSummary(const std::filesystem::path& batch_dir);
std::string SummaryMarkdown(const nlohmann::json& summary);
// Builds and writes summary.json and summary.md (atomically); returns the summary. Throws
// std::runtime_error when either (or imr-batch/) is a file imr did not write
// (io::ForeignBatchFiles): it is never overwritten.
nlohmann::json WriteSummary(const std::filesystem::path& batch_dir, const std::string& written_by);

// "3 sequences: 2 ok, 1 failed" from the summary's "counts" ("1 sequence"; interrupted, not run
// and reuse only when there are any), for summary.md and `imr report`.
std::string CountsSentence(const nlohmann::json& counts);

// The viewer page of the batch folder from its summary (host/report/viewer_page.h), its notes
// logged as warnings; the page's path, or empty (with a warning) when it cannot be written or
// index.html or assets/ is not imr's: the summary still stands.
std::filesystem::path WriteViewerPage(const std::filesystem::path& batch_dir,
                                      const nlohmann::json& summary);

std::string UtcNow();  // "2026-11-21T22:03:34Z"

}  // namespace imr::batch
