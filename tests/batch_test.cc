// `imr run` as a batch (issue 7): sequences in child processes (a crashing plugin fails only its
// sequence), shards, resume after SIGKILL through manifests, the summary, `imr report`, and the
// scripts of `imr submit --dry-run`. Engine-only synthetic sequences keep it to seconds.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <set>
#include <thread>

#include "host/batch/manifest.h"
#include "host/util/sha256.h"
#include "host/util/write_rule.h"
#include "test_util.h"

namespace imr::testing {
namespace {
namespace fs = std::filesystem;
using nlohmann::json;

const std::string kImr = IMR_EXE;

json Job(int frames, const std::vector<std::string>& sequences = {"street", "room", "plane"}) {
  return {{"sequences", sequences},
          {"input", {{"format", "synthetic"}, {"options", {{"frames", frames}, {"seed", 3}}}}},
          {"pipeline",
           {{{"kind", "weight_policy"}, {"plugin", "org.imr.policy.nearest"}},
            {{"kind", "exporter"}, {"plugin", "org.imr.exporter.assimp"}}}},
          {"output", {{"directory", "runs/{sequence}"}, {"formats", {"ply", "glb"}}}}};
}

json ReadJson(const fs::path& p) { return json::parse(ReadText(p)); }

// The names on stdout lines that start with `status` ("ok", "skipped", "FAILED").
std::set<std::string> Listed(const std::string& out, const std::string& status) {
  std::set<std::string> names;
  std::istringstream in(out);
  for (std::string line; std::getline(in, line);) {
    if (line.rfind(status + " ", 0) != 0) continue;
    std::istringstream words(line.substr(status.size()));
    std::string name;
    words >> name;
    names.insert(name);
  }
  return names;
}

class Batch : public ::testing::Test {
 protected:
  Batch() : dir_("batch") {}
  fs::path WriteJob(const json& j, const std::string& name = "job.json") {
    const fs::path p = dir_ / name;
    WriteText(p, j.dump(2));
    return p;
  }
  CommandResult Imr(const std::string& args, const std::string& env = "") {
    return RunShell(env + " " + Quote(kImr) + " " + args);
  }
  fs::path Out(const std::string& seq) const { return dir_ / "runs" / seq; }
  // Every file of a finished sequence is in its manifest with its checksum, and nothing else is
  // there: no partial file, no temporary left behind.
  void ExpectExactlyTheManifest(const std::string& seq) {
    const fs::path out = Out(seq);
    std::string error;
    const auto m = batch::ReadManifest(out, &error);
    ASSERT_TRUE(m) << seq << ": " << error;
    std::set<std::string> listed;
    for (const auto& e : m->files) {
      listed.insert(e.path);
      EXPECT_EQ(imr::Sha256File(out / e.path), e.sha256) << seq << "/" << e.path;
    }
    for (const auto& e : fs::recursive_directory_iterator(out)) {
      if (!e.is_regular_file()) continue;
      const std::string rel = fs::relative(e.path(), out).string();
      // The manifest itself, and imr's ledger of what it wrote (host/util/write_rule.h).
      if (rel == batch::kManifestFile || e.path().filename() == kWriteLedgerName) continue;
      EXPECT_TRUE(listed.count(rel)) << seq << "/" << rel << " is not in the manifest";
    }
  }
  ScratchDir dir_;
};

TEST_F(Batch, ManySequencesGiveASummaryAndARerunSkipsThem) {
  const fs::path job = WriteJob(Job(12));
  auto r = Imr("run " + Quote(job.string()) + " --jobs 2");
  ASSERT_EQ(r.status, 0) << r.out << r.err;
  EXPECT_EQ(Listed(r.out, "ok"), (std::set<std::string>{"street", "room", "plane"})) << r.out;
  EXPECT_NE(r.out.find("summary: " + (dir_ / "runs" / "summary.md").string()), std::string::npos) << r.out;
  // Not a terminal: plain progress lines.
  EXPECT_NE(r.err.find("progress: 3/3 sequences done"), std::string::npos) << r.err;
  for (const char* s : {"street", "room", "plane"}) ExpectExactlyTheManifest(s);

  const json summary = ReadJson(dir_ / "runs" / "summary.json");
  EXPECT_EQ(summary["counts"]["ok"], 3);
  EXPECT_EQ(summary["written_by"], "imr run");
  for (const json& s : summary["sequences"]) {
    EXPECT_EQ(s["status"], "ok") << s.dump();
    EXPECT_EQ(s["frames"], 12);
    EXPECT_GT(s["keyframes"].get<int>(), 0);
    EXPECT_GT(s["mesh"]["faces"].get<int>(), 100);
    EXPECT_GT(s["mesh"]["bytes"].get<int>(), 1000);
    EXPECT_LT(s["accuracy"]["mean_truth_to_mesh"].get<double>(), 0.5);  // from the report
  }
  const std::string md = ReadText(dir_ / "runs" / "summary.md");
  EXPECT_NE(md.find("3 sequences: 3 ok, 0 failed."), std::string::npos) << md;
  EXPECT_NE(md.find("| street | ok | 12 |"), std::string::npos) << md;

  // Nothing changed: nothing is redone.
  r = Imr("run " + Quote(job.string()));
  ASSERT_EQ(r.status, 0) << r.out << r.err;
  EXPECT_EQ(Listed(r.out, "skipped"), (std::set<std::string>{"street", "room", "plane"})) << r.out;
  EXPECT_EQ(ReadJson(dir_ / "runs" / "summary.json")["counts"]["reused"], 3);
  // A damaged output is redone, and so is everything after a change of plugin params (a
  // param given with its default value is no change).
  WriteText(Out("room") / "mesh.glb", "damaged");
  r = Imr("run " + Quote(job.string()));
  EXPECT_EQ(Listed(r.out, "ok"), std::set<std::string>{"room"}) << r.out;
  EXPECT_NE(r.err.find("room: running (mesh.glb changed since it was written (checksum))"),
            std::string::npos) << r.err;
  json changed = Job(12);
  changed["pipeline"][1]["params"] = {{"point_ids", true}};
  WriteJob(changed);
  r = Imr("run " + Quote(job.string()));
  EXPECT_EQ(Listed(r.out, "skipped").size(), 3u) << r.out;
  changed["pipeline"][1]["params"] = {{"point_ids", false}};
  WriteJob(changed);
  r = Imr("run " + Quote(job.string()));
  EXPECT_EQ(Listed(r.out, "ok").size(), 3u) << r.out;
  EXPECT_NE(r.err.find("the job changed since the last run (pipeline)"), std::string::npos) << r.err;
  // --force redoes all.
  r = Imr("run --force " + Quote(job.string()));
  EXPECT_EQ(Listed(r.out, "ok").size(), 3u) << r.out;
}

TEST_F(Batch, ARedoneSequenceDropsFilesItNoLongerWrites) {
  ASSERT_EQ(Imr("run -q " + Quote(WriteJob(Job(20, {"street"})).string())).status, 0);
  EXPECT_TRUE(fs::exists(Out("street") / "mesh.glb"));
  json j = Job(20, {"street"});
  j["output"]["formats"] = {"ply"};
  auto r = Imr("run -q " + Quote(WriteJob(j).string()));
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_FALSE(fs::exists(Out("street") / "mesh.glb"));
  ExpectExactlyTheManifest("street");
}

TEST_F(Batch, TwoShardsCoverEverySequenceExactlyOnce) {
  const fs::path job = WriteJob(Job(15));
  auto a = Imr("run --shard 1/2 " + Quote(job.string()));
  auto b = Imr("run --shard 2/2 " + Quote(job.string()));
  ASSERT_EQ(a.status, 0) << a.out << a.err;
  ASSERT_EQ(b.status, 0) << b.out << b.err;
  const auto first = Listed(a.out, "ok"), second = Listed(b.out, "ok");
  std::multiset<std::string> all(first.begin(), first.end());
  all.insert(second.begin(), second.end());
  EXPECT_EQ(all, (std::multiset<std::string>{"plane", "room", "street"})) << a.out << b.out;
  EXPECT_FALSE(first.empty());
  EXPECT_FALSE(second.empty());
  // Shards leave the summary to `imr report`.
  EXPECT_FALSE(fs::exists(dir_ / "runs" / "summary.json"));
  EXPECT_NE(a.out.find("when every shard is done: imr report " + (dir_ / "runs").string()),
            std::string::npos) << a.out;
  // A Slurm array task finds its shard without flags: task 1 of 0-1 is shard 2/2.
  auto s = Imr("run " + Quote(job.string()),
               "SLURM_ARRAY_TASK_ID=1 SLURM_ARRAY_TASK_MIN=0 SLURM_ARRAY_TASK_COUNT=2");
  EXPECT_EQ(s.status, 0) << s.err;
  EXPECT_EQ(Listed(s.out, "skipped"), second) << s.out << s.err;
  EXPECT_NE(s.err.find("shard 2/2 (Slurm array task 1)"), std::string::npos) << s.err;
  // Listing order does not matter (and the same job in another order is up to date).
  auto c = Imr("run --shard 1/2 " +
               Quote(WriteJob(Job(15, {"plane", "street", "room"}), "reordered.json").string()));
  EXPECT_EQ(Listed(c.out, "skipped"), first) << c.out;

  auto rep = Imr("report " + Quote((dir_ / "runs").string()));
  EXPECT_EQ(rep.status, 0) << rep.out << rep.err;
  EXPECT_NE(rep.out.find("3 sequences: 3 ok (3 from an earlier run), 0 failed\n"), std::string::npos) << rep.out;
  EXPECT_EQ(ReadJson(dir_ / "runs" / "summary.json")["written_by"], "imr report");
}

TEST_F(Batch, ACrashingPluginFailsOnlyItsSequence) {
  json j = Job(20);
  j["plugin_paths"] = {IMR_TEST_PLUGIN_DIR};
  j["pipeline"].push_back({{"kind", "exporter"},
                           {"plugin", "org.imr.test.exporter.crashing"},
                           {"params", {{"segv_in", "runs/room"}, {"allocate_in", "runs/plane"}}}});
  j["output"]["formats"] = {"ply", "crash"};
  const fs::path job = WriteJob(j);
  auto r = Imr("run --jobs 2 --max-rss 400M " + Quote(job.string()));
  EXPECT_EQ(r.status, 2) << r.out << r.err;  // the exit status counts the failed sequences
  EXPECT_EQ(Listed(r.out, "ok"), std::set<std::string>{"street"}) << r.out;
  EXPECT_EQ(Listed(r.out, "FAILED"), (std::set<std::string>{"room", "plane"})) << r.out;
  EXPECT_NE(r.out.find("crashed: signal SIGSEGV (Segmentation fault)"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("over --max-rss 400 MiB"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("3 sequences, 2 failed"), std::string::npos) << r.out;
  ExpectExactlyTheManifest("street");
  EXPECT_FALSE(fs::exists(Out("room") / batch::kManifestFile));

  const json summary = ReadJson(dir_ / "runs" / "summary.json");
  EXPECT_EQ(summary["counts"]["failed"], 2);
  const json& room = summary["sequences"][1];
  EXPECT_EQ(room["name"], "room");
  EXPECT_EQ(room["status"], "failed");
  EXPECT_EQ(room["signal"], "SIGSEGV");
  EXPECT_FALSE(room["log_tail"].empty());  // the last lines the sequence logged
  EXPECT_NE(summary["sequences"][2]["error"].get<std::string>().find("resident memory"),
            std::string::npos);
  const std::string md = ReadText(dir_ / "runs" / "summary.md");
  EXPECT_NE(md.find("| room | failed |"), std::string::npos) << md;
  EXPECT_NE(md.find("Ended by SIGSEGV."), std::string::npos) << md;

  // abort() is named too (another job: its own output folder, as jobs must not share one).
  j["sequences"] = {"street"};
  j["output"]["directory"] = "runs-abort/{sequence}";
  j["pipeline"][2]["params"] = {{"abort_in", "runs-abort/street"}};
  r = Imr("run -q " + Quote(WriteJob(j, "abort.json").string()));
  EXPECT_EQ(r.status, 1) << r.out << r.err;
  EXPECT_NE(r.out.find("crashed: signal SIGABRT (Aborted)"), std::string::npos) << r.out;
}

TEST_F(Batch, AKilledBatchResumesWithoutPartialFiles) {
  json j = Job(40);
  j["output"]["formats"] = {"ply"};
  j["output"]["snapshot_every"] = 2;
  const fs::path job = WriteJob(j);
  const pid_t pid = ::fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    ::freopen("/dev/null", "w", stdout);
    ::freopen("/dev/null", "w", stderr);
    ::execl(kImr.c_str(), kImr.c_str(), "run", job.c_str(), static_cast<char*>(nullptr));
    ::_exit(127);
  }
  // Kill it while the second sequence is half done: street finished, room has snapshots.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  bool killed = false;
  while (std::chrono::steady_clock::now() < deadline) {
    std::error_code ec;
    const bool street_done = fs::exists(Out("street") / batch::kManifestFile, ec);
    int snapshots = 0;
    if (fs::is_directory(Out("room") / "snapshots", ec))
      for (const auto& e : fs::directory_iterator(Out("room") / "snapshots", ec))
        snapshots += e.path().filename().string()[0] != '.' ? 1 : 0;
    if (street_done && snapshots >= 2) {
      ::kill(pid, SIGKILL);
      killed = true;
      break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  int status = 0;
  ::waitpid(pid, &status, 0);
  ASSERT_TRUE(killed) << "the batch ended before room was half done";
  ASSERT_TRUE(WIFSIGNALED(status));
  std::this_thread::sleep_for(std::chrono::milliseconds(300));  // its child follows it
  EXPECT_FALSE(fs::exists(Out("room") / batch::kManifestFile));
  EXPECT_FALSE(fs::exists(Out("room") / "report.json"));
  // What is there under a final name is whole: every mesh reads back.
  for (const auto& e : fs::recursive_directory_iterator(Out("room"))) {
    bool temporary = false;  // a dot name, or inside a staging folder
    for (const auto& c : fs::relative(e.path(), Out("room"))) temporary |= c.string()[0] == '.';
    if (!e.is_regular_file() || temporary) continue;
    auto r = Imr("evaluate " + Quote(e.path().string()) + " --truth " + Quote(e.path().string()) +
                 " --precision-samples 100");
    EXPECT_EQ(r.status, 0) << e.path() << " does not read back: " << r.err;
  }

  // The report tells what the kill left: street done, room interrupted, plane not started.
  auto rep = Imr("report " + Quote((dir_ / "runs").string()));
  EXPECT_EQ(rep.status, 2);  // interrupted + not run
  EXPECT_NE(rep.out.find("3 sequences: 1 ok, 0 failed, 1 interrupted, 1 not run"), std::string::npos)
      << rep.out;
  EXPECT_EQ(ReadJson(dir_ / "runs" / "summary.json")["sequences"][1]["status"], "interrupted");

  auto r = Imr("run " + Quote(job.string()));
  ASSERT_EQ(r.status, 0) << r.out << r.err;
  EXPECT_EQ(Listed(r.out, "skipped"), std::set<std::string>{"street"}) << r.out;
  EXPECT_EQ(Listed(r.out, "ok"), (std::set<std::string>{"room", "plane"})) << r.out;
  for (const char* s : {"street", "room", "plane"}) ExpectExactlyTheManifest(s);
  const json summary = ReadJson(dir_ / "runs" / "summary.json");
  EXPECT_EQ(summary["counts"]["ok"], 3);
  EXPECT_EQ(summary["counts"]["reused"], 1);
}

// `imr report` while an `imr run` holds the batch folder (issue 44, finding 12): its sequence is
// running, not killed; the report exits 75 (EX_TEMPFAIL, as `imr run` does) naming the holder's
// pid and writes nothing. Once the run has ended, it reports.
TEST_F(Batch, ReportWhileARunHoldsTheFolderWritesNothing) {
  json j = Job(3000, {"street"});
  j["output"]["formats"] = {"ply"};
  const fs::path job = WriteJob(j);
  const pid_t pid = ::fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    ::freopen("/dev/null", "w", stdout);
    ::freopen("/dev/null", "w", stderr);
    ::execl(kImr.c_str(), kImr.c_str(), "run", job.c_str(), static_cast<char*>(nullptr));
    ::_exit(127);
  }
  // Running: its sequence's output folder made (the lock is taken before).
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  std::error_code ec;
  while (std::chrono::steady_clock::now() < deadline && !fs::is_directory(Out("street"), ec))
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  ASSERT_TRUE(fs::is_directory(Out("street"))) << "the run did not start";
  const CommandResult rep = Imr("report " + Quote((dir_ / "runs").string()));
  const bool still_running = ::waitpid(pid, nullptr, WNOHANG) == 0;
  ::kill(pid, SIGKILL);
  ::waitpid(pid, nullptr, 0);
  ASSERT_TRUE(still_running) << "the run ended before the report: make it longer";
  EXPECT_EQ(rep.status, 75) << rep.out << rep.err;
  EXPECT_NE(rep.err.find("pid " + std::to_string(pid)), std::string::npos) << rep.err;
  EXPECT_NE(rep.err.find("is using this batch folder"), std::string::npos) << rep.err;
  EXPECT_EQ(rep.err.find("never ended"), std::string::npos) << rep.err;
  for (const char* f : {"summary.json", "summary.md", "index.html", "assets"})
    EXPECT_FALSE(fs::exists(dir_ / "runs" / f)) << f;

  std::this_thread::sleep_for(std::chrono::milliseconds(300));  // its child follows it
  const CommandResult after = Imr("report " + Quote((dir_ / "runs").string()));
  EXPECT_EQ(after.status, 1) << after.out << after.err;  // the killed sequence: interrupted
  EXPECT_EQ(ReadJson(dir_ / "runs" / "summary.json")["sequences"][0]["status"], "interrupted");
}

TEST_F(Batch, ProgressBarOnATerminal) {
  if (RunShell("command -v script").status != 0) GTEST_SKIP() << "no `script` to make a terminal";
  // 60 frames (~0.5 s): the bar redraws at most 10 times a second, and a 20-frame run (0.2 s) on a
  // loaded machine could end before any redraw saw a keyframe of it (2 of 25 runs failed so).
  const fs::path job = WriteJob(Job(60, {"street"}));
  auto r = RunShell("script -qec " + Quote(Quote(kImr) + " run " + Quote(job.string())) + " /dev/null");
  EXPECT_EQ(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("\r\033[K["), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("] 1/1 sequences done"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("street keyframe"), std::string::npos) << r.out;
}

TEST_F(Batch, SubmitDryRunWritesReadableScripts) {
  const fs::path job = WriteJob(Job(20));
  auto r = Imr("submit " + Quote(job.string()) +
               " --tasks 5 --partition short --time 1:00:00 --mem 2G --max-rss 1G --dry-run");
  ASSERT_EQ(r.status, 0) << r.out << r.err;
  const fs::path slurm = dir_ / "runs" / "imr-batch" / "slurm";
  const std::string array = ReadText(slurm / "array.sbatch");
  const std::string reduce = ReadText(slurm / "report.sbatch");
  EXPECT_NE(array.find("#SBATCH --array=0-2\n"), std::string::npos) << array;  // 3 sequences
  EXPECT_NE(array.find("#SBATCH --partition=short\n"), std::string::npos) << array;
  EXPECT_NE(array.find("#SBATCH --time=1:00:00\n"), std::string::npos) << array;
  EXPECT_NE(array.find("#SBATCH --mem=2G\n"), std::string::npos) << array;
  EXPECT_NE(array.find(" run " + job.string() + " --sequences-from "), std::string::npos) << array;
  EXPECT_NE(array.find("--max-rss 1073741824"), std::string::npos) << array;
  EXPECT_NE(reduce.find(" report " + (dir_ / "runs").string()), std::string::npos) << reduce;
  EXPECT_EQ(ReadText(dir_ / "runs" / "imr-batch" / "sequences.txt").find("street\nroom\nplane\n") ==
                std::string::npos,
            false);
  EXPECT_NE(r.out.find("--dependency=afterany:<array job id>"), std::string::npos) << r.out;
  EXPECT_EQ(RunShell("bash -n " + Quote((slurm / "array.sbatch").string())).status, 0);
  // Before any task ran, the report says nothing ran.
  auto rep = Imr("report " + Quote(job.string()));
  EXPECT_EQ(rep.status, 3) << rep.out << rep.err;
  EXPECT_NE(rep.out.find("3 sequences: 0 ok, 0 failed, 3 not run"), std::string::npos) << rep.out;
}

TEST_F(Batch, BadOptionsAreUsageErrors) {
  const std::string job = Quote(WriteJob(Job(20)).string());
  const std::pair<std::string, std::string> cases[] = {
      {"run --shard 3/2 " + job, "--shard: expected I/N with 1 <= I <= N"},
      {"run --shard 0/2 " + job, "shards are numbered from 1"},
      {"run --jobs 0 " + job, "--jobs must be in 1..1024"},
      {"run --max-rss lots " + job, "--max-rss: expected a size like 512M or 4G, got 'lots'"},
      {"submit --tasks 0 " + job, "--tasks must be at least 1"},
      {"report " + Quote((dir_ / "nowhere").string()), "is not a batch folder"},
  };
  for (const auto& [args, message] : cases) {
    auto r = Imr(args);
    EXPECT_EQ(r.status, 64) << args << "\n" << r.err;
    EXPECT_NE(r.err.find(message), std::string::npos) << args << "\n" << r.err;
  }
  WriteText(dir_ / "list.txt", "street\nmud\n");
  auto r = Imr("run --sequences-from " + Quote((dir_ / "list.txt").string()) + " " + job);
  EXPECT_EQ(r.status, 64);
  EXPECT_NE(r.err.find("'mud' is not a sequence of the job"), std::string::npos) << r.err;
  r = Imr("run " + job, "SLURM_ARRAY_TASK_ID=3");
  EXPECT_EQ(r.status, 64);
  EXPECT_NE(r.err.find("SLURM_ARRAY_TASK_COUNT is not set"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(dir_ / "runs"));
}

TEST_F(Batch, EveryFolderUnderADirectoryIsASequence) {
  for (const char* s : {"drive_b", "drive_a", ".hidden"}) WriteText(dir_ / "data" / s / "sfm_data.json", "{}");
  WriteText(dir_ / "data" / "notes.txt", "not a folder");
  json j = Job(20);
  j["input"] = {{"format", "openmvg"}};
  j["pipeline"] = {{{"kind", "weight_policy"}, {"plugin", "org.imr.policy.nearest"}},
                   {{"kind", "exporter"}, {"plugin", "org.imr.exporter.assimp"}}};
  for (const char* pattern : {"data/*/", "data/*/sfm_data.json"}) {
    j["sequences"] = {pattern};
    auto r = Imr("validate " + Quote(WriteJob(j).string()));
    ASSERT_EQ(r.status, 0) << pattern << "\n" << r.err;
    EXPECT_NE(r.out.find("(2 sequences"), std::string::npos) << r.out;
    EXPECT_LT(r.out.find("  drive_a -> " + (dir_ / "runs" / "drive_a").string()),
              r.out.find("  drive_b -> "))
        << r.out;
  }
  // Without {sequence}, several matches would share a folder.
  j["output"]["directory"] = "runs/all";
  auto r = Imr("validate " + Quote(WriteJob(j).string()));
  EXPECT_EQ(r.status, 64);
  EXPECT_NE(r.err.find("sequences[0] matches 2 sequences, which would share one folder"),
            std::string::npos) << r.err;
}

}  // namespace
}  // namespace imr::testing
