// imr: the command-line host. Subcommands: run, submit, report, validate, plugins, evaluate;
// --version, --help. Exit status (host/util/exit_status.h): run and report: 0 every sequence
// fine, else how many failed (1..63, 63 = 63 or more); other commands: 0 or 1; 64 bad usage or
// invalid job; 73 the batch folder cannot be created; 75 another run holds the batch folder.
#include "host/batch/batch.h"
#include "host/batch/child.h"
#include "host/batch/slurm.h"
#include "host/batch/summary.h"
#include "host/eval/evaluate.h"
#include "host/pipeline/job_validation.h"
#include "host/pipeline/run.h"
#include "host/pipeline/stage_watch.h"
#include "host/plugin/host_services.h"
#include "host/plugin/registry.h"
#include "host/render/render_cli.h"
#include "host/report/viewer_page.h"
#include "host/util/atomic_file.h"
#include "host/util/exit_status.h"
#include "host/util/json_text.h"
#include "host/util/log.h"

#include <boost/program_options.hpp>

#include <unistd.h>

#include <charconv>
#include <csignal>
#include <cstdlib>
#include <cstdio>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

namespace po = boost::program_options;
namespace fs = std::filesystem;

namespace {

using imr::kExitFailed;
using imr::kExitOk;
using imr::kExitUsage;

const char* kUsage =
    "imr — incremental manifold reconstruction with moving points\n"
    "\n"
    "Usage: imr <command> [options]\n"
    "\n"
    "Commands:\n"
    "  run JOB.json       run a job: every sequence (each in its own process), written to the\n"
    "                     job's output folders, with a batch summary; finished sequences are\n"
    "                     skipped on a re-run (--shard I/N, --jobs J, --force, --max-rss SIZE,\n"
    "                     --export-stream FILE, --export-colmap DIR: see `imr run --help`)\n"
    "  submit JOB.json    run a job on a Slurm cluster: an array of --tasks N tasks, then a job\n"
    "                     that writes the batch summary (see `imr submit --help`)\n"
    "  report RUN_DIR     merge the sequences' reports of a batch folder into summary.json/.md\n"
    "                     and a viewer page (index.html: the table, plots, each mesh in 3D)\n"
    "  validate JOB.json  check a job and report every problem, without running it\n"
    "  plugins            list the plugins found (kind, id, version, ABI, file) and refusals\n"
    "  evaluate MESH      accuracy of a mesh against ground truth (points, a reference mesh or\n"
    "                     KITTI Velodyne scans): distances, completeness, precision, as JSON\n"
    "  render MESH        draw a mesh into a camera of a sequence over its image (shaded and/or\n"
    "                     wireframe), or top-down with the camera path, as PNG\n"
    "\n"
    "Options:\n"
    "  --version          print the version and the plugin ABI\n"
    "  -h, --help         this help; `imr <command> --help` for a command's options\n"
    "\n"
    "Plugins are searched in a job's plugin_paths, then IMR_PLUGIN_PATH (':'-separated),\n"
    "then the installed folder next to the executable (../lib/imr/plugins).\n"
    "Exit status: run, report: 0 every sequence ok, else the number that failed (1..63; 63 means\n"
    "63 or more; the others still ran); evaluate, render, submit: 1 failed; 64 bad usage or an\n"
    "invalid job (nothing ran); 73 the batch folder cannot be created (read-only, full);\n"
    "75 another imr run is using the batch folder (try again when it has ended).\n";

void OnSignal(int signal) { imr::plugin::RequestCancel(signal); }

// Ctrl-C, kill and a closed terminal all stop a run the same way: no new sequence starts, the
// running ones are stopped, the summary is written.
void HandleStopSignals() {
  for (int signal : {SIGINT, SIGTERM, SIGHUP}) std::signal(signal, OnSignal);
}

// Parses a subcommand's options; returns false (after printing) on --help or an error.
bool ParseCommand(const std::string& name, const std::string& synopsis,
                  po::options_description& opts, po::positional_options_description& pos,
                  const std::vector<std::string>& args, po::variables_map* vm, int* status) {
  opts.add_options()("help,h", "show this help")("quiet,q", "only errors")(
      "verbose,v", "debug output");
  try {
    po::store(po::command_line_parser(args).options(opts).positional(pos).run(), *vm);
    if (vm->count("help")) {  // before notify(): --help needs no required argument
      std::cout << "Usage: " << synopsis << "\n" << opts << "\n";
      *status = kExitOk;
      return false;
    }
    po::notify(*vm);
  } catch (const po::error& e) {
    std::cerr << "imr " << name << ": " << e.what() << "\n\nUsage: " << synopsis << "\n"
              << opts << "\n";
    *status = kExitUsage;
    return false;
  }
  if (vm->count("quiet")) imr::SetLogLevel(imr::LogLevel::kWarning);
  if (vm->count("verbose")) imr::SetLogLevel(imr::LogLevel::kDebug);
  return true;
}

void PrintProblems(const fs::path& job, const std::vector<imr::io::Problem>& problems) {
  std::cerr << job.string() << ": " << problems.size() << " problem"
            << (problems.size() == 1 ? "" : "s") << ":\n";
  for (const auto& p : problems) std::cerr << "  " << p.ToString() << "\n";
}

// Loads the plugins a job can see and validates it; prints every problem when it is invalid.
bool LoadJob(const fs::path& job, imr::plugin::PluginRegistry* registry,
             imr::pipeline::ValidatedJob* v) {
  *v = imr::pipeline::LoadAndValidateJob(job, registry);
  if (v->ok()) return true;
  PrintProblems(job, v->problems);
  return false;
}

int CmdValidate(const std::vector<std::string>& args) {
  po::options_description opts("imr validate options");
  opts.add_options()("job", po::value<std::string>()->required(), "job file (JSON)");
  po::positional_options_description pos;
  pos.add("job", 1);
  po::variables_map vm;
  int status = kExitOk;
  if (!ParseCommand("validate", "imr validate JOB.json", opts, pos, args, &vm, &status)) return status;
  const fs::path job = vm["job"].as<std::string>();
  imr::plugin::PluginRegistry registry;
  imr::pipeline::ValidatedJob v;
  if (!LoadJob(job, &registry, &v)) return kExitUsage;
  std::cout << job.string() << ": valid (" << v.sequences.size() << " sequence"
            << (v.sequences.size() == 1 ? "" : "s") << ", " << v.job.pipeline.size()
            << " stages)\n";
  for (const auto& s : v.sequences)
    std::cout << "  " << s.name << " -> " << v.job.OutputDirectory(s.name).string() << "\n";
  std::cout << "batch folder (summary, imr report): "
            << imr::batch::BatchDirectory(v.job).string() << "\n";
  return kExitOk;
}

const char* kRunNotes =
    "Export paths are templates: {sequence} (the sequence's name), {job} (the job file's stem)\n"
    "and {output} (the sequence's output folder, from the job). Relative paths are relative to\n"
    "the current folder. A job with several sequences needs {sequence} or {output} in them.\n"
    "  --export-stream '{output}/stream.json'   the updates that reached the engine, as SLAM\n"
    "      JSON 0.3 (with imr's keyframe extensions); a job with \"input\": {\"format\":\n"
    "      \"slam_json\"} on that file reproduces the same mesh, and other meshers can read it.\n"
    "  --export-colmap '{output}/colmap'        the final points and the cameras that see them,\n"
    "      as a COLMAP text model (cameras.txt, images.txt, points3D.txt).\n"
    "Exports are written (atomically) only for sequences that succeed, before the mesh and\n"
    "report.json; the report lists them under \"exports\".\n"
    "\n"
    "Batches: each sequence runs in its own process (a crash fails that sequence only); when it\n"
    "succeeds, manifest.json (its files with SHA-256, and the job's hash) is written last, and a\n"
    "re-run skips it while the job and the files still match (--force: redo all). The batch\n"
    "folder (the part of output.directory before {sequence}) gets summary.json and summary.md,\n"
    "and the viewer page index.html (--no-viewer: not written), refreshed by every run.\n"
    "--shard I/N runs the I-th of N balanced, deterministic shares (inside a Slurm array task\n"
    "the share comes from SLURM_ARRAY_TASK_ID/COUNT/MIN); a shard writes no summary: run\n"
    "`imr report RUN_DIR` when all are done. Progress: a bar on a terminal, else a line every\n"
    "few seconds; -q: none.\n"
    "Ctrl-C, SIGTERM and SIGHUP stop the run: no sequence starts, the running ones get SIGTERM\n"
    "(SIGKILL 10 s later) and count as interrupted, and the summary is written.\n"
    "Exit status: 0 every sequence ok or up to date; else the number of sequences that failed,\n"
    "were interrupted or did not run (1..63; 63 means 63 or more); 64 bad usage or job; 73 the\n"
    "batch folder cannot be created; 75 another imr run holds it (each case: nothing ran).\n";

// This executable, for the child processes and the Slurm scripts.
std::string SelfPath(const char* argv0) {
  std::error_code ec;
  const fs::path p = fs::read_symlink("/proc/self/exe", ec);
  return ec ? fs::absolute(argv0).string() : p.string();
}
std::string g_argv0;

// The flags of pipeline::RunOptions, shared by run and submit (which hands them to its tasks).
void AddRunOptionFlags(po::options_description& opts) {
  opts.add_options()(
      "export-stream", po::value<std::string>()->value_name("FILE"),
      "also write the engine's input stream as SLAM JSON 0.3 (replayable)")(
      "export-colmap", po::value<std::string>()->value_name("DIR"),
      "also write the final points and their cameras as a COLMAP text model")(
      "trace", po::value<std::string>()->value_name("FILE"),
      "per keyframe, one JSON line: points, cells, resident memory, times")(
      "check-invariants",
      "after every keyframe, check that the surface is a 2-manifold and the weights are "
      "consistent; stop the sequence naming the keyframe and the cell if not (slow)")(
      "check-invariants-every", po::value<int>()->value_name("N"),
      "the same check after every N-th keyframe")(
      "stage-timeout", po::value<double>()->value_name("SECONDS"),
      "fail a sequence when a call into a plugin takes longer (a stage's timeout_seconds "
      "wins; 0: no limit, the default)");
}

bool ReadRunOptions(const po::variables_map& vm, const char* cmd, imr::pipeline::RunOptions* o) {
  const std::pair<const char*, std::string*> paths[] = {
      {"export-stream", &o->export_stream}, {"export-colmap", &o->export_colmap},
      {"trace", &o->trace}};
  for (const auto& [flag, value] : paths) {
    if (!vm.count(flag)) continue;
    *value = vm[flag].as<std::string>();
    if (value->empty()) {
      std::cerr << "imr " << cmd << ": --" << flag << ": the path must not be empty\n";
      return false;
    }
  }
  if (vm.count("stage-timeout")) {
    o->stage_timeout = vm["stage-timeout"].as<double>();
    if (const std::string e = imr::pipeline::CheckStageTimeout(o->stage_timeout); !e.empty()) {
      std::cerr << "imr " << cmd << ": --stage-timeout: " << e << ", got "
                << vm["stage-timeout"].as<double>() << "\n";
      return false;
    }
  }
  if (vm.count("check-invariants")) o->check_invariants_every = 1;
  if (vm.count("check-invariants-every")) {
    o->check_invariants_every = vm["check-invariants-every"].as<int>();
    if (o->check_invariants_every < 1) {
      std::cerr << "imr " << cmd << ": --check-invariants-every: expected a number of keyframes "
                << ">= 1, got " << o->check_invariants_every << "\n";
      return false;
    }
  }
  return true;
}

bool ParseSize(const po::variables_map& vm, const char* cmd, uint64_t* bytes) {
  if (!vm.count("max-rss")) return true;
  const auto b = imr::batch::ParseBytes(vm["max-rss"].as<std::string>());
  if (!b) {
    std::cerr << "imr " << cmd << ": --max-rss: expected a size like 512M or 4G, got '"
              << vm["max-rss"].as<std::string>() << "'\n";
    return false;
  }
  *bytes = *b;
  return true;
}

int CmdRun(const std::vector<std::string>& args) {
  po::options_description opts("imr run options");
  opts.add_options()("job", po::value<std::string>()->required(), "job file (JSON)");
  AddRunOptionFlags(opts);
  opts.add_options()(
      "shard", po::value<std::string>()->value_name("I/N"),
      "run only the I-th of N shares of the sequences (default: from a Slurm array task)")(
      "jobs,j", po::value<int>()->default_value(1)->value_name("J"), "sequences run at once")(
      "force", "redo every sequence, even those whose manifest matches")(
      "max-rss", po::value<std::string>()->value_name("SIZE"),
      "kill a sequence whose process uses more resident memory (e.g. 4G)")(
      "sequences-from", po::value<std::string>()->value_name("FILE"),
      "only the sequences named in FILE, one per line (imr submit's frozen list)")(
      "no-viewer", "do not write the viewer page (RUN_DIR/index.html) after the summary");
  po::positional_options_description pos;
  pos.add("job", 1);
  po::variables_map vm;
  int status = kExitOk;
  const std::string synopsis =
      std::string("imr run JOB.json [--shard I/N] [--jobs J] [--force] [--max-rss SIZE]\n"
                  "       [--export-stream FILE] [--export-colmap DIR] [--trace FILE]\n"
                  "       [--check-invariants | --check-invariants-every N] [-q|-v]\n\n") +
      kRunNotes;
  if (!ParseCommand("run", synopsis, opts, pos, args, &vm, &status)) return status;
  const fs::path job = vm["job"].as<std::string>();
  imr::pipeline::RunOptions run_options;
  if (!ReadRunOptions(vm, "run", &run_options)) return kExitUsage;

  imr::batch::BatchOptions batch;
  batch.jobs = vm["jobs"].as<int>();
  batch.force = vm.count("force") > 0;
  batch.verbose = vm.count("verbose") > 0;
  batch.executable = SelfPath(g_argv0.c_str());
  batch.viewer_page = vm.count("no-viewer") == 0;
  if (!ParseSize(vm, "run", &batch.max_rss)) return kExitUsage;
  if (vm.count("sequences-from")) batch.sequences_from = vm["sequences-from"].as<std::string>();
  std::string error;
  if (vm.count("shard")) {
    auto shard = imr::batch::ParseShard(vm["shard"].as<std::string>(), &error);
    if (!shard) {
      std::cerr << "imr run: --shard: " << error << "\n";
      return kExitUsage;
    }
    batch.shard = *shard;
    batch.shard_origin = "--shard";
  } else if (auto shard = imr::batch::ShardFromSlurm(&std::getenv, &error)) {
    batch.shard = *shard;
    batch.shard_origin = std::string("Slurm array task ") + std::getenv("SLURM_ARRAY_TASK_ID");
  } else if (!error.empty()) {
    std::cerr << "imr run: " << error << "\n";
    return kExitUsage;
  }
  batch.progress = vm.count("quiet") ? imr::batch::ProgressMode::kNone
                   : ::isatty(STDERR_FILENO) ? imr::batch::ProgressMode::kBar
                                             : imr::batch::ProgressMode::kLines;

  imr::plugin::PluginRegistry registry;
  imr::pipeline::ValidatedJob v;
  if (!LoadJob(job, &registry, &v)) return kExitUsage;
  auto problems = imr::pipeline::CheckRunOptions(run_options, v);
  for (auto& p : imr::batch::CheckBatch(v, batch)) problems.push_back(p);
  if (!problems.empty()) {
    for (const auto& p : problems) std::cerr << "imr run: " << p << "\n";
    return kExitUsage;
  }
  // The batch folder, and this run's hold on it: an environment problem, not a failure.
  const fs::path batch_dir = imr::batch::BatchDirectory(v.job);
  std::shared_ptr<imr::batch::BatchLock> lock;
  try {
    lock = imr::batch::LockBatchFolder(batch_dir, batch.shard);
  } catch (const imr::batch::BatchFolderBusy& e) {
    std::cerr << "imr run: " << e.what() << "\n";
    return imr::kExitTempFail;
  } catch (const std::exception& e) {
    std::cerr << "imr run: " << batch_dir.string() << ": cannot create the batch folder ("
              << e.what() << ")\n";
    return imr::kExitCantCreate;
  }
  HandleStopSignals();
  const auto result = imr::batch::RunBatch(v, registry, run_options, batch);
  // One line per sequence on stdout: where the results are, or why there are none.
  using imr::batch::SequenceStatus;
  for (const auto& s : result.outcomes) {
    const char* name = s.name.c_str();
    switch (s.status) {
      case SequenceStatus::kOk:
        std::printf("ok      %-20s %7.2f s  %s\n", name, s.seconds, s.output_directory.string().c_str());
        break;
      case SequenceStatus::kSkipped:
        std::printf("skipped %-20s up to date  %s\n", name, s.output_directory.string().c_str());
        break;
      case SequenceStatus::kFailed:
        std::printf("FAILED  %-20s %7.2f s  %s\n", name, s.seconds, s.detail.c_str());
        break;
      case SequenceStatus::kInterrupted:
        std::printf("stopped %-20s %7.2f s  %s\n", name, s.seconds, s.detail.c_str());
        break;
      case SequenceStatus::kNotRun:
        std::printf("not run %-20s %s\n", name, s.detail.c_str());
        break;
    }
  }
  const int failed = result.Count(SequenceStatus::kFailed) +
                     result.Count(SequenceStatus::kInterrupted) +
                     result.Count(SequenceStatus::kNotRun);
  std::printf("%zu sequence%s, %d failed", result.outcomes.size(),
              result.outcomes.size() == 1 ? "" : "s", result.Count(SequenceStatus::kFailed));
  if (const int n = result.Count(SequenceStatus::kInterrupted)) std::printf(", %d interrupted", n);
  if (const int n = result.Count(SequenceStatus::kSkipped)) std::printf(", %d skipped (up to date)", n);
  if (const int n = result.Count(SequenceStatus::kNotRun)) std::printf(", %d not run", n);
  if (batch.shard.active())
    std::printf(" (shard %s)\nwhen every shard is done: imr report %s\n",
                batch.shard.ToString().c_str(), result.batch_directory.string().c_str());
  else if (result.summary_written)
    std::printf("\nsummary: %s%s%s\n", (result.batch_directory / "summary.md").string().c_str(),
                result.viewer_page.empty() ? "" : "\nviewer page: ",
                result.viewer_page.string().c_str());
  else
    std::printf("\n");
  return imr::ExitStatusForFailures(failed);
}

const char* kSubmitNotes =
    "Writes two sbatch scripts into RUN_DIR/imr-batch/slurm/ (RUN_DIR: the part of the job's\n"
    "output.directory before {sequence}) and submits them: an array of --tasks tasks, each\n"
    "running `imr run` on its share of the sequences (its shard comes from the array task id),\n"
    "and a reduce job that runs `imr report RUN_DIR` after every task has ended\n"
    "(--dependency=afterany), writing RUN_DIR/summary.md and summary.json. The sequence list is\n"
    "frozen in RUN_DIR/imr-batch/sequences.txt. Task logs: RUN_DIR/imr-batch/slurm/logs/.\n"
    "Submitting again (or `sbatch` on the array script) redoes only unfinished sequences.\n"
    "--dry-run writes the scripts and prints the sbatch commands without submitting.\n"
    "Exit status: 0 submitted; 1 sbatch failed (its message is shown); 64 bad usage or job; 73\n"
    "the batch folder cannot be created.\n";

int CmdSubmit(const std::vector<std::string>& args) {
  imr::batch::SubmitOptions d;
  po::options_description opts("imr submit options");
  opts.add_options()("job", po::value<std::string>()->required(), "job file (JSON)")(
      "tasks,n", po::value<int>()->required()->value_name("N"), "array tasks")(
      "partition,p", po::value<std::string>()->value_name("P"), "Slurm partition")(
      "time,t", po::value<std::string>()->value_name("T"), "time limit per task (e.g. 2:00:00)")(
      "mem", po::value<std::string>()->value_name("M"), "memory per task (e.g. 8G)")(
      "cpus-per-task,c", po::value<int>()->default_value(d.cpus_per_task), "CPUs per task")(
      "jobs,j", po::value<int>()->value_name("J"),
      "sequences at once in a task (default: --cpus-per-task)")(
      "account,A", po::value<std::string>(), "Slurm account")(
      "qos", po::value<std::string>(), "Slurm quality of service")(
      "sbatch-arg", po::value<std::vector<std::string>>()->value_name("ARG"),
      "another sbatch option for the array, e.g. --sbatch-arg=--constraint=avx2 (repeatable)")(
      "max-rss", po::value<std::string>()->value_name("SIZE"),
      "imr run --max-rss for the tasks: kill a sequence over this resident memory")(
      "force", "redo every sequence, even finished ones")(
      "dry-run", "write the scripts and print the sbatch commands; submit nothing");
  AddRunOptionFlags(opts);
  po::positional_options_description pos;
  pos.add("job", 1);
  po::variables_map vm;
  int status = kExitOk;
  const std::string synopsis =
      std::string("imr submit JOB.json --tasks N [--partition P] [--time T] [--mem M]\n"
                  "       [--cpus-per-task C] [--jobs J] [--max-rss SIZE] [--force] [--dry-run]\n\n") +
      kSubmitNotes;
  if (!ParseCommand("submit", synopsis, opts, pos, args, &vm, &status)) return status;
  imr::batch::SubmitOptions o;
  o.tasks = vm["tasks"].as<int>();
  o.cpus_per_task = vm["cpus-per-task"].as<int>();
  if (vm.count("jobs")) o.jobs = vm["jobs"].as<int>();
  if (vm.count("partition")) o.partition = vm["partition"].as<std::string>();
  if (vm.count("time")) o.time = vm["time"].as<std::string>();
  if (vm.count("mem")) o.mem = vm["mem"].as<std::string>();
  if (vm.count("account")) o.account = vm["account"].as<std::string>();
  if (vm.count("qos")) o.qos = vm["qos"].as<std::string>();
  if (vm.count("sbatch-arg")) o.sbatch_args = vm["sbatch-arg"].as<std::vector<std::string>>();
  o.force = vm.count("force") > 0;
  o.dry_run = vm.count("dry-run") > 0;
  o.executable = SelfPath(g_argv0.c_str());
  if (!ParseSize(vm, "submit", &o.max_rss)) return kExitUsage;
  if (std::string e = o.Check(); !e.empty()) {
    std::cerr << "imr submit: " << e << "\n";
    return kExitUsage;
  }
  imr::pipeline::RunOptions run_options;
  if (!ReadRunOptions(vm, "submit", &run_options)) return kExitUsage;
  const fs::path job = vm["job"].as<std::string>();
  imr::plugin::PluginRegistry registry;
  imr::pipeline::ValidatedJob v;
  if (!LoadJob(job, &registry, &v)) return kExitUsage;
  imr::batch::BatchOptions batch_check;
  batch_check.executable = o.executable;
  auto problems = imr::pipeline::CheckRunOptions(run_options, v);
  for (auto& p : imr::batch::CheckBatch(v, batch_check)) problems.push_back(p);
  if (!problems.empty()) {
    for (const auto& p : problems) std::cerr << "imr submit: " << p << "\n";
    return kExitUsage;
  }
  const fs::path batch_dir = imr::batch::BatchDirectory(v.job);
  try {
    imr::EnsureWritableDirectory(batch_dir / imr::batch::kBatchSubdir);
  } catch (const std::exception& e) {
    std::cerr << "imr submit: " << batch_dir.string() << ": cannot create the batch folder ("
              << e.what() << ")\n";
    return imr::kExitCantCreate;
  }
  const auto r = imr::batch::Submit(v, registry, run_options, o);
  auto join = [](const std::vector<std::string>& words) {
    std::string s;
    for (const auto& w : words) s += (s.empty() ? "" : " ") + imr::batch::ShellQuote(w);
    return s;
  };
  std::printf("batch folder: %s\n", r.batch_directory.string().c_str());
  std::printf("array script: %s (%d task%s over %zu sequences)\n", r.array_script.string().c_str(),
              r.tasks, r.tasks == 1 ? "" : "s", v.sequences.size());
  std::printf("reduce script: %s (imr report %s)\n", r.reduce_script.string().c_str(),
              r.batch_directory.string().c_str());
  if (o.dry_run) {
    std::printf("dry run, nothing submitted; to submit:\n  %s\n  %s\n", join(r.array_command).c_str(),
                join(r.reduce_command).c_str());
  } else {
    std::printf("submitted array job %s and reduce job %s (runs after the array ends)\n",
                r.array_job_id.c_str(), r.reduce_job_id.c_str());
    std::printf("logs: %s\n", r.log_directory.string().c_str());
    std::printf("summary (when job %s has run): %s\n", r.reduce_job_id.c_str(),
                (r.batch_directory / "summary.md").string().c_str());
  }
  return kExitOk;
}

int CmdReport(const std::vector<std::string>& args) {
  po::options_description opts("imr report options");
  opts.add_options()("dir", po::value<std::string>()->required(),
                     "batch folder (RUN_DIR), or the job file whose batch folder it is");
  po::positional_options_description pos;
  pos.add("dir", 1);
  po::variables_map vm;
  int status = kExitOk;
  const std::string synopsis =
      "imr report RUN_DIR|JOB.json [-q]\n\n"
      "Merges the per-sequence results of a batch folder (the part of the job's\n"
      "output.directory before {sequence}) into RUN_DIR/summary.json and summary.md: every\n"
      "sequence's status (its manifest and files are checked), frames, time, mesh size,\n"
      "accuracy, and for failures the cause and last log lines. Needs no plugins.\n"
      "Also writes RUN_DIR/index.html: the table, the PNGs in RUN_DIR and RUN_DIR/plots (e.g.\n"
      "from tools/plots/imr_plots.py RUN_DIR/summary.json --out RUN_DIR/plots), and each mesh\n"
      "viewable in 3D in a browser, offline (<model-viewer> is copied beside the page).\n"
      "A sequence whose process was killed (a time limit, SIGKILL) shows as interrupted.\n"
      "Exit status: 0 every sequence ok; else the number that failed, were interrupted or did not\n"
      "run (1..63; 63 means 63 or more); 64 not a batch folder or bad usage.";
  if (!ParseCommand("report", synopsis, opts, pos, args, &vm, &status)) return status;
  fs::path dir = vm["dir"].as<std::string>();
  std::error_code ec;
  if (fs::is_regular_file(dir, ec)) {
    auto parsed = imr::io::ParseJobFile(dir);
    if (!parsed.ok()) {
      PrintProblems(dir, parsed.problems);
      return kExitUsage;
    }
    dir = imr::batch::BatchDirectory(parsed.job);
  }
  nlohmann::json summary;
  try {
    summary = imr::batch::WriteSummary(dir, "imr report");
  } catch (const std::exception& e) {
    std::cerr << "imr report: " << e.what() << "\n";
    return kExitUsage;
  }
  // The page is a view of the summary: if it cannot be written, the summary still stands.
  try {
    const auto page = imr::report::WriteBatchPage(dir, summary);
    for (const std::string& note : page.notes) imr::LogWarning("viewer page: " + note);
    std::printf("viewer page: %s (%d mesh%s in 3D)\n", page.page.string().c_str(),
                page.meshes_viewable, page.meshes_viewable == 1 ? "" : "es");
  } catch (const std::exception& e) {
    imr::LogWarning(std::string("viewer page not written: ") + e.what());
  }
  for (const auto& r : summary["sequences"]) {
    const std::string st = r["status"].get<std::string>();
    const std::string label = st == "ok" ? "ok" : st == "failed" ? "FAILED" : st;
    // The output folder as the summary stores it: relative to the batch folder, as bytes.
    const std::string where = r["error"].is_string()
                                  ? r["error"].get<std::string>()
                                  : (dir / imr::GetBytes(r, "output")).lexically_normal().string();
    std::printf("%-7s %-20s %s\n", label.c_str(), r["name"].get<std::string>().c_str(), where.c_str());
  }
  const auto& c = summary["counts"];
  std::printf("%s\nsummary: %s\n", imr::batch::CountsSentence(c).c_str(),
              (dir / "summary.md").string().c_str());
  return imr::ExitStatusForFailures(c["failed"].get<int>() + c["interrupted"].get<int>() +
                                           c["not_run"].get<int>());
}

// The hidden per-sequence command of `imr run`'s child processes.
int CmdRunSequence(const std::vector<std::string>& args) {
  imr::batch::ChildArguments a;
  for (std::size_t i = 0; i < args.size(); ++i) {
    const std::string& k = args[i];
    const bool has_value = i + 1 < args.size();
    if (k == "-v") a.verbose = true;
    else if (k == "--job" && has_value) a.job = args[++i];
    else if (k == "--sequence" && has_value) a.sequence = args[++i];
    else if (k == "--parent-pid" && has_value) a.parent_pid = std::atoi(args[++i].c_str());
    else if (k == "--export-stream" && has_value) a.run_options.export_stream = args[++i];
    else if (k == "--export-colmap" && has_value) a.run_options.export_colmap = args[++i];
    else if (k == "--trace" && has_value) a.run_options.trace = args[++i];
    else if (k == "--check-invariants-every" && has_value)
      a.run_options.check_invariants_every = std::atoi(args[++i].c_str());
    else if (k == "--stage-timeout" && has_value)
      a.run_options.stage_timeout = std::strtod(args[++i].c_str(), nullptr);
    else {
      std::cerr << "imr " << imr::batch::kChildCommand << ": unexpected argument '" << k
                << "' (an internal command of imr run)\n";
      return kExitUsage;
    }
  }
  if (a.job.empty() || a.sequence.empty()) {
    std::cerr << "imr " << imr::batch::kChildCommand << ": needs --job and --sequence\n";
    return kExitUsage;
  }
  HandleStopSignals();
  return imr::batch::RunSequenceChild(a);
}

int CmdPlugins(const std::vector<std::string>& args) {
  po::options_description opts("imr plugins options");
  opts.add_options()("plugin-path,p", po::value<std::vector<std::string>>(),
                     "extra folder or .so to search first (repeatable)");
  po::positional_options_description pos;
  po::variables_map vm;
  int status = kExitOk;
  if (!ParseCommand("plugins", "imr plugins [-p PATH]...", opts, pos, args, &vm, &status)) return status;
  std::vector<fs::path> paths;
  if (vm.count("plugin-path"))
    for (const auto& p : vm["plugin-path"].as<std::vector<std::string>>()) paths.emplace_back(p);
  for (const auto& p : imr::plugin::PluginRegistry::DefaultSearchPaths()) paths.push_back(p);
  imr::plugin::PluginRegistry registry;
  registry.Scan(paths);
  std::printf("%-14s %-34s %-8s %-5s %s\n", "KIND", "ID", "VERSION", "ABI", "FILE");
  for (const auto& p : registry.plugins())
    std::printf("%-14s %-34s %-8s %-5s %s\n", p.kind().c_str(), p.id().c_str(),
                p.version().c_str(), p.abi().c_str(), p.file.string().c_str());
  if (!registry.refusals().empty()) {
    std::printf("\nRefused:\n");
    for (const auto& r : registry.refusals()) std::printf("  %s\n", r.ToString().c_str());
  }
  std::printf("\nSearched: ");
  for (std::size_t i = 0; i < registry.searched().size(); ++i)
    std::printf("%s%s", i ? ":" : "", registry.searched()[i].string().c_str());
  std::printf("\n");
  return kExitOk;
}


const char* kEvaluateNotes =
    "MESH: .obj, .ply, .gltf or .glb (what the exporter writes), or ASCII .off (other meshers).\n"
    "Ground truth: --truth FILE, a point cloud (.ply without faces, .xyz/.txt/.asc: x y z per\n"
    "line, more columns ignored) or a reference mesh (sampled uniformly by area at\n"
    "--truth-density), or --velodyne-seq DIR alone: the Velodyne scans of a KITTI sequence\n"
    "(odometry: a folder with calib.txt; raw: a drive folder) placed in its world frame. With\n"
    "--velodyne-seq the ground truth (and the mesh samples of precision) are cropped to what the\n"
    "cameras saw: inside a camera's frustum and within --max-ray-length of its centre; without\n"
    "cameras nothing is cropped, and the report says so. Distances: ground truth -> nearest mesh\n"
    "triangle (the paper's mean; CloudCompare's cloud-to-mesh distance). Completeness(tau): share\n"
    "of ground-truth points within tau of the mesh; precision(tau): share of mesh area\n"
    "(--precision-samples samples) within tau of the ground truth. The JSON keys are documented\n"
    "in host/eval/README.md.\n"
    "Exit status: 0 evaluated; 1 a file is missing or bad, or nothing is left to evaluate;\n"
    "64 bad usage.\n";

// "0.05,0.1" -> {0.05, 0.1}; false on anything else.
bool ParseList(const std::string& s, std::vector<double>* out) {
  out->clear();
  std::stringstream ss(s);
  for (std::string item; std::getline(ss, item, ',');) {
    double v = 0.0;
    const auto r = std::from_chars(item.data(), item.data() + item.size(), v);
    if (r.ec != std::errc() || r.ptr != item.data() + item.size()) return false;
    out->push_back(v);
  }
  return !out->empty();
}

int CmdEvaluate(const std::vector<std::string>& args) {
  imr::eval::EvaluationOptions d;  // the defaults, for the help text
  po::options_description opts("imr evaluate options");
  opts.add_options()("mesh", po::value<std::string>()->required(), "mesh to evaluate")(
      "truth", po::value<std::string>()->value_name("FILE"),
      "ground truth: point cloud (.ply, .xyz) or reference mesh (.ply, .obj, .gltf, .glb, .off)")(
      "velodyne-seq", po::value<std::string>()->value_name("DIR"),
      "KITTI sequence: its cameras crop the ground truth; its Velodyne scans are the ground "
      "truth when --truth is not given")(
      "tau", po::value<std::string>()->default_value("0.05,0.1,0.2,0.5"),
      "thresholds of completeness and precision, comma-separated (scene units)")(
      "max-ray-length", po::value<double>()->default_value(d.max_ray_length),
      "crop: greatest distance from the camera that sees a point (<= 0: no limit)")(
      "no-crop", "do not crop to the cameras' view")(
      "frames", po::value<std::string>()->value_name("FIRST[:COUNT[:STEP]]"),
      "frames of --velodyne-seq to use (cameras and scans), as the job's input options")(
      "camera", po::value<int>()->default_value(-1), "KITTI camera 0..3 (-1: the lowest present)")(
      "scan-step", po::value<int>()->default_value(1),
      "Velodyne ground truth: every n-th frame's scan")(
      "truth-density", po::value<double>()->default_value(d.truth_density),
      "reference-mesh ground truth: samples per unit area")(
      "precision-samples", po::value<std::size_t>()->default_value(d.precision_samples),
      "mesh samples for precision")(
      "seed", po::value<uint64_t>()->default_value(d.seed), "seed of the samplings")(
      "per-point", po::value<std::string>()->value_name("FILE"),
      "write each ground-truth point's distance, one per line in input order (nan: cropped)")(
      "out,o", po::value<std::string>()->value_name("FILE"), "write the report as JSON")(
      "threads,j", po::value<int>()->default_value(0), "worker threads (0: all cores)");
  po::positional_options_description pos;
  pos.add("mesh", 1);
  po::variables_map vm;
  int status = kExitOk;
  const std::string synopsis =
      std::string("imr evaluate MESH (--truth FILE | --velodyne-seq DIR) [--tau LIST]\n"
                  "       [--max-ray-length L] [--out report.json] [--per-point FILE] [--threads N]\n\n") +
      kEvaluateNotes;
  if (!ParseCommand("evaluate", synopsis, opts, pos, args, &vm, &status)) return status;

  auto usage = [](const std::string& what) {
    std::cerr << "imr evaluate: " << what << " (imr evaluate --help)\n";
    return kExitUsage;
  };
  imr::eval::EvaluationInputs in;
  in.mesh = vm["mesh"].as<std::string>();
  if (vm.count("truth")) in.truth = vm["truth"].as<std::string>();
  if (vm.count("velodyne-seq")) in.sequence = vm["velodyne-seq"].as<std::string>();
  if (in.truth.empty() && in.sequence.empty())
    return usage("no ground truth: give --truth FILE or --velodyne-seq DIR");
  if (vm.count("frames") &&
      !imr::io::ParseFrameSelection(vm["frames"].as<std::string>(), &in.sequence_options))
    return usage("--frames: expected FIRST[:COUNT[:STEP]], got '" + vm["frames"].as<std::string>() + "'");
  if ((vm.count("frames") || !vm["camera"].defaulted()) && in.sequence.empty())
    return usage("--frames and --camera need --velodyne-seq");
  in.sequence_options.camera = vm["camera"].as<int>();
  const std::string problem = in.sequence_options.Check();
  if (!problem.empty()) return usage(problem);
  in.scan_step = vm["scan-step"].as<int>();
  if (in.scan_step < 1) return usage("--scan-step must be at least 1");
  if (vm.count("per-point")) in.per_point = vm["per-point"].as<std::string>();

  imr::eval::EvaluationOptions o;
  if (!ParseList(vm["tau"].as<std::string>(), &o.taus))
    return usage("--tau: expected numbers separated by commas, got '" + vm["tau"].as<std::string>() + "'");
  o.max_ray_length = vm["max-ray-length"].as<double>();
  o.crop = !vm.count("no-crop");
  o.truth_density = vm["truth-density"].as<double>();
  o.precision_samples = vm["precision-samples"].as<std::size_t>();
  o.seed = vm["seed"].as<uint64_t>();
  o.threads = vm["threads"].as<int>();
  if (const std::string p = o.Problem(); !p.empty()) return usage(p);

  // Output folders first: a missing one should not cost a whole evaluation.
  const std::string out = vm.count("out") ? vm["out"].as<std::string>() : "";
  for (const std::string& f : {out, in.per_point})
    if (!f.empty()) imr::EnsureWritableDirectory(fs::absolute(f).parent_path());

  const nlohmann::json report = imr::eval::EvaluateFiles(in, o, &imr::eval::ReadKittiSequence);
  std::cout << imr::eval::FormatReport(report);
  if (!out.empty()) {
    imr::WriteFileAtomically(out, report.dump(2) + "\n");
    std::cout << "report written to " << out << "\n";
  }
  return kExitOk;
}

}  // namespace

