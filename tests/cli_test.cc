// The imr executable end to end: plugins, validate, run, and what each does with bad input.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include "test_util.h"

namespace imr::testing {
namespace {
namespace fs = std::filesystem;
using nlohmann::json;

const std::string kImr = IMR_EXE;

// A small engine-only job on the synthetic street: fast enough for the suite.
json SmallJob() {
  return json::parse(R"({
    "description": "test job",
    "sequences": ["street"],
    "input": {"format": "synthetic", "options": {"frames": 40, "seed": 3}},
    "pipeline": [
      {"kind": "weight_policy", "plugin": "org.imr.policy.nearest"},
      {"kind": "exporter", "plugin": "org.imr.exporter.assimp"}
    ],
    "output": {"directory": "runs/{sequence}", "formats": ["obj", "ply", "gltf", "glb"]}
  })");
}

class Cli : public ::testing::Test {
 protected:
  Cli() : dir_("cli") {}
  fs::path WriteJob(const json& j, const std::string& name = "job.json") {
    const fs::path p = dir_ / name;
    WriteText(p, j.dump(2));
    return p;
  }
  CommandResult Imr(const std::string& args) { return RunShell(kImr + " " + args); }
  // Every file under `root` (recursively), names relative to it.
  static std::vector<std::string> Files(const fs::path& root) {
    std::vector<std::string> out;
    if (!fs::exists(root)) return out;
    for (const auto& e : fs::recursive_directory_iterator(root))
      out.push_back(fs::relative(e.path(), root).string());
    std::sort(out.begin(), out.end());
    return out;
  }
  ScratchDir dir_;
};

TEST_F(Cli, VersionAndHelp) {
  auto r = Imr("--version");
  EXPECT_EQ(r.status, 0);
  EXPECT_NE(r.out.find("imr "), std::string::npos);
  EXPECT_NE(r.out.find("plugin ABI 1."), std::string::npos) << r.out;
  for (const char* cmd : {"run --help", "validate --help", "plugins --help", "report --help",
                          "evaluate --help", "render --help", "submit --help", "mesh --help",
                          "options --help", "--help"}) {
    auto h = Imr(cmd);
    EXPECT_EQ(h.status, 0) << cmd;
    EXPECT_NE(h.out.find("Usage"), std::string::npos) << cmd << ": " << h.out;
  }
  auto bad = Imr("frobnicate");
  EXPECT_EQ(bad.status, 64);
  EXPECT_NE(bad.err.find("unknown command 'frobnicate'"), std::string::npos);
  auto noarg = Imr("run");
  EXPECT_EQ(noarg.status, 64);
  EXPECT_NE(noarg.err.find("imr run: needs a job file: imr run JOB.json"), std::string::npos)
      << noarg.err;
  EXPECT_EQ(noarg.err.find("the option '--job' is required"), std::string::npos) << noarg.err;
}

// imr under jemalloc gives freed pages back within about a second (host/cli/main.cc): its
// options are the ones jemalloc reads from the executable.
TEST_F(Cli, JemallocGivesFreedPagesBack) {
#ifndef IMR_TEST_JEMALLOC_CONF
  GTEST_SKIP() << "imr is built without jemalloc";
#else
  const auto r = RunShell("MALLOC_CONF=confirm_conf:true " + kImr + " --version");
  EXPECT_EQ(r.status, 0);
  EXPECT_NE(r.err.find("global variable malloc_conf): \"background_thread:true,dirty_decay_ms:1000\""),
            std::string::npos) << r.err;
  EXPECT_NE(r.err.find("Set conf value: dirty_decay_ms:1000"), std::string::npos) << r.err;
#endif
}

// The children's flags are read strictly: a garbled value names its flag, nothing becomes 0.
TEST_F(Cli, TheChildCommandRefusesGarbledValues) {
  for (const auto& [flag, value] : {std::pair{"--stage-timeout", "abc"},
                                    {"--check-invariants-every", "2x"},
                                    {"--check-invariants-every", "0"},
                                    {"--parent-pid", "12a"}}) {
    auto r = Imr(std::string("__run-sequence --job j.json --sequence s ") + flag + " " + value);
    EXPECT_EQ(r.status, 64) << flag << " " << value;
    EXPECT_NE(r.err.find(std::string(flag) + ": expected"), std::string::npos) << r.err;
    EXPECT_NE(r.err.find(std::string("'") + value + "'"), std::string::npos) << r.err;
  }
}

TEST_F(Cli, OptionsListsEngineInputEvaluationAndPluginOptions) {
  auto r = Imr("options");
  ASSERT_EQ(r.status, 0) << r.err;
  for (const char* text :
       {"steiner_spacing  number >= 1e-09, default 5.0, unit: m", "check_invariants  boolean",
        "input format colmap", "views_per_keyframe", "input format kitti_odometry", "evaluation",
        "plugin org.imr.policy.nearest (weight_policy)", "plugin org.imr.exporter.assimp"})
    EXPECT_NE(r.out.find(text), std::string::npos) << text << " missing from\n" << r.out;
  auto engine = Imr("options --only engine");
  ASSERT_EQ(engine.status, 0);
  EXPECT_EQ(engine.out.find("input format"), std::string::npos);
  EXPECT_NE(engine.out.find("window  integer >= 1, default 15, unit: cameras"), std::string::npos);
  EXPECT_EQ(Imr("options --only nothing").status, 64);
}

TEST_F(Cli, PluginsVerboseListsEachPluginsParams) {
  auto r = Imr("plugins -v -p " + Quote(IMR_EXAMPLE_PLUGIN_DIR));
  ASSERT_EQ(r.status, 0) << r.err;
  const auto at = r.out.find("org.imr.example.policy.max");
  ASSERT_NE(at, std::string::npos) << r.out;
  EXPECT_NE(r.out.find("radius  number >= 0.0, default 1.0", at), std::string::npos) << r.out;
  EXPECT_EQ(Imr("plugins").out.find("radius  number"), std::string::npos);
}

TEST_F(Cli, PluginsListsTheBuiltInPlugins) {
  auto r = Imr("plugins");
  ASSERT_EQ(r.status, 0) << r.err;
  for (const char* id : {"org.imr.policy.mean", "org.imr.policy.weighted_mean",
                         "org.imr.policy.nearest", "org.imr.exporter.assimp"})
    EXPECT_NE(r.out.find(id), std::string::npos) << id << " missing from\n" << r.out;
  EXPECT_NE(r.out.find("weight_policy"), std::string::npos);
  EXPECT_NE(r.out.find("exporter"), std::string::npos);
  EXPECT_EQ(r.out.find("Refused"), std::string::npos) << r.out;
}

TEST_F(Cli, PluginsRefusesBadLibrariesByName) {
  auto r = Imr("plugins -p " + Quote(IMR_TEST_PLUGIN_DIR));
  ASSERT_EQ(r.status, 0) << r.err;
  // Another ABI major: the file and both versions are named.
  EXPECT_NE(r.out.find("test_bad_abi_plugin.so"), std::string::npos) << r.out;
  // The host's own minor: imr --version says it (cli_test does not include the SDK).
  const CommandResult version = Imr("--version");
  const std::size_t abi = version.out.find("ABI 1.");
  ASSERT_NE(abi, std::string::npos) << version.out;
  const std::string host_abi = version.out.substr(abi, version.out.find_first_not_of("0123456789.", abi + 4) - abi);
  EXPECT_NE(r.out.find("built for plugin ABI 2.3, this host speaks " + host_abi), std::string::npos)
      << r.out;
  // No entry symbol.
  EXPECT_NE(r.out.find("test_no_entry_plugin.so: not an imr plugin: no entry symbol "
                       "'imr_plugin_entry'"),
            std::string::npos)
      << r.out;
  // The good one in the same folder is still listed.
  EXPECT_NE(r.out.find("org.imr.test.policy.failing"), std::string::npos);
}

TEST_F(Cli, ALibraryThatCannotBeLoadedIsNamedWithTheLoadersReason) {
  WriteText(dir_ / "plugins" / "corrupt.so", "this is not an ELF file");
  auto r = Imr("plugins -p " + Quote((dir_ / "plugins").string()));
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.out.find((dir_ / "plugins" / "corrupt.so").string() + ": cannot load: "),
            std::string::npos)
      << r.out;
  // A job that points at the folder is still usable (it does not use the broken file), and the
  // refusal is reported as a warning.
  json j = SmallJob();
  j["plugin_paths"] = {(dir_ / "plugins").string()};
  auto v = Imr("validate " + Quote(WriteJob(j).string()));
  EXPECT_EQ(v.status, 0) << v.err;
  EXPECT_NE(v.err.find("warning: plugin refused: " + (dir_ / "plugins" / "corrupt.so").string()),
            std::string::npos)
      << v.err;
}

