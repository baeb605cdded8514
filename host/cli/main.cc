// imr: the command-line host. A table of commands (COLMAP's exe/colmap.cc), one file per group:
// batch_commands.cc (run, submit, report), job_commands.cc (validate, plugins),
// evaluate_command.cc, render_command.cc. Exit status (host/util/exit_status.h): run and report:
// 0 every sequence fine, else how many failed (1..63, 63 = 63 or more); other commands: 0 or 1;
// 64 bad usage or invalid job; 73 the batch folder cannot be created; 75 another run holds the
// batch folder.
#include "host/cli/command.h"
#include "host/pipeline/run.h"
#include "host/util/exit_status.h"
#include "host/util/write_rule.h"

#include <imr/sdk/plugin.h>

#include <cstdio>
#include <iostream>
#include <string>
#include <vector>

#ifdef IMR_JEMALLOC_CONF
// jemalloc's options, read as it starts (the MALLOC_CONF environment variable is read after and
// wins): freed pages go back to the system after about a second, by a background thread, rather
// than after 10 s and only when the same arena allocates again. The end of a 1,000-frame image
// drive held 120 MB of freed pages (report.json memory.final_heap_bytes: 150 MB resident for 30 MB
// allocated; 49 MB with these) and peaked at 409 MB (382 MB); the engine's time on the street
// stream the same within noise (tools/bench/paired_speed.sh, B/A 1.017). Issue 46.
extern "C" {
__attribute__((visibility("default"))) const char* malloc_conf = "background_thread:true,dirty_decay_ms:1000";
}
#endif

namespace {

using imr::cli::Command;

const std::vector<Command>& Commands() {
  static const std::vector<Command> commands = [] {
    std::vector<Command> all;
    for (auto group : {&imr::cli::BatchCommands, &imr::cli::JobCommands,
                       &imr::cli::EvaluateCommands, &imr::cli::RenderCommands,
                       &imr::cli::TilesCommands})
      for (Command& c : group()) all.push_back(std::move(c));
    return all;
  }();
  return commands;
}

std::string Usage() {
  std::string s =
      "imr — incremental manifold reconstruction with moving points\n"
      "\n"
      "Usage: imr <command> [options]\n"
      "\n"
      "Commands:\n";
  for (const Command& c : Commands()) {
    if (c.hidden) continue;
    std::string line = "  " + c.usage;
    line.resize(std::max<std::size_t>(line.size() + 1, 21), ' ');
    for (std::size_t b = 0, e = 0; b <= c.summary.size(); b = e + 1) {
      e = c.summary.find('\n', b);
      if (e == std::string::npos) e = c.summary.size();
      s += (b == 0 ? line : std::string(21, ' ')) + c.summary.substr(b, e - b) + "\n";
    }
  }
  return s +
         "\n"
         "Options:\n"
         "  --version          print the version and the plugin ABI\n"
         "  -h, --help         this help; `imr <command> --help` for a command's options\n"
         "\n"
         "Plugins are searched in a job's plugin_paths, then IMR_PLUGIN_PATH (':'-separated),\n"
         "then the installed folder next to the executable (../lib/imr/plugins).\n"
         "Exit status: run, report: 0 every sequence ok, else the number that failed (1..63; 63 means\n"
         "63 or more; the others still ran); evaluate, render, submit, tiles: 1 failed; 64 bad usage or an\n"
         "invalid job (nothing ran); 73 the batch folder cannot be created (read-only, full);\n"
         "75 another imr run is using the batch folder (try again when it has ended).\n";
}

}  // namespace

int main(int argc, char** argv) {
  imr::cli::SetArgv0(argv[0]);
  std::vector<std::string> args(argv + 1, argv + argc);
  if (args.empty()) {
    std::cerr << Usage();
    return imr::kExitUsage;
  }
  const std::string cmd = args[0];
  args.erase(args.begin());
  if (cmd == "--help" || cmd == "-h" || cmd == "help") {
    std::cout << Usage();
    return imr::kExitOk;
  }
  if (cmd == "--version") {
    std::printf("imr %s (plugin ABI %d.%d)\n", imr::pipeline::Version(), IMR_ABI_MAJOR,
                IMR_ABI_MINOR);
    return imr::kExitOk;
  }
  for (const Command& c : Commands()) {
    if (c.name != cmd) continue;
    // What the command reads; every write asks the rule (host/util/write_rule.h).
    imr::InputScope inputs;
    try {
      return c.run(args);
    } catch (const imr::WriteRefused& e) {
      std::cerr << "imr " << cmd << ": " << e.what() << "\n";
      return imr::kExitCantCreate;
    } catch (const std::exception& e) {
      std::cerr << "imr " << cmd << ": " << e.what() << "\n";
      return imr::kExitFailed;
    }
  }
  std::cerr << "imr: unknown command '" << cmd << "'\n\n" << Usage();
  return imr::kExitUsage;
}