int main(int argc, char** argv) {
  g_argv0 = argv[0];
  std::vector<std::string> args(argv + 1, argv + argc);
  if (args.empty()) {
    std::cerr << kUsage;
    return kExitUsage;
  }
  const std::string cmd = args[0];
  args.erase(args.begin());
  try {
    if (cmd == "--help" || cmd == "-h" || cmd == "help") {
      std::cout << kUsage;
      return kExitOk;
    }
    if (cmd == "--version") {
      std::printf("imr %s (plugin ABI %d.%d)\n", imr::pipeline::Version(), IMR_ABI_MAJOR,
                  IMR_ABI_MINOR);
      return kExitOk;
    }
    if (cmd == "run") return CmdRun(args);
    if (cmd == "submit") return CmdSubmit(args);
    if (cmd == "report") return CmdReport(args);
    if (cmd == imr::batch::kChildCommand) return CmdRunSequence(args);
    if (cmd == "validate") return CmdValidate(args);
    if (cmd == "plugins") return CmdPlugins(args);
    if (cmd == "evaluate") return CmdEvaluate(args);
    if (cmd == "render") return imr::render::RenderMain(argc - 1, argv + 1);
  } catch (const std::exception& e) {
    std::cerr << "imr " << cmd << ": " << e.what() << "\n";
    return kExitFailed;
  }
  std::cerr << "imr: unknown command '" << cmd << "'\n\n" << kUsage;
  return kExitUsage;
}