TEST_F(Cli, ImrPluginPathIsSearched) {
  auto r = RunShell("IMR_PLUGIN_PATH=" + Quote(IMR_EXAMPLE_PLUGIN_DIR) + " " + kImr + " plugins");
  ASSERT_EQ(r.status, 0);
  EXPECT_NE(r.out.find("org.imr.example.policy.max"), std::string::npos) << r.out;
}

// --set: any job key, the value as JSON else a string; in report.json and in the resume hash.
TEST_F(Cli, SetOverridesTheJobAndAChangedSetRedoesTheSequence) {
  const std::string job = Quote(WriteJob(SmallJob()).string());
  auto r = Imr("run -q " + job + " --set engine.steiner_spacing=2 --set output.stem=m");
  ASSERT_EQ(r.status, 0) << r.err;
  const fs::path report = dir_ / "runs/street/report.json";
  json rep = json::parse(ReadText(report));
  EXPECT_EQ(rep["engine_options"]["steiner_spacing"], 2.0);
  EXPECT_EQ(rep["overrides"], json({"engine.steiner_spacing=2", "output.stem=m"}));
  EXPECT_TRUE(fs::exists(dir_ / "runs/street/m.ply"));
  // The same overrides: up to date. Another value: run again, and recorded.
  r = Imr("run " + job + " --set engine.steiner_spacing=2 --set output.stem=m");
  EXPECT_NE(r.out.find("skipped street"), std::string::npos) << r.out;
  r = Imr("run " + job + " --set engine.steiner_spacing=3 --set output.stem=m");
  EXPECT_NE(r.out.find("ok      street"), std::string::npos) << r.out;
  EXPECT_EQ(json::parse(ReadText(report))["engine_options"]["steiner_spacing"], 3.0);
  // Without --set the job's own values again, and no overrides in the report.
  r = Imr("run -q " + job);
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_FALSE(json::parse(ReadText(report)).contains("overrides"));
  // Into arrays, and a string where the value is not JSON.
  r = Imr("validate " + job + " --set pipeline[0].plugin=org.imr.policy.mean --set "
          "'output.formats=[\"ply\"]'");
  EXPECT_EQ(r.status, 0) << r.err;
  // Mistakes are named like the job's own.
  r = Imr("validate " + job + " --set engine.stiener_spacing=2 --set pipeline[7].params.x=1 "
          "--set novalue --set engine.window=zero");
  EXPECT_EQ(r.status, 64);
  for (const char* text : {"engine.stiener_spacing: unknown key",
                           "--set pipeline[7].params.x=1: pipeline has 2 entries, no [7]",
                           "--set novalue: expected KEY=VALUE",
                           "engine.window: expected integer >= 1, got \"zero\""})
    EXPECT_NE(r.err.find(text), std::string::npos) << text << " missing from\n" << r.err;
}

