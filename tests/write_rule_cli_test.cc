// The write rule end to end (issue 44; host/util/write_rule.h): every command that writes is run
// against a folder of the user's own files and against the run's own inputs, and each such
// file's bytes must be unchanged after it, with a refusal that names it. One table: a row per
// command and target; the Python module's rows are in host/python/tests/test_write_rule.py.
#include "tests/test_util.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <functional>
#include <map>
#include <string>
#include <vector>

namespace imr::testing {
namespace {
namespace fs = std::filesystem;
using nlohmann::json;

const std::string kImr = IMR_EXE;

json SyntheticJob(const std::string& out_dir, int frames = 30) {
  return {{"sequences", {"street"}},
          {"input", {{"format", "synthetic"}, {"options", {{"frames", frames}, {"seed", 3}}}}},
          {"pipeline", {{{"kind", "exporter"}, {"plugin", "org.imr.exporter.assimp"}}}},
          {"output", {{"directory", out_dir}, {"formats", {"ply"}}}}};
}

// Prepared once for the whole table: a run with tiles (its folder is merged), a SLAM JSON stream
// and a COLMAP model exported by imr (inputs of later runs), a KITTI-layout sequence.
class WriteRuleCli : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new ScratchDir("write-rule");
    const fs::path d = dir_->path();
    json job = SyntheticJob("base/{sequence}", 40);
    job["output"]["tiles"] = {{"size", 20}};
    WriteText(d / "base.json", job.dump(2));
    const CommandResult r =
        RunShell(kImr + " run -q " + Quote((d / "base.json").string()) + " --export-stream " +
                 Quote((d / "stream.json").string()) + " --export-colmap " +
                 Quote((d / "model").string()));
    ASSERT_EQ(r.status, 0) << r.err;
#ifdef IMR_SYNTH_EXE
    const CommandResult g = RunShell(std::string(IMR_SYNTH_EXE) + " --out " +
                                     Quote((d / "seq").string()) +
                                     " --frames 6 --width 200 --height 60 --no-lidar --color -q");
    ASSERT_EQ(g.status, 0) << g.err;
#endif
  }
  static void TearDownTestSuite() {
    delete dir_;
    dir_ = nullptr;
  }
  static fs::path D() { return dir_->path(); }
  static ScratchDir* dir_;
};
ScratchDir* WriteRuleCli::dir_ = nullptr;

struct Row {
  std::string name;
  // Makes the row's own folder D/<name> with the user's files; returns the files that must keep
  // their bytes (absolute).
  std::function<std::vector<fs::path>(const fs::path& row)> setup;
  // The command after `imr `, in the row's folder.
  std::function<std::string(const fs::path& row)> command;
  int status;  // the exit status expected
};

std::string Q(const fs::path& p) { return Quote(p.string()); }

