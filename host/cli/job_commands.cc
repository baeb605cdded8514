// Commands about jobs and what they can name: validate, plugins.
#include "host/batch/summary.h"
#include "host/cli/command.h"
#include "host/io/engine_options.h"
#include "host/io/input_formats.h"
#include "host/pipeline/tiles.h"
#include "host/util/exit_status.h"

#include <algorithm>
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

// -p PATH (repeatable): extra folders or .so files searched before the default ones.
void AddPluginPathFlag(po::options_description& opts) {
  opts.add_options()("plugin-path,p", po::value<std::vector<std::string>>(),
                     "extra folder or .so to search first (repeatable)");
}
void ScanPlugins(const po::variables_map& vm, plugin::PluginRegistry* registry) {
  std::vector<fs::path> paths;
  if (vm.count("plugin-path"))
    for (const auto& p : vm["plugin-path"].as<std::vector<std::string>>()) paths.emplace_back(p);
  for (const auto& p : plugin::PluginRegistry::DefaultSearchPaths()) paths.push_back(p);
  registry->Scan(paths);
}

int CmdPlugins(const std::vector<std::string>& args) {
  po::options_description opts("imr plugins options");
  AddPluginPathFlag(opts);
  po::positional_options_description pos;
  po::variables_map vm;
  int status = kExitOk;
  const char* synopsis =
      "imr plugins [-p PATH]... [-v]\n\n"
      "Lists the plugins found; -v also lists each plugin's params (type, bounds, default, unit,\n"
      "description) from its schema, as a job's pipeline[i].params takes them.";
  if (!ParseCommand("plugins", synopsis, opts, pos, args, &vm, &status)) return status;
  plugin::PluginRegistry registry;
  ScanPlugins(vm, &registry);
  std::printf("%-14s %-34s %-8s %-5s %s\n", "KIND", "ID", "VERSION", "ABI", "FILE");
  const bool params = vm.count("verbose") > 0;
  for (const auto& p : registry.plugins()) {
    std::printf("%-14s %-34s %-8s %-5s %s\n", p.kind().c_str(), p.id().c_str(),
                p.version().c_str(), p.abi().c_str(), p.file.string().c_str());
    if (!params) continue;
    if (p.descriptor->description != nullptr && *p.descriptor->description)
      std::printf("    %s\n", p.descriptor->description);
    std::printf("%s", p.params_schema.empty() ? "    (no params)\n"
                                              : io::SchemaText(p.params_schema, "    ").c_str());
  }
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


const char* kOptionsSections[] = {"engine", "input", "evaluation", "tiles", "plugins"};

int CmdOptions(const std::vector<std::string>& args) {
  po::options_description opts("imr options options");
  opts.add_options()("only", po::value<std::string>()->value_name("SECTION"),
                     "one section: engine, input, evaluation, tiles or plugins")(
      "markdown", "Markdown tables (docs/engine.md's engine table is `--only engine --markdown`)");
  AddPluginPathFlag(opts);
  po::positional_options_description pos;
  po::variables_map vm;
  int status = kExitOk;
  const char* synopsis =
      "imr options [--only engine|input|evaluation|tiles|plugins] [--markdown] [-p PATH]...\n\n"
      "Every option a job can set, from the schemas imr validates jobs with: the engine's (the\n"
      "job's \"engine\"), each input format's (\"input\": {\"format\", \"options\"}), the\n"
      "evaluation's (\"evaluation\"), the tiles' (\"output\": {\"tiles\"}) and each plugin's\n"
      "params (\"pipeline\"[i].params), each with what it accepts (type, bounds), its default,\n"
      "unit and description. Any of them can be overridden on the command line: imr run\n"
      "JOB.json --set engine.steiner_spacing=2.";
  if (!ParseCommand("options", synopsis, opts, pos, args, &vm, &status)) return status;
  const std::string only = vm.count("only") ? vm["only"].as<std::string>() : "";
  if (!only.empty() && std::find(std::begin(kOptionsSections), std::end(kOptionsSections), only) ==
                           std::end(kOptionsSections)) {
    std::cerr << "imr options: --only: expected engine, input, evaluation, tiles or plugins, got '" << only
              << "'\n";
    return kExitUsage;
  }
  const bool markdown = vm.count("markdown") > 0;
  // One section: a heading (unless it is the only one asked for) and the schema's listing.
  auto section = [&](const std::string& name, const std::string& heading, const std::string& note,
                     const nlohmann::json& schema) {
    const bool shown = only.empty() || only == name;
    if (!shown) return;
    if (only.empty() || heading != name)
      std::printf(markdown ? "\n### %s\n\n" : "\n%s\n", heading.c_str());
    if (!note.empty()) std::printf(markdown ? "%s\n\n" : "  %s\n", note.c_str());
    std::printf("%s", schema.empty() ? (markdown ? "(none)\n" : "  (none)\n")
                      : (markdown ? io::SchemaMarkdown(schema) : io::SchemaText(schema)).c_str());
  };
  section("engine", "engine", "", io::EngineOptionsSchema());
  for (const io::InputFormat& f : io::InputFormats())
    section("input", "input format " + f.name, f.description, f.options_schema);
  section("evaluation", "evaluation", "", pipeline::EvaluationSchema());
  section("tiles", "tiles", "output.tiles: the surface as OGC 3D Tiles (docs/tiles.md)", pipeline::TilesSchema());
  section("tiles", "tiles.origin", "output.tiles.origin: where the tiles stand on the Earth (docs/tiles.md, "
          "Geo-referenced tiles)", pipeline::TilesOriginSchema());
  if (only.empty() || only == "plugins") {
    plugin::PluginRegistry registry;
    ScanPlugins(vm, &registry);
    for (const auto& p : registry.plugins())
      section("plugins", "plugin " + p.id() + " (" + p.kind() + ")",
              p.descriptor->description != nullptr ? p.descriptor->description : "",
              p.params_schema);
  }
  return kExitOk;
}

}  // namespace

std::vector<Command> JobCommands() {
  return {
      {"validate", "validate JOB.json", "check a job and report every problem, without running it",
       &CmdValidate},
      {"options", "options",
       "every engine, input, evaluation, tiles and plugin option a job can set,\n"
       "with its default, bounds, unit and description",
       &CmdOptions},
      {"plugins", "plugins", "list the plugins found (kind, id, version, ABI, file) and refusals;\n"
       "-v: also each plugin's params", &CmdPlugins},
  };
}

}  // namespace imr::cli