// imr mesh: the job built from the command line, run as imr run runs it.
TEST_F(Cli, MeshBuildsTheJobAndWritesTheMeshWhereAsked) {
  const fs::path out = dir_ / "out/street.ply";
  fs::create_directories(out.parent_path());
  auto r = Imr("mesh -q --input street --format synthetic --out " + Quote(out.string()) +
               " --set input.options.frames=40 --set input.options.seed=3");
  ASSERT_EQ(r.status, 0) << r.out << r.err;
  ASSERT_TRUE(fs::exists(out));
  EXPECT_EQ(ReadText(out).rfind("ply\n", 0), 0u);
  const fs::path work = dir_ / "out/street.imr";
  const json job = json::parse(ReadText(work / "job.json"));
  EXPECT_EQ(job["input"]["format"], "synthetic");
  EXPECT_EQ(job["output"]["formats"], json({"ply"}));
  const json report = json::parse(ReadText(work / "mesh/report.json"));
  EXPECT_EQ(report["input"]["options"]["frames"], 40);
  EXPECT_GT(report["mesh"]["faces"].get<int>(), 0);
  // The mesh is the run's, byte for byte.
  EXPECT_EQ(ReadText(out), ReadText(work / "mesh/street.ply"));
  // A finished run is not redone; options of imr run pass through (--force redoes it).
  const std::string again = "mesh --input street --format synthetic --out " + Quote(out.string()) +
                            " --set input.options.frames=40 --set input.options.seed=3";
  r = Imr(again);
  EXPECT_NE(r.out.find("skipped street"), std::string::npos) << r.out;
  r = Imr(again + " --force --check-invariants");
  EXPECT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.out.find("ok      street"), std::string::npos) << r.out;
  // Bad usage: what was expected.
  auto bad = Imr("mesh --input street --format synthetic --out m.stl");
  EXPECT_EQ(bad.status, 64);
  EXPECT_NE(bad.err.find("--out: expected a file ending in .ply, .obj, .gltf or .glb"), std::string::npos);
  bad = Imr("mesh --input sparse/0 --format colmop --out m.ply");
  EXPECT_EQ(bad.status, 64);
  EXPECT_NE(bad.err.find("--format: expected synthetic, openmvg, colmap"), std::string::npos) << bad.err;
  bad = Imr("mesh --format colmap --out m.ply");
  EXPECT_NE(bad.err.find("needs --input"), std::string::npos) << bad.err;
}

