#include "host/batch/summary.h"

#include "host/batch/batch.h"
#include "host/batch/manifest.h"
#include "host/batch/progress.h"

#include <gtest/gtest.h>

#include <fstream>
#include <random>

namespace imr::batch {
namespace {
namespace fs = std::filesystem;
using nlohmann::json;

fs::path BatchDirOf(const std::string& output_directory, const std::string& job_file) {
  const auto parsed = io::ParseJobText(
      json({{"sequences", {"a", "b"}},
            {"input", {{"format", "synthetic"}}},
            {"pipeline", {{{"kind", "exporter"}, {"plugin", "x"}}}},
            {"output", {{"directory", output_directory}}}})
          .dump(),
      job_file);
  return BatchDirectory(parsed.job);
}

TEST(BatchDirectory, IsTheTemplateBeforeItsSequenceComponent) {
  EXPECT_EQ(BatchDirOf("runs/{sequence}", "/data/jobs/j.json"), "/data/jobs/runs");
  EXPECT_EQ(BatchDirOf("../out/{job}/{sequence}/mesh", "/data/jobs/street.json"), "/data/out/street");
  EXPECT_EQ(BatchDirOf("/abs/seq_{sequence}", "/data/jobs/j.json"), "/abs");
  EXPECT_EQ(BatchDirOf("{sequence}", "/data/jobs/j.json"), "/data/jobs");
}

class SummaryTest : public ::testing::Test {
 protected:
  SummaryTest() {
    dir_ = fs::temp_directory_path() / ("imr-summary-test-" + std::to_string(std::random_device{}()));
    fs::create_directories(dir_);
  }
  ~SummaryTest() override { fs::remove_all(dir_); }
  void Write(const fs::path& p, const std::string& text) {
    fs::create_directories(p.parent_path());
    std::ofstream(p, std::ios::binary) << text;
  }
  // A finished sequence: mesh, report, manifest for `hash`.
  void Finish(const std::string& name, const json& report) {
    const fs::path out = dir_ / name;
    Write(out / "mesh.ply", std::string(3000, 'p'));
    Write(out / "mesh.glb", std::string(1000, 'g'));
    Write(out / "snapshots" / "mesh_kf000005.ply", "s");
    Write(out / "report.json", report.dump());
    const json identity = {{"sequence", name}};
    WriteManifest(MakeManifest(name, identity,
                               {out / "snapshots" / "mesh_kf000005.ply", out / "mesh.ply",
                                out / "mesh.glb", out / "report.json"},
                               out),
                  out);
  }
  fs::path dir_;
};

TEST_F(SummaryTest, OneRowPerSequenceWithStatusFiguresAndCauses) {
  BatchInfo info;
  info.job_file = "/jobs/j.json";
  info.job_name = "j";
  info.output_stem = "mesh";
  for (const char* n : {"street", "room", "pl|ane", "drive", "moved", "killed"})
    info.sequences.push_back({n, std::string("src/") + n, dir_ / n, HashIdentity({{"sequence", n}})});
  WriteBatchInfo(dir_, info);
  const json report = {{"seconds", 1.25},
                       {"input", {{"options", {{"frames", 40}}}}},
                       {"engine", {{"keyframes", 8}}},
                       {"mesh", {{"vertices", 500}, {"faces", 900}}},
                       {"accuracy", {{"mean_truth_to_mesh", 0.0421}, {"completeness", 0.93}}}};
  Finish("street", report);
  Finish("room", report);
  Finish("moved", report);
  Write(dir_ / "moved" / "mesh.glb", "changed");
  WriteStatusRecord(dir_, {"street", "ok", 1.3, "", -1, "", {}, "host", "t", "", {}});
  WriteStatusRecord(dir_, {"room", "skipped", 0.0, "", -1, "", {}, "host", "t", "", {}});
  WriteStatusRecord(dir_, {"moved", "ok", 0.0, "", -1, "", {}, "host", "t", "", {}});
  WriteStatusRecord(dir_, {"pl|ane", "failed", 0.5, "crashed: signal SIGSEGV (Segmentation fault)",
                           -1, "SIGSEGV", {"[pl|ane] keyframe 3", "about to crash"}, "node7", "t", "",
                           {"most points never entered the mesh"}});
  WriteStatusRecord(dir_, {"killed", "running", 0.0, "", -1, "", {}, "node3", "", "2026-01-02T03:04:05Z", {}});

  const json s = WriteSummary(dir_, "imr report");
  EXPECT_EQ(s["counts"], json({{"sequences", 6}, {"ok", 2}, {"reused", 1}, {"failed", 2},
                               {"interrupted", 1}, {"not_run", 1}}));
  const json& street = s["sequences"][0];
  EXPECT_EQ(street["status"], "ok");
  EXPECT_FALSE(street["reused"].get<bool>());
  EXPECT_EQ(street["frames"], 40);
  EXPECT_EQ(street["keyframes"], 8);
  EXPECT_EQ(street["seconds"], 1.25);
  EXPECT_EQ(street["mesh"]["faces"], 900);
  EXPECT_EQ(street["mesh"]["bytes"], 4000);  // mesh.ply + mesh.glb, not snapshots or the report
  EXPECT_EQ(street["accuracy"]["completeness"], 0.93);
  EXPECT_TRUE(s["sequences"][1]["reused"].get<bool>());
  const json& crashed = s["sequences"][2];
  EXPECT_EQ(crashed["status"], "failed");
  EXPECT_EQ(crashed["signal"], "SIGSEGV");
  EXPECT_EQ(crashed["host"], "node7");
  EXPECT_EQ(crashed["log_tail"].size(), 2u);
  // Warnings given before the failure stay with it.
  EXPECT_EQ(crashed["warnings"], json::array({"most points never entered the mesh"}));
  EXPECT_EQ(s["sequences"][3]["status"], "not run");
  EXPECT_EQ(s["sequences"][4]["status"], "failed");
  EXPECT_EQ(s["sequences"][4]["error"],
            "outputs changed after the run: mesh.glb changed since it was written (checksum)");
  EXPECT_EQ(s["sequences"][5]["status"], "interrupted");
  EXPECT_NE(s["sequences"][5]["error"].get<std::string>().find(
                "started on node3 at 2026-01-02T03:04:05Z and never ended"),
            std::string::npos);

  const std::string md = SummaryMarkdown(s);
  EXPECT_NE(md.find("6 sequences: 2 ok (1 from an earlier run), 2 failed, 1 interrupted, 1 not run."),
            std::string::npos) << md;
  EXPECT_NE(md.find("| street | ok | 40 | 8 | 1.25 | 900 | 4 KiB | 0.0421 | 0.930 |  |"), std::string::npos) << md;
  EXPECT_NE(md.find("| room | ok (earlier run) |"), std::string::npos) << md;
  EXPECT_NE(md.find("| pl\\|ane | failed |"), std::string::npos) << md;  // a pipe is escaped
  EXPECT_NE(md.find("| drive | not run |"), std::string::npos) << md;
  EXPECT_NE(md.find("## Failures"), std::string::npos);
  EXPECT_NE(md.find("Ended by SIGSEGV."), std::string::npos);
  EXPECT_NE(md.find("about to crash"), std::string::npos);
  EXPECT_NE(md.find("## Warnings\n\n### pl\\|ane\n\n- most points never entered the mesh"),
            std::string::npos) << md;
  // Both files are on disk.
  EXPECT_TRUE(fs::exists(dir_ / "summary.json"));
  EXPECT_TRUE(fs::exists(dir_ / "summary.md"));
}

TEST_F(SummaryTest, AFolderWithoutBatchInfoIsNamed) {
  try {
    BuildSummary(dir_);
    FAIL();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("is not a batch folder"), std::string::npos) << e.what();
  }
}

TEST(StatusFileName, FitsAnyName) {
  EXPECT_EQ(StatusFileName("street"), "street.json");
  EXPECT_EQ(StatusFileName("2011_09_26 drive-0001"), "2011_09_26 drive-0001.json");
  for (const std::string& name : {std::string(250, 'n'), std::string("caf\xE9"), std::string("a/b"),
                                  std::string("new\nline"), std::string(".hidden"), std::string("#x")}) {
    const std::string f = StatusFileName(name);
    EXPECT_LE(f.size(), 100u) << f;
    EXPECT_EQ(f.find('/'), std::string::npos) << f;
    EXPECT_NE(f[0], '.') << f;
    EXPECT_NE(f, StatusFileName(name + "x"));  // the hash tells them apart
  }
}

TEST(SequenceList, EveryNameRoundTrips) {
  const std::vector<std::string> names = {"street", " lead", "trail ", "#hash", "\"quoted\"",
                                          "new\nline", "tab\there", "caf\xE9", "back\\slash"};
  const fs::path file = fs::temp_directory_path() / ("imr-list-test-" + std::to_string(std::random_device{}()));
  {
    std::ofstream out(file, std::ios::binary);
    out << "# a comment\n\n";
    for (const auto& n : names) out << SequenceListLine(n) << "\n";
    out << "  plain with blanks around  \n";
  }
  std::vector<std::string> expected = names;
  expected.push_back("plain with blanks around");  // unquoted lines are trimmed, as before
  EXPECT_EQ(ReadSequenceList(file), expected);
  EXPECT_EQ(SequenceListLine("street"), "street");
  EXPECT_EQ(SequenceListLine(" lead"), "\" lead\"");
  std::ofstream(file) << "\"unterminated\n";
  try {
    ReadSequenceList(file);
    ADD_FAILURE() << "no error";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(file.string() + ":1: a quoted name"), std::string::npos) << e.what();
  }
  fs::remove(file);
}

TEST(Progress, DescribesSequencesAndEtas) {
  const auto t0 = std::chrono::steady_clock::now();
  BatchProgress p;
  p.total = 4;
  p.done = 2;
  p.failed = 1;
  p.skipped = 1;
  p.running.push_back({"street", {10, 40, 50}, t0});
  const auto now = t0 + std::chrono::seconds(10);
  EXPECT_EQ(ProgressDisplay::Describe(p, now, t0),
            "2/4 sequences done, 1 failed, 1 up to date | street keyframe 10/40 (frame 50) ETA 30 s"
            " | batch ETA 14 s");
  EXPECT_EQ(FormatDuration(3725), "1:02:05");
}

}  // namespace
}  // namespace imr::batch