std::vector<Row> Rows(const fs::path& d) {
  auto user_file = [](const fs::path& p, const std::string& text = "the user's own bytes\n") {
    fs::create_directories(p.parent_path());
    WriteText(p, text);
    return p;
  };
  // A copy of the shared input, so a row that fails to refuse cannot spoil the next.
  auto copy = [](const fs::path& from, const fs::path& to) {
    fs::create_directories(to.parent_path());
    fs::copy(from, to, fs::copy_options::recursive);
    std::vector<fs::path> files;
    if (fs::is_directory(to)) {
      for (const auto& e : fs::recursive_directory_iterator(to))
        if (e.is_regular_file()) files.push_back(e.path());
    } else {
      files.push_back(to);
    }
    return files;
  };
  auto job = [](const fs::path& row, const json& j) {
    WriteText(row / "job.json", j.dump(2));
    return row / "job.json";
  };
  std::vector<Row> rows = {
      {"run_over_a_users_mesh",
       [=](const fs::path& row) {
         job(row, SyntheticJob("out/{sequence}"));
         return std::vector<fs::path>{user_file(row / "out" / "street" / "mesh.ply")};
       },
       [](const fs::path& row) { return "run -q " + Q(row / "job.json"); }, 1},
      {"run_over_a_users_report",
       [=](const fs::path& row) {
         job(row, SyntheticJob("out/{sequence}"));
         return std::vector<fs::path>{user_file(row / "out" / "street" / "report.json", "{}\n")};
       },
       [](const fs::path& row) { return "run -q " + Q(row / "job.json"); }, 1},
      {"run_export_stream_onto_its_input",
       [=](const fs::path& row) {
         auto files = copy(d / "stream.json", row / "in.json");
         json j = SyntheticJob("out/{sequence}");
         j["sequences"] = {(row / "in.json").string()};
         j["input"] = {{"format", "slam_json"}};
         job(row, j);
         return files;
       },
       [](const fs::path& row) {
         return "run -q " + Q(row / "job.json") + " --export-stream " + Q(row / "in.json");
       },
       1},
      {"run_export_stream_onto_its_job_file",
       [=](const fs::path& row) {
         return std::vector<fs::path>{job(row, SyntheticJob("out/{sequence}"))};
       },
       [](const fs::path& row) {
         return "run -q " + Q(row / "job.json") + " --export-stream " + Q(row / "job.json");
       },
       1},
      {"run_export_stream_over_a_users_file",
       [=](const fs::path& row) {
         job(row, SyntheticJob("out/{sequence}"));
         return std::vector<fs::path>{user_file(row / "mine.json")};
       },
       [](const fs::path& row) {
         return "run -q " + Q(row / "job.json") + " --export-stream " + Q(row / "mine.json");
       },
       1},
      {"run_trace_over_a_users_file",
       [=](const fs::path& row) {
         job(row, SyntheticJob("out/{sequence}"));
         return std::vector<fs::path>{user_file(row / "trace.jsonl")};
       },
       [](const fs::path& row) {
         return "run -q " + Q(row / "job.json") + " --trace " + Q(row / "trace.jsonl");
       },
       1},
      {"mesh_export_colmap_onto_its_input_model",
       [=](const fs::path& row) { return copy(d / "model", row / "m3"); },
       [](const fs::path& row) {
         return "mesh -q --input " + Q(row / "m3") + " --format colmap --out " +
                Q(row / "x.ply") + " --export-colmap " + Q(row / "m3");
       },
       1},
      {"run_export_colmap_over_a_users_model",
       [=](const fs::path& row) {
         job(row, SyntheticJob("out/{sequence}"));
         return std::vector<fs::path>{user_file(row / "theirs" / "images.txt")};
       },
       [](const fs::path& row) {
         return "run -q " + Q(row / "job.json") + " --export-colmap " + Q(row / "theirs");
       },
       1},
      {"run_viewer_assets_of_the_user",
       [=](const fs::path& row) {
         job(row, SyntheticJob("out/{sequence}"));
         return std::vector<fs::path>{user_file(row / "out" / "assets" / "meshes" / "0.js"),
                                      user_file(row / "out" / "assets" / "imr-tiles-viewer.js")};
       },
       [](const fs::path& row) { return "run -q " + Q(row / "job.json"); }, 73},
      {"mesh_work_folder_with_a_users_job",
       [=](const fs::path& row) {
         return std::vector<fs::path>{user_file(row / "work" / "job.json", "{\"mine\": 1}\n")};
       },
       [](const fs::path& row) {
         return "mesh -q --input street --format synthetic --out " + Q(row / "x.ply") +
                " --work " + Q(row / "work");
       },
       73},
      {"mesh_default_work_folder_with_a_users_job",
       [=](const fs::path& row) {
         return std::vector<fs::path>{user_file(row / "x.imr" / "job.json", "{\"mine\": 1}\n")};
       },
       [](const fs::path& row) {
         return "mesh -q --input street --format synthetic --out " + Q(row / "x.ply");
       },
       73},
      {"mesh_out_over_a_users_file",
       [=](const fs::path& row) { return std::vector<fs::path>{user_file(row / "x.ply")}; },
       [](const fs::path& row) {
         return "mesh -q --input street --format synthetic --out " + Q(row / "x.ply") +
                " --set input.options.frames=20";
       },
       73},
      {"tiles_merge_onto_a_tile_of_the_run",
       [=](const fs::path& row) { return copy(d / "base" / "street", row / "run"); },
       [](const fs::path& row) {
         return "tiles merge " + Q(row / "run") + " --out " +
                Q(row / "run" / "tiles" / "tile_000001.glb");
       },
       73},
      {"tiles_merge_onto_the_runs_mesh",
       [=](const fs::path& row) { return copy(d / "base" / "street", row / "run"); },
       [](const fs::path& row) {
         return "tiles merge " + Q(row / "run") + " --out " + Q(row / "run" / "mesh.ply");
       },
       73},
      {"tiles_merge_over_a_users_file",
       [=](const fs::path& row) {
         copy(d / "base" / "street", row / "run");
         return std::vector<fs::path>{user_file(row / "merged.ply")};
       },
       [](const fs::path& row) {
         return "tiles merge " + Q(row / "run") + " --out " + Q(row / "merged.ply");
       },
       73},
      {"evaluate_out_onto_its_mesh",
       [=](const fs::path& row) { return copy(d / "base" / "street" / "mesh.ply", row / "mesh.ply"); },
       [](const fs::path& row) {
         return "evaluate " + Q(row / "mesh.ply") + " --truth " + Q(row / "mesh.ply") +
                " --no-crop --out " + Q(row / "mesh.ply");
       },
       73},
      {"evaluate_out_over_a_users_file",
       [=](const fs::path& row) {
         copy(d / "base" / "street" / "mesh.ply", row / "mesh.ply");
         return std::vector<fs::path>{user_file(row / "eval.json")};
       },
       [](const fs::path& row) {
         return "evaluate " + Q(row / "mesh.ply") + " --truth " + Q(row / "mesh.ply") +
                " --no-crop --out " + Q(row / "eval.json");
       },
       73},
      {"render_out_over_a_users_png",
       [=](const fs::path& row) {
         copy(d / "base" / "street" / "mesh.ply", row / "mesh.ply");
         return std::vector<fs::path>{user_file(row / "shot.png")};
       },
       [](const fs::path& row) {
         return "render " + Q(row / "mesh.ply") + " --top-down --out " + Q(row / "shot.png");
       },
       73},
      {"report_over_a_users_summary",
       [=](const fs::path& row) {
         fs::create_directories(row / "b" / "imr-batch");
         WriteText(row / "b" / "imr-batch" / "batch.json", "{}");
         return std::vector<fs::path>{user_file(row / "b" / "summary.md", "# my notes\n")};
       },
       [](const fs::path& row) { return "report " + Q(row / "b"); }, 73},
      {"submit_over_a_users_script",
       [=](const fs::path& row) {
         job(row, SyntheticJob("out/{sequence}"));
         return std::vector<fs::path>{
             user_file(row / "out" / "imr-batch" / "sequences.txt", "my list\n")};
       },
       [](const fs::path& row) {
         return "submit " + Q(row / "job.json") + " --tasks 1 --dry-run";
       },
       73},
  };
#ifdef IMR_SYNTH_EXE
  rows.push_back(
      {"render_out_onto_an_input_frame",
       [=](const fs::path& row) {
         auto files = copy(d / "seq", row / "seq");
         copy(d / "base" / "street" / "mesh.ply", row / "mesh.ply");
         return files;
       },
       [](const fs::path& row) {
         return "render " + Q(row / "mesh.ply") + " --sequence " + Q(row / "seq") +
                " --format kitti_odometry --frame 3 --out " +
                Q(row / "seq" / "image_2" / "000003.png");
       },
       73});
#endif
  return rows;
}