// Issue 47 items 3 and 5: imr mesh saves its --set overrides in WORK/job.json (running that job
// again gives the same mesh bytes; it used to leave them out), its last lines name every file
// the run wrote, and the scale decision is one line at the default verbosity (it was -v only).
TEST_F(Cli, MeshSavesItsOverridesNamesItsFilesAndSaysTheScale) {
  const fs::path out = dir_ / "saved/street.ply";
  fs::create_directories(out.parent_path());
  const CommandResult r =
      Imr("mesh --input street --format synthetic --out " + Quote(out.string()) +
          " --set input.options.frames=30 --set input.options.seed=5 --set engine.scale=auto");
  ASSERT_EQ(r.status, 0) << r.out << r.err;
  EXPECT_NE(r.err.find("[street] engine.scale auto: median ray"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("decided every length"), std::string::npos) << r.err;
  const fs::path work = dir_ / "saved/street.imr";
  EXPECT_NE(r.out.find("wrote: street.ply, report.json, manifest.json\n"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("summary: " + (work / "mesh/summary.md").string() + ", summary.json"),
            std::string::npos) << r.out;
  EXPECT_NE(r.out.find("mesh: " + out.string() + "\njob: " + (work / "job.json").string()),
            std::string::npos) << r.out;
  const json job = json::parse(ReadText(work / "job.json"));
  EXPECT_EQ(job["input"]["options"]["frames"], 30) << job.dump();
  EXPECT_EQ(job["input"]["options"]["seed"], 5) << job.dump();
  EXPECT_EQ(job["engine"]["scale"], "auto") << job.dump();
  // The saved job alone redoes the same mesh.
  const std::string mesh = ReadText(out);
  fs::remove(work / "mesh/street.ply");
  const CommandResult again = Imr("run -q --force " + Quote((work / "job.json").string()));
  ASSERT_EQ(again.status, 0) << again.out << again.err;
  EXPECT_EQ(ReadText(work / "mesh/street.ply"), mesh);
  EXPECT_EQ(json::parse(ReadText(work / "mesh/report.json"))["input"]["options"]["frames"], 30);
}

TEST_F(Cli, ValidateAcceptsAGoodJob) {
  auto r = Imr("validate " + Quote(WriteJob(SmallJob()).string()));
  EXPECT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.out.find("valid (1 sequence"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("runs/street"), std::string::npos) << r.out;
}

TEST_F(Cli, ValidateReportsMalformedJsonWithLineAndColumn) {
  const fs::path p = dir_ / "broken.json";
  WriteText(p, "{\n  \"sequences\": [\"street\"],\n  \"input\": {\"format\": }\n}\n");
  auto r = Imr("validate " + Quote(p.string()));
  EXPECT_EQ(r.status, 64);
  EXPECT_NE(r.err.find("broken.json: malformed JSON at line 3, column"), std::string::npos)
      << r.err;
}

TEST_F(Cli, ValidateReportsEveryProblemWithItsPath) {
  json j = SmallJob();
  j["pipeline"][0]["params"] = {{"radius", "1"}};  // wrong plugin below: nearest has no params
  j["pipeline"].push_back({{"kind", "weight_policy"}, {"plugin", "org.imr.policy.nearset"}});
  j["input"]["options"]["frames"] = "15";
  j["input"]["options"]["seeed"] = 2;
  j["outptu"] = {};
  j["engine"] = {{"window", 0}, {"visibility_mode", "magic"}};
  j["output"]["formats"] = {"obj", "stl"};
  auto r = Imr("validate " + Quote(WriteJob(j).string()));
  EXPECT_EQ(r.status, 64);
  const std::vector<std::string> expected = {
      "input.options.frames: expected integer in [1, 200000], got \"15\"",
      "input.options.seeed: unknown key",
      "outptu: unknown key",
      "engine.window: expected integer >= 1, got 0",
      "engine.visibility_mode: expected string (one of \"weights\", \"rays\" or \"exact\"), got "
      "\"magic\"",
      "pipeline[0].params.radius: unknown key (no parameters accepted)",
      "pipeline[2].plugin: unknown plugin id \"org.imr.policy.nearset\" (known weight_policy "
      "plugins: org.imr.policy.mean, org.imr.policy.nearest or org.imr.policy.weighted_mean",
      "output.formats[1]: \"stl\" is not written by any exporter stage"};
  for (const auto& e : expected) EXPECT_NE(r.err.find(e), std::string::npos) << e << "\nin\n" << r.err;
}

TEST_F(Cli, ValidateChecksParamsAgainstThePluginSchema) {
  json j = SmallJob();
  j["pipeline"][0] = {{"kind", "weight_policy"},
                      {"plugin", "org.imr.example.policy.max"},
                      {"params", {{"radius", "15"}}}};
  j["plugin_paths"] = {IMR_EXAMPLE_PLUGIN_DIR};
  auto r = Imr("validate " + Quote(WriteJob(j).string()));
  EXPECT_EQ(r.status, 64);
  EXPECT_NE(r.err.find("pipeline[0].params.radius: expected number >= 0.0, got \"15\""),
            std::string::npos)
      << r.err;
}

TEST_F(Cli, ValidateRefusesAPluginOfTheWrongKind) {
  json j = SmallJob();
  j["pipeline"][1]["plugin"] = "org.imr.policy.mean";  // a policy where an exporter belongs
  auto r = Imr("validate " + Quote(WriteJob(j).string()));
  EXPECT_EQ(r.status, 64);
  EXPECT_NE(r.err.find("pipeline[1].plugin: plugin org.imr.policy.mean ("), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("is a weight_policy plugin, the stage's kind is exporter"), std::string::npos)
      << r.err;
}

TEST_F(Cli, ValidateNamesMissingFilesAndFolders) {
  auto r = Imr("validate " + Quote((dir_ / "nope.json").string()));
  EXPECT_EQ(r.status, 64);
  EXPECT_NE(r.err.find("nope.json: no such file"), std::string::npos) << r.err;
  json j = SmallJob();
  j["plugin_paths"] = {"does/not/exist"};
  j["sequences"] = {"street", "moon"};
  auto r2 = Imr("validate " + Quote(WriteJob(j).string()));
  EXPECT_EQ(r2.status, 64);
  EXPECT_NE(r2.err.find("plugin_paths[0]: no such file or folder"), std::string::npos) << r2.err;
  EXPECT_NE(r2.err.find("sequences[1]: input format 'synthetic' takes the names"), std::string::npos)
      << r2.err;
}

TEST_F(Cli, RunWritesMeshesAndAReport) {
  auto r = Imr("run -q " + Quote(WriteJob(SmallJob()).string()));
  ASSERT_EQ(r.status, 0) << r.out << r.err;
  const fs::path out = dir_ / "runs" / "street";
  for (const char* f : {"mesh.obj", "mesh.ply", "mesh.gltf", "mesh.glb", "report.json"})
    EXPECT_TRUE(fs::is_regular_file(out / f)) << f;
  for (const auto& f : Files(out)) EXPECT_EQ(f.find(".imr-staging"), std::string::npos) << f;
  const json report = json::parse(ReadText(out / "report.json"));
  EXPECT_EQ(report["sequence"]["name"], "street");
  EXPECT_TRUE(report["mesh"]["manifold"].get<bool>());
  EXPECT_TRUE(report["mesh"]["boundary_closed_manifold"].get<bool>());
  EXPECT_GT(report["mesh"]["faces"].get<int>(), 100);
  EXPECT_GT(report["engine"]["points_moved"].get<int>(), 0);  // points do move
  EXPECT_EQ(report["plugins"][0]["id"], "org.imr.policy.nearest");
  // Truth -> mesh: the true surface points are covered (a failed carving leaves them far away).
  // Mesh -> scene is not bounded here: with the default Steiner rule it includes triangles that
  // touch Steiner points (engine tests bound the real-point surface).
  EXPECT_LT(report["accuracy"]["mean_truth_to_mesh"].get<double>(), 0.5);
  EXPECT_GT(report["accuracy"]["completeness"].get<double>(), 0.6);
  // -q: errors and warnings only (issue 37): no ok line, no summary lines on stdout.
  EXPECT_EQ(r.out, "");
  r = Imr("run --force " + Quote((dir_ / "job.json").string()));
  EXPECT_NE(r.out.find("1 sequence, 0 failed"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("ok      street"), std::string::npos) << r.out;
}

// Two processes (different memory layouts) write the same bytes: outputs are reproducible.
TEST_F(Cli, TwoRunsWriteIdenticalMeshes) {
  json j = SmallJob();
  j["output"]["formats"] = {"ply", "glb"};
  j["output"]["directory"] = "first/{sequence}";
  auto r1 = Imr("run -q " + Quote(WriteJob(j, "a.json").string()));
  j["output"]["directory"] = "second/{sequence}";
  auto r2 = Imr("run -q " + Quote(WriteJob(j, "b.json").string()));
  ASSERT_EQ(r1.status, 0) << r1.out << r1.err;
  ASSERT_EQ(r2.status, 0) << r2.out << r2.err;
  for (const char* f : {"mesh.ply", "mesh.glb"}) {
    const std::string a = ReadText(dir_ / "first" / "street" / f);
    EXPECT_FALSE(a.empty()) << f;
    EXPECT_TRUE(a == ReadText(dir_ / "second" / "street" / f)) << f << " differs between runs";
  }
}

TEST_F(Cli, OneFailingSequenceDoesNotStopTheOthers) {
  json j = SmallJob();
  j["sequences"] = {"room", "street"};
  j["input"]["options"]["frames"] = 20;
  // Make room's output folder impossible (root ignores permissions): a file in its way.
  WriteText(dir_ / "runs" / "room", "not a folder");
  auto r = Imr("run " + Quote(WriteJob(j).string()));
  EXPECT_EQ(r.status, 1) << r.out << r.err;
  EXPECT_NE(r.out.find("FAILED  room"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("runs/room"), std::string::npos) << r.out;  // the path is named
  EXPECT_NE(r.out.find("ok      street"), std::string::npos) << r.out;
  EXPECT_TRUE(fs::is_regular_file(dir_ / "runs" / "street" / "report.json"));
  EXPECT_NE(r.out.find("2 sequences, 1 failed"), std::string::npos);
}

TEST_F(Cli, APolicyThatFailsLeavesNoPartialOutput) {
  for (const std::string params : {R"({"fail_after": 3})", R"({"nan": true})"}) {
    json j = SmallJob();
    j["pipeline"][0] = {{"kind", "weight_policy"},
                        {"plugin", "org.imr.test.policy.failing"},
                        {"params", json::parse(params)}};
    j["engine"]["visibility_mode"] = "weights";  // the mode that calls a policy
    j["plugin_paths"] = {IMR_TEST_PLUGIN_DIR};
    auto r = Imr("run -q " + Quote(WriteJob(j).string()));
    EXPECT_EQ(r.status, 1) << params << r.out << r.err;
    EXPECT_NE(r.out.find("org.imr.test.policy.failing"), std::string::npos) << r.out;
    EXPECT_TRUE(Files(dir_ / "runs" / "street").empty()) << params;
  }
}

// --check-invariants: a policy returning negative weights (finite, so nothing else objects)
// breaks the engine's weight invariant; the run stops there, naming the keyframe and the cell.
TEST_F(Cli, CheckInvariantsStopsAtTheKeyframeAndCell) {
  json j = SmallJob();
  j["pipeline"][0] = {{"kind", "weight_policy"},
                      {"plugin", "org.imr.test.policy.failing"},
                      {"params", {{"negative", true}}}};
  j["engine"]["visibility_mode"] = "weights";  // the mode that calls a policy
  j["plugin_paths"] = {IMR_TEST_PLUGIN_DIR};
  const std::string job = Quote(WriteJob(j).string());
  auto r = Imr("run -q --check-invariants " + job);
  EXPECT_EQ(r.status, 1) << r.out << r.err;
  EXPECT_NE(r.out.find("invariant check failed"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("keyframe "), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("cell {"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("< 0 although nonnegative_weights is on"), std::string::npos) << r.out;
  EXPECT_TRUE(Files(dir_ / "runs" / "street").empty());
  // Without the flag only the final check runs (it looks at the weights too): the same job
  // fails after its last keyframe instead of at the first bad one.
  r = Imr("run -q " + job);
  EXPECT_EQ(r.status, 1) << r.out << r.err;
  EXPECT_NE(r.out.find("invariant check failed after the last keyframe"), std::string::npos)
      << r.out;
  EXPECT_TRUE(Files(dir_ / "runs" / "street").empty());
  // With a sound policy the checks pass and the report counts them; --trace writes one line
  // per keyframe.
  j["pipeline"][0] = {{"kind", "weight_policy"}, {"plugin", "org.imr.policy.nearest"}};
  r = Imr("run -q --check-invariants-every 2 --trace '{output}/trace.jsonl' " +
          Quote(WriteJob(j, "good.json").string()));
  ASSERT_EQ(r.status, 0) << r.out << r.err;
  const json report = json::parse(ReadText(dir_ / "runs" / "street" / "report.json"));
  const int keyframes = report["engine"]["keyframes"].get<int>();
  EXPECT_EQ(report["invariant_checks"]["count"].get<int>(), keyframes / 2);
  std::istringstream trace(ReadText(dir_ / "runs" / "street" / "trace.jsonl"));
  int lines = 0, checked = 0;
  for (std::string line; std::getline(trace, line); ++lines) {
    const json t = json::parse(line);
    EXPECT_EQ(t["keyframe"].get<int>(), lines + 1);
    EXPECT_GT(t["rss_bytes"].get<double>(), 1e6);
    checked += t.contains("check_seconds") ? 1 : 0;
  }
  EXPECT_EQ(lines, keyframes);
  EXPECT_EQ(checked, keyframes / 2);
  EXPECT_FALSE(fs::exists(dir_ / "runs" / "street" / "trace.jsonl.partial"));
}

TEST_F(Cli, APluginThatFailsToCreateIsNamed) {
  json j = SmallJob();
  j["pipeline"][0] = {{"kind", "weight_policy"},
                      {"plugin", "org.imr.test.policy.failing"},
                      {"params", {{"fail_create", true}}}};
  j["plugin_paths"] = {IMR_TEST_PLUGIN_DIR};
  auto r = Imr("run -q " + Quote(WriteJob(j).string()));
  EXPECT_EQ(r.status, 1);
  EXPECT_NE(r.out.find("org.imr.test.policy.failing: create failed: params.fail_create: asked to fail"),
            std::string::npos)
      << r.out;
}

TEST_F(Cli, AnInvalidJobRunsNothing) {
  json j = SmallJob();
  j["pipeline"][0]["plugin"] = "org.imr.policy.none";
  auto r = Imr("run " + Quote(WriteJob(j).string()));
  EXPECT_EQ(r.status, 64);
  EXPECT_FALSE(fs::exists(dir_ / "runs"));
}

}  // namespace
}  // namespace imr::testing
