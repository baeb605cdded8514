// Commands that run jobs: run (each sequence in a child process: batch), submit (a Slurm array),
// report (a batch folder's summary and viewer page), and the children's hidden command.
#include "host/batch/batch.h"
#include "host/batch/child.h"
#include "host/batch/manifest.h"
#include "host/batch/run_flags.h"
#include "host/batch/slurm.h"
#include "host/batch/summary.h"
#include "host/cli/command.h"
#include "host/io/batch_folder.h"
#include "host/io/colmap_model.h"
#include "host/io/input_formats.h"
#include "host/pipeline/scale.h"
#include "host/report/viewer_page.h"
#include "host/util/atomic_file.h"
#include "host/util/input_file.h"
#include "host/util/exit_status.h"
#include "host/util/write_rule.h"
#include "host/util/json_text.h"
#include "host/util/log.h"
#include "host/util/strict_number.h"

#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <memory>
#include <optional>

namespace imr::cli {
namespace {

namespace fs = std::filesystem;

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
    "few seconds; -q: none, and only errors and warnings (a failed sequence's line, no ok lines\n"
    "and no summary lines: the exit status says the rest).\n"
    "Ctrl-C, SIGTERM and SIGHUP stop the run: no sequence starts, the running ones get SIGTERM\n"
    "(SIGKILL 10 s later) and count as interrupted, and the summary is written.\n"
    "Exit status: 0 every sequence ok or up to date; else the number of sequences that failed,\n"
    "were interrupted or did not run (1..63; 63 means 63 or more); 64 bad usage or job; 73 the\n"
    "batch folder cannot be created or holds a summary.md, summary.json, index.html, assets/ or\n"
    "imr-batch/ that imr did not write; 75 another imr run holds it (each case: nothing ran); 73\n"
    "also when the batch summary could not be written after the run.\n";

bool ParseSize(const po::variables_map& vm, const char* cmd, uint64_t* bytes) {
  if (!vm.count("max-rss")) return true;
  const auto b = imr::batch::ParseBytes(vm["max-rss"].as<std::string>());
  if (!b) {
    std::cerr << "imr " << cmd << ": --max-rss: expected a size like 512M or 4G, got '"
              << OneLine(vm["max-rss"].as<std::string>(), 200) << "' (at most 4 EiB)\n";
    return false;
  }
  *bytes = *b;
  return true;
}

// Loads the job with its --set overrides and checks the run's and the batch's options against
// it; prints every problem and returns false when it cannot run.
bool LoadRunnableJob(const char* cmd, const fs::path& job, const po::variables_map& vm,
                     const pipeline::RunOptions& run_options, const batch::BatchOptions& batch,
                     plugin::PluginRegistry* registry, pipeline::ValidatedJob* v) {
  if (!LoadJob(job, JobOverrides(vm), registry, v)) return false;
  auto problems = pipeline::CheckRunOptions(run_options, *v);
  for (auto& p : batch::CheckBatch(*v, batch)) problems.push_back(p);
  for (const auto& p : problems) std::cerr << "imr " << cmd << ": " << p << "\n";
  return problems.empty();
}

// The batch's options from imr run's flags; false (having said why) on a bad value.
bool ReadBatchOptions(const po::variables_map& vm, imr::batch::BatchOptions* batch) {
  batch->jobs = vm["jobs"].as<int>();
  batch->force = vm.count("force") > 0;
  batch->verbose = vm.count("verbose") > 0;
  batch->executable = SelfPath();
  batch->viewer_page = vm.count("no-viewer") == 0;
  if (!ParseSize(vm, "run", &batch->max_rss)) return false;
  if (vm.count("sequences-from")) {
    batch->sequences_from = vm["sequences-from"].as<std::string>();
    NoteInput(batch->sequences_from, "the list of sequences (--sequences-from)");
  }
  std::string error;
  if (vm.count("shard")) {
    auto shard = imr::batch::ParseShard(vm["shard"].as<std::string>(), &error);
    if (!shard) {
      std::cerr << "imr run: --shard: " << error << "\n";
      return false;
    }
    batch->shard = *shard;
    batch->shard_origin = "--shard";
  } else if (auto shard = imr::batch::ShardFromSlurm(&std::getenv, &error)) {
    batch->shard = *shard;
    batch->shard_origin = std::string("Slurm array task ") + std::getenv("SLURM_ARRAY_TASK_ID");
  } else if (!error.empty()) {
    std::cerr << "imr run: " << error << "\n";
    return false;
  }
  batch->progress = vm.count("quiet") ? imr::batch::ProgressMode::kNone
                    : ::isatty(STDERR_FILENO) ? imr::batch::ProgressMode::kBar
                                              : imr::batch::ProgressMode::kLines;
  return true;
}

// The batch folder, and this run's hold on it: an environment problem, not a failure. The exit
// status when it cannot be held (having said why).
std::optional<int> HoldBatchFolder(const fs::path& batch_dir, const imr::batch::BatchOptions& batch,
                                   std::shared_ptr<imr::batch::BatchLock>* lock) {
  if (const std::string foreign = io::ForeignBatchFiles(batch_dir, batch.viewer_page);
      !foreign.empty()) {
    std::cerr << "imr run: " << foreign << "\n";
    return imr::kExitCantCreate;
  }
  try {
    *lock = imr::batch::LockBatchFolder(batch_dir, batch.shard);
  } catch (const imr::batch::BatchFolderBusy& e) {
    std::cerr << "imr run: " << e.what() << "\n";
    return imr::kExitTempFail;
  } catch (const std::exception& e) {
    std::cerr << "imr run: " << batch_dir.string() << ": cannot create the batch folder ("
              << e.what() << ")\n";
    return imr::kExitCantCreate;
  }
  return std::nullopt;
}

// Under a finished sequence's line, every file it wrote (its manifest's list): the mesh, the
// report, tiles, exports (issue 47: users looked for them).
void PrintWrittenFiles(const fs::path& output) {
  std::string why;
  const std::optional<imr::batch::Manifest> m = imr::batch::ReadManifest(output, &why);
  if (!m) return;
  std::string line;
  for (const std::string& f : imr::batch::WrittenFilesForLog(*m))
    line += (line.empty() ? "" : ", ") + f;
  std::printf("        wrote: %s\n", line.c_str());
}

// One line per sequence on stdout: where the results are, or why there are none; with -q only
// the ones that say why (errors).
void PrintOutcomes(const imr::batch::BatchRunResult& result, bool quiet) {
  using imr::batch::SequenceStatus;
  for (const auto& s : result.outcomes) {
    const char* name = s.name.c_str();
    switch (s.status) {
      case SequenceStatus::kOk:
        if (!quiet) {
          std::printf("ok      %-20s %7.2f s  %s\n", name, s.seconds, s.output_directory.string().c_str());
          PrintWrittenFiles(s.output_directory);
        }
        break;
      case SequenceStatus::kSkipped:
        if (!quiet) {
          std::printf("skipped %-20s up to date  %s\n", name, s.output_directory.string().c_str());
          PrintWrittenFiles(s.output_directory);
        }
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
}

// The summary lines (not with -q: the exit status tells the rest).
void PrintBatchTotals(const imr::batch::BatchRunResult& result, const imr::batch::BatchOptions& batch) {
  using imr::batch::SequenceStatus;
  std::printf("%zu sequence%s, %d failed", result.outcomes.size(),
              result.outcomes.size() == 1 ? "" : "s", result.Count(SequenceStatus::kFailed));
  if (const int n = result.Count(SequenceStatus::kInterrupted)) std::printf(", %d interrupted", n);
  if (const int n = result.Count(SequenceStatus::kSkipped)) std::printf(", %d skipped (up to date)", n);
  if (const int n = result.Count(SequenceStatus::kNotRun)) std::printf(", %d not run", n);
  if (batch.shard.active())
    std::printf(" (shard %s)\nwhen every shard is done: imr report %s\n",
                batch.shard.ToString().c_str(), result.batch_directory.string().c_str());
  else if (result.summary_written)
    std::printf("\nsummary: %s, summary.json (imr's bookkeeping: imr-batch/)%s%s\n",
                (result.batch_directory / "summary.md").string().c_str(),
                result.viewer_page.empty() ? "" : "\nviewer page: ",
                result.viewer_page.string().c_str());
  else
    std::printf("\n");
}

int CmdRun(const std::vector<std::string>& args) {
  po::options_description opts("imr run options");
  opts.add_options()("job", po::value<std::string>()->required(), "job file (JSON)");
  AddJobOverrideFlag(opts);
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
      std::string("imr run JOB.json [--set KEY=VALUE]... [--shard I/N] [--jobs J] [--force]\n"
                  "       [--max-rss SIZE] [--export-stream FILE] [--export-colmap DIR] [--trace FILE]\n"
                  "       [--check-invariants | --check-invariants-every N] [-q|-v]\n\n") +
      kRunNotes;
  if (!ParseCommand("run", synopsis, opts, pos, args, &vm, &status,
                    {{"job", "needs a job file: imr run JOB.json (see configs/ for examples)"}}))
    return status;
  const fs::path job = vm["job"].as<std::string>();
  imr::pipeline::RunOptions run_options;
  if (!ReadRunOptions(vm, "run", &run_options)) return kExitUsage;
  NoteInput(job, "the job file");
  imr::batch::BatchOptions batch;
  if (!ReadBatchOptions(vm, &batch)) return kExitUsage;

  imr::plugin::PluginRegistry registry;
  imr::pipeline::ValidatedJob v;
  if (!LoadRunnableJob("run", job, vm, run_options, batch, &registry, &v)) return kExitUsage;
  std::shared_ptr<imr::batch::BatchLock> lock;
  if (const std::optional<int> held = HoldBatchFolder(imr::batch::BatchDirectory(v.job), batch, &lock))
    return *held;
  HandleStopSignals();
  const auto result = imr::batch::RunBatch(v, registry, run_options, batch);
  const bool quiet = vm.count("quiet") > 0;
  PrintOutcomes(result, quiet);
  if (!quiet) PrintBatchTotals(result, batch);
  using imr::batch::SequenceStatus;
  const int failed = result.Count(SequenceStatus::kFailed) +
                     result.Count(SequenceStatus::kInterrupted) +
                     result.Count(SequenceStatus::kNotRun);
  // The summary is the batch's result: not writing it is the batch folder's failure (its error
  // is on stderr), whatever the sequences did.
  if (!batch.shard.active() && !result.summary_written) return imr::kExitCantCreate;
  return imr::ExitStatusForFailures(failed);
}

const char* kMeshNotes =
    "One mesh from one sequence, without writing a job: imr mesh builds the job (the input, the\n"
    "image front end when the format has images, the engine with its defaults, the assimp\n"
    "exporter), writes it to WORK/job.json and runs it as `imr run WORK/job.json` would (a child\n"
    "process, resume, the report in WORK/mesh/report.json), then copies the mesh (and its\n"
    "companion files: an OBJ's .mtl, a glTF's .bin) to --out. The format of the mesh comes from\n"
    "--out's extension: .ply, .obj, .gltf or .glb. --set changes any value of the built job\n"
    "(--set engine.steiner_spacing=0.1, --set input.options.views_per_keyframe=4); `imr options`\n"
    "lists them. Any other option is handed to imr run (--force, --check-invariants, ...).\n"
    "Example (COLMAP): imr mesh --input sparse/0 --format colmap --out mesh.ply\n"
    "Exit status: 0 written; 1 the run failed (its report and log say why); 64 bad usage; 73\n"
    "the mesh could not be copied to --out (the run's result stays in WORK/mesh).\n";

// imr mesh's request, as given and checked.
struct MeshRequest {
  po::variables_map vm;
  std::vector<std::string> forwarded;  // options of imr run
  std::string input, format;
  const io::InputFormat* f = nullptr;
  fs::path out;     // absolute
  std::string ext;  // --out's extension, lower case
  fs::path work;
};

int MeshUsage(const std::string& what) {
  std::cerr << "imr mesh: " << what << " (imr mesh --help)\n";
  return kExitUsage;
}

// imr mesh's flags into m.vm and m.forwarded; an exit status when done (help, bad usage).
std::optional<int> ParseMeshFlags(const std::vector<std::string>& args, MeshRequest* m) {
  po::options_description opts("imr mesh options");
  opts.add_options()("input,i", po::value<std::string>()->value_name("PATH"),
                     "the sequence: a folder or file (e.g. a COLMAP sparse/0), or a synthetic "
                     "scene's name")(
      "format,f", po::value<std::string>()->value_name("FORMAT"),
      "its input format, as a job's input.format (`imr options --only input` lists them)")(
      "out,o", po::value<std::string>()->value_name("FILE"), "the mesh: .ply, .obj, .gltf or .glb")(
      "work", po::value<std::string>()->value_name("DIR"),
      "where the job and its run go (default: beside --out, named after it, ending in .imr)");
  AddJobOverrideFlag(opts);
  opts.add_options()("help,h", "show this help")("quiet,q", "errors and warnings only")("verbose,v",
                                                                           "debug output");
  const std::string synopsis =
      std::string("imr mesh --input PATH --format FORMAT --out MESH.ply [--set KEY=VALUE]...\n"
                  "         [--work DIR] [imr run options]\n\n") +
      kMeshNotes;
  try {
    const po::parsed_options parsed =
        po::command_line_parser(args).options(opts).allow_unregistered().run();
    po::store(parsed, m->vm);
    m->forwarded = po::collect_unrecognized(parsed.options, po::include_positional);
    if (m->vm.count("help")) {
      std::cout << "Usage: " << synopsis << "\n" << opts << "\n";
      return kExitOk;
    }
    po::notify(m->vm);
  } catch (const po::error& e) {
    return MeshUsage(e.what());
  }
  return std::nullopt;
}

// The flags' values, checked before anything is written; an exit status when they are wrong.
std::optional<int> CheckMeshFlags(MeshRequest* m) {
  const po::variables_map& vm = m->vm;
  for (const char* required : {"input", "format", "out"})
    if (!vm.count(required)) return MeshUsage(std::string("needs --") + required);
  if (vm["out"].as<std::string>().empty()) return MeshUsage("--out: expected a mesh file name, got ''");
  // --out decides the output: the run must write there and nowhere else.
  for (const std::string& o : JobOverrides(vm)) {
    const std::string key = o.substr(0, o.find('='));
    for (const char* owned : {"output", "output.directory", "output.stem", "output.formats"})
      if (key == owned || key.rfind(std::string(owned) + "[", 0) == 0 ||
          (key.rfind(std::string(owned) + ".", 0) == 0 && std::string(owned) != "output"))
        return MeshUsage("--set " + OneLine(o, 200) + ": imr mesh sets output.directory, output.stem "
                         "and output.formats from --out (and --work); change those instead");
  }
  m->input = vm["input"].as<std::string>();
  m->format = vm["format"].as<std::string>();
  m->f = io::FindInputFormat(m->format);
  if (m->f == nullptr) {
    std::vector<std::string> names;
    for (const io::InputFormat& x : io::InputFormats()) names.push_back(x.name);
    return MeshUsage("--format: expected " + io::JoinAlternatives(names) + ", got '" + m->format + "'");
  }
  m->out = fs::absolute(vm["out"].as<std::string>()).lexically_normal();
  if (std::error_code ec; fs::is_directory(m->out, ec))
    return MeshUsage("--out: " + m->out.string() + " is a folder; name the mesh file (e.g. " +
                     (m->out / "mesh.ply").string() + ")");
  m->ext = m->out.extension().string();
  for (char& c : m->ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (m->ext != ".ply" && m->ext != ".obj" && m->ext != ".gltf" && m->ext != ".glb")
    return MeshUsage("--out: expected a file ending in .ply, .obj, .gltf or .glb, got '" +
                     m->out.filename().string() + "'");
  m->work = vm.count("work") ? fs::absolute(vm["work"].as<std::string>())
                             : m->out.parent_path() / (m->out.stem().string() + ".imr");
  return std::nullopt;
}

// What the input is, before anything is written: a path that does not exist, or a folder that
// is something else than the model (a mapper's sparse/ above its sub-models, a folder of
// photos), is a usage error that names --input. Then --out: a file imr may not write costs no
// run.
std::optional<int> CheckMeshInputAndOutput(const MeshRequest& m) {
  if (m.f->sequences_are_paths) {
    const fs::path in = fs::absolute(m.input).lexically_normal();
    std::error_code ec;
    if (!fs::exists(in, ec))
      return MeshUsage("--input: " + in.string() + " does not exist");
    if (m.format == "colmap" && fs::is_directory(in, ec) && !fs::exists(in / "cameras.bin", ec) &&
        !fs::exists(in / "cameras.txt", ec)) {
      const std::string hint = io::ColmapFolderHint(in);
      if (!hint.empty()) return MeshUsage("--input: " + in.string() + " is not a COLMAP model: " + hint);
    }
  }
  if (m.f->sequences_are_paths) NoteInput(fs::absolute(m.input), "the input (--input)");
  if (const std::string why = WhyNotWritable(m.out); !why.empty()) {
    std::cerr << "imr mesh: --out " << m.out.string() << ": " << why << "; nothing ran\n";
    return kExitCantCreate;
  }
  return std::nullopt;
}

// The job imr run would be given (paths absolute: the job file lives in WORK). The --set
// overrides go into the saved job, so that `imr run WORK/job.json` redoes this very mesh (issue
// 47); ones that do not apply are left in `overrides` for imr run, which names them.
nlohmann::json MeshJob(const MeshRequest& m, std::vector<std::string>* overrides) {
  nlohmann::json job = {
      {"description", "built by imr mesh: " + m.input + " (" + m.format + ") -> " + m.out.string()},
      {"sequences", {m.f->sequences_are_paths ? fs::absolute(m.input).lexically_normal().string() : m.input}},
      {"input", {{"format", m.format}}},
      {"pipeline", nlohmann::json::array()},
      {"output", {{"directory", "mesh"}, {"stem", m.out.stem().string()}, {"formats", {m.ext.substr(1)}}}}};
  if (m.f->needs_front_end) {
    // Images: the surface imr-bench quality found best, as in the README's default job (issue
    // 45; docs/refinement.md): a track a point from its first keyframe on, points from depth
    // maps of the keyframes beside the tracked ones, a 4 m Steiner grid to carve between them,
    // the surface refined from the images every 10 keyframes, its planar regions triangulated
    // again, its edges flipped where the other diagonal lies smoother and its face normals
    // filtered, the three in turn three times, faces the keyframes see from behind dropped
    // (docs/engine.md).
    job["engine"] = {{"window", 15},
                     {"steiner_export", "any_steiner"},
                     {"retriangulate_planes", 0.1},
                     {"flip_edges", true},
                     {"filter_normals", 3},
                     {"mesh_pass_rounds", 3},
                     {"drop_back_faces", true}};
    // The 4 m grid is the street's (metres); a model in its own units (the Middlebury rings:
    // centimetres of a statue) keeps the grid engine.scale auto chooses.
    if (pipeline::ScaleModeOf(nlohmann::json::object(), m.format) == pipeline::ScaleMode::kMetric)
      job["engine"]["steiner_spacing"] = 4.0;
    job["pipeline"].push_back({{"kind", "features"}, {"plugin", "org.imr.features.edge_klt"}});
    job["pipeline"].push_back({{"kind", "refiner"},
                               {"plugin", "org.imr.refiner.ceres"},
                               {"params", {{"min_keyframes", 1}}}});
    job["pipeline"].push_back({{"kind", "dense"}, {"plugin", "org.imr.dense.patchmatch"}});
    job["pipeline"].push_back(
        {{"kind", "mesh_refiner"}, {"plugin", "org.imr.refine.photometric"}, {"every_keyframes", 10}});
  }
  job["pipeline"].push_back({{"kind", "exporter"}, {"plugin", "org.imr.exporter.assimp"}});
  *overrides = JobOverrides(m.vm);
  nlohmann::json applied = job;
  std::vector<io::Problem> problems;
  io::ApplyJobOverrides(*overrides, &applied, &problems);
  if (problems.empty()) {
    job = std::move(applied);
    overrides->clear();
  }
  return job;
}

// The run's output folder holds the mesh and its companions; report.json lists them. The mesh
// is copied to --out as named (the exporter writes the extension in lower case), companions by
// their names; each copy is atomic, and a failure is the output's, not the run's (73).
int CopyMeshToOut(const MeshRequest& m, const fs::path& job_file) {
  const fs::path folder = m.work / "mesh";
  const std::string mesh_name = m.out.stem().string() + m.ext;
  std::vector<std::string> files;
  try {
    InputStream in(folder / "report.json", "the report of imr mesh's run", InputRole::kOwnOutput);
    const nlohmann::json report = nlohmann::json::parse(in);
    for (const auto& name : report.at("files")) files.push_back(name.get<std::string>());
  } catch (const std::exception& e) {
    std::cerr << "imr mesh: " << (folder / "report.json").string() << ": unreadable ("
              << e.what() << ")\n";
    return kExitFailed;
  }
  if (std::find(files.begin(), files.end(), mesh_name) == files.end()) {
    std::cerr << "imr mesh: the run wrote no " << (folder / mesh_name).string()
              << " (its report.json lists the files it wrote)\n";
    return kExitFailed;
  }
  std::vector<std::string> copied;
  for (const std::string& n : files) {
    if (n == "report.json") continue;
    const fs::path to = n == mesh_name ? m.out : m.out.parent_path() / n;
    try {
      CopyFileAtomically(folder / n, to);
    } catch (const std::exception& e) {
      std::cerr << "imr mesh: cannot copy the mesh to --out: " << e.what()
                << " (the run's result stays in " << folder.string() << ")\n";
      return kExitCantCreate;
    }
    copied.push_back(to.filename().string());
  }
  std::string companions;
  for (const std::string& n : copied)
    if (n != m.out.filename().string()) companions += (companions.empty() ? " (with " : ", ") + n;
  if (!companions.empty()) companions += ")";
  // The last lines: the mesh where asked, and the job that redoes it (the run's own files are
  // named above them, under its "ok" line).
  if (!m.vm.count("quiet"))
    std::printf("mesh: %s%s\njob: %s (imr run it to redo this mesh; the run's files are in %s)\n",
                m.out.string().c_str(), companions.c_str(), job_file.string().c_str(),
                folder.string().c_str());
  return kExitOk;
}

int CmdMesh(const std::vector<std::string>& args) {
  MeshRequest m;
  if (const std::optional<int> done = ParseMeshFlags(args, &m)) return *done;
  if (const std::optional<int> bad = CheckMeshFlags(&m)) return *bad;
  if (const std::optional<int> bad = CheckMeshInputAndOutput(m)) return *bad;
  std::vector<std::string> overrides;
  const nlohmann::json job = MeshJob(m, &overrides);
  const fs::path job_file = m.work / "job.json";
  try {
    EnsureWritableDirectory(m.work);
    WriteFileAtomically(job_file, job.dump(2) + "\n");
  } catch (const std::exception& e) {
    std::cerr << "imr mesh: " << m.work.string() << ": cannot write the job (" << e.what() << ")\n";
    return kExitCantCreate;
  }

  std::vector<std::string> run_args = {job_file.string()};
  for (const std::string& o : overrides) run_args.insert(run_args.end(), {"--set", o});
  if (m.vm.count("quiet")) run_args.push_back("-q");
  if (m.vm.count("verbose")) run_args.push_back("-v");
  run_args.insert(run_args.end(), m.forwarded.begin(), m.forwarded.end());
  if (const int status = CmdRun(run_args); status != kExitOk) return status;
  return CopyMeshToOut(m, job_file);
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
  AddJobOverrideFlag(opts);
  AddRunOptionFlags(opts);
  po::positional_options_description pos;
  pos.add("job", 1);
  po::variables_map vm;
  int status = kExitOk;
  const std::string synopsis =
      std::string("imr submit JOB.json --tasks N [--partition P] [--time T] [--mem M]\n"
                  "       [--cpus-per-task C] [--jobs J] [--max-rss SIZE] [--force] [--dry-run]\n\n") +
      kSubmitNotes;
  if (!ParseCommand("submit", synopsis, opts, pos, args, &vm, &status,
                    {{"job", "needs a job file: imr submit JOB.json --tasks N"}}))
    return status;
  // An option given with an empty value is a mistake, not "the default".
  for (const char* name : {"partition", "time", "mem", "account", "qos"})
    if (vm.count(name) && vm[name].as<std::string>().empty()) {
      std::cerr << "imr submit: --" << name << ": expected a value, got ''\n";
      return kExitUsage;
    }
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
  o.executable = SelfPath();
  if (!ParseSize(vm, "submit", &o.max_rss)) return kExitUsage;
  if (std::string e = o.Check(); !e.empty()) {
    std::cerr << "imr submit: " << e << "\n";
    return kExitUsage;
  }
  imr::pipeline::RunOptions run_options;
  if (!ReadRunOptions(vm, "submit", &run_options)) return kExitUsage;
  const fs::path job = vm["job"].as<std::string>();
  NoteInput(job, "the job file");
  imr::plugin::PluginRegistry registry;
  imr::pipeline::ValidatedJob v;
  imr::batch::BatchOptions batch_check;
  batch_check.executable = o.executable;
  if (!LoadRunnableJob("submit", job, vm, run_options, batch_check, &registry, &v))
    return kExitUsage;
  const fs::path batch_dir = imr::batch::BatchDirectory(v.job);
  if (const std::string e = imr::batch::CheckScriptPaths(batch_dir); !e.empty()) {
    std::cerr << "imr submit: " << e << "\n";
    return kExitUsage;
  }
  // The reduce job writes the summary and the viewer page: refuse now, not hours later.
  if (const std::string foreign = io::ForeignBatchFiles(batch_dir, true); !foreign.empty()) {
    std::cerr << "imr submit: " << foreign << "\n";
    return imr::kExitCantCreate;
  }
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
      "run (1..63; 63 means 63 or more); 64 not a batch folder or bad usage; 73 RUN_DIR holds a\n"
      "summary.json or summary.md that imr did not write (it is left alone; so is a foreign\n"
      "index.html or assets/: the page is then not written); 75 an imr run (or a shard of one)\n"
      "is using the batch folder: nothing is written, run it again when that run has ended.";
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
  // A running `imr run` (or shard) holds the folder: its sequences are not ended, and the
  // summary would call them killed.
  std::shared_ptr<imr::batch::BatchLock> lock;
  try {
    lock = imr::batch::HoldBatchFolderForReport(dir);
  } catch (const imr::batch::BatchFolderBusy& e) {
    std::cerr << "imr report: " << e.what() << "\n";
    return imr::kExitTempFail;
  }
  if (const std::string foreign = io::ForeignBatchFiles(dir, false); !foreign.empty()) {
    std::cerr << "imr report: " << foreign << "\n";
    return imr::kExitCantCreate;
  }
  nlohmann::json summary;
  try {
    summary = imr::batch::WriteSummary(dir, "imr report");
  } catch (const std::exception& e) {
    std::cerr << "imr report: " << e.what() << "\n";
    return kExitUsage;
  }
  // The page is a view of the summary: if it cannot be written, the summary still stands.
  std::string foreign_page;
  for (const char* entry : {"index.html", "assets"})
    if (foreign_page.empty()) foreign_page = io::ForeignBatchEntry(dir, entry);
  if (!foreign_page.empty()) {
    imr::LogWarning("viewer page not written: " + foreign_page +
                    ": imr does not overwrite a file it did not write");
  } else {
    try {
      const auto page = imr::report::WriteBatchPage(dir, summary);
      for (const std::string& note : page.notes) imr::LogWarning("viewer page: " + note);
      for (const std::string& line : page.info) imr::LogInfo("viewer page: " + line);
      std::printf("viewer page: %s (%d mesh%s in 3D%s)\n", page.page.string().c_str(),
                  page.meshes_viewable, page.meshes_viewable == 1 ? "" : "es",
                  page.tilesets_viewable == 0   ? ""
                  : page.tilesets_viewable == 1 ? ", 1 run's tiles"
                                                : (", " + std::to_string(page.tilesets_viewable) +
                                                   " runs' tiles").c_str());
    } catch (const std::exception& e) {
      imr::LogWarning(std::string("viewer page not written: ") + e.what());
    }
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

// The hidden per-sequence command of `imr run`'s child processes. Every value is parsed strictly:
// a garbled one is an error naming the flag (exit 64), never a silent 0.
int CmdRunSequence(const std::vector<std::string>& args) {
  batch::ChildArguments a;
  auto fail = [](const std::string& what) {
    std::cerr << "imr " << batch::kChildCommand << ": " << what
              << " (an internal command of imr run)\n";
    return kExitUsage;
  };
  for (std::size_t i = 0; i < args.size(); ++i) {
    const std::string& k = args[i];
    if (k == "-v") {
      a.verbose = true;
      continue;
    }
    const batch::RunFlag* flag = k.rfind("--", 0) == 0 ? batch::FindRunFlag(k.substr(2)) : nullptr;
    const bool takes_value = flag == nullptr || !flag->value_name.empty();
    if (takes_value && i + 1 >= args.size()) return fail(k + ": expected a value");
    const std::string value = takes_value ? args[++i] : "";
    if (flag != nullptr) {
      if (const std::string e = flag->parse(value, &a.run_options); !e.empty())
        return fail(k + ": " + e);
    } else if (k == "--job") {
      a.job = value;
    } else if (k == "--sequence") {
      a.sequence = value;
    } else if (k == "--set") {
      a.overrides.push_back(value);
    } else if (k == "--parent-pid") {
      if (!ParseWholeInteger(value, &a.parent_pid) || a.parent_pid < 1)
        return fail("--parent-pid: expected a process id, got '" + value + "'");
    } else {
      return fail("unexpected argument '" + k + "'");
    }
  }
  if (a.job.empty() || a.sequence.empty()) return fail("needs --job and --sequence");
  HandleStopSignals();
  return batch::RunSequenceChild(a);
}

}  // namespace

std::vector<Command> BatchCommands() {
  return {
      {"run", "run JOB.json",
       "run a job: every sequence (each in its own process), written to the\n"
       "job's output folders, with a batch summary; finished sequences are\n"
       "skipped on a re-run (--set KEY=VALUE, --shard I/N, --jobs J, --force,\n"
       "--max-rss SIZE, --export-stream FILE, --export-colmap DIR:\n"
       "see `imr run --help`)",
       &CmdRun},
      {"mesh", "mesh --input PATH",
       "one mesh from one sequence, no job file: --format F (a job's input\n"
       "format) --out MESH.ply|.obj|.gltf|.glb; runs as imr run does",
       &CmdMesh},
      {"submit", "submit JOB.json",
       "run a job on a Slurm cluster: an array of --tasks N tasks, then a job\n"
       "that writes the batch summary (see `imr submit --help`)",
       &CmdSubmit},
      {"report", "report RUN_DIR",
       "merge the sequences' reports of a batch folder into summary.json/.md\n"
       "and a viewer page (index.html: the table, plots, each mesh in 3D)",
       &CmdReport},
      {batch::kChildCommand, "", "", &CmdRunSequence, /*hidden=*/true},
  };
}

}  // namespace imr::cli
