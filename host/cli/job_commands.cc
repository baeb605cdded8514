// Commands about jobs and what they can name: validate, plugins.
#include "host/batch/summary.h"
#include "host/cli/command.h"
#include "host/util/exit_status.h"

#include <cstdio>
#include <iostream>

namespace imr::cli {
namespace {

namespace fs = std::filesystem;

int CmdValidate(const std::vector<std::string>& args) {
  po::options_description opts("imr validate options");
  opts.add_options()("job", po::value<std::string>()->required(), "job file (JSON)");
  AddJobOverrideFlag(opts);
  po::positional_options_description pos;
  pos.add("job", 1);
  po::variables_map vm;
  int status = kExitOk;
  if (!ParseCommand("validate", "imr validate JOB.json [--set KEY=VALUE]...", opts, pos, args, &vm, &status,
                    {{"job", "needs a job file: imr validate JOB.json"}}))
    return status;
  const fs::path job = vm["job"].as<std::string>();
  imr::plugin::PluginRegistry registry;
  imr::pipeline::ValidatedJob v;
  if (!LoadJob(job, JobOverrides(vm), &registry, &v)) return kExitUsage;
  std::cout << job.string() << ": valid (" << v.sequences.size() << " sequence"
            << (v.sequences.size() == 1 ? "" : "s") << ", " << v.job.pipeline.size()
            << " stages)\n";
  for (const auto& s : v.sequences)
    std::cout << "  " << s.name << " -> " << v.job.OutputDirectory(s.name).string() << "\n";
  std::cout << "batch folder (summary, imr report): "
            << imr::batch::BatchDirectory(v.job).string() << "\n";
  return kExitOk;
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

std::vector<Command> JobCommands() {
  return {
      {"validate", "validate JOB.json", "check a job and report every problem, without running it",
       &CmdValidate},
      {"plugins", "plugins", "list the plugins found (kind, id, version, ABI, file) and refusals",
       &CmdPlugins},
  };
}

}  // namespace imr::cli
