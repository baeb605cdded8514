#include "tools/bench/common/frame.h"

#include <gtest/gtest.h>

#include <fstream>
#include <string>
#include <vector>

#include "host/io/testing/temp_dir.h"

namespace imr::bench {
namespace {

namespace fs = std::filesystem;

// argv for Options::Parse from words.
struct Argv {
  explicit Argv(std::vector<std::string> w) : words(std::move(w)) {
    for (std::string& s : words) ptrs.push_back(s.data());
  }
  int argc() const { return static_cast<int>(ptrs.size()); }
  char** argv() { return ptrs.data(); }
  std::vector<std::string> words;
  std::vector<char*> ptrs;
};

struct Parsed {
  int frames = 7;
  uint64_t seed = 1;
  double tau = 0.2;
  bool images = true, quick = false;
  std::string work;
  std::vector<std::string> modes = {"nearest"};
  std::vector<int> cores = {1};
};

Options Declare(Parsed* p, int error_status = 2) {
  Options o("imr-bench test", "usage: imr-bench test [...]\n", error_status);
  o.Int("--frames", &p->frames).Uint64("--seed", &p->seed).Double("--tau", &p->tau);
  o.Flag("--no-images", &p->images, false).String("--work", &p->work);
  o.List("--modes", &p->modes).IntList("--cores", &p->cores, 1);
  o.Action("--quick", [p] { p->quick = true; });
  return o;
}

TEST(Options, EachKindTakesItsValue) {
  Parsed p;
  Argv a({"--frames", "300", "--seed", "18446744073709551615", "--tau", "0.5", "--no-images",
          "--work", "/tmp/w", "--modes", "exact,rays5", "--cores", "1,2", "--quick"});
  int status = -1;
  ASSERT_TRUE(Declare(&p).Parse(a.argc(), a.argv(), &status));
  EXPECT_EQ(p.frames, 300);
  EXPECT_EQ(p.seed, 18446744073709551615ull);
  EXPECT_DOUBLE_EQ(p.tau, 0.5);
  EXPECT_FALSE(p.images);
  EXPECT_EQ(p.work, "/tmp/w");
  EXPECT_EQ(p.modes, (std::vector<std::string>{"exact", "rays5"}));
  EXPECT_EQ(p.cores, (std::vector<int>{1, 2}));
  EXPECT_TRUE(p.quick);
}

TEST(Options, NothingGivenKeepsTheDefaults) {
  Parsed p;
  Argv a({});
  int status = -1;
  ASSERT_TRUE(Declare(&p).Parse(a.argc(), a.argv(), &status));
  EXPECT_EQ(p.frames, 7);
  EXPECT_TRUE(p.images);
  EXPECT_EQ(p.cores, (std::vector<int>{1}));
}

TEST(Options, BadInputStopsWithTheBenchsStatusAndNamesTheOption) {
  const std::vector<std::vector<std::string>> bad = {
      {"--bogus"}, {"--frames"}, {"--frames", "ten"}, {"--frames", "10x"},
      {"--seed", "-1"}, {"--tau", "fast"}, {"--cores", "1,0"}, {"--cores", "2,,3"}};
  for (const auto& words : bad) {
    Parsed p;
    Argv a(words);
    int status = -1;
    testing::internal::CaptureStderr();
    EXPECT_FALSE(Declare(&p, 64).Parse(a.argc(), a.argv(), &status)) << words[0];
    const std::string err = testing::internal::GetCapturedStderr();
    EXPECT_EQ(status, 64) << words[0];
    EXPECT_NE(err.find("imr-bench test: "), std::string::npos) << err;
    EXPECT_NE(err.find(words[0]), std::string::npos) << err;
    EXPECT_EQ(p.frames, 7);  // a bad value is not taken
  }
}

TEST(Options, HelpPrintsTheUsageAndStopsWithZero) {
  Parsed p;
  Argv a({"--frames", "3", "--help"});
  int status = -1;
  testing::internal::CaptureStdout();
  EXPECT_FALSE(Declare(&p).Parse(a.argc(), a.argv(), &status));
  EXPECT_EQ(testing::internal::GetCapturedStdout(), "usage: imr-bench test [...]\n");
  EXPECT_EQ(status, 0);
}

TEST(Options, ACustomValueSaysWhatWasExpected) {
  std::string taken;
  Options o("imr-bench test", "usage\n");
  o.Custom("--pair", [&](const std::string& v) {
    if (v.find('=') == std::string::npos) return std::string("KEY=VALUE");
    taken = v;
    return std::string();
  });
  Argv good({"--pair", "a=b"}), bad({"--pair", "ab"});
  int status = -1;
  EXPECT_TRUE(o.Parse(good.argc(), good.argv(), &status));
  EXPECT_EQ(taken, "a=b");
  testing::internal::CaptureStderr();
  EXPECT_FALSE(o.Parse(bad.argc(), bad.argv(), &status));
  EXPECT_EQ(testing::internal::GetCapturedStderr(),
            "imr-bench test: --pair: expected KEY=VALUE, got 'ab'\n");
  EXPECT_EQ(status, 2);
}

TEST(Markdown, HeaderHasItsRuleAndRowsTheirCells) {
  testing::internal::CaptureStdout();
  MarkdownHeader({"run", "wall s", Format("RSS at frame %d", 250)});
  MarkdownRow({"a", Format("%.1f", 2.25), ""});
  EXPECT_EQ(testing::internal::GetCapturedStdout(),
            "| run | wall s | RSS at frame 250 |\n|---|---|---|\n| a | 2.2 |  |\n");
}

TEST(Format, LongerThanAnyBuffer) {
  const std::string s = Format("%s-%d", std::string(5000, 'x').c_str(), 7);
  EXPECT_EQ(s.size(), 5002u);
  EXPECT_EQ(s.substr(4998), "xx-7");
}

TEST(WorkFolder, AMadeOneGoesAGivenOneStays) {
  io::testing::TempDir tmp("imr-bench-frame");
  const fs::path given = tmp / "given";
  {
    const WorkFolder w(given.string(), "test");
    EXPECT_TRUE(w.given());
    EXPECT_TRUE(fs::is_directory(given));
    w.Finish();
  }
  EXPECT_TRUE(fs::is_directory(given));
  const WorkFolder made("", "test");
  EXPECT_FALSE(made.given());
  EXPECT_TRUE(fs::is_directory(made.path()));
  EXPECT_NE(made.path().filename().string().find("imr-bench-test-"), std::string::npos);
  made.Finish(false);  // kept after a failure
  EXPECT_TRUE(fs::is_directory(made.path()));
  made.Finish();
  EXPECT_FALSE(fs::exists(made.path()));
}

// A stand-in for imr: writes the job it was given beside a report.json in the job's output
// folder, exits with the status the job names.
void WriteFakeImr(const fs::path& script) {
  std::ofstream(script) << "#!/bin/sh\n"
                           "# run ARGS... .../job.json ARGS...\n"
                           "for a; do case $a in */job.json) job=$a;; esac; done\n"
                           "out=$(sed -n 's/.*\"directory\": \"\\(.*\\)\".*/\\1/p' \"$job\")\n"
                           "mkdir -p \"$out\"\n"
                           "echo \"$@\" > \"$out/args.txt\"\n"
                           "grep -q '\"fail\": true' \"$job\" && exit 3\n"
                           "echo '{\"engine\": {\"seconds\": {\"total\": 1.5}}}' > \"$out/report.json\"\n";
  fs::permissions(script, fs::perms::owner_all);
}

TEST(RunImrJob, WritesTheJobRunsItAndReadsItsReport) {
  io::testing::TempDir tmp("imr-bench-frame");
  WriteFakeImr(tmp / "imr");
  const nlohmann::json job = {{"output", {{"directory", (tmp / "out").string()}}}};
  ImrJob how;
  how.job_file = tmp / "job.json";
  how.imr = (tmp / "imr").string();
  how.args = "-q --force";
  how.extra = "--export-stream s.json";
  testing::internal::CaptureStderr();  // the command echoed
  const ImrJobResult r = RunImrJob(job, how);
  testing::internal::GetCapturedStderr();
  EXPECT_TRUE(r.ok());
  EXPECT_EQ(r.status, 0);
  EXPECT_GT(r.peak_rss_mb, 0.0);
  EXPECT_EQ(r.log, tmp / "job.log");
  EXPECT_DOUBLE_EQ(r.report["engine"]["seconds"]["total"].get<double>(), 1.5);
  EXPECT_EQ(ReadFileBytes(tmp / "out/args.txt"),
            "run -q --force " + (tmp / "job.json").string() + " --export-stream s.json\n");
}

TEST(RunImrJob, AFailedRunIsNotOk) {
  io::testing::TempDir tmp("imr-bench-frame");
  WriteFakeImr(tmp / "imr");
  const nlohmann::json job = {{"output", {{"directory", (tmp / "out").string()}}}, {"fail", true}};
  ImrJob how;
  how.job_file = tmp / "job.json";
  how.imr = (tmp / "imr").string();
  testing::internal::CaptureStderr();
  const ImrJobResult r = RunImrJob(job, how);
  testing::internal::GetCapturedStderr();
  EXPECT_EQ(r.status, 3);
  EXPECT_FALSE(r.ok());
  EXPECT_TRUE(r.report.is_null());
}

}  // namespace
}  // namespace imr::bench