TEST_F(WriteRuleCli, NoCommandWritesOverAUsersFileOrItsOwnInputs) {
  for (const Row& row : Rows(D())) {
    SCOPED_TRACE(row.name);
    const fs::path folder = D() / row.name;
    fs::create_directories(folder);
    const std::vector<fs::path> kept = row.setup(folder);
    ASSERT_FALSE(kept.empty());
    std::map<fs::path, std::string> before;
    for (const fs::path& p : kept) before[p] = ReadText(p);
    const CommandResult r = RunShell("cd " + Q(folder) + " && " + kImr + " " + row.command(folder));
    EXPECT_EQ(r.status, row.status) << r.err << r.out;
    // The refusal names one of the protected files (or the folder holding them) and says why.
    const std::string all = r.err + r.out;
    bool named = false;
    for (const fs::path& p : kept) {
      named |= all.find(p.string()) != std::string::npos;
      named |= all.find(p.parent_path().string() + ":") != std::string::npos;
    }
    EXPECT_TRUE(named) << all;
    EXPECT_TRUE(all.find("imr never writes") != std::string::npos ||
                all.find("imr did not write") != std::string::npos ||
                all.find("not a report of this job's sequence") != std::string::npos)
        << all;
    std::cout << "[ message  ] " << row.name << " (" << r.status << "): " << all.substr(0, all.find('\n'))
              << "\n";
    for (const auto& [p, bytes] : before) {
      ASSERT_TRUE(fs::exists(p)) << p << " was removed";
      EXPECT_EQ(ReadText(p), bytes) << p << " was changed";
    }
  }
}

