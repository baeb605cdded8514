// imr: the command-line host. Subcommands: run, validate, plugins, evaluate; --version, --help.
// Exit status: 0 success; 1 a sequence failed (the others still ran) or an evaluation failed;
// 2 bad usage or invalid job.
#include "host/eval/evaluate.h"
#include "host/pipeline/job_validation.h"
#include "host/pipeline/run.h"
#include "host/plugin/host_services.h"
#include "host/plugin/registry.h"
#include "host/util/atomic_file.h"
#include "host/util/log.h"

#include <boost/program_options.hpp>

#include <charconv>
#include <csignal>
#include <cstdio>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

namespace po = boost::program_options;
namespace fs = std::filesystem;

namespace {

constexpr int kExitOk = 0;
constexpr int kExitFailed = 1;
constexpr int kExitUsage = 2;

const char* kUsage =
    "imr — incremental manifold reconstruction with moving points\n"
    "\n"
    "Usage: imr <command> [options]\n"
    "\n"
    "Commands:\n"
    "  run JOB.json       run a job: every sequence, written to the job's output folders\n"
    "                     (--export-stream FILE, --export-colmap DIR: see `imr run --help`)\n"
    "  validate JOB.json  check a job and report every problem, without running it\n"
    "  plugins            list the plugins found (kind, id, version, ABI, file) and refusals\n"
    "  evaluate MESH      accuracy of a mesh against ground truth (points, a reference mesh or\n"
    "                     KITTI Velodyne scans): distances, completeness, precision, as JSON\n"
    "\n"
    "Options:\n"
    "  --version          print the version and the plugin ABI\n"
    "  -h, --help         this help; `imr <command> --help` for a command's options\n"
    "\n"
    "Plugins are searched in a job's plugin_paths, then IMR_PLUGIN_PATH (':'-separated),\n"
    "then the installed folder next to the executable (../lib/imr/plugins).\n"
    "Exit status: 0 success, 1 a sequence failed (the others still ran) or an evaluation failed,\n"
    "2 bad usage or job.\n";

void OnSignal(int) { imr::plugin::RequestCancel(); }

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
    "report.json; the report lists them under \"exports\".\n";

int CmdRun(const std::vector<std::string>& args) {
  po::options_description opts("imr run options");
  opts.add_options()("job", po::value<std::string>()->required(), "job file (JSON)")(
      "export-stream", po::value<std::string>()->value_name("FILE"),
      "also write the engine's input stream as SLAM JSON 0.3 (replayable)")(
      "export-colmap", po::value<std::string>()->value_name("DIR"),
      "also write the final points and their cameras as a COLMAP text model");
  po::positional_options_description pos;
  pos.add("job", 1);
  po::variables_map vm;
  int status = kExitOk;
  const std::string synopsis =
      std::string("imr run JOB.json [--export-stream FILE] [--export-colmap DIR] [-q|-v]\n\n") +
      kRunNotes;
  if (!ParseCommand("run", synopsis, opts, pos, args, &vm, &status)) return status;
  const fs::path job = vm["job"].as<std::string>();
  imr::pipeline::RunOptions run_options;
  if (vm.count("export-stream")) run_options.export_stream = vm["export-stream"].as<std::string>();
  if (vm.count("export-colmap")) run_options.export_colmap = vm["export-colmap"].as<std::string>();
  if ((vm.count("export-stream") && run_options.export_stream.empty()) ||
      (vm.count("export-colmap") && run_options.export_colmap.empty())) {
    std::cerr << "imr run: an export path must not be empty\n";
    return kExitUsage;
  }
  imr::plugin::PluginRegistry registry;
  imr::pipeline::ValidatedJob v;
  if (!LoadJob(job, &registry, &v)) return kExitUsage;
  const auto option_problems = imr::pipeline::CheckRunOptions(run_options, v);
  if (!option_problems.empty()) {
    for (const auto& p : option_problems) std::cerr << "imr run: " << p << "\n";
    return kExitUsage;
  }
  std::signal(SIGINT, OnSignal);
  std::signal(SIGTERM, OnSignal);
  auto batch = imr::pipeline::RunJob(v, registry, run_options);
  // One line per sequence on stdout: where the results are, or why there are none.
  for (const auto& s : batch.sequences) {
    if (s.ok) {
      std::printf("ok      %-20s %7.2f s  %s\n", s.name.c_str(), s.seconds,
                  s.output_directory.string().c_str());
    } else {
      std::printf("FAILED  %-20s %7.2f s  %s\n", s.name.c_str(), s.seconds, s.error.c_str());
    }
  }
  std::printf("%zu sequence%s, %d failed\n", batch.sequences.size(),
              batch.sequences.size() == 1 ? "" : "s", batch.failed());
  return batch.failed() > 0 ? kExitFailed : kExitOk;
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
    "MESH: .obj, .ply, .gltf or .glb (what the exporter writes). Ground truth: --truth FILE, a\n"
    "point cloud (.ply without faces, .xyz/.txt/.asc: x y z per line, more columns ignored) or a\n"
    "reference mesh (sampled uniformly by area at --truth-density), or --velodyne-seq DIR alone:\n"
    "the Velodyne scans of a KITTI sequence (odometry: a folder with calib.txt; raw: a drive\n"
    "folder) placed in its world frame. With --velodyne-seq the ground truth (and the mesh\n"
    "samples of precision) are cropped to what the cameras saw: inside a camera's frustum and\n"
    "within --max-ray-length of its centre; without cameras nothing is cropped, and the report\n"
    "says so. Distances: ground truth -> nearest mesh triangle (the paper's mean; CloudCompare's\n"
    "cloud-to-mesh distance). Completeness(tau): share of ground-truth points within tau of the\n"
    "mesh; precision(tau): share of mesh area (--precision-samples samples) within tau of the\n"
    "ground truth. The JSON keys are documented in host/eval/README.md.\n"
    "Exit status: 0 evaluated; 1 a file is missing or bad, or nothing is left to evaluate;\n"
    "2 bad usage.\n";

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

// "FIRST[:COUNT[:STEP]]" -> the image sequence's frame selection; false when malformed.
bool ParseFrames(const std::string& s, imr::io::ImageSequenceOptions* o) {
  int v[3] = {0, -1, 1};
  std::stringstream ss(s);
  int n = 0;
  for (std::string item; std::getline(ss, item, ':'); ++n) {
    if (n == 3) return false;
    const auto r = std::from_chars(item.data(), item.data() + item.size(), v[n]);
    if (r.ec != std::errc() || r.ptr != item.data() + item.size()) return false;
  }
  if (n == 0) return false;
  o->first_frame = v[0];
  o->frame_count = v[1];
  o->frame_step = v[2];
  return true;
}

int CmdEvaluate(const std::vector<std::string>& args) {
  imr::eval::EvaluationOptions d;  // the defaults, for the help text
  po::options_description opts("imr evaluate options");
  opts.add_options()("mesh", po::value<std::string>()->required(), "mesh to evaluate")(
      "truth", po::value<std::string>()->value_name("FILE"),
      "ground truth: point cloud (.ply, .xyz) or reference mesh (.ply, .obj, .gltf, .glb)")(
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
  if (vm.count("frames") && !ParseFrames(vm["frames"].as<std::string>(), &in.sequence_options))
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
    if (cmd == "validate") return CmdValidate(args);
    if (cmd == "plugins") return CmdPlugins(args);
    if (cmd == "evaluate") return CmdEvaluate(args);
  } catch (const std::exception& e) {
    std::cerr << "imr " << cmd << ": " << e.what() << "\n";
    return kExitFailed;
  }
  std::cerr << "imr: unknown command '" << cmd << "'\n\n" << kUsage;
  return kExitUsage;
}
