// `imr run` over many sequences: picks this process's shard, skips sequences whose manifest
// matches (resume), runs each of the others in a child process (isolation: a crash fails that
// sequence only), J at a time, with a progress display, records each outcome in the batch folder
// and writes the batch summary. See summary.h for the batch folder's layout.
#pragma once

#include "host/batch/progress.h"
#include "host/batch/shard.h"
#include "host/pipeline/run.h"

#include <cstdint>
#include <filesystem>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

namespace imr::batch {

struct BatchOptions {
  // This process's share of the sequences (--shard I/N, or a Slurm array task's).
  Shard shard;
  // Where `shard` came from, for the log ("--shard", "SLURM_ARRAY_TASK_ID=1").
  std::string shard_origin;
  // Sequences run at once, each in its own process.
  int jobs = 1;
  // Redo every sequence, even those whose manifest matches.
  bool force = false;
  // Kill a sequence whose process's resident memory exceeds this many bytes (0: no limit).
  uint64_t max_rss = 0;
  // Only the sequences named in this file, one per line (imr submit freezes the job's list so
  // that every array task shards the same set). Empty: every sequence of the job.
  std::filesystem::path sequences_from;
  // Progress display (kNone with --quiet).
  ProgressMode progress = ProgressMode::kLines;
  // Seconds between progress lines when not on a terminal.
  double progress_interval = 5.0;
  // Log level handed to the children ("-v" shows their debug lines).
  bool verbose = false;
  // The imr executable the children run (this one: /proc/self/exe).
  std::string executable;
  // After the summary, the viewer page RUN_DIR/index.html (host/report; `imr run --no-viewer`:
  // not written). A re-run writes it again.
  bool viewer_page = true;

  // Empty when usable, otherwise what is wrong (naming the option).
  std::string Check() const;
};

// kInterrupted: stopped by a signal to the batch (Ctrl-C, SIGTERM, SIGHUP) while it ran.
enum class SequenceStatus { kOk, kSkipped, kFailed, kInterrupted, kNotRun };
const char* ToString(SequenceStatus s);

struct SequenceOutcome {
  std::string name;
  std::filesystem::path output_directory;
  SequenceStatus status = SequenceStatus::kNotRun;
  double seconds = 0.0;
  std::string detail;  // failed: the cause; skipped: why; redone: why the manifest did not match
  int exit_code = -1;  // the child's exit status (-1: it did not exit)
  int signal = 0;      // the signal that ended the child
  uint64_t peak_rss = 0;
  std::vector<std::string> log_tail;
  std::vector<std::string> warnings;  // failed: warnings given before it failed
};

struct BatchRunResult {
  std::filesystem::path batch_directory;
  std::vector<SequenceOutcome> outcomes;  // this run's sequences, in the job's order
  bool summary_written = false;           // not for a shard: `imr report` merges them
  std::filesystem::path viewer_page;      // index.html when written, else empty
  int Count(SequenceStatus s) const;
};

// A sequence list (--sequences-from, imr submit's frozen list): one name a line; blank lines
// and '#' comments are skipped and other lines trimmed, except lines in double quotes, which are
// unescaped (\", \\, \n, \r, \t, \xNN): so every name, of any bytes, reads back as it was.
// SequenceListLine writes a name so (quoted when it needs to be).
std::string SequenceListLine(const std::string& name);
// Throws std::runtime_error naming the file and line when it cannot be read, is larger than
// kMaxSequenceListBytes, has a line longer than kMaxSequenceListLine or a NUL byte, or a quoted
// line is malformed; messages quote at most a few hundred bytes of a line.
std::vector<std::string> ReadSequenceList(const std::filesystem::path& file);
inline constexpr std::size_t kMaxSequenceListBytes = 64u << 20;
inline constexpr std::size_t kMaxSequenceListLine = 64u << 10;

// Thrown by LockBatchFolder when another run holds the lock; the message names it.
struct BatchFolderBusy : std::runtime_error {
  using std::runtime_error::runtime_error;
};
// The lock of a batch folder for one `imr run` (imr-batch/lock): exclusive, or, for a shard,
// shared with the other shards plus the shard's own (imr-batch/lock-shard-I-of-N). Creates
// imr-batch/ (throws std::runtime_error naming the folder when it cannot); throws BatchFolderBusy
// naming the holder (pid, host, since when) when another run has it. Released on destruction.
class BatchLock;
std::shared_ptr<BatchLock> LockBatchFolder(const std::filesystem::path& batch_dir, const Shard& shard);
// `imr report`'s hold on a batch folder while it writes the summary: the batch lock, exclusive
// (no run starts meanwhile). Null when no run ever locked the folder (no imr-batch/lock: nothing
// is created) or the file system cannot lock; throws BatchFolderBusy naming the holder when a
// run (or a shard of one) holds it: the summary would call its running sequences killed.
std::shared_ptr<BatchLock> HoldBatchFolderForReport(const std::filesystem::path& batch_dir);

// Problems with the options for this job (an unknown name in sequences_from, a sequence whose
// output folder is the batch folder's own imr-batch/); empty when usable.
std::vector<std::string> CheckBatch(const pipeline::ValidatedJob& job, const BatchOptions& options);

BatchRunResult RunBatch(const pipeline::ValidatedJob& job, const plugin::PluginRegistry& registry,
                        const pipeline::RunOptions& run_options, const BatchOptions& options);

// Records the job and its sequences in the batch folder (imr-batch/batch.json).
void RecordBatch(const pipeline::ValidatedJob& job, const plugin::PluginRegistry& registry,
                 const pipeline::RunOptions& run_options);

// The hidden per-sequence command the children run: loads the job, runs one sequence, writes its
// manifest, and reports progress and the result as JSON lines on fd kChildMessageFd. Returns the
// process's exit status (0 ok, 1 failed, 2 bad arguments).
struct ChildArguments {
  std::filesystem::path job;
  std::string sequence;
  pipeline::RunOptions run_options;  // exports
  std::vector<std::string> overrides;  // the job's --set KEY=VALUE, applied when loading it
  bool verbose = false;
  // The batch process: the child dies with it (PR_SET_PDEATHSIG), so killing a batch kills
  // its sequences too. 0: not checked.
  int parent_pid = 0;
};
int RunSequenceChild(const ChildArguments& args);
inline constexpr const char* kChildCommand = "__run-sequence";

}  // namespace imr::batch