// --export-stream and --export-colmap are written streamed from spools in a staging folder beside
// them (issue 46): a run killed while writing the stream (a file size limit's SIGXFSZ) leaves no
// half file under the final names; one whose write fails (the limit's EFBIG, the signal ignored)
// exits non-zero naming the file and leaves neither a half file nor a staging folder.
TEST_F(WriteRuleCli, AnExportCutShortLeavesNoHalfFile) {
  const fs::path row = D() / "cut-export";
  fs::create_directories(row);
  WriteText(row / "job.json", SyntheticJob("out/{sequence}", 60).dump(2));
  for (const bool killed : {true, false}) {
    const fs::path at = row / (killed ? "killed" : "failed");
    fs::create_directories(at);
    // 1,200 KiB a file (prlimit: bytes, where sh's ulimit counts blocks of a size the shell
    // chooses): the mesh, the spools (17,700 observations of 48 bytes) and the COLMAP files fit,
    // the stream (1.6 MB) not.
    const std::string limit = std::string(killed ? "" : "trap '' XFSZ; ") + "prlimit --fsize=1228800 ";
    const CommandResult r = RunShell(limit + kImr + " run -q --force " + Q(row / "job.json") +
                                     " --export-stream " + Q(at / "s.json") + " --export-colmap " +
                                     Q(at / "colmap"));
    EXPECT_NE(r.status, 0) << (killed ? "killed" : "failed");  // the sequence's process's
    EXPECT_FALSE(fs::exists(at / "s.json"));
    EXPECT_FALSE(fs::exists(at / "colmap" / "points3D.txt"));
    if (killed) {
      EXPECT_NE(r.err.find("SIGXFSZ"), std::string::npos) << r.err;
      continue;
    }
    // The file named where it was to go, not its staged copy.
    EXPECT_NE(r.err.find((at / "s.json").string() + ": write failed: File too large"), std::string::npos)
        << r.err;
    for (const auto& e : fs::directory_iterator(at))
      EXPECT_NE(e.path().filename().string().rfind(".imr-staging-", 0), 0u) << e.path() << " was left";
  }
}

// What imr wrote, it may write again: the same commands succeed on their own earlier outputs.
TEST_F(WriteRuleCli, ARerunReplacesWhatImrWrote) {
  const fs::path row = D() / "rerun";
  fs::create_directories(row);
  WriteText(row / "job.json", SyntheticJob("out/{sequence}").dump(2));
  for (int i = 0; i < 2; ++i) {
    const CommandResult r = RunShell(kImr + " run -q --force " + Q(row / "job.json") +
                                     " --export-stream " + Q(row / "s.json"));
    ASSERT_EQ(r.status, 0) << r.err;
  }
  for (int i = 0; i < 2; ++i) {
    const CommandResult r =
        RunShell(kImr + " render " + Q(row / "out" / "street" / "mesh.ply") + " --top-down --out " +
                 Q(row / "shot.png"));
    ASSERT_EQ(r.status, 0) << r.err;
  }
  // A file the user changed after imr wrote it is theirs: the next render refuses it. (A run's
  // outputs that its manifest names are redone whatever their bytes: a damaged mesh, Batch.)
  WriteText(row / "shot.png", "edited\n");
  const CommandResult r =
      RunShell(kImr + " render " + Q(row / "out" / "street" / "mesh.ply") + " --top-down --out " +
               Q(row / "shot.png"));
  EXPECT_EQ(r.status, 73);
  EXPECT_NE(r.err.find("changed since imr wrote it"), std::string::npos) << r.err;
  EXPECT_TRUE(ReadText(row / "shot.png") == "edited\n");
}

// A re-run that fails removes the earlier outputs it was replacing (finding 15): a mesh and a
// report without their manifest would look whole. Only imr's files go: a user's file stays.
TEST_F(WriteRuleCli, AFailedRerunLeavesNothingThatLooksWhole) {
  const fs::path row = D() / "failed-rerun";
  fs::create_directories(row);
  fs::copy_file(D() / "stream.json", row / "in.json");
  json j = SyntheticJob("out/{sequence}");
  j["sequences"] = {(row / "in.json").string()};
  j["input"] = {{"format", "slam_json"}};
  WriteText(row / "job.json", j.dump(2));
  CommandResult r = RunShell(kImr + " run -q " + Q(row / "job.json"));
  ASSERT_EQ(r.status, 0) << r.err;
  const fs::path out = row / "out" / "in.json";
  ASSERT_TRUE(fs::exists(out / "mesh.ply"));
  ASSERT_TRUE(fs::exists(out / "manifest.json"));
  WriteText(out / "notes.txt", "the user's notes\n");
  WriteText(row / "in.json", "{\"slam_data_version\": \"0.3\", \"views\": [");  // cut short
  r = RunShell(kImr + " run -q --force " + Q(row / "job.json"));
  EXPECT_EQ(r.status, 1) << r.err;
  for (const char* f : {"mesh.ply", "report.json", "manifest.json"})
    EXPECT_FALSE(fs::exists(out / f)) << f << " of the earlier run looks whole";
  EXPECT_EQ(ReadText(out / "notes.txt"), "the user's notes\n");
}

}  // namespace
}  // namespace imr::testing
