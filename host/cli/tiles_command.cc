// imr tiles merge: a run's 3D Tiles (output.tiles; host/pipeline/tiles.h) as one mesh file,
// vertices merged by key, through the exporter plugin as `imr run` writes meshes.
#include "host/cli/command.h"
#include "host/io/schema.h"
#include "host/pipeline/mesh_export.h"
#include "host/pipeline/tiles.h"
#include "host/plugin/host_services.h"
#include "host/util/atomic_file.h"
#include "host/util/exit_status.h"
#include "host/util/write_rule.h"

#include <cstdio>
#include <iostream>

namespace imr::cli {
namespace {

namespace fs = std::filesystem;

const char* kMergeNotes =
    "Reads RUN_FOLDER/tileset.json (a sequence's output folder of a job with output.tiles) and\n"
    "every tile it lists, and tiles a stopped run wrote after its last tileset.json, and writes\n"
    "them as one mesh: vertices the tiles share along their seams (the same `_VERTEX_KEY`) become\n"
    "one, so the union is one surface, checked to be a 2-manifold with boundary. The format is\n"
    "the extension of --out (.ply, .obj, .gltf, .glb), written by org.imr.exporter.assimp (or\n"
    "--exporter ID) as `imr run` writes meshes, atomically. Positions are the tiles' (float32\n"
    "relative to each tile's origin: sub-millimetre). Of a run that did not finish (stopped or\n"
    "failed, as tileset.json says) the tiles written are merged, and said so; a vertex where they\n"
    "touch at a point only (the surface between them never written) is kept apart, one per fan.\n"
    "Exit status: 0 written; 1 the tiles cannot be read or merged, or the mesh written (the\n"
    "message names the file); 64 bad usage; 73 --out is a file imr may not write (inside the run\n"
    "folder, or a file imr did not write).\n";

int CmdTilesMerge(const std::vector<std::string>& args) {
  po::options_description opts("imr tiles merge options");
  opts.add_options()("run", po::value<std::string>()->required(), "the run's output folder")(
      "out,o", po::value<std::string>()->required()->value_name("MESH"),
      "the mesh to write (.ply, .obj, .gltf, .glb)")(
      "exporter", po::value<std::string>()->default_value("org.imr.exporter.assimp")->value_name("ID"),
      "the exporter plugin that writes it")(
      "plugin-path,p", po::value<std::vector<std::string>>(), "extra folder or .so to search first (repeatable)");
  po::positional_options_description pos;
  pos.add("run", 1);
  po::variables_map vm;
  int status = kExitOk;
  const std::string synopsis = std::string("imr tiles merge RUN_FOLDER --out MESH.ply [-p PATH]...\n\n") + kMergeNotes;
  if (!ParseCommand("tiles merge", synopsis, opts, pos, args, &vm, &status,
                    {{"run", "needs a run's output folder: imr tiles merge RUN_FOLDER --out MESH.ply"},
                     {"out", "needs --out MESH.ply (or .obj, .gltf, .glb)"}}))
    return status;
  const fs::path run = vm["run"].as<std::string>();
  const fs::path out = fs::absolute(vm["out"].as<std::string>()).lexically_normal();
  std::string format = out.extension().string();
  for (char& c : format) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (format != ".ply" && format != ".obj" && format != ".gltf" && format != ".glb") {
    std::cerr << "imr tiles merge: --out: expected a file ending in .ply, .obj, .gltf or .glb, got '"
              << out.filename().string() << "' (imr tiles merge --help)\n";
    return kExitUsage;
  }
  format = format.substr(1);
  const bool quiet = vm.count("quiet") > 0;
  NoteInput(run, "the run folder being merged");  // nothing is written into what is read
  // The mesh goes into a folder the user has: none is created for it.
  std::error_code ec;
  if (!fs::is_directory(out.parent_path(), ec)) {
    std::cerr << "imr tiles merge: --out: " << out.parent_path().string()
              << (fs::exists(out.parent_path(), ec) ? ": not a folder" : ": no such folder")
              << " (imr tiles merge writes into an existing folder)\n";
    return kExitFailed;
  }
  try {
    CheckWriteTarget(out);
    const pipeline::MergedTiles merged = pipeline::MergeTiles(run);
    const engine::ManifoldCheckResult check = engine::CheckMesh(merged.mesh, /*closed=*/false);
    if (!quiet) {
      for (const std::string& note : merged.notes) std::fprintf(stderr, "note: %s\n", note.c_str());
      std::printf("merged %d tiles: %zu vertices (%lld shared by tiles along their seams, each "
                  "once), %zu triangles\n",
                  merged.tiles, merged.mesh.vertices.size() / 3,
                  static_cast<long long>(merged.seam_vertices), merged.mesh.faces.size() / 3);
    }
    if (!check.ok) {
      std::cerr << "imr tiles merge: " << run.string() << ": the merged tiles are not a 2-manifold "
                << "with boundary (" << check.message << "): not written\n";
      return kExitFailed;
    }
    plugin::PluginRegistry registry;
    std::vector<fs::path> paths;
    if (vm.count("plugin-path"))
      for (const auto& p : vm["plugin-path"].as<std::vector<std::string>>()) paths.emplace_back(p);
    for (const auto& p : plugin::PluginRegistry::DefaultSearchPaths()) paths.push_back(p);
    registry.Scan(paths);
    const std::string id = vm["exporter"].as<std::string>();
    const plugin::PluginInfo* info = registry.Find(id);
    if (info == nullptr || info->kind() != "exporter") {
      std::cerr << "imr tiles merge: --exporter " << id << ": no such exporter plugin (imr plugins "
                << "lists them)\n";
      return kExitUsage;
    }
    io::StageSpec stage;
    stage.kind = "exporter";
    stage.plugin = id;
    stage.json_path = "--exporter";
    pipeline::Exporters exporters;
    exporters.emplace_back(&stage, plugin::CreateInstance(*info, io::WithDefaults(info->params_schema, nlohmann::json::object())));
    pipeline::StageWatch watch;
    StagingDirectory staging(out.parent_path());
    pipeline::ExportMesh(merged.mesh, pipeline::ExportContext{}, {format}, exporters, staging.path(),
                         out.stem().string(), watch, 0.0);
    if (!fs::exists(staging.path() / out.filename()))
      throw std::runtime_error(id + " does not write " + format);
    const std::vector<fs::path> written = staging.Commit(out.filename().string());
    if (!quiet)
      std::printf("a 2-manifold with boundary%s; written: %s\n",
                  merged.complete ? "" : " (of a run that did not finish)", out.string().c_str());
  } catch (const WriteRefused& e) {
    std::cerr << "imr tiles merge: " << e.what() << "\n";
    return kExitCantCreate;
  } catch (const std::exception& e) {
    std::cerr << "imr tiles merge: " << e.what() << "\n";
    return kExitFailed;
  }
  return kExitOk;
}

int CmdTiles(const std::vector<std::string>& args) {
  const std::string usage =
      "Usage: imr tiles merge RUN_FOLDER --out MESH.ply   (imr tiles merge --help)\n";
  if (args.empty() || args[0] == "--help" || args[0] == "-h") {
    (args.empty() ? std::cerr : std::cout) << usage;
    return args.empty() ? kExitUsage : kExitOk;
  }
  if (args[0] != "merge") {
    std::cerr << "imr tiles: unknown subcommand '" << args[0] << "'\n" << usage;
    return kExitUsage;
  }
  return CmdTilesMerge(std::vector<std::string>(args.begin() + 1, args.end()));
}

}  // namespace

std::vector<Command> TilesCommands() {
  return {{"tiles", "tiles merge RUN",
           "one mesh (--out MESH.ply|.obj|.gltf|.glb) from a run's 3D Tiles\n"
           "(output.tiles), finished or stopped: seam vertices merged",
           &CmdTiles}};
}

}  // namespace imr::cli
