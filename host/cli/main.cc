// imr: the command-line host. Subcommands: run, validate, plugins; --version, --help.
// Exit status: 0 success; 1 a sequence failed (the others still ran); 2 bad usage or invalid job.
#include "host/pipeline/job_validation.h"
#include "host/pipeline/run.h"
#include "host/plugin/host_services.h"
#include "host/plugin/registry.h"
#include "host/util/log.h"

#include <boost/program_options.hpp>

#include <csignal>
#include <cstdio>
#include <iostream>
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
    "\n"
    "Options:\n"
    "  --version          print the version and the plugin ABI\n"
    "  -h, --help         this help; `imr <command> --help` for a command's options\n"
    "\n"
    "Plugins are searched in a job's plugin_paths, then IMR_PLUGIN_PATH (':'-separated),\n"
    "then the installed folder next to the executable (../lib/imr/plugins).\n"
    "Exit status: 0 success, 1 a sequence failed (the others still ran), 2 bad usage or job.\n";

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
  } catch (const std::exception& e) {
    std::cerr << "imr " << cmd << ": " << e.what() << "\n";
    return kExitFailed;
  }
  std::cerr << "imr: unknown command '" << cmd << "'\n\n" << kUsage;
  return kExitUsage;
}
