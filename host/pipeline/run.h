// Running a validated job: for each sequence, input -> engine (with the policy plugin) ->
// exporter plugins, then a JSON report. A failing sequence is recorded and the others go on.
// Outputs go through a staging folder and are renamed into place; report.json comes last.
// Every update is put in a canonical order (io::CanonicalOrder) before the engine sees it, so a
// replay of an exported stream gives the engine exactly the same input.
#pragma once

#include "host/pipeline/job_validation.h"

#include <nlohmann/json.hpp>

#include <filesystem>
#include <functional>
#include <string>
#include <vector>

namespace imr {
class InputScope;
}

namespace imr::pipeline {

struct SequenceResult {
  std::string name;
  bool ok = false;
  std::string error;                        // why it failed (names the file or field)
  bool interrupted = false;                 // it stopped for Ctrl-C, SIGTERM or SIGHUP
  std::filesystem::path output_directory;
  std::vector<std::filesystem::path> files;  // written outputs, report last
  // Also written, before the mesh: snapshots and exports (for the sequence's manifest).
  std::vector<std::filesystem::path> extra_files;
  double seconds = 0.0;
  nlohmann::json report;                    // the report written as report.json
  // Warnings given on the way, kept when the sequence fails after them (the summary lists them).
  std::vector<std::string> warnings;
};

// Where a running sequence is, for progress displays.
struct SequenceProgress {
  int keyframes = 0;        // keyframes applied so far
  int total_keyframes = -1; // -1: not known in advance
  int frame = 0;            // frame number of the latest keyframe
};

// Extra outputs of `imr run`, beside each sequence's mesh and report.
struct RunOptions {
  // --export-stream: the SLAM JSON 0.3 stream of the updates that reached the engine (replaying
  // it with input format slam_json reproduces the mesh). A path template: {sequence} (sequence
  // name), {job} (job file stem), {output} (the sequence's output folder); relative paths are
  // relative to the current folder. Empty: not written.
  std::string export_stream;
  // --export-colmap: a folder (same template) for the final points and their visibility as a
  // COLMAP text model (cameras.txt, images.txt, points3D.txt). Empty: not written.
  std::string export_colmap;
  // --check-invariants (1) / --check-invariants-every N: after every N-th keyframe, the engine's
  // full check (dO a closed 2-manifold, weights consistent); a failure stops the sequence with
  // an error naming the keyframe and the cell. 0: only the check after the last keyframe.
  int check_invariants_every = 0;
  // --trace: a JSON-lines file (same template as export_stream), one object per keyframe:
  // keyframe, frame, points, vertices, cells, cells_in_o, rss_bytes, engine_seconds and, where
  // the check ran, check_seconds; the first and every 10th keyframe also engine_bytes (the
  // engine's Memory().Total(): RSS minus it is what the host holds). Written as <path>.partial and renamed when the sequence ends
  // (also when it fails: every line is whole), so a killed run leaves only the .partial.
  std::string trace;
  // --stage-timeout: seconds a call into a plugin may take when its stage sets no
  // timeout_seconds; past it the sequence fails (host/pipeline/stage_watch.h). 0: no limit.
  double stage_timeout = 0.0;
  // --threads: threads of the engine's ray casting, overriding the job's engine.threads. 0: the
  // job's value (its default: every core of the affinity mask). The mesh does not depend on it.
  int threads = 0;
  // --no-overlap (false): the image front end makes each keyframe only when the engine asks for
  // it. By default (true), when the process may run on 2 cores or more, it makes the next
  // keyframes on a thread of its own while the engine applies the current one (prefetch.h); the
  // mesh and the report's contents are the same either way.
  bool overlap = true;
  // Called after every keyframe (from the running thread); empty: not called.
  std::function<void(const SequenceProgress&)> progress;
  // Called (from the running thread) with the lines a user should read at the default verbosity,
  // "[sequence] ..." (the scale decision, a trimmed sequence): `imr run` shows its sequences'
  // other info lines only with -v. Empty: logged at info.
  std::function<void(const std::string&)> note;
  // Called on the watchdog thread when a stage times out, with the message; must end the
  // process (the plugin call cannot be unwound). Empty: log it and exit with status 124.
  std::function<void(const std::string&)> on_stage_timeout;
};

// Problems with `options` for this job, e.g. a fixed export path for a job with several
// sequences (they would overwrite each other). Empty when usable.
std::vector<std::string> CheckRunOptions(const RunOptions& options, const ValidatedJob& job);
// An export path template expanded for one sequence.
std::filesystem::path ExpandExportPath(const std::string& tmpl, const ValidatedJob& job,
                                       const std::string& sequence);

// Names what one sequence of the job reads (the job file, the sequence's file or folder, the
// evaluation's ground truth) in `inputs`, so that nothing the run writes can be one of them.
void NoteJobInputs(const ValidatedJob& job, const SequenceRef& seq, InputScope* inputs);

// Why the sequence's run may not write one of the files it will write (its mesh, report.json,
// manifest.json, --export-stream / --export-colmap / --trace targets; the tile writer checks its
// tileset.json itself, for the job and sequence too), as the write
// rule says it with the inputs of the live InputScopes, naming the file; "" when it may.
std::string WhyNotWritableOutputs(const ValidatedJob& job, const RunOptions& options,
                                  const SequenceRef& seq);

// Runs one sequence in this process (`imr run` gives each its own child process: host/batch);
// never throws for a failing sequence (ok false, error set). The steps are in run.cc.
SequenceResult RunOneSequence(const ValidatedJob& job, const plugin::PluginRegistry& registry,
                              const RunOptions& options, const SequenceRef& seq);

// imr's own version, for reports and `imr --version`.
const char* Version();

}  // namespace imr::pipeline
