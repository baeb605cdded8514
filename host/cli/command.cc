#include "host/cli/command.h"

#include "host/batch/run_flags.h"
#include "host/plugin/host_services.h"
#include "host/util/exit_status.h"
#include "host/util/log.h"

#include <csignal>
#include <iostream>

namespace imr::cli {
namespace fs = std::filesystem;

namespace {

std::string g_argv0;

void OnSignal(int signal) { plugin::RequestCancel(signal); }

}  // namespace

bool ParseCommand(const std::string& name, const std::string& synopsis,
                  po::options_description& opts, po::positional_options_description& pos,
                  const std::vector<std::string>& args, po::variables_map* vm, int* status,
                  const std::vector<std::pair<std::string, std::string>>& missing_hint) {
  opts.add_options()("help,h", "show this help")("quiet,q", "errors and warnings only")(
      "verbose,v", "debug output");
  try {
    po::store(po::command_line_parser(args).options(opts).positional(pos).run(), *vm);
    if (vm->count("help")) {  // before notify(): --help needs no required argument
      std::cout << "Usage: " << synopsis << "\n" << opts << "\n";
      *status = kExitOk;
      return false;
    }
    for (const auto& [option, hint] : missing_hint)
      if (!vm->count(option)) {
        std::cerr << "imr " << name << ": " << hint << " (imr " << name << " --help)\n";
        *status = kExitUsage;
        return false;
      }
    po::notify(*vm);
  } catch (const po::error& e) {
    std::cerr << "imr " << name << ": " << e.what() << "\n\nUsage: " << synopsis << "\n"
              << opts << "\n";
    *status = kExitUsage;
    return false;
  }
  if (vm->count("quiet")) SetLogLevel(LogLevel::kWarning);
  if (vm->count("verbose")) SetLogLevel(LogLevel::kDebug);
  return true;
}

void AddJobOverrideFlag(po::options_description& opts) {
  opts.add_options()("set", po::value<std::vector<std::string>>()->value_name("KEY=VALUE"),
                     "override a value of the job (repeatable): KEY a path into the job "
                     "(engine.steiner_spacing, pipeline[1].params.max_distance), VALUE JSON or "
                     "else a string");
}

std::vector<std::string> JobOverrides(const po::variables_map& vm) {
  return vm.count("set") ? vm["set"].as<std::vector<std::string>>() : std::vector<std::string>{};
}

void PrintProblems(const fs::path& job, const std::vector<io::Problem>& problems) {
  std::cerr << job.string() << ": " << problems.size() << " problem"
            << (problems.size() == 1 ? "" : "s") << ":\n";
  for (const auto& p : problems) std::cerr << "  " << p.ToString() << "\n";
}

bool LoadJob(const fs::path& job, const std::vector<std::string>& overrides,
             plugin::PluginRegistry* registry, pipeline::ValidatedJob* v) {
  *v = pipeline::LoadAndValidateJob(job, registry, overrides);
  if (v->ok()) return true;
  PrintProblems(job, v->problems);
  return false;
}

void AddRunOptionFlags(po::options_description& opts) {
  for (const batch::RunFlag& f : batch::RunFlags()) {
    if (f.value_name.empty())
      opts.add_options()(f.name.c_str(), f.help.c_str());
    else
      opts.add_options()(f.name.c_str(), po::value<std::string>()->value_name(f.value_name),
                         f.help.c_str());
  }
}

bool ReadRunOptions(const po::variables_map& vm, const char* cmd, pipeline::RunOptions* o) {
  for (const batch::RunFlag& f : batch::RunFlags()) {
    if (!vm.count(f.name)) continue;
    const std::string text = f.value_name.empty() ? "" : vm[f.name].as<std::string>();
    if (const std::string e = f.parse(text, o); !e.empty()) {
      std::cerr << "imr " << cmd << ": --" << f.name << ": " << e << "\n";
      return false;
    }
  }
  return true;
}

void SetArgv0(const char* argv0) { g_argv0 = argv0; }

std::string SelfPath() {
  std::error_code ec;
  const fs::path p = fs::read_symlink("/proc/self/exe", ec);
  return ec ? fs::absolute(g_argv0).string() : p.string();
}

void HandleStopSignals() {
  for (int signal : {SIGINT, SIGTERM, SIGHUP}) std::signal(signal, OnSignal);
}

}  // namespace imr::cli
