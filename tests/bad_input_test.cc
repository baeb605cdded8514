// The bad-input catalogue (issue 9; tests/BAD_INPUTS.md): one test per entry. Each runs the real
// `imr run` on a job whose sequences are [the bad one, a good one] and checks the four
// guarantees the same way (ExpectOnlyTheBadSequenceFails):
//   (a) the failed sequence's error, in summary.json, summary.md and on stderr, names the file
//       and the field or line;
//   (b) imr exits non-zero;
//   (c) the good sequence finished: its mesh, report and manifest are there;
//   (d) no partial output: the bad sequence's folder holds no file, and nothing in the batch
//       folder is a staging folder or a temporary.
// A bad job file is refused as a whole before anything runs (ExpectJobRefused). The image
// entries damage copies of one small imr-synth sequence made once for the suite; the SfM/SLAM
// entries damage exports of a synthetic run made once too.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include <signal.h>
#include <sys/mount.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <functional>
#include <iostream>
#include <map>
#include <set>
#include <sstream>

#include "host/io/image_io.h"
#include "host/util/exit_status.h"
#include "host/util/write_rule.h"
#include "test_util.h"

namespace imr::testing {
namespace {
namespace fs = std::filesystem;
using nlohmann::json;

const std::string kImr = IMR_EXE;
const std::string kSynth = IMR_SYNTH_EXE;
const std::string kTestPlugins = IMR_TEST_PLUGIN_DIR;
const std::string kTestLibraries = IMR_TEST_LIBRARY_DIR;

json ReadJson(const fs::path& p) { return json::parse(ReadText(p)); }

// Files and folders under `root` whose names say they are unfinished: staging folders,
// atomic-write temporaries, partial traces.
std::vector<std::string> Leftovers(const fs::path& root) {
  std::vector<std::string> found;
  std::error_code ec;
  if (!fs::exists(root, ec)) return found;
  for (const auto& e : fs::recursive_directory_iterator(root)) {
    const std::string name = e.path().filename().string();
    if (name.rfind(".imr-staging-", 0) == 0 || (name[0] == '.' && name.find(".tmp-") != std::string::npos) ||
        (name.size() > 8 && name.substr(name.size() - 8) == ".partial"))
      found.push_back(fs::relative(e.path(), root).string());
  }
  return found;
}

std::vector<std::string> FilesUnder(const fs::path& root) {
  std::vector<std::string> found;
  std::error_code ec;
  if (!fs::exists(root, ec)) return found;
  for (const auto& e : fs::recursive_directory_iterator(root))
    if (e.is_regular_file()) found.push_back(fs::relative(e.path(), root).string());
  return found;
}

// A tmpfs mounted for one test and unmounted by the destructor (also when an assertion fails).
class TmpfsMount {
 public:
  TmpfsMount(const fs::path& dir, unsigned long flags, const std::string& options) : dir_(dir) {
    fs::create_directories(dir);
    if (::mount("tmpfs", dir.c_str(), "tmpfs", flags, options.c_str()) != 0)
      error_ = std::strerror(errno);
  }
  ~TmpfsMount() {
    if (error_.empty()) ::umount2(dir_.c_str(), MNT_DETACH);
  }
  TmpfsMount(const TmpfsMount&) = delete;
  TmpfsMount& operator=(const TmpfsMount&) = delete;
  // Empty when mounted, else why not (as a skip message).
  std::string SkipReason() const {
    return error_.empty() ? "" : "cannot mount a tmpfs at " + dir_.string() + " (" + error_ +
                                     "): the test needs root or CAP_SYS_ADMIN";
  }

 private:
  fs::path dir_;
  std::string error_;
};

// The image pipeline on KITTI odometry folders, as front_end_test runs it.
json ImageJob(const std::vector<std::string>& sequences) {
  return {{"sequences", sequences},
          {"input", {{"format", "kitti_odometry"}}},
          {"pipeline",
           {{{"kind", "features"}, {"plugin", "org.imr.features.edge_klt"}},
            {{"kind", "refiner"}, {"plugin", "org.imr.refiner.ceres"}},
            {{"kind", "weight_policy"}, {"plugin", "org.imr.policy.nearest"}},
            {{"kind", "exporter"}, {"plugin", "org.imr.exporter.assimp"}}}},
          {"engine", {{"steiner_export", "any_steiner"}}},
          {"output", {{"directory", "runs/{sequence}"}, {"formats", {"ply"}}}}};
}

// The engine alone on an SfM/SLAM export.
json EngineJob(const std::string& format, const std::vector<std::string>& sequences) {
  return {{"sequences", sequences},
          {"input", {{"format", format}}},
          {"pipeline",
           {{{"kind", "weight_policy"}, {"plugin", "org.imr.policy.nearest"}},
            {{"kind", "exporter"}, {"plugin", "org.imr.exporter.assimp"}}}},
          {"output", {{"directory", "runs/{sequence}"}, {"formats", {"ply"}}}}};
}

// Synthetic observation streams: the bad sequence is "street", the good one "room".
json SyntheticJob() {
  json j = EngineJob("synthetic", {"street", "room"});
  j["input"]["options"] = {{"frames", 20}, {"seed", 3}};
  j["plugin_paths"] = {kTestPlugins};
  return j;
}

// An OpenMVG sfm_data (cereal layout) with the views, poses and points of an exported stream:
// each point at its last estimate, observed by the views that saw it.
json OpenMvgFromStream(const json& stream) {
  json views = json::array(), extrinsics = json::array(), structure = json::array();
  std::map<uint64_t, json> position;
  std::map<uint64_t, std::vector<uint64_t>> seen_by;
  uint64_t pointer = 0x80000001ull;
  for (const json& v : stream["views"]) {
    const uint64_t id = v["viewId"];
    views.push_back({{"key", id},
                     {"value", {{"ptr_wrapper", {{"id", pointer++},
                                                 {"data", {{"local_path", ""},
                                                           {"filename", v["filename"]},
                                                           {"width", v["width"]},
                                                           {"height", v["height"]},
                                                           {"id_view", id},
                                                           {"id_intrinsic", 0},
                                                           {"id_pose", id}}}}}}}});
    extrinsics.push_back({{"key", id},
                          {"value", {{"rotation", v["extrinsic"]["rotation"]},
                                     {"center", v["extrinsic"]["center"]}}}});
    for (const json& o : v["observations"]) {
      position[o["pointId"]] = o["X"];
      seen_by[o["pointId"]].push_back(id);
    }
  }
  for (const auto& [id, x] : position) {
    json obs = json::array();
    for (uint64_t view : seen_by[id])
      obs.push_back({{"key", view}, {"value", {{"id_feat", 0}, {"x", {0.0, 0.0}}}}});
    structure.push_back({{"key", id}, {"value", {{"X", x}, {"observations", obs}}}});
  }
  return {{"sfm_data_version", "0.3"},
          {"root_path", ""},
          {"views", views},
          {"intrinsics", {{{"key", 0}, {"value", stream["intrinsics"][0]["value"]}}}},
          {"extrinsics", extrinsics},
          {"structure", structure},
          {"control_points", json::array()}};
}

// The helpers every entry uses; each test works in its own scratch folder (Case()).
class Catalogue : public ::testing::Test {
 protected:
  Catalogue() : scratch_("bad-input") {}
  const fs::path& Case() const { return scratch_.path(); }

  // `imr run` on `job` from this test's folder, with a relative job path as people type it. A
  // previous run's folder is cleared first, unless it holds a test's mount point (`keep_runs`).
  CommandResult Run(const json& job, const std::string& flags = "", bool keep_runs = false) const {
    if (!keep_runs) fs::remove_all(Case() / "runs");
    WriteText(Case() / "job.json", job.dump(2));
    return InCase("run --jobs 2 job.json " + flags);
  }

  // imr with `args` in this test's folder, under a time limit: a hang on bad input fails the
  // test (status 124) instead of stalling the suite.
  // `env`: assignments put before the command ("NAME=value ").
  CommandResult InCase(const std::string& args, const std::string& env = "") const {
    return RunShell("cd " + Quote(Case().string()) + " && " + env + "timeout -k 5 300 " +
                    Quote(kImr) + " " + args);
  }

  // The four guarantees for a job whose sequence `bad` is bad and `good` is fine; `error_has`:
  // what the failure must name (the file, the field or line, what was expected).
  void ExpectOnlyTheBadSequenceFails(const json& job, const std::string& bad,
                                     const std::string& good,
                                     const std::vector<std::string>& error_has,
                                     const std::string& flags = "", bool keep_runs = false) const {
    CheckOnlyTheBadSequenceFailed(Run(job, flags, keep_runs), Case() / "runs", job, bad, good,
                                  error_has);
  }

  // The same checks on a run already made, whose batch folder is `batch`. `bad_folder_empty`:
  // false when the bad sequence's folder held files before the run (the test checks them).
  void CheckOnlyTheBadSequenceFailed(const CommandResult& r, const fs::path& batch,
                                     const json& job, const std::string& bad,
                                     const std::string& good,
                                     const std::vector<std::string>& error_has,
                                     bool bad_folder_empty = true) const {
    // (b) a non-zero status (not a particular one: `imr run` counts failures).
    EXPECT_NE(r.status, 0) << r.out << r.err;
    ASSERT_TRUE(fs::exists(batch / "summary.json")) << r.out << r.err;
    const json summary = ReadJson(batch / "summary.json");
    const json bad_entry = SummaryRow(summary, bad), good_entry = SummaryRow(summary, good);
    ASSERT_TRUE(bad_entry.is_object()) << bad << " not in " << summary.dump(2);
    ASSERT_TRUE(good_entry.is_object()) << good << " not in " << summary.dump(2);
    // (a) the error names the file and the field, in the summary and on stderr.
    EXPECT_EQ(bad_entry["status"], "failed") << bad_entry.dump(2);
    const std::string error = bad_entry.value("error", "");
    const std::string md = ReadText(batch / "summary.md");
    for (const std::string& e : error_has) {
      EXPECT_NE(error.find(e), std::string::npos) << "summary.json's error lacks '" << e << "': " << error;
      EXPECT_NE(md.find(e), std::string::npos) << "summary.md lacks '" << e << "':\n" << md;
      EXPECT_NE(r.err.find(e), std::string::npos) << "stderr lacks '" << e << "':\n" << r.err;
    }
    std::cout << "[ message  ] " << error << "\n";  // what BAD_INPUTS.md quotes
    // (c) the good sequence finished.
    EXPECT_EQ(good_entry["status"], "ok") << good_entry.dump(2) << "\n" << r.err;
    ExpectOutputs(OutputOf(batch, good_entry), job);
    // (d) nothing of the bad sequence that could pass for output, no leftovers anywhere.
    if (bad_folder_empty) {
      EXPECT_EQ(FilesUnder(OutputOf(batch, bad_entry)), std::vector<std::string>{}) << "in " << bad;
    }
    EXPECT_EQ(Leftovers(batch), std::vector<std::string>{});
  }

  // Bad input imr now handles: every sequence of `names` finishes ok, with its outputs.
  void CheckEverySequenceOk(const CommandResult& r, const fs::path& batch, const json& job,
                            const std::vector<std::string>& names) const {
    EXPECT_EQ(r.status, 0) << r.out << r.err;
    ASSERT_TRUE(fs::exists(batch / "summary.json")) << r.out << r.err;
    const json summary = ReadJson(batch / "summary.json");
    for (const std::string& name : names) {
      const json row = SummaryRow(summary, name);
      ASSERT_TRUE(row.is_object()) << name << " not in " << summary.dump(2);
      EXPECT_EQ(row["status"], "ok") << row.dump(2) << "\n" << r.err;
      ExpectOutputs(OutputOf(batch, row), job);
    }
    EXPECT_EQ(Leftovers(batch), std::vector<std::string>{});
  }

  static json SummaryRow(const json& summary, const std::string& name) {
    for (const json& s : summary["sequences"])
      if (s["name"] == name) return s;
    return json();
  }
  // A summary row's output folder (relative to the batch folder, or absolute).
  static fs::path OutputOf(const fs::path& batch, const json& row) {
    return batch / row.value("output", std::string());
  }
  static void ExpectOutputs(const fs::path& out, const json& job) {
    for (const json& f : job["output"]["formats"]) {
      const fs::path mesh = out / ("mesh." + f.get<std::string>());
      EXPECT_GT(fs::exists(mesh) ? fs::file_size(mesh) : 0u, 0u) << mesh << " missing or empty";
    }
    EXPECT_TRUE(fs::exists(out / "report.json")) << out;
    EXPECT_TRUE(fs::exists(out / "manifest.json")) << out;
  }

  // A job refused as a whole: non-zero status, stderr names the job file and each of
  // `error_has` (the JSON path and what was expected), nothing ran, nothing was written.
  void ExpectJobRefused(const std::string& job_text, const std::vector<std::string>& error_has,
                        const std::string& flags = "") const {
    fs::remove_all(Case() / "runs");
    WriteText(Case() / "job.json", job_text);
    const CommandResult r = InCase("run job.json " + flags);
    EXPECT_NE(r.status, 0) << r.out << r.err;
    if (flags.empty()) {  // named as typed: imr ran in Case() on "job.json"
      EXPECT_EQ(r.err.rfind("job.json: ", 0), 0u) << r.err;
    }
    for (const std::string& e : error_has)
      EXPECT_NE(r.err.find(e), std::string::npos) << "stderr lacks '" << e << "':\n" << r.err;
    EXPECT_FALSE(fs::exists(Case() / "runs")) << "a refused job wrote " << Case() / "runs";
    std::cout << "[ message  ] " << r.err.substr(0, 400) << "\n";
  }

 private:
  ScratchDir scratch_;
};

// Image sequences: one small imr-synth sequence (12 frames, a third of KITTI's size, coarse
// Velodyne scans) made once for the suite; each test damages a copy.
class BadImages : public Catalogue {
 protected:
  static void SetUpTestSuite() {
    dir_ = new ScratchDir("bad-images");
    const CommandResult r = RunShell(Quote(kSynth) + " --out " + Quote(Sequence().string()) +
                                     " --frames 12 --width 414 --height 125 --lidar-step 2 -q");
    ASSERT_EQ(r.status, 0) << r.out << r.err;
  }
  static void TearDownTestSuite() {
    delete dir_;
    dir_ = nullptr;
  }
  void SetUp() override { ASSERT_TRUE(fs::exists(Sequence() / "poses.txt")) << "no sequence"; }
  static fs::path Sequence() { return *dir_ / "street"; }
  fs::path CopySequence() const {
    fs::copy(Sequence(), Case() / "bad", fs::copy_options::recursive);
    return Case() / "bad";
  }
  static ScratchDir* dir_;
};
ScratchDir* BadImages::dir_ = nullptr;

// SfM/SLAM exports: a synthetic street's engine input as SLAM JSON and a COLMAP model (imr's
// own exports), and as OpenMVG (converted here), made once for the suite.
class BadSfm : public Catalogue {
 protected:
  static void SetUpTestSuite() {
    dir_ = new ScratchDir("bad-sfm");
    json job = SyntheticJob();
    job["sequences"] = {"street"};
    job["output"]["directory"] = "fixture-run";
    WriteText(*dir_ / "fixture.json", job.dump(2));
    const CommandResult r = RunShell(Quote(kImr) + " run -q " + Quote((*dir_ / "fixture.json").string()) +
                                     " --export-stream " + Quote(Fixture("slam/good.json").string()) +
                                     " --export-colmap " + Quote(Fixture("colmap").string()));
    ASSERT_EQ(r.status, 0) << r.out << r.err;
    WriteText(Fixture("openmvg/good.json"),
              OpenMvgFromStream(ReadJson(Fixture("slam/good.json"))).dump());
  }
  static void TearDownTestSuite() {
    delete dir_;
    dir_ = nullptr;
  }
  void SetUp() override { ASSERT_TRUE(fs::exists(Fixture("openmvg/good.json"))) << "no fixtures"; }
  static fs::path Fixture(const std::string& name) { return *dir_ / "fixtures" / name; }
  // A copy of the COLMAP model at `to`: a sequence folder of the "colmap" format.
  static fs::path CopyModel(const fs::path& to) {
    fs::create_directories(to.parent_path());
    fs::copy(Fixture("colmap"), to, fs::copy_options::recursive);
    return to;
  }
  static ScratchDir* dir_;
};
ScratchDir* BadSfm::dir_ = nullptr;

// Applies `edit` to the words of the first data line (not a '#' comment) of a COLMAP text file.
void EditFirstDataLine(const fs::path& file, const std::function<void(std::vector<std::string>&)>& edit) {
  std::istringstream in(ReadText(file));
  std::string text;
  bool done = false;
  for (std::string line; std::getline(in, line);) {
    if (!done && !line.empty() && line[0] != '#') {
      std::istringstream words(line);
      std::vector<std::string> w;
      for (std::string x; words >> x;) w.push_back(x);
      edit(w);
      line.clear();
      for (const auto& x : w) line += (line.empty() ? "" : " ") + x;
      done = true;
    }
    text += line + "\n";
  }
  WriteText(file, text);
}

class BadJob : public Catalogue {};
class BadPlugin : public Catalogue {};
class BadOutput : public Catalogue {};

// ---- Images (kitti_odometry through features -> refiner -> engine -> exporter) ----

TEST_F(BadImages, TruncatedPng) {
  const fs::path png = CopySequence() / "image_0/000005.png";
  const std::string bytes = ReadText(png);
  WriteText(png, bytes.substr(0, bytes.size() / 3));
  ExpectOnlyTheBadSequenceFails(ImageJob({"bad", Sequence().string()}), "bad", "street",
                                {(Case() / "bad/image_0/000005.png").string(), "cannot decode",
                                 "truncated"});
}

TEST_F(BadImages, CorruptPng) {
  // Same size, garbage in the middle of the pixel data: the chunk's CRC no longer matches.
  const fs::path png = CopySequence() / "image_0/000005.png";
  std::string bytes = ReadText(png);
  for (std::size_t i = bytes.size() / 2; i < bytes.size() / 2 + 64; ++i) bytes[i] = static_cast<char>(~bytes[i]);
  WriteText(png, bytes);
  ExpectOnlyTheBadSequenceFails(ImageJob({"bad", Sequence().string()}), "bad", "street",
                                {(Case() / "bad/image_0/000005.png").string(), "cannot decode"});
}

TEST_F(BadImages, MissingFrameInTheMiddle) {
  fs::remove(CopySequence() / "image_0/000006.png");
  ExpectOnlyTheBadSequenceFails(ImageJob({"bad", Sequence().string()}), "bad", "street",
                                {(Case() / "bad/image_0/000006.png").string(), "no such file",
                                 "pose line 7", "poses.txt"});
}

TEST_F(BadImages, EmptySequence) {
  const fs::path seq = CopySequence();
  for (const auto& e : fs::directory_iterator(seq / "image_0")) fs::remove(e.path());
  ExpectOnlyTheBadSequenceFails(ImageJob({"bad", Sequence().string()}), "bad", "street",
                                {(Case() / "bad/image_0").string(), "no .png images"});
}

TEST_F(BadImages, OneFrameSequence) {
  const fs::path seq = CopySequence();
  for (const auto& e : fs::directory_iterator(seq / "image_0"))
    if (e.path().filename() != "000000.png") fs::remove(e.path());
  for (const char* f : {"poses.txt", "times.txt"}) {
    const std::string text = ReadText(seq / f);
    WriteText(seq / f, text.substr(0, text.find('\n') + 1));
  }
  ExpectOnlyTheBadSequenceFails(ImageJob({"bad", Sequence().string()}), "bad", "street",
                                {(Case() / "bad/image_0/000000.png").string(), "one frame",
                                 "at least 2 frames"});
}

TEST_F(BadImages, ImagesOfDifferentSizes) {
  const fs::path png = CopySequence() / "image_0/000004.png";
  const io::Image full = io::ReadImage(png.string());
  io::Image cut;  // the top-left (width - 14) x (height - 5)
  cut.width = full.width - 14;
  cut.height = full.height - 5;
  cut.channels = full.channels;
  cut.stride_bytes = static_cast<int64_t>(cut.width) * cut.channels;
  for (int y = 0; y < cut.height; ++y) {
    const auto row = full.pixels.begin() + static_cast<std::ptrdiff_t>(y * full.stride_bytes);
    cut.pixels.insert(cut.pixels.end(), row, row + cut.stride_bytes);
  }
  io::WriteImage(png.string(), cut);
  ExpectOnlyTheBadSequenceFails(
      ImageJob({"bad", Sequence().string()}), "bad", "street",
      {png.string(), "image is " + std::to_string(cut.width) + "x" + std::to_string(cut.height),
       "the sequence's first is " + std::to_string(full.width) + "x" + std::to_string(full.height)});
}

TEST_F(BadImages, PoseWithNaN) {
  ReplaceLine(CopySequence() / "poses.txt", 4, "1 0 0 0 0 1 0 0 0 0 1 nan");
  ExpectOnlyTheBadSequenceFails(ImageJob({"bad", Sequence().string()}), "bad", "street",
                                {(Case() / "bad/poses.txt:5").string(), "number 12",
                                 "'nan' is not a finite number"});
}

TEST_F(BadImages, PoseWithInf) {
  ReplaceLine(CopySequence() / "poses.txt", 4, "1 0 0 inf 0 1 0 0 0 0 1 0");
  ExpectOnlyTheBadSequenceFails(ImageJob({"bad", Sequence().string()}), "bad", "street",
                                {(Case() / "bad/poses.txt:5").string(), "number 4",
                                 "'inf' is not a finite number"});
}

TEST_F(BadImages, PoseWithWrongColumnCount) {
  ReplaceLine(CopySequence() / "poses.txt", 4, "1 0 0 0 0 1 0 0 0 0 1");
  ExpectOnlyTheBadSequenceFails(ImageJob({"bad", Sequence().string()}), "bad", "street",
                                {(Case() / "bad/poses.txt:5").string(), "11 numbers, expected 12"});
}

TEST_F(BadImages, PoseWithNonOrthonormalRotation) {
  ReplaceLine(CopySequence() / "poses.txt", 4, "1 0.3 0 0 0 1 0 0 0 0 1 5");
  ExpectOnlyTheBadSequenceFails(ImageJob({"bad", Sequence().string()}), "bad", "street",
                                {(Case() / "bad/poses.txt:5").string(), "rotation",
                                 "not orthonormal"});
}

TEST_F(BadImages, FewerPoseLinesThanImages) {
  const fs::path poses = CopySequence() / "poses.txt";
  std::string text = ReadText(poses);
  for (int i = 0; i < 3; ++i) text = text.substr(0, text.rfind('\n', text.size() - 2) + 1);
  WriteText(poses, text);
  ExpectOnlyTheBadSequenceFails(ImageJob({"bad", Sequence().string()}), "bad", "street",
                                {poses.string(), "9 poses (lines)", "12 images",
                                 "expected one pose per image"});
}

TEST_F(BadImages, CalibrationMissingAMatrix) {
  const fs::path calib = CopySequence() / "calib.txt";
  std::string kept;
  std::istringstream in(ReadText(calib));
  for (std::string line; std::getline(in, line);)
    if (line.rfind("P0:", 0) != 0) kept += line + "\n";
  WriteText(calib, kept);
  ExpectOnlyTheBadSequenceFails(ImageJob({"bad", Sequence().string()}), "bad", "street",
                                {calib.string(), "no line 'P0:'", "projection of camera 0"});
}

TEST_F(BadImages, CalibrationWithASingularK) {
  // fx = 0: K is singular, nothing projects.
  const fs::path calib = CopySequence() / "calib.txt";
  std::string text = ReadText(calib);
  const auto first = text.find(' ', text.find("P0:")) + 1;
  text.replace(first, text.find(' ', first) - first, "0");
  WriteText(calib, text);
  ExpectOnlyTheBadSequenceFails(ImageJob({"bad", Sequence().string()}), "bad", "street",
                                {calib.string() + ":1", "P0 is not a rectified projection",
                                 "fx, fy > 0"});
}

TEST_F(BadImages, VelodyneBinNotAMultipleOf16Bytes) {
  const fs::path bin = CopySequence() / "velodyne/000003.bin";
  WriteText(bin, ReadText(bin).substr(0, 1000));
  json job = ImageJob({"bad", Sequence().string()});
  job["evaluation"] = {{"truth", "velodyne"}, {"scan_step", 1}};
  ExpectOnlyTheBadSequenceFails(job, "bad", "street",
                                {bin.string(), "1000 bytes, not a multiple of 16"});
}

// ---- SfM/SLAM exports (the engine alone) ----

TEST_F(BadSfm, SlamJsonDanglingIntrinsicId) {
  json j = ReadJson(Fixture("slam/good.json"));
  j["views"][3]["id_intrinsic"] = 7;
  WriteText(Case() / "bad.json", j.dump());
  ExpectOnlyTheBadSequenceFails(EngineJob("slam_json", {"bad.json", Fixture("slam/good.json")}),
                                "bad.json", "good.json",
                                {(Case() / "bad.json").string(), "views[3].id_intrinsic",
                                 "uses intrinsic 7, which intrinsics does not list"});
}

TEST_F(BadSfm, SlamJsonDanglingRemovedPoint) {
  json j = ReadJson(Fixture("slam/good.json"));
  j["imr_stream"]["keyframes"][1]["removed_points"].push_back(987654);
  WriteText(Case() / "bad.json", j.dump());
  ExpectOnlyTheBadSequenceFails(EngineJob("slam_json", {"bad.json", Fixture("slam/good.json")}),
                                "bad.json", "good.json",
                                {(Case() / "bad.json").string(),
                                 "imr_stream.keyframes[1].removed_points", "987654"});
}

TEST_F(BadSfm, OpenMvgDanglingViewId) {
  json j = ReadJson(Fixture("openmvg/good.json"));
  j["structure"][0]["value"]["observations"][0]["key"] = 99999;
  WriteText(Case() / "bad.json", j.dump());
  ExpectOnlyTheBadSequenceFails(EngineJob("openmvg", {"bad.json", Fixture("openmvg/good.json")}),
                                "bad.json", "good.json",
                                {(Case() / "bad.json").string(),
                                 "structure[0].value.observations[0].key", "view 99999"});
}

TEST_F(BadSfm, ColmapDanglingImageId) {
  const fs::path model = CopyModel(Case() / "bad");
  // The first point's first track entry: POINT3D_ID X Y Z R G B ERROR IMAGE_ID POINT2D_IDX ...
  EditFirstDataLine(model / "points3D.txt", [](std::vector<std::string>& w) { w.at(8) = "99999"; });
  ExpectOnlyTheBadSequenceFails(EngineJob("colmap", {"bad", Fixture("colmap")}), "bad", "colmap",
                                {(model / "points3D.txt").string(), "image 99999"});
}

TEST_F(BadSfm, SfmJsonWrongTypes) {
  json j = ReadJson(Fixture("slam/good.json"));
  j["views"][3]["extrinsic"]["center"] = "abc";
  WriteText(Case() / "bad.json", j.dump());
  ExpectOnlyTheBadSequenceFails(EngineJob("slam_json", {"bad.json", Fixture("slam/good.json")}),
                                "bad.json", "good.json",
                                {(Case() / "bad.json").string(), "views[3].extrinsic.center",
                                 "expected 3 numbers, got \"abc\""});
  j = ReadJson(Fixture("openmvg/good.json"));
  j["intrinsics"][0]["value"]["ptr_wrapper"]["data"]["focal_length"] = "800";
  WriteText(Case() / "bad.json", j.dump());
  ExpectOnlyTheBadSequenceFails(EngineJob("openmvg", {"bad.json", Fixture("openmvg/good.json")}),
                                "bad.json", "good.json",
                                {(Case() / "bad.json").string(),
                                 "intrinsics[0].value.ptr_wrapper.data.focal_length",
                                 "expected a number, got \"800\""});
}

// Not an error: SfM/SLAM formats carry fields imr does not use (imr's own stream export adds
// some that other readers skip), so unknown keys are read past. Both sequences succeed.
TEST_F(BadSfm, SfmJsonUnknownKeysAreIgnored) {
  json j = ReadJson(Fixture("slam/good.json"));
  j["views"][3]["extrinsic"]["colour"] = "red";
  j["made_by"] = {{"tool", "another SLAM"}};
  WriteText(Case() / "bad.json", j.dump());
  const CommandResult r = Run(EngineJob("slam_json", {"bad.json", Fixture("slam/good.json")}));
  EXPECT_EQ(r.status, 0) << r.out << r.err;
  EXPECT_TRUE(fs::exists(Case() / "runs/bad.json/mesh.ply"));
  j = ReadJson(Fixture("openmvg/good.json"));
  j["views"][0]["value"]["ptr_wrapper"]["data"]["exposure"] = 0.01;
  WriteText(Case() / "bad.json", j.dump());
  const CommandResult m = Run(EngineJob("openmvg", {"bad.json", Fixture("openmvg/good.json")}));
  EXPECT_EQ(m.status, 0) << m.out << m.err;
  EXPECT_TRUE(fs::exists(Case() / "runs/bad.json/mesh.ply"));
}

TEST_F(BadSfm, SfmJsonNumberBeyondADouble) {
  // 1e400 is valid JSON syntax but no double: the reader says which number and where.
  std::string text = ReadText(Fixture("slam/good.json"));
  const auto at = text.find("\"center\": [0, 0, 1.65]");
  ASSERT_NE(at, std::string::npos);
  text.replace(at, 22, "\"center\": [0, 0, 1e400]");
  WriteText(Case() / "bad.json", text);
  ExpectOnlyTheBadSequenceFails(EngineJob("slam_json", {"bad.json", Fixture("slam/good.json")}),
                                "bad.json", "good.json",
                                {(Case() / "bad.json").string(), "number 1e400 at byte",
                                 "out of range"});
  text = ReadJson(Fixture("openmvg/good.json")).dump();
  const auto x = text.find("\"X\":[");
  ASSERT_NE(x, std::string::npos);
  text.replace(x + 5, text.find(']', x) - x - 5, "-1e400,0,0");
  WriteText(Case() / "bad.json", text);
  ExpectOnlyTheBadSequenceFails(EngineJob("openmvg", {"bad.json", Fixture("openmvg/good.json")}),
                                "bad.json", "good.json",
                                {(Case() / "bad.json").string(), "number -1e400 at byte",
                                 "out of range"});
}

TEST_F(BadSfm, SfmJsonHugeCoordinate) {
  // 1e308 is a double, but a point there is a broken export: squared distances overflow.
  json j = ReadJson(Fixture("slam/good.json"));
  j["views"][3]["observations"][0]["X"] = {1e308, 0.0, 0.0};
  WriteText(Case() / "bad.json", j.dump());
  ExpectOnlyTheBadSequenceFails(EngineJob("slam_json", {"bad.json", Fixture("slam/good.json")}),
                                "bad.json", "good.json",
                                {(Case() / "bad.json").string(), "views[3].observations[0].X[0]",
                                 "within +-1e12"});
  j = ReadJson(Fixture("openmvg/good.json"));
  j["extrinsics"][2]["value"]["center"][1] = -1e308;
  WriteText(Case() / "bad.json", j.dump());
  ExpectOnlyTheBadSequenceFails(EngineJob("openmvg", {"bad.json", Fixture("openmvg/good.json")}),
                                "bad.json", "good.json",
                                {(Case() / "bad.json").string(),
                                 "extrinsics[2].value.center[1]", "within +-1e12"});
}

TEST_F(BadSfm, SfmJsonIntegerBeyondInt64) {
  std::string text = ReadText(Fixture("slam/good.json"));
  const auto at = text.find("\"viewId\": 3,");
  ASSERT_NE(at, std::string::npos);
  text.replace(at, 12, "\"viewId\": 123456789012345678901234567890,");
  WriteText(Case() / "bad.json", text);
  ExpectOnlyTheBadSequenceFails(EngineJob("slam_json", {"bad.json", Fixture("slam/good.json")}),
                                "bad.json", "good.json",
                                {(Case() / "bad.json").string(), "views[3].viewId",
                                 "expected an id (integer >= 0)"});
  // 2^64 - 1 parses (unsigned) but is no int64: it used to wrap to -1.
  text = ReadJson(Fixture("openmvg/good.json")).dump();
  const auto w = text.find("\"width\":", text.find("\"intrinsics\""));
  ASSERT_NE(w, std::string::npos);
  text.replace(w, text.find_first_of(",}", w) - w, "\"width\":18446744073709551615");
  WriteText(Case() / "bad.json", text);
  ExpectOnlyTheBadSequenceFails(EngineJob("openmvg", {"bad.json", Fixture("openmvg/good.json")}),
                                "bad.json", "good.json",
                                {(Case() / "bad.json").string(),
                                 "intrinsics[0].value.ptr_wrapper.data.width", "fits in 64 bits"});
}

TEST_F(BadSfm, SfmJsonDeepNesting) {
  // 100000 nested arrays: reading must not recurse that deep (printing the value for the
  // message once did, and overflowed the stack).
  const std::string deep = std::string(100000, '[') + std::string(100000, ']');
  std::string text = ReadText(Fixture("slam/good.json"));
  text.insert(text.find("\"views\": [") + 10, deep + ", ");
  WriteText(Case() / "bad.json", text);
  ExpectOnlyTheBadSequenceFails(EngineJob("slam_json", {"bad.json", Fixture("slam/good.json")}),
                                "bad.json", "good.json",
                                {(Case() / "bad.json").string(), "views[0]",
                                 "nested deeper than 100 levels"});
  text = ReadJson(Fixture("openmvg/good.json")).dump();
  text.insert(text.find("\"structure\":[") + 13, deep + ",");
  WriteText(Case() / "bad.json", text);
  ExpectOnlyTheBadSequenceFails(EngineJob("openmvg", {"bad.json", Fixture("openmvg/good.json")}),
                                "bad.json", "good.json",
                                {(Case() / "bad.json").string(), "structure[0]",
                                 "nested deeper than 100 levels"});
}

// ---- The job file: refused as a whole, nothing runs ----

json GoodJob() { return EngineJob("synthetic", {"street"}); }

TEST_F(BadJob, JobWithWrongTypes) {
  json j = GoodJob();
  j["output"]["formats"] = "ply";
  j["pipeline"][0]["params"] = {{"k", 1}};  // nearest takes none
  j["input"]["options"] = {{"frames", "twenty"}};
  ExpectJobRefused(j.dump(2), {"output.formats: expected array of strings, got string \"ply\"",
                               "input.options.frames: expected integer in [1, 200000], got "
                               "\"twenty\"",
                               "pipeline[0].params.k: unknown key"});
}

TEST_F(BadJob, JobWithUnknownKeys) {
  json j = GoodJob();
  j["sequence"] = {"street"};  // a typo for "sequences"
  j["pipeline"][1]["parms"] = json::object();
  j["engine"] = {{"windw", 10}};
  ExpectJobRefused(j.dump(2), {"sequence: unknown key", "pipeline[1].parms: unknown key",
                               "engine.windw: unknown key"});
}

TEST_F(BadJob, JobWithANumberBeyondADouble) {
  const std::string text = "{\n  \"sequences\": [\"street\"],\n  \"engine\": {\"steiner_spacing\": 1e400},\n"
                           "  \"input\": {\"format\": \"synthetic\"}\n}\n";
  ExpectJobRefused(text, {"job.json: malformed JSON at line 3, column 33", "number overflow parsing '1e400'"});
}

TEST_F(BadJob, JobWithHugeNumbersWhereTheyMatter) {
  json j = GoodJob();
  j["engine"]["free_threshold"] = 1e308;       // no integer weight unit holds it
  j["pipeline"][0]["timeout_seconds"] = 1e308;  // a deadline past the end of time
  ExpectJobRefused(j.dump(2), {"free_threshold", "too large",
                               "pipeline[0].timeout_seconds: expected a number of seconds > 0 and "
                               "at most 31536000"});
}

TEST_F(BadJob, JobWithIntegersBeyondTheirRange) {
  json j = GoodJob();
  j["engine"]["window"] = int64_t{1} << 40;          // used to wrap to 0
  j["output"]["snapshot_every"] = int64_t{1} << 40;  // used to wrap to 0: no snapshots
  j["input"]["options"] = {{"frames", (int64_t{1} << 32) + 20}};  // used to wrap to 20
  ExpectJobRefused(j.dump(2), {"engine.window: expected integer >= 1 (a 32-bit integer",
                               "output.snapshot_every: expected an integer in [0, 2147483647]",
                               "input.options.frames: expected integer in [1, 200000] (a 32-bit "
                               "integer"});
  std::string text = GoodJob().dump(2);
  text.insert(text.find("\"input\""), "\"engine\": {\"window\": 123456789012345678901234567890},\n  ");
  ExpectJobRefused(text, {"engine.window: expected integer >= 1 (a 32-bit integer, at most "
                          "2147483647), got 1.2345678901234568e+29"});
  // The same hint for a whole number written as a float (issue 36: 1e308 lacked it).
  j = GoodJob();
  j["engine"]["window"] = 1e308;
  ExpectJobRefused(j.dump(2), {"engine.window: expected integer >= 1 (a 32-bit integer, at most "
                               "2147483647), got 1e+308"});
}

// Synthetic input options that would build a scene or a loop without bound: each alone is
// bounded by the schema (a 10,000 km street used to be built whole, then the machine ran out of
// memory); what only their combination breaks is refused when the job is validated, by name.
TEST_F(BadJob, SyntheticOptionsThatWouldNotFit) {
  json j = GoodJob();
  j["input"]["options"] = {{"frames", 10000000}};
  ExpectJobRefused(j.dump(2), {"input.options.frames: expected integer in [1, 200000], got "
                               "10000000"});
  j["input"]["options"] = {{"frames", 150000}, {"speed", 2.0}};
  ExpectJobRefused(j.dump(2), {"input.options: frames x speed: 300000 m, expected at most 200000"});
  j["input"]["options"] = {{"frames", 20}, {"track_frames", 1}};
  ExpectJobRefused(j.dump(2), {"input.options: track_frames: expected 0 or >= min_observations "
                               "(2), got 1 (no track would ever be reported)"});
  j["input"]["options"] = {{"frames", 20}, {"track_frames", 17}, {"track_density", 100.0},
                           {"max_range", 200.0}};
  ExpectJobRefused(j.dump(2), {"input.options: track_density x max_range^2: 4e+06, expected at "
                               "most 250000"});
}

TEST_F(BadJob, JobWithDeepNesting) {
  std::string text = GoodJob().dump(2);
  text.insert(text.find("\"input\""),
              "\"engine\": {\"w1\":\n" + std::string(100000, '[') + std::string(100000, ']') + "},\n  ");
  ExpectJobRefused(text, {"job.json: line 3, column 99", "nested deeper than 100 levels"});
}

TEST_F(BadJob, JobWithBadTimeouts) {
  for (const json& t : {json(-1), json(0), json("2"), json(nullptr)}) {
    json j = GoodJob();
    j["pipeline"][1]["timeout_seconds"] = t;
    ExpectJobRefused(j.dump(2), {"pipeline[1].timeout_seconds: expected a number of seconds > 0"});
  }
  for (const char* seconds : {"-1", "nan", "1e9"})
    ExpectJobRefused(GoodJob().dump(2), {"--stage-timeout: expected a number of seconds"},
                     std::string("--stage-timeout=") + seconds);
}

// ---- Plugins that misbehave (tests/plugins/*), in the bad sequence only ----

json WithFailingPolicy(const json& params) {
  json j = SyntheticJob();
  json p = params;
  p["only_in"] = "street";
  j["pipeline"][0] = {{"kind", "weight_policy"}, {"plugin", "org.imr.test.policy.failing"},
                      {"params", p}};
  j["engine"]["visibility_mode"] = "weights";  // the mode that calls a policy
  return j;
}

TEST_F(BadPlugin, PluginThatFailsToCreate) {
  ExpectOnlyTheBadSequenceFails(WithFailingPolicy({{"fail_create", true}}), "street", "room",
                                {"pipeline[0] (weight_policy): org.imr.test.policy.failing: "
                                 "create failed: params.fail_create: asked to fail"});
}

TEST_F(BadPlugin, PluginThatThrows) {
  // An exception in plugin code becomes an error status at the ABI (the SDK's wrapper).
  ExpectOnlyTheBadSequenceFails(WithFailingPolicy({{"fail_after", 0}}), "street", "room",
                                {"keyframe 1", "weight policy org.imr.test.policy.failing",
                                 "failing policy: transfer failed on purpose"});
}

TEST_F(BadPlugin, PluginThatReturnsNaNWeights) {
  ExpectOnlyTheBadSequenceFails(WithFailingPolicy({{"nan", true}}), "street", "room",
                                {"keyframe 1", "weight policy org.imr.test.policy.failing",
                                 "non-finite weight"});
}

TEST_F(BadPlugin, PluginThatHangs) {
  json j = WithFailingPolicy({{"hang", true}});
  j["pipeline"][0]["timeout_seconds"] = 1;
  const auto start = std::chrono::steady_clock::now();
  ExpectOnlyTheBadSequenceFails(j, "street", "room",
                                {"stage \"weight_policy\" (pipeline[0], plugin "
                                 "org.imr.test.policy.failing) did not return within 1 s",
                                 "(keyframe 1, frame ", "the limit is pipeline[0].timeout_seconds"});
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(20));
  // The batch records how the process ended: timeout(1)'s status.
  const json summary = ReadJson(Case() / "runs/summary.json");
  EXPECT_EQ(summary["sequences"][0]["exit_code"], 124) << summary.dump(2);
}

TEST_F(BadPlugin, ExporterThatHangsMidWrite) {
  // It writes half a file into the staging folder and never returns: the watchdog must take
  // the staging folder away with the process.
  json j = SyntheticJob();
  j["pipeline"].push_back({{"kind", "exporter"},
                           {"plugin", "org.imr.test.exporter.crashing"},
                           {"params", {{"hang_in", "runs/street"}}}});
  j["output"]["formats"] = {"ply", "crash"};
  ExpectOnlyTheBadSequenceFails(j, "street", "room",
                                {"stage \"exporter\" (pipeline[2], plugin "
                                 "org.imr.test.exporter.crashing) did not return within 1 s",
                                 "writing the mesh", "the limit is --stage-timeout"},
                                "--stage-timeout 1");
  // Fixed, the job runs again over the same folders and the failed sequence is redone whole.
  j["pipeline"][2]["params"] = json::object();
  const CommandResult again = Run(j, "--stage-timeout 1", /*keep_runs=*/true);
  EXPECT_EQ(again.status, 0) << again.out << again.err;
  EXPECT_NE(again.out.find("ok      street"), std::string::npos) << again.out;
  EXPECT_TRUE(fs::exists(Case() / "runs/street/mesh.crash"));
  EXPECT_EQ(ReadText(Case() / "runs/street/mesh.crash").find("half"), std::string::npos);
  EXPECT_TRUE(fs::exists(Case() / "runs/street/manifest.json"));
}

// ---- Where the output goes ----

TEST_F(BadOutput, OutputFolderNotWritable) {
  // Root writes through chmod, so the folder is a read-only file system.
  const fs::path out = Case() / "runs/street";
  TmpfsMount ro(out, MS_RDONLY, "size=1m");
  if (!ro.SkipReason().empty()) GTEST_SKIP() << ro.SkipReason();
  ExpectOnlyTheBadSequenceFails(SyntheticJob(), "street", "room",
                                {out.string() + ": folder not writable: Read-only file system"},
                                "", /*keep_runs=*/true);
}

TEST_F(BadOutput, DiskFullWhileWritingTheMesh) {
  const fs::path out = Case() / "runs/street";
  TmpfsMount full(out, 0, "size=16k");
  if (!full.SkipReason().empty()) GTEST_SKIP() << full.SkipReason();
  json j = SyntheticJob();
  j["output"]["formats"] = {"obj", "ply", "glb"};
  // No half file: assimp used to write a truncated mesh and report success.
  ExpectOnlyTheBadSequenceFails(j, "street", "room",
                                {out.string() + "/.imr-staging-", "/mesh.obj: write failed: No space "
                                                                  "left on device"},
                                "", /*keep_runs=*/true);
}

TEST_F(BadOutput, DiskFullWhileWritingTheReport) {
  // Room for the mesh but not for report.json: the mesh must not stay behind either (it used to
  // be moved into place before the report was written). A first run measures both. Without
  // point ids the exporter writes the PLY once, at its final size.
  json j = SyntheticJob();
  j["pipeline"][1]["params"] = {{"point_ids", false}};
  const CommandResult first = Run(j);
  ASSERT_EQ(first.status, 0) << first.err;
  const uintmax_t mesh = fs::file_size(Case() / "runs/street/mesh.ply");
  const uintmax_t report = fs::file_size(Case() / "runs/street/report.json");
  ASSERT_GT(report, 4096u) << "the report must need more than the spare page";
  fs::remove_all(Case() / "runs");
  const fs::path out = Case() / "runs/street";
  const uintmax_t pages = (mesh + 4095) / 4096 + 1;  // the mesh and one spare page
  TmpfsMount full(out, 0, "size=" + std::to_string(pages * 4096));
  if (!full.SkipReason().empty()) GTEST_SKIP() << full.SkipReason();
  ExpectOnlyTheBadSequenceFails(j, "street", "room",
                                {out.string() + "/.imr-staging-", "/report.json: write failed: No "
                                                                  "space left on device"},
                                "", /*keep_runs=*/true);
}

// ==== Round 2 (issue 15): what outside probes found ====

// PNG chunks end with a CRC-32 (ISO 3309) of their type and data.
uint32_t Crc32(const unsigned char* data, std::size_t size) {
  uint32_t crc = 0xffffffffu;
  for (std::size_t i = 0; i < size; ++i) {
    crc ^= data[i];
    for (int k = 0; k < 8; ++k) crc = (crc >> 1) ^ (0xedb88320u & (0u - (crc & 1u)));
  }
  return ~crc;
}

// Makes a PNG's header declare `width` x `height` (CRC fixed, pixel data unchanged): what a
// decoder trusts before it reads a pixel.
void DeclarePngSize(const fs::path& png, uint32_t width, uint32_t height) {
  std::string bytes = ReadText(png);
  ASSERT_GT(bytes.size(), 33u);
  ASSERT_EQ(bytes.substr(12, 4), "IHDR") << png;
  auto put = [&bytes](std::size_t at, uint32_t v) {
    for (int i = 0; i < 4; ++i) bytes[at + i] = static_cast<char>((v >> (24 - 8 * i)) & 0xff);
  };
  put(16, width);
  put(20, height);
  put(29, Crc32(reinterpret_cast<const unsigned char*>(bytes.data()) + 12, 17));
  WriteText(png, bytes);
}

// Multiplies the rotation entries of every line of a KITTI poses file (or of line `only`,
// 0-based) by `factor`: a rotation that far from orthonormal.
void ScalePoseRotations(const fs::path& poses, double factor, int only = -1) {
  std::istringstream in(ReadText(poses));
  std::string text;
  int index = 0;
  for (std::string line; std::getline(in, line); ++index) {
    std::istringstream words(line);
    std::vector<double> v;
    for (double x; words >> x;) v.push_back(x);
    std::string out;
    for (std::size_t k = 0; k < v.size(); ++k) {
      const bool rotation = k % 4 != 3 && (only < 0 || only == index);
      char buf[32];
      std::snprintf(buf, sizeof(buf), "%.17g", rotation ? v[k] * factor : v[k]);
      out += (k ? " " : "") + std::string(buf);
    }
    text += out + "\n";
  }
  WriteText(poses, text);
}

// A background `imr run` of this test's job.json: its pid (imr's own), and its exit status
// once it has ended.
class BackgroundRun {
 public:
  BackgroundRun(const fs::path& dir, const std::string& tag) : dir_(dir), tag_(tag) {
    const std::string t = Quote(tag);
    RunShell("cd " + Quote(dir.string()) + " && ( sh -c 'echo $$ >" + t + ".pid; exec " +
             Quote(kImr) + " run --jobs 2 job.json' >" + t + ".out 2>" + t + ".err; echo $? >" +
             t + ".status ) &");
    for (int i = 0; i < 100 && pid_ <= 0; ++i) {
      pid_ = std::atoi(ReadText(dir / (tag + ".pid")).c_str());
      if (pid_ <= 0) ::usleep(50000);
    }
  }
  pid_t pid() const { return pid_; }
  // Waits up to `seconds` for the run to end; its exit status, or -1.
  int Wait(int seconds) const {
    for (int i = 0; i < seconds * 10; ++i) {
      const std::string s = ReadText(dir_ / (tag_ + ".status"));
      if (!s.empty() && s.back() == '\n') return std::atoi(s.c_str());
      ::usleep(100000);
    }
    return -1;
  }
  std::string Output() const {
    return ReadText(dir_ / (tag_ + ".out")) + ReadText(dir_ / (tag_ + ".err"));
  }

 private:
  fs::path dir_;
  std::string tag_;
  pid_t pid_ = -1;
};

// Waits up to `seconds` for `file` to exist and hold `text`.
bool WaitForText(const fs::path& file, const std::string& text, int seconds) {
  for (int i = 0; i < seconds * 10; ++i) {
    if (ReadText(file).find(text) != std::string::npos) return true;
    ::usleep(100000);
  }
  return false;
}

// ---- The front end overlapped with the engine (issue 18: by default on 2 cores, the front end
// makes the next keyframes on its own thread while the engine applies one; --no-overlap: not).
// Whatever fails, on which thread, the run ends the same way with and without it. ----

class Overlap : public BadImages {
 protected:
  // A longer sequence than BadImages' (40 frames, 9 keyframes): the front end still has
  // keyframes to make when the engine fails at keyframe 2.
  static void SetUpTestSuite() {
    dir_ = new ScratchDir("overlap");
    const CommandResult r = RunShell(Quote(kSynth) + " --out " + Quote(Sequence().string()) +
                                     " --frames 40 --width 414 --height 125 --no-lidar -q");
    ASSERT_EQ(r.status, 0) << r.out << r.err;
  }
  // The image job on a copy of the suite's sequence ("bad") and the sequence itself ("street"),
  // the test policy misbehaving with `params` in "bad" only.
  static json ImageJobWithFailingPolicy(const json& params) {
    json j = ImageJob({"bad", Sequence().string()});
    json p = params;
    p["only_in"] = "bad";
    j["pipeline"][2] = {{"kind", "weight_policy"}, {"plugin", "org.imr.test.policy.failing"},
                        {"params", p}};
    j["engine"]["visibility_mode"] = "weights";  // the mode that calls a policy
    j["plugin_paths"] = {kTestPlugins};
    return j;
  }
  // `job` with the front end overlapped and not: "bad" fails, naming `error_has`, in both, with
  // the same error and the same exit code; "street" is ok. The bad sequence's summary row.
  json ExpectTheSameFailureWithAndWithout(const json& job, const std::vector<std::string>& error_has) {
    json rows[2];
    for (const int overlap : {1, 0}) {
      const CommandResult r = Run(job, overlap ? "" : "--no-overlap");
      CheckOnlyTheBadSequenceFailed(r, Case() / "runs", job, "bad", "street", error_has);
      const json row = SummaryRow(ReadJson(Case() / "runs/summary.json"), "bad");
      rows[overlap] = {{"error", row.value("error", "")}, {"exit_code", row.value("exit_code", json())},
                       {"status", row.value("status", "")}, {"imr_status", r.status}};
    }
    EXPECT_EQ(rows[1], rows[0]) << "with the overlap, then without";
    return rows[1];
  }
  void SetUp() override {
    BadImages::SetUp();
    CopySequence();
  }
};

TEST_F(Overlap, FrameMissingAheadOfTheEngine) {
  // Frame 26 ends keyframe 6: the front end meets it while the engine applies keyframe 4 or 5.
  fs::remove(Case() / "bad/image_0/000026.png");
  ExpectTheSameFailureWithAndWithout(
      ImageJob({"bad", Sequence().string()}), {(Case() / "bad/image_0/000026.png").string(), "no such file"});
}

TEST_F(Overlap, PolicyFailsWhileTheFrontEndRunsAhead) {
  const auto start = std::chrono::steady_clock::now();
  ExpectTheSameFailureWithAndWithout(ImageJobWithFailingPolicy({{"fail_after", 0}}),
                                     {"keyframe 2", "weight policy org.imr.test.policy.failing",
                                      "failing policy: transfer failed on purpose"});
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(60));
}

TEST_F(Overlap, PolicyHangsWhileTheFrontEndRunsAhead) {
  // The watchdog sees the policy's call on the engine's thread while the features and refiner
  // plugins are called on the other, and names the engine thread's position.
  json job = ImageJobWithFailingPolicy({{"hang", true}});
  job["pipeline"][2]["timeout_seconds"] = 1;
  const json row = ExpectTheSameFailureWithAndWithout(
      job, {"stage \"weight_policy\" (pipeline[2], plugin org.imr.test.policy.failing) did not "
            "return within 1 s (keyframe 2, frame 6); the limit is pipeline[2].timeout_seconds"});
  EXPECT_EQ(row["exit_code"], 124) << row.dump(2);
}

TEST_F(Overlap, EachFrontEndInstanceStaysOnOneThread) {
  // The SDK promises one thread per instance (create, calls, destroy). The test plugin checks it
  // and tracks nothing, so a run that keeps the promise fails for want of a surface.
  json job = ImageJob({"bad"});
  job["pipeline"][0] = {{"kind", "features"}, {"plugin", "org.imr.test.features.thread_checked"}};
  job["plugin_paths"] = {kTestPlugins};
  for (const char* flags : {"", "--no-overlap"}) {
    const CommandResult r = Run(job, flags);
    EXPECT_NE(r.status, 0) << r.out << r.err;
    const json row = SummaryRow(ReadJson(Case() / "runs/summary.json"), "bad");
    EXPECT_NE(row.value("error", "").find("no surface was reconstructed"), std::string::npos)
        << flags << "\n" << row.dump(2) << r.err;
    EXPECT_EQ(r.err.find("thread_checked"), std::string::npos) << flags << "\n" << r.err;
  }
}

TEST_F(Overlap, SignalWhileTheFrontEndRunsAhead) {
  // SIGTERM to the batch while "bad" is busy in its (slow) policy with keyframes made ahead of
  // it: the sequence stops by itself at the next keyframe, joins the front end's thread and
  // counts as interrupted; it is not killed after the grace period.
  json job = ImageJobWithFailingPolicy({{"sleep_ms", 30}});
  job["sequences"] = {"bad"};
  WriteText(Case() / "job.json", job.dump(2));
  const BackgroundRun run(Case(), "run");
  ASSERT_GT(run.pid(), 0);
  ASSERT_TRUE(WaitForText(Case() / "runs/imr-batch/status/bad.json", "running", 60)) << run.Output();
  ::sleep(2);  // past keyframe 0, into the policy's calls
  ::kill(run.pid(), SIGTERM);
  const auto signalled = std::chrono::steady_clock::now();
  const int status = run.Wait(60);
  EXPECT_NE(status, 0) << run.Output();
  // Sooner than the batch's 10 s grace before it kills a sequence that does not stop.
  EXPECT_LT(std::chrono::steady_clock::now() - signalled, std::chrono::seconds(8)) << run.Output();
  ASSERT_TRUE(fs::exists(Case() / "runs/summary.json")) << run.Output();
  const json row = SummaryRow(ReadJson(Case() / "runs/summary.json"), "bad");
  EXPECT_EQ(row["status"], "interrupted") << row.dump(2);
  EXPECT_NE(row.value("error", "").find("stopped by SIGTERM"), std::string::npos) << row.dump(2);
  EXPECT_EQ(row.value("error", "").find("was killed"), std::string::npos) << row.dump(2);
  EXPECT_EQ(Leftovers(Case() / "runs"), std::vector<std::string>{});
}

TEST_F(BadSfm, FolderNamedLikeAPlaceholder) {
  // Placeholders are replaced in one pass over the template: a name holding "{sequence}" or
  // "{job}" is text (the replacement used to find what it had just inserted, and spin for ever).
  for (const char* name : {"{sequence}", "x{job}", "good"}) CopyModel(Case() / "seqs" / name);
  const json job = EngineJob("colmap", {"seqs/*/"});
  WriteText(Case() / "job.json", job.dump(2));
  const CommandResult v = InCase("validate job.json");
  EXPECT_EQ(v.status, 0) << v.out << v.err;
  EXPECT_NE(v.out.find("{sequence} -> " + (Case() / "runs/{sequence}").string() + "\n"),
            std::string::npos) << v.out;
  EXPECT_NE(v.out.find("x{job} -> " + (Case() / "runs/x{job}").string() + "\n"), std::string::npos)
      << v.out;
  CheckEverySequenceOk(Run(job), Case() / "runs", job, {"{sequence}", "x{job}", "good"});
  // A job file named {job}.json with {job} in its template.
  json named = job;
  named["output"]["directory"] = "runs/{job}/{sequence}";
  WriteText(Case() / "{job}.json", named.dump(2));
  const CommandResult n = InCase("run --jobs 2 '{job}.json'");
  CheckEverySequenceOk(n, Case() / "runs/{job}", named, {"{sequence}", "x{job}", "good"});
  EXPECT_TRUE(fs::exists(Case() / "runs/{job}/{sequence}/mesh.ply"));
}

TEST_F(BadSfm, SequenceNameNotUtf8) {
  // Names are bytes on Linux: a Latin-1 "café" folder is a sequence like any other. Its output
  // folder keeps the bytes; JSON files, which need text, show the byte escaped (caf\xE9).
  const std::string latin1 = std::string("caf") + '\xE9';
  CopyModel(Case() / "seqs" / latin1);
  CopyModel(Case() / "seqs/good");
  const json job = EngineJob("colmap", {"seqs/*/"});
  const CommandResult r = Run(job);
  CheckEverySequenceOk(r, Case() / "runs", job, {"good"});
  const json summary = ReadJson(Case() / "runs/summary.json");
  EXPECT_EQ(SummaryRow(summary, "caf\\xE9").value("status", ""), "ok") << summary.dump(2);
  ExpectOutputs(Case() / "runs" / latin1, job);
  EXPECT_EQ(ReadJson(Case() / "runs" / latin1 / "report.json")["sequence"]["name"], "caf\\xE9");
  // imr report reads the batch folder back: the name's bytes round-trip.
  const CommandResult rep = InCase("report runs");
  EXPECT_EQ(rep.status, 0) << rep.out << rep.err;
  EXPECT_EQ(SummaryRow(ReadJson(Case() / "runs/summary.json"), "caf\\xE9").value("status", ""), "ok");
}

TEST_F(BadPlugin, HalfCopiedPlugin) {
  // The first half of a real plugin, as an interrupted copy leaves it: loading it used to kill
  // every command with SIGBUS. It is refused by name; the job runs without it.
  const fs::path dir = Case() / "more-plugins";
  const std::string bytes = ReadText(fs::path(kTestPlugins) / "test_failing_policy.so");
  WriteText(dir / "half.so", bytes.substr(0, bytes.size() / 2));
  json job = SyntheticJob();
  job["plugin_paths"].push_back("more-plugins");
  const CommandResult r = Run(job);
  CheckEverySequenceOk(r, Case() / "runs", job, {"street", "room"});
  const std::string refusal = (dir / "half.so").string() + ": cannot load: truncated: ";
  EXPECT_NE(r.err.find("plugin refused: " + refusal), std::string::npos) << r.err;
  for (const char* command : {"plugins -p more-plugins", "validate job.json"}) {
    const CommandResult c = InCase(command);
    EXPECT_EQ(c.status, 0) << command << "\n" << c.out << c.err;
    EXPECT_NE((c.out + c.err).find("half.so: cannot load: truncated: "), std::string::npos)
        << c.out << c.err;
  }
  std::cout << "[ message  ] " << r.err.substr(r.err.find(refusal), 200) << "\n";
}

TEST_F(BadOutput, TwoJobsShareAnOutputFolder) {
  // Job A writes street as PLY and GLB; job B writes street into the same folder (PLY only) and
  // plane into its own. B's clean-up of "files it no longer writes" used to delete A's mesh.glb.
  json a = SyntheticJob();
  a["sequences"] = {"street"};
  a["output"]["formats"] = {"ply", "glb"};
  WriteText(Case() / "job-a.json", a.dump(2));
  const CommandResult ra = InCase("run -q job-a.json");
  ASSERT_EQ(ra.status, 0) << ra.out << ra.err;
  const std::string glb = ReadText(Case() / "runs/street/mesh.glb");
  json b = SyntheticJob();
  b["sequences"] = {"street", "plane"};
  WriteText(Case() / "job-b.json", b.dump(2));
  const CommandResult rb = InCase("run --jobs 2 job-b.json");
  CheckOnlyTheBadSequenceFailed(rb, Case() / "runs", b, "street", "plane",
                                {(Case() / "runs/street/manifest.json").string(),
                                 "written by another job (" + (Case() / "job-a.json").string() + ")",
                                 "give each job its own output folder"},
                                /*bad_folder_empty=*/false);
  EXPECT_EQ(ReadText(Case() / "runs/street/mesh.glb"), glb) << "job B changed job A's mesh";
  // Job A still finds its sequence finished.
  const CommandResult again = InCase("run job-a.json");
  EXPECT_EQ(again.status, 0) << again.out << again.err;
  EXPECT_NE(again.out.find("skipped street"), std::string::npos) << again.out;
}

TEST_F(BadImages, PngDeclaringAHugeSize) {
  // 30000 x 30000 in the header of frame 0 (a 0.9 MB file of that size decodes for seconds
  // into gigabytes): refused from the header, against input.options.max_image_megapixels.
  fs::path png = CopySequence() / "image_0/000000.png";
  DeclarePngSize(png, 30000, 30000);
  const auto start = std::chrono::steady_clock::now();
  ExpectOnlyTheBadSequenceFails(ImageJob({"bad", Sequence().string()}), "bad", "street",
                                {png.string(), "image is 30000x30000 (900 megapixels)",
                                 "more than input.options.max_image_megapixels (50)"});
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(60));
  // A later frame declaring another size than the sequence's is refused before decoding too.
  fs::remove_all(Case() / "bad");
  png = CopySequence() / "image_0/000005.png";
  DeclarePngSize(png, 2000, 2000);
  ExpectOnlyTheBadSequenceFails(ImageJob({"bad", Sequence().string()}), "bad", "street",
                                {png.string(), "image is 2000x2000, the sequence's first is 414x125"});
}

TEST_F(BadImages, PoseRotationsSlightlyOffOrthonormal) {
  // Rotations 1.4e-6 from orthonormal (6-7 significant digits, as ../shared's dinoSparseRing):
  // the reader re-orthonormalises them; the refiner, which checks to 1e-6, used to refuse frame
  // 0 naming neither file nor line.
  const fs::path poses = CopySequence() / "poses.txt";
  ScalePoseRotations(poses, 1.0 + 1.4e-6);
  const json job = ImageJob({"bad", Sequence().string()});
  CheckEverySequenceOk(Run(job), Case() / "runs", job, {"bad", "street"});
  // Beyond the one tolerance: refused, naming file and line.
  ScalePoseRotations(poses, 1.0 + 2e-4, 4);
  ExpectOnlyTheBadSequenceFails(job, "bad", "street",
                                {poses.string() + ":5", "not orthonormal",
                                 "more than the 0.0001 imr re-orthonormalises"});
}

TEST_F(BadSfm, ColmapBytesThatAreNotText) {
  // A 0xFF byte in cameras.txt: the message names the file, the line and the field (it used to
  // be lost: the child could not send a message holding the byte as JSON, and the summary said
  // "interrupted").
  const fs::path model = CopyModel(Case() / "bad");
  EditFirstDataLine(model / "cameras.txt", [](std::vector<std::string>& w) { w.at(4) = "\xff" + w.at(4); });
  ExpectOnlyTheBadSequenceFails(EngineJob("colmap", {"bad", Fixture("colmap")}), "bad", "colmap",
                                {(model / "cameras.txt").string() + " line ",
                                 "expected a parameter (number), got \"\\xFF"});
  // A 0xFF byte in an image name, with --export-stream: the stream (JSON) escapes it.
  fs::remove_all(model);
  CopyModel(model);
  EditFirstDataLine(model / "images.txt", [](std::vector<std::string>& w) { w.at(9) += "\xff"; });
  const json job = EngineJob("colmap", {"bad", Fixture("colmap")});
  CheckEverySequenceOk(Run(job, "--export-stream '{output}/stream.json'"), Case() / "runs", job,
                       {"bad", "colmap"});
  EXPECT_NE(ReadText(Case() / "runs/bad/stream.json").find("\\\\xFF"), std::string::npos);
}

TEST_F(BadPlugin, TwoRunsOfOneJobAtOnce) {
  // The first run's street hangs in its weight policy (until its 6 s stage timeout); a second
  // run of the same job meanwhile is refused, naming the first's pid, and writes nothing.
  json j = WithFailingPolicy({{"hang", true}});
  j["pipeline"][0]["timeout_seconds"] = 6;
  WriteText(Case() / "job.json", j.dump(2));
  const BackgroundRun first(Case(), "first");
  ASSERT_GT(first.pid(), 0);
  ASSERT_TRUE(WaitForText(Case() / "runs/imr-batch/status/street.json", "running", 60))
      << first.Output();
  const CommandResult second = InCase("run job.json");
  EXPECT_EQ(second.status, kExitTempFail) << second.out << second.err;
  for (const std::string& e : std::vector<std::string>{(Case() / "runs/imr-batch/lock").string(),
                                                      "pid " + std::to_string(first.pid()),
                                                      "another imr run"})
    EXPECT_NE(second.err.find(e), std::string::npos) << "stderr lacks '" << e << "':\n" << second.err;
  std::cout << "[ message  ] " << second.err.substr(second.err.find("imr run: ")) << "\n";
  // Another job whose output folder is street's (its batch folder is that folder): one process
  // writes an output folder at a time.
  json other = SyntheticJob();
  other["sequences"] = {"street"};
  other["output"]["directory"] = "runs/street";
  WriteText(Case() / "other.json", other.dump(2));
  const CommandResult o = InCase("run other.json");
  EXPECT_NE(o.status, 0) << o.out << o.err;
  EXPECT_NE(o.err.find((Case() / "runs/street").string() + ": another imr process (pid "),
            std::string::npos) << o.err;
  EXPECT_NE(o.err.find("is writing into this output folder"), std::string::npos) << o.err;
  std::cout << "[ message  ] " << o.err.substr(o.err.find("street failed: ")) << "\n";
  EXPECT_NE(first.Wait(120), 0) << first.Output();  // street timed out
  const json summary = ReadJson(Case() / "runs/summary.json");
  EXPECT_EQ(SummaryRow(summary, "room")["status"], "ok") << summary.dump(2);
  EXPECT_EQ(SummaryRow(summary, "street")["status"], "failed") << summary.dump(2);
  EXPECT_NE(first.Output().find("summary: "), std::string::npos) << first.Output();
}

TEST_F(BadSfm, SubmitWithNamesThatNeedQuoting) {
  // Names with leading or trailing blanks, a leading '#' or a newline: the frozen sequence list
  // of `imr submit` round-trips them (its tasks used to exit 64, and '#' names were dropped).
  const std::vector<std::string> names = {" lead", "trail ", "#hash", "new\nline", "good"};
  for (const std::string& n : names) CopyModel(Case() / "seqs" / n);
  const json job = EngineJob("colmap", {"seqs/*/"});
  WriteText(Case() / "job.json", job.dump(2));
  const CommandResult s = InCase("submit job.json --tasks 2 --dry-run");
  ASSERT_EQ(s.status, 0) << s.out << s.err;
  // What each array task runs: the script, with the shard Slurm would give it.
  for (const char* task : {"0", "1"}) {
    const CommandResult t = RunShell(
        "cd " + Quote(Case().string()) + " && SLURM_ARRAY_TASK_ID=" + task +
        " SLURM_ARRAY_TASK_COUNT=2 SLURM_ARRAY_TASK_MIN=0 timeout -k 5 300 bash runs/imr-batch/slurm/array.sbatch");
    EXPECT_EQ(t.status, 0) << "task " << task << ":\n" << t.out << t.err;
  }
  CheckEverySequenceOk(InCase("report runs"), Case() / "runs", job, names);
}

TEST_F(BadJob, OutputFoldersThatCollideOrEscape) {
  for (const char* d : {"seqs/a", "seqs/b"}) fs::create_directories(Case() / d);
  // ".*/" matches "." and "..": their output folders would be the batch folder and its parent.
  ExpectJobRefused(EngineJob("colmap", {"seqs/.*/"}).dump(2),
                   {"sequences[0]: sequence '.': its output folder " + (Case() / "runs").string() +
                        " is the batch folder itself",
                    "sequences[0]: sequence '..': its output folder " + Case().string() +
                        " is outside the batch folder " + (Case() / "runs").string()});
  json j = EngineJob("colmap", {"seqs/*/"});
  j["output"]["directory"] = "out/{sequence}/../shared";
  ExpectJobRefused(j.dump(2), {"output.directory: sequences 'a' and 'b' would both write to " +
                               (Case() / "out/shared").string()});
  // An export path that is an output folder: the stream would be a file where the folder goes.
  ExpectJobRefused(GoodJob().dump(2),
                   {"--export-stream {output}: " + (Case() / "runs/street").string() +
                    " is the output folder of sequence 'street'"},
                   "--export-stream '{output}'");
}

TEST_F(BadOutput, BatchFolderMovedThenReported) {
  // The batch folder records paths relative to itself: moved elsewhere, `imr report` finds
  // every file (it used to follow the old absolute paths and call every sequence failed).
  const json job = SyntheticJob();
  ASSERT_EQ(Run(job).status, 0);
  fs::rename(Case() / "runs", Case() / "moved");
  CheckEverySequenceOk(InCase("report moved"), Case() / "moved", job, {"street", "room"});
  const json summary = ReadJson(Case() / "moved/summary.json");
  EXPECT_EQ(SummaryRow(summary, "street")["output"], "street") << summary.dump(2);
  EXPECT_TRUE(fs::exists(Case() / "moved/index.html"));
}

TEST_F(BadJob, JobWithDuplicateKeys) {
  // JSON keeps the last of two equal keys: a typo is never silently ignored, so both are named.
  const std::string text =
      "{\n  \"sequences\": [\"street\"],\n  \"engine\": {\"window\": 10,\n             \"window\": 20},\n"
      "  \"input\": {\"format\": \"synthetic\"},\n"
      "  \"pipeline\": [{\"kind\": \"weight_policy\", \"plugin\": \"org.imr.policy.nearest\"},\n"
      "               {\"kind\": \"exporter\", \"plugin\": \"org.imr.exporter.assimp\", \"plugin\": \"x\"}],\n"
      "  \"output\": {\"directory\": \"runs/{sequence}\"}\n}\n";
  ExpectJobRefused(text, {"engine.window: the key appears twice (line 3, column 14 and line 4, column 14)",
                          "pipeline[1].plugin: the key appears twice (line 7, column 37 and line 7, column 74)"});
}

TEST_F(BadSfm, ColmapHugeCoordinate) {
  // One bound for every reader: the JSON readers refuse beyond +-1e12, COLMAP too now.
  const fs::path model = CopyModel(Case() / "bad");
  EditFirstDataLine(model / "points3D.txt", [](std::vector<std::string>& w) { w.at(1) = "1e308"; });
  ExpectOnlyTheBadSequenceFails(EngineJob("colmap", {"bad", Fixture("colmap")}), "bad", "colmap",
                                {(model / "points3D.txt").string() + " line ", "X",
                                 "expected a coordinate within +-1e12 (scene units), got 1e+308"});
}

TEST_F(BadImages, PoseWithHugeTranslation) {
  const fs::path poses = CopySequence() / "poses.txt";
  ReplaceLine(poses, 4, "1 0 0 1e300 0 1 0 0 0 0 1 5");
  ExpectOnlyTheBadSequenceFails(ImageJob({"bad", Sequence().string()}), "bad", "street",
                                {poses.string() + ":5", "number 4",
                                 "expected a coordinate within +-1e12 (scene units), got 1e+300"});
}

TEST_F(BadSfm, AllPointsAtOnePosition) {
  // Every point at one position: all but the first are refused as duplicates. Not an error, but
  // a warning (on stderr, in report.json and the summary), and report.json counts them. The
  // position is ahead of every camera (a position behind most of them is refused as impossible
  // since issue 36: ImpossibleOrStaleInput).
  json j = ReadJson(Fixture("slam/good.json"));
  for (json& v : j["views"])
    for (json& o : v["observations"]) o["X"] = {1.0, 30.0, 0.5};
  WriteText(Case() / "bad.json", j.dump());
  const json job = EngineJob("slam_json", {"bad.json", Fixture("slam/good.json")});
  const CommandResult r = Run(job);
  const json summary = ReadJson(Case() / "runs/summary.json");
  const json row = SummaryRow(summary, "bad.json");
  const std::string warning = "most points never entered the mesh: ";
  EXPECT_NE(r.err.find("warning: [bad.json] "), std::string::npos) << r.err;
  EXPECT_NE(r.err.find(warning), std::string::npos) << r.err;
  EXPECT_NE(ReadText(Case() / "runs/summary.md").find(warning), std::string::npos);
  EXPECT_NE(row.value("warnings", json::array()).dump().find(warning), std::string::npos) << row.dump(2);
  if (row["status"] == "ok") {
    const json report = ReadJson(Case() / "runs/bad.json/report.json");
    EXPECT_GT(report["engine"].value("points_duplicate", 0), 0) << report["engine"].dump(2);
    EXPECT_NE(report.value("warnings", json::array()).dump().find(warning), std::string::npos);
  }
  std::cout << "[ message  ] " << r.err.substr(r.err.find("warning: [bad.json]"), 300) << "\n";
}

TEST_F(BadSfm, OutputFolderHoldsAnotherToolsFiles) {
  // The output folder holds another tool's manifest.json: refused, the file kept (it used to be
  // overwritten silently). The same for a report.json imr did not write. (An output folder that
  // is the input folder is refused whatever it holds: the write rule, WriteRuleCli.)
  const fs::path bad = Case() / "out/bad";
  CopyModel(Case() / "seqs/bad");
  CopyModel(Case() / "seqs/good");
  fs::create_directories(bad);
  const std::string foreign = "{\"made_by\": \"another tool\"}\n";
  WriteText(bad / "manifest.json", foreign);
  json job = EngineJob("colmap", {"seqs/bad", "seqs/good"});
  job["output"]["directory"] = "out/{sequence}";
  WriteText(Case() / "job.json", job.dump(2));
  CheckOnlyTheBadSequenceFailed(InCase("run --jobs 2 job.json"), Case() / "out", job, "bad", "good",
                                {(bad / "manifest.json").string(), "not a manifest of imr",
                                 "imr would overwrite it"},
                                /*bad_folder_empty=*/false);
  EXPECT_EQ(ReadText(bad / "manifest.json"), foreign);
  fs::remove(bad / "manifest.json");
  WriteText(bad / "report.json", foreign);
  CheckOnlyTheBadSequenceFailed(InCase("run --jobs 2 job.json"), Case() / "out", job, "bad", "good",
                                {(bad / "report.json").string(), "not a report of this job's sequence",
                                 "imr would overwrite it"},
                                /*bad_folder_empty=*/false);
  EXPECT_EQ(ReadText(bad / "report.json"), foreign);
}

TEST_F(BadPlugin, SymlinkLoopNamedLikeAPlugin) {
  // It used to stop every command with an uncaught filesystem error (status 1).
  const fs::path dir = Case() / "more-plugins";
  fs::create_directories(dir);
  fs::create_symlink("loop.so", dir / "loop.so");
  json job = SyntheticJob();
  job["plugin_paths"].push_back("more-plugins");
  const CommandResult r = Run(job);
  CheckEverySequenceOk(r, Case() / "runs", job, {"street", "room"});
  const std::string refusal = (dir / "loop.so").string() + ": cannot read: Too many levels of symbolic links";
  EXPECT_NE(r.err.find(refusal), std::string::npos) << r.err;
  const CommandResult p = InCase("plugins -p more-plugins");
  EXPECT_EQ(p.status, 0) << p.out << p.err;
  EXPECT_NE(p.out.find("loop.so: cannot read: Too many levels of symbolic links"), std::string::npos) << p.out;
}

TEST_F(BadOutput, BatchFolderNotWritable) {
  // The batch folder cannot be created: an environment error with its own status (73,
  // EX_CANTCREAT), not 1 as if one sequence had failed. Nothing runs.
  const fs::path ro = Case() / "ro";
  TmpfsMount mount(ro, MS_RDONLY, "size=64k");
  if (!mount.SkipReason().empty()) GTEST_SKIP() << mount.SkipReason();
  json job = SyntheticJob();
  job["output"]["directory"] = "ro/runs/{sequence}";
  const CommandResult r = Run(job);
  EXPECT_EQ(r.status, kExitCantCreate) << r.out << r.err;
  EXPECT_NE(r.err.find("imr run: " + (ro / "runs").string() + ": cannot create the batch folder"),
            std::string::npos) << r.err;
  EXPECT_NE(r.err.find("Read-only file system"), std::string::npos) << r.err;
  EXPECT_EQ(r.out.find("street"), std::string::npos) << r.out;
  std::cout << "[ message  ] " << r.err.substr(r.err.find("imr run: ")) << "\n";
}

TEST_F(BadSfm, SequenceNameOf250Characters) {
  // Its status record's file name is derived to fit (NAME_MAX is 255 bytes, and an atomic
  // write's temporary adds to it): it used to be missing, so a crash showed as nothing at all.
  const std::string name(250, 'n');
  CopyModel(Case() / "seqs" / name);
  CopyModel(Case() / "seqs/good");
  const json job = EngineJob("colmap", {"seqs/*/"});
  const CommandResult r = Run(job);
  CheckEverySequenceOk(r, Case() / "runs", job, {name, "good"});
  EXPECT_EQ(r.err.find("cannot record"), std::string::npos) << r.err;
  int records = 0;
  for (const auto& e : fs::directory_iterator(Case() / "runs/imr-batch/status"))
    if (e.path().filename() != kWriteLedgerName)
      records += ReadJson(e.path()).value("sequence", "") == name ? 1 : 0;
  EXPECT_EQ(records, 1);
}

TEST_F(BadImages, CalibrationWithAByteOrderMark) {
  // A UTF-8 byte order mark (as Windows editors save) is skipped: it used to hide "P0:".
  const fs::path calib = CopySequence() / "calib.txt";
  WriteText(calib, "\xEF\xBB\xBF" + ReadText(calib));
  const json job = ImageJob({"bad", Sequence().string()});
  CheckEverySequenceOk(Run(job), Case() / "runs", job, {"bad", "street"});
}

TEST_F(BadImages, FolderNamedLikeAnImage) {
  const fs::path png = CopySequence() / "image_0/000003.png";
  fs::remove(png);
  fs::create_directory(png);
  ExpectOnlyTheBadSequenceFails(ImageJob({"bad", Sequence().string()}), "bad", "street",
                                {png.string() + ": is a folder, expected a .png image",
                                 "pose line 4"});
}

// Issue 47: the first 8 of 12 images kept, times.txt and poses.txt left whole (the usual way to
// cut a sequence; it was refused: "12 timestamps (lines), but ... has 8 images"). The first 8
// lines serve; the log says so at the default verbosity and report.json lists it as a warning.
// frame_count within the kept images works the same.
TEST_F(BadImages, ATrimmedSequenceUsesTheFirstLinesAndSaysSo) {
  const fs::path seq = CopySequence();
  for (const auto& folder : fs::directory_iterator(seq))
    if (folder.is_directory() && folder.path().filename().string().rfind("image_", 0) == 0)
      for (int i = 8; i < 12; ++i) {
        char name[32];
        std::snprintf(name, sizeof name, "%06d.png", i);
        fs::remove(folder.path() / name);
      }
  ASSERT_FALSE(fs::exists(seq / "image_0/000008.png"));
  ASSERT_TRUE(fs::exists(seq / "image_0/000007.png"));
  const CommandResult r = Run(ImageJob({"bad"}));
  ASSERT_EQ(r.status, 0) << r.out << r.err;
  const std::string note = (seq / "times.txt").string() + ": 12 timestamps (lines) for the 8 images of " +
                           (seq / "image_0").string() + " (000000.png .. 000007.png): a trimmed "
                           "sequence; the first 8 are used";
  EXPECT_NE(r.err.find("[bad] " + note), std::string::npos) << r.err;
  const json report = ReadJson(Case() / "runs/bad/report.json");
  EXPECT_EQ(report["input"]["summary"]["frames"], 8) << report["input"].dump();
  const std::string warnings = report.value("warnings", json::array()).dump();
  EXPECT_NE(warnings.find(note), std::string::npos) << warnings;
  EXPECT_NE(warnings.find((seq / "poses.txt").string() + ": 12 poses (lines) for the 8 images"),
            std::string::npos) << warnings;

  // --set input.options.frame_count=6 (it failed the same way): 6 frames.
  const CommandResult six = Run(ImageJob({"bad"}), "--set input.options.frame_count=6");
  ASSERT_EQ(six.status, 0) << six.out << six.err;
  EXPECT_EQ(ReadJson(Case() / "runs/bad/report.json")["input"]["summary"]["frames"], 6);
}

TEST_F(BadImages, PngDeclaring60000Squared) {
  // Beyond what the decoder itself accepts: still named by size, without OpenCV's own text.
  const fs::path png = CopySequence() / "image_0/000000.png";
  DeclarePngSize(png, 60000, 60000);
  ExpectOnlyTheBadSequenceFails(ImageJob({"bad", Sequence().string()}), "bad", "street",
                                {png.string() + ": image is 60000x60000 (3600 megapixels)"});
  const json summary = ReadJson(Case() / "runs/summary.json");
  const std::string error = SummaryRow(summary, "bad").value("error", "");
  EXPECT_EQ(error.find("OpenCV"), std::string::npos) << error;
  EXPECT_EQ(error.find("not a PNG/JPEG"), std::string::npos) << error;
  // With the limit raised past it, the decoder's own limit is named.
  json job = ImageJob({"bad", Sequence().string()});
  job["input"]["options"] = {{"max_image_megapixels", 5000}};
  ExpectOnlyTheBadSequenceFails(job, "bad", "street",
                                {png.string() + ": image is 60000x60000 (3600 megapixels), more "
                                                "than the image decoder reads (1074)"});
}

TEST_F(BadPlugin, PluginBuiltForAnotherMachine) {
  // A real plugin whose ELF header says AArch64: the loader's own message was "No such file or
  // directory", then ": Bad file descriptor".
  const fs::path dir = Case() / "more-plugins";
  std::string bytes = ReadText(fs::path(kTestPlugins) / "test_failing_policy.so");
  bytes[18] = static_cast<char>(183);  // e_machine = EM_AARCH64
  bytes[19] = 0;
  WriteText(dir / "arm.so", bytes);
  json job = SyntheticJob();
  job["plugin_paths"].push_back("more-plugins");
  const CommandResult r = Run(job);
  CheckEverySequenceOk(r, Case() / "runs", job, {"street", "room"});
  const std::string refusal =
      (dir / "arm.so").string() + ": cannot load: built for AArch64 (ELF machine 183)";
  EXPECT_NE(r.err.find(refusal), std::string::npos) << r.err;
  EXPECT_EQ(r.err.find("No such file or directory"), std::string::npos) << r.err;
  EXPECT_EQ(r.err.find("Bad file descriptor"), std::string::npos) << r.err;
  std::cout << "[ message  ] " << r.err.substr(r.err.find(refusal), 200) << "\n";
}

TEST_F(BadPlugin, PluginWithAnUndefinedSymbol) {
  // The loader's refusal (RTLD_NOW) names the symbol, and nothing after it.
  const CommandResult r = InCase("plugins -p " + Quote(kTestLibraries + "/test_unresolved_plugin.so"));
  EXPECT_EQ(r.status, 0) << r.out << r.err;
  EXPECT_NE(r.out.find("test_unresolved_plugin.so: cannot load: "), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("undefined symbol: imr_test_missing_symbol\n"), std::string::npos) << r.out;
  EXPECT_EQ(r.out.find("Bad file descriptor"), std::string::npos) << r.out;
}

TEST_F(BadPlugin, ForeignLibraryIsNotLoaded) {
  // Files without imr's entry symbol in their dynamic symbol table are refused unopened: their
  // constructors never run (IMR_PLUGIN_PATH=/usr/lib/x86_64-linux-gnu made libmemusage print
  // its heap report).
  const fs::path marker = Case() / "constructor-ran";
  const CommandResult r = InCase("plugins -p " + Quote(kTestLibraries + "/test_constructor_library.so"),
                                 "IMR_TEST_CONSTRUCTOR_MARKER=" + Quote(marker.string()) + " ");
  EXPECT_EQ(r.status, 0) << r.out << r.err;
  EXPECT_NE(r.out.find("test_constructor_library.so: not an imr plugin: no entry symbol "
                       "'imr_plugin_entry' in its dynamic symbol table"),
            std::string::npos) << r.out;
  EXPECT_FALSE(fs::exists(marker)) << "the library's constructor ran";
}

TEST_F(BadPlugin, HangupWhileASequenceRuns) {
  // SIGHUP (a closed terminal, a logout) stops the batch like Ctrl-C: the summary is written and
  // the sequence it stopped is "interrupted", not "failed". Street hangs in its policy and
  // ignores the batch's SIGTERM: it is killed after the grace period.
  WriteText(Case() / "job.json", WithFailingPolicy({{"hang", true}}).dump(2));
  const BackgroundRun run(Case(), "run");
  ASSERT_GT(run.pid(), 0);
  ASSERT_TRUE(WaitForText(Case() / "runs/imr-batch/status/street.json", "running", 60)) << run.Output();
  ::sleep(2);  // into the hang (keyframe 1's transfer)
  ::kill(run.pid(), SIGHUP);
  const int status = run.Wait(120);
  EXPECT_NE(status, 0) << run.Output();
  EXPECT_NE(status, 128 + SIGHUP) << "killed by SIGHUP\n" << run.Output();
  ASSERT_TRUE(fs::exists(Case() / "runs/summary.json")) << run.Output();
  const json summary = ReadJson(Case() / "runs/summary.json");
  const json street = SummaryRow(summary, "street");
  EXPECT_EQ(street["status"], "interrupted") << summary.dump(2);
  EXPECT_NE(street.value("error", "").find("stopped by SIGHUP"), std::string::npos) << street.dump(2);
  EXPECT_NE(street.value("error", "").find("did not stop within 10 s of SIGTERM and was killed"),
            std::string::npos) << street.dump(2);
  EXPECT_EQ(summary["counts"]["failed"], 0) << summary.dump(2);
  std::cout << "[ message  ] " << street.value("error", "") << "\n";
}

TEST_F(BadJob, JobFileWithoutEnd) {
  // /dev/zero used to be read without bound: job files are capped at 64 MiB. A device is now
  // refused by the open rule before a byte is read (tests/input_rule_test.cc), so the cap is
  // tried on a regular file of 65 MiB (sparse: no disk written).
  const fs::path big = Case() / "big.json";
  { std::ofstream(big, std::ios::binary); }
  fs::resize_file(big, std::uintmax_t{65} << 20);
  const CommandResult r = RunShell("ulimit -v 4194304; timeout -k 2 60 " + Quote(kImr) +
                                   " validate " + Quote(big.string()));
  EXPECT_EQ(r.status, kExitUsage) << r.out << r.err.substr(0, 400);
  EXPECT_NE(r.err.find("big.json: more than 64 MiB: not a job file"), std::string::npos) << r.err;
}

// ---- Issue 16: SfM output as users bring it ----

// The data lines (not '#' comments) of a COLMAP text file.
std::vector<std::string> DataLines(const fs::path& file, bool keep_blank) {
  std::istringstream in(ReadText(file));
  std::vector<std::string> lines;
  for (std::string line; std::getline(in, line);)
    if ((keep_blank || !line.empty()) && (line.empty() || line[0] != '#')) lines.push_back(line);
  return lines;
}

std::vector<std::string> Words(const std::string& line) {
  std::istringstream in(line);
  std::vector<std::string> w;
  for (std::string x; in >> x;) w.push_back(x);
  return w;
}

std::string Joined(const std::vector<std::string>& words) {
  std::string s;
  for (const auto& x : words) s += (s.empty() ? "" : " ") + x;
  return s;
}

TEST_F(BadSfm, ColmapModelWithoutPoints) {
  // The mapper registered images but triangulated nothing (or only poses were exported): it used
  // to run the engine and fail with "no surface was reconstructed ... nothing to export", naming
  // neither the file nor the cause.
  const fs::path model = CopyModel(Case() / "bad");
  std::vector<std::string> images = DataLines(model / "images.txt", true);
  for (std::size_t i = 1; i < images.size(); i += 2) {  // every POINTS2D line: no 3D point
    std::vector<std::string> w = Words(images[i]);
    for (std::size_t k = 2; k < w.size(); k += 3) w[k] = "-1";
    images[i] = Joined(w);
  }
  std::string text;
  for (const auto& l : images) text += l + "\n";
  WriteText(model / "images.txt", text);
  WriteText(model / "points3D.txt", "# 3D point list with one line of data per point:\n# Number of points: 0\n");
  ExpectOnlyTheBadSequenceFails(EngineJob("colmap", {"bad", Fixture("colmap")}), "bad", "colmap",
                                {(model / "points3D.txt").string(),
                                 "nothing to mesh: the model has no 3D points"});
}

TEST_F(BadSfm, ColmapModelOfTwoImages) {
  // Only COLMAP's initial pair registered: two fans of rays, not a surface (it used to give a
  // "mesh" of a few dozen triangles and succeed).
  const fs::path model = CopyModel(Case() / "bad");
  const std::vector<std::string> images = DataLines(model / "images.txt", true);
  std::set<std::string> kept;
  std::string text;
  for (std::size_t i = 0; i + 1 < images.size() && kept.size() < 2; i += 2) {
    kept.insert(Words(images[i]).at(0));
    text += images[i] + "\n" + images[i + 1] + "\n";
  }
  WriteText(model / "images.txt", text);
  text.clear();
  for (const std::string& line : DataLines(model / "points3D.txt", false)) {
    const std::vector<std::string> w = Words(line);
    std::vector<std::string> out(w.begin(), w.begin() + 8);
    for (std::size_t k = 8; k + 1 < w.size(); k += 2)
      if (kept.count(w[k])) out.insert(out.end(), {w[k], w[k + 1]});
    text += Joined(out) + "\n";
  }
  WriteText(model / "points3D.txt", text);
  ExpectOnlyTheBadSequenceFails(EngineJob("colmap", {"bad", Fixture("colmap")}), "bad", "colmap",
                                {(model / "images.txt").string(), "nothing to mesh: only 2 posed views",
                                 "at least 3", "register more images"});
}

TEST_F(BadSfm, OpenMvgWithoutStructure) {
  // What openMVG_main_SfMInit_ImageListing writes: views and intrinsics, no poses, no points.
  json j = ReadJson(Fixture("openmvg/good.json"));
  j.erase("structure");
  j.erase("extrinsics");
  WriteText(Case() / "bad.json", j.dump());
  ExpectOnlyTheBadSequenceFails(EngineJob("openmvg", {"bad.json", Fixture("openmvg/good.json")}),
                                "bad.json", "good.json",
                                {(Case() / "bad.json").string(), "missing field \"extrinsics\"",
                                 "SfMInit_ImageListing", "openMVG_main_ComputeStructureFromKnownPoses"});
  // Poses but no structure (a third-party writer): the same advice, for the points.
  j = ReadJson(Fixture("openmvg/good.json"));
  j.erase("structure");
  WriteText(Case() / "bad.json", j.dump());
  ExpectOnlyTheBadSequenceFails(EngineJob("openmvg", {"bad.json", Fixture("openmvg/good.json")}),
                                "bad.json", "good.json",
                                {(Case() / "bad.json").string(),
                                 "missing field \"structure\": the file has no 3D points",
                                 "openMVG_main_ComputeStructureFromKnownPoses"});
}

TEST_F(BadSfm, OpenMvgBinarySfmData) {
  // openMVG_main_SfM writes sfm_data.bin (cereal's portable binary archive) by default.
  std::string bytes = "\x01";
  bytes += std::string("\x03\0\0\0\0\0\0\0", 8) + "0.3" + std::string(16, '\0');
  WriteText(Case() / "sfm_data.bin", bytes);
  ExpectOnlyTheBadSequenceFails(EngineJob("openmvg", {"sfm_data.bin", Fixture("openmvg/good.json")}),
                                "sfm_data.bin", "good.json",
                                {(Case() / "sfm_data.bin").string(), "an OpenMVG binary sfm_data",
                                 "openMVG_main_ConvertSfM_DataFormat -i " + (Case() / "sfm_data.bin").string() +
                                     " -o " + (Case() / "sfm_data.json").string()});
}

TEST_F(BadSfm, OpenMvgOddFieldsOfVersions02And03) {
  // Found in the wild: version 0.2, views with pose priors (view_priors), prior_focal_length
  // beside focal_length: not an error, read past. Fewer distortion values than the model has:
  // refused naming the field and the count (it said "expected 3 numbers").
  json j = ReadJson(Fixture("openmvg/good.json"));
  j["sfm_data_version"] = "0.2";
  json& view = j["views"][0]["value"];
  view["polymorphic_id"] = 2147483650u;
  view["polymorphic_name"] = "view_priors";
  view["ptr_wrapper"]["data"].update({{"use_pose_center_prior", true}, {"center_weight", {1.0, 1.0, 1.0}},
                                      {"center", {9.0, 9.0, 9.0}}, {"use_pose_rotation_prior", false},
                                      {"rotation_weight", 1.0}, {"rotation", {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}}}});
  json& data = j["intrinsics"][0]["value"]["ptr_wrapper"]["data"];
  data["prior_focal_length"] = 480;
  WriteText(Case() / "priors.json", j.dump());
  const json job = EngineJob("openmvg", {"priors.json", Fixture("openmvg/good.json")});
  CheckEverySequenceOk(Run(job), Case() / "runs", job, {"priors.json", "good.json"});

  j["intrinsics"][0]["value"]["polymorphic_name"] = "pinhole_radial_k3";
  data["disto_k3"] = {0.01, 0.0};
  WriteText(Case() / "bad.json", j.dump());
  ExpectOnlyTheBadSequenceFails(EngineJob("openmvg", {"bad.json", Fixture("openmvg/good.json")}),
                                "bad.json", "good.json",
                                {(Case() / "bad.json").string(),
                                 "intrinsics[0].value.ptr_wrapper.data.disto_k3",
                                 "the pinhole_radial_k3 model has 3 distortion values, got 2"});
}

// ---- Issue 36: outside probes of the landed build, as a careless or hostile user, a full
// disk or a scheduler would try it ----

// A job of two synthetic sequences that `imr submit` accepts.
json SubmitJob() {
  json j = EngineJob("synthetic", {"street", "room"});
  j["input"]["options"] = {{"frames", 20}, {"seed", 3}};
  return j;
}

// The lines of the scripts `imr submit` wrote into `batch`, and whether bash parses them.
std::vector<std::string> ScriptLines(const fs::path& batch) {
  std::vector<std::string> lines;
  for (const char* name : {"array.sbatch", "report.sbatch"}) {
    const fs::path script = batch / "imr-batch/slurm" / name;
    const CommandResult n = RunShell("bash -n " + Quote(script.string()));
    EXPECT_EQ(n.status, 0) << script << ": " << n.err;
    std::istringstream in(ReadText(script));
    for (std::string line; std::getline(in, line);) lines.push_back(line);
  }
  return lines;
}

TEST_F(BadJob, SubmitValuesThatWouldRunCommands) {
  // A newline in --time, --mem, --partition, --sbatch-arg ended the #SBATCH line and the rest ran
  // as a command in both scripts; --mem -5G and --time '' were written unchecked. Each is now
  // refused before anything is written (64).
  WriteText(Case() / "job.json", SubmitJob().dump(2));
  const std::vector<std::pair<std::string, std::string>> refused = {
      {"--time " + Quote("1:00:00\ntouch X #"), "--time: expected a Slurm time limit (minutes, M:S, "
                                                "H:M:S, D-H, D-H:M or D-H:M:S, or UNLIMITED), got "
                                                "'1:00:00\\ntouch X #'"},
      {"--time ''", "--time: expected a value, got ''"},
      {"--time 1:2:3:4", "--time: expected a Slurm time limit"},
      {"--mem -5G", "--mem: expected a memory size in megabytes, or with a unit K, M, G or T (e.g. "
                    "8G), got '-5G'"},
      {"--partition " + Quote("gpu\ntouch X"), "--partition: 'gpu\\ntouch X' holds a control "
                                               "character (a newline would end the #SBATCH line)"},
      {"--account " + Quote("a\nb"), "--account: 'a\\nb' holds a control character"},
      {"--qos " + Quote("q\rq"), "--qos: 'q\\rq' holds a control character"},
      {"--sbatch-arg " + Quote("--constraint=x\ntouch X"), "--sbatch-arg: '--constraint=x\\ntouch X' "
                                                          "holds a control character"},
      {"--sbatch-arg " + Quote("touch X"), "--sbatch-arg: expected an sbatch option"},
  };
  for (const auto& [flags, message] : refused) {
    const CommandResult r = InCase("submit job.json --tasks 2 --dry-run " + flags);
    EXPECT_EQ(r.status, kExitUsage) << flags << "\n" << r.out << r.err;
    EXPECT_NE(r.err.find("imr submit: " + message), std::string::npos) << flags << "\n" << r.err;
    EXPECT_FALSE(fs::exists(Case() / "runs")) << flags << " wrote " << Case() / "runs";
  }
  EXPECT_FALSE(fs::exists(Case() / "X"));
  // A job file whose name holds a newline: written on one line in the comments and as one
  // ANSI-C quoted word in the commands; no line of either script is the injected command.
  const std::string name = "j\ntouch Y #.json";
  WriteText(Case() / name, SubmitJob().dump(2));
  const CommandResult r = InCase("submit " + Quote(name) + " --tasks 2 --dry-run --time 1:00:00 --mem 2G");
  ASSERT_EQ(r.status, 0) << r.out << r.err;
  for (const std::string& line : ScriptLines(Case() / "runs")) EXPECT_NE(line.rfind("touch", 0), 0u) << line;
  EXPECT_NE(ReadText(Case() / "runs/imr-batch/slurm/array.sbatch").find("# Job " + (Case() / "j\\ntouch Y #.json").string()),
            std::string::npos);
  std::cout << "[ message  ] " << refused[0].second << "\n";
}

TEST_F(BadJob, SteinerGridThatWouldNeverEnd) {
  // engine.max_ray_length=1e12 or steiner_spacing=1e-9 passed validation and then ran for ever
  // (the grid around the first camera has ~1e32 nodes); now refused up front, naming the options
  // and the size. Milder values that only filled the memory are refused the same way.
  for (const auto& [set, size] : std::vector<std::pair<std::string, std::string>>{
           {"engine.max_ray_length=1e12", "6.4e+34 nodes"},
           {"engine.steiner_spacing=1e-9", "7.29e+32 nodes"},
           {"engine.steiner_margin=1e9", "6.4e+25 nodes"},
           {"engine.steiner_spacing=0.1", "7.34e+08 nodes"}}) {
    ExpectJobRefused(GoodJob().dump(2),
                     {"engine: the Steiner grid would have " + size + " around each camera",
                      "more than the 1e+07 allowed: raise steiner_spacing or lower max_ray_length "
                      "or steiner_margin"},
                     "--set " + set);
  }
}

TEST_F(BadJob, EngineUpdateThatRunsLong) {
  // A grid within the bound that still takes seconds per keyframe (a 0.45 m spacing: the grid
  // follows the rays (issue 47), and along the first keyframe's it takes more than 4 s; 0.9 m
  // took 1 s): the engine's update is watched under --stage-timeout like a plugin call, and
  // SIGTERM reaches its loops (it used to be ignored until the SIGKILL).
  json j = GoodJob();
  j["engine"]["steiner_spacing"] = 0.45;
  WriteText(Case() / "job.json", j.dump(2));
  const CommandResult t = InCase("run job.json --stage-timeout 1");
  EXPECT_NE(t.status, 0) << t.out << t.err;
  EXPECT_NE(t.err.find("stage \"engine\" (engine) did not return within 1 s (keyframe 0, frame "),
            std::string::npos) << t.err;
  EXPECT_NE(t.err.find("the limit is --stage-timeout"), std::string::npos) << t.err;
  EXPECT_EQ(Leftovers(Case() / "runs"), std::vector<std::string>{});

  fs::remove_all(Case() / "runs");
  const BackgroundRun run(Case(), "run");
  ASSERT_GT(run.pid(), 0);
  ASSERT_TRUE(WaitForText(Case() / "runs/imr-batch/status/street.json", "running", 60)) << run.Output();
  ::sleep(2);  // into the first camera's grid
  const auto sent = std::chrono::steady_clock::now();
  ::kill(run.pid(), SIGTERM);
  EXPECT_NE(run.Wait(60), 0) << run.Output();
  const double took = std::chrono::duration<double>(std::chrono::steady_clock::now() - sent).count();
  EXPECT_LT(took, 8.0) << "SIGTERM did not stop the engine's loop\n" << run.Output();
  const json street = SummaryRow(ReadJson(Case() / "runs/summary.json"), "street");
  EXPECT_EQ(street["status"], "interrupted") << street.dump(2);
  EXPECT_EQ(street.value("error", "").find("was killed"), std::string::npos) << street.dump(2);
  const std::size_t at = t.err.find("stage \"engine\"");
  std::cout << "[ message  ] " << t.err.substr(at, t.err.find('\n', at) - at)
            << "; SIGTERM ended the run in " << took << " s\n";
}

TEST_F(BadSfm, BatchFolderHoldsTheUsersFiles) {
  // output.directory "{sequence}_mesh" makes the job's own folder the batch folder: the user's
  // index.html and summary.md beside the input used to be replaced. Refused (73), untouched.
  // (Output into the input's own folder, "{sequence}", is refused by the write rule itself:
  // WriteRuleCli.)
  CopyModel(Case() / "A");
  json job = EngineJob("colmap", {"A"});
  job["output"]["directory"] = "{sequence}_mesh";
  WriteText(Case() / "index.html", "<p>my page</p>\n");
  WriteText(Case() / "summary.md", "# my notes\n");
  WriteText(Case() / "job.json", job.dump(2));
  CommandResult r = InCase("run job.json");
  EXPECT_EQ(r.status, kExitCantCreate) << r.out << r.err;
  EXPECT_NE(r.err.find("imr run: " + (Case() / "summary.md").string() +
                       ": a file imr did not write (no record of it in imr's ledger " +
                       (Case() / ".imr-written").string() +
                       "); imr never writes over a file it did not write: imr would overwrite it "
                       "with the batch summary"),
            std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(Case() / "A_mesh/report.json")) << "it ran";
  std::cout << "[ message  ] " << r.err.substr(r.err.find("imr run: ")) << "\n";
  fs::remove(Case() / "summary.md");
  r = InCase("run job.json");
  EXPECT_EQ(r.status, kExitCantCreate) << r.out << r.err;
  EXPECT_NE(r.err.find((Case() / "index.html").string() + ": a file imr did not write"),
            std::string::npos) << r.err;
  EXPECT_NE(r.err.find("or give imr run --no-viewer"), std::string::npos) << r.err;
  // Without the page it runs; the user's page stays, and imr's own files are rewritten freely.
  for (int i = 0; i < 2; ++i) {
    r = InCase("run job.json --no-viewer");
    EXPECT_EQ(r.status, 0) << r.out << r.err;
  }
  EXPECT_EQ(ReadText(Case() / "index.html"), "<p>my page</p>\n");
  EXPECT_EQ(ReadText(Case() / "summary.md").rfind("# imr batch summary", 0), 0u);
  // `imr report` keeps the summary and leaves the page alone.
  r = InCase("report job.json");
  EXPECT_EQ(r.status, 0) << r.out << r.err;
  EXPECT_NE(r.err.find("viewer page not written: " + (Case() / "index.html").string()), std::string::npos) << r.err;
  EXPECT_EQ(ReadText(Case() / "index.html"), "<p>my page</p>\n");
}

TEST_F(BadJob, JobNamedLikeAParentFolder) {
  // "...json" has the stem "..": runs/{job}/{sequence} climbed out of runs/, and `imr validate`
  // accepted it.
  json j = GoodJob();
  j["output"]["directory"] = "runs/{job}/{sequence}";
  WriteText(Case() / "...json", j.dump(2));
  const CommandResult r = InCase("validate ...json");
  EXPECT_EQ(r.status, kExitUsage) << r.out << r.err;
  EXPECT_NE(r.err.find("output.directory: {job} would be '..' (the job file ...json): not a folder "
                       "name; rename the job file"),
            std::string::npos) << r.err;
  EXPECT_EQ(InCase("run ...json").status, kExitUsage);
  EXPECT_FALSE(fs::exists(Case() / "runs"));
  std::cout << "[ message  ] " << r.err << "\n";
}

TEST_F(BadSfm, GlobOverTheOutputFolder) {
  // Sequences "cm/*/" with output "cm/{sequence}_mesh": every re-run took imr's own folders
  // (cm/imr-batch, cm/assets, A_mesh) for sequences, and the batch grew (0, then 4, then 8
  // failures). They are left out; a re-run is up to date.
  CopyModel(Case() / "cm/A");
  CopyModel(Case() / "cm/B");
  json job = EngineJob("colmap", {"cm/*/"});
  job["output"]["directory"] = "cm/{sequence}_mesh";
  WriteText(Case() / "job.json", job.dump(2));
  for (int run = 0; run < 3; ++run) {
    const CommandResult r = InCase("run job.json");
    EXPECT_EQ(r.status, 0) << "run " << run << "\n" << r.out << r.err;
    const json summary = ReadJson(Case() / "cm/summary.json");
    EXPECT_EQ(summary["counts"]["sequences"], 2) << summary.dump(2);
    if (run > 0) {
      EXPECT_NE(r.out.find("2 skipped (up to date)"), std::string::npos) << r.out;
    }
  }
  EXPECT_FALSE(fs::exists(Case() / "cm/A_mesh_mesh"));
  const CommandResult v = InCase("validate job.json -v");
  EXPECT_NE(v.err.find("left out what imr wrote"), std::string::npos) << v.err;
}

TEST_F(BadSfm, SequenceNamedLikeTheBatchFolderFiles) {
  // summary.md used to fail the summary ("Is a directory") and still exit 0; index.html stopped
  // the viewer page; assets shared the viewer's folder; imr-batch passed `imr validate`.
  for (const char* n : {"summary.md", "summary.json", "index.html", "assets", "imr-batch", "good"})
    CopyModel(Case() / "seqs" / n);
  WriteText(Case() / "job.json", EngineJob("colmap", {"seqs/*/"}).dump(2));
  const CommandResult r = InCase("validate job.json");
  EXPECT_EQ(r.status, kExitUsage) << r.out << r.err;
  for (const char* n : {"summary.md", "summary.json", "index.html", "assets", "imr-batch"})
    EXPECT_NE(r.err.find("sequence '" + std::string(n) + "': its output folder " +
                         (Case() / "runs" / n).string() + " is the batch folder's " + n +
                         ", which imr run writes"),
              std::string::npos) << n << "\n" << r.err;
  ExpectJobRefused(EngineJob("colmap", {"seqs/*/"}).dump(2), {"is the batch folder's summary.md"});
}

TEST_F(BadJob, SequenceListWithoutEnd) {
  // --sequences-from had no bound: a 2 GB file of zeros took 33 s and 8.4 GB, a 200 MB line was
  // echoed whole (NUL bytes too) into the log. Now 64 MiB and 64 KiB lines at most, and the
  // message quotes 80 bytes.
  WriteText(Case() / "job.json", GoodJob().dump(2));
  ASSERT_EQ(RunShell("truncate -s 2G " + Quote((Case() / "zeros.txt").string())).status, 0);
  const auto t0 = std::chrono::steady_clock::now();
  CommandResult r = RunShell("ulimit -v 4194304; cd " + Quote(Case().string()) + " && " +
                             Quote(kImr) + " run job.json --sequences-from zeros.txt");
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_EQ(r.status, kExitUsage) << r.err.substr(0, 400);
  EXPECT_NE(r.err.find("zeros.txt: more than 64 MiB: not a sequence list"), std::string::npos) << r.err.substr(0, 400);
  EXPECT_LT(seconds, 10.0);
  WriteText(Case() / "long.txt", "street\n" + std::string(200000, 'x') + std::string(1, '\0') + "\n");
  r = InCase("run job.json --sequences-from long.txt");
  EXPECT_EQ(r.status, kExitUsage) << r.err.substr(0, 400);
  EXPECT_NE(r.err.find("long.txt:2: 200001 bytes, more than a name (65536 at most): " +
                       std::string(80, 'x') + "... (200001 bytes)"),
            std::string::npos) << r.err.substr(0, 400);
  EXPECT_LT(r.err.size(), 2000u);
  std::cout << "[ message  ] " << r.err.substr(0, 200) << "\n";
}

TEST_F(BadSfm, HugeSparseFileNamedLikeAMesh) {
  // `imr evaluate` and `imr render` read a 2 GB sparse file whole (2.1 GB, up to 12 s) before
  // "not a PLY file"; the header is now read first.
  const fs::path zeros = Case() / "zeros.ply";
  ASSERT_EQ(RunShell("truncate -s 2G " + Quote(zeros.string())).status, 0);
  const fs::path mesh = *dir_ / "fixture-run/mesh.ply";
  for (const std::string& args :
       {"evaluate " + Quote(zeros.string()) + " --truth " + Quote(mesh.string()),
        "evaluate " + Quote(mesh.string()) + " --truth " + Quote(zeros.string()),
        "render " + Quote(zeros.string()) + " --sequence " + Quote(Fixture("slam/good.json").string()) +
            " --format slam_json --frame 0 --out " + Quote((Case() / "r.png").string())}) {
    const auto t0 = std::chrono::steady_clock::now();
    const CommandResult r = RunShell("ulimit -v 2097152; " + Quote(kImr) + " " + args);
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    EXPECT_NE(r.status, 0) << args;
    EXPECT_NE(r.err.find(zeros.string() + ": not a PLY file (no 'ply' first line)"), std::string::npos)
        << args << "\n" << r.err;
    EXPECT_LT(seconds, 3.0) << args;
  }
}

// Forgetting (engine.forget) that leaves input out says so (issue 44, finding 11). A street
// stream exported by imr (200 frames), then two ways to reach what was forgotten: the car drives
// back over its path (the same points seen again, re-estimated 0.3 m higher), and the cameras
// and every position from keyframe 20 on jump 1 km aside (a SLAM system's relocalisation: the
// points still tracked move with them). With forget_distance 5 the mesh then differs from the
// run without forgetting; report.json's warnings and stderr say why, with the counts.
TEST_F(BadSfm, ForgettingThatLeavesInputOutSaysSo) {
  json job = SyntheticJob();
  job["sequences"] = {"street"};
  job["input"]["options"]["frames"] = 200;
  job["output"]["directory"] = "export-run";
  WriteText(Case() / "export.json", job.dump(2));
  const CommandResult exported = InCase("run -q export.json --export-stream street.json");
  ASSERT_EQ(exported.status, 0) << exported.err;
  const json stream = ReadJson(Case() / "street.json");
  const json& keyframes = stream["imr_stream"]["keyframes"];
  ASSERT_GT(keyframes.size(), 30u);
  const int64_t last = keyframes.back()["keyframe"], last_frame = keyframes.back()["frame"];

  // Back over the path: each keyframe's views again in reverse order, new view ids, the points
  // each view saw first (its own keyframe's estimates), 0.3 m higher.
  json back = stream;
  uint64_t max_view = 0;
  for (const json& v : stream["views"]) max_view = std::max<uint64_t>(max_view, v["viewId"]);
  for (int64_t k = last; k >= 0; --k) {
    const int64_t again = last + 1 + (last - k);
    back["imr_stream"]["keyframes"].push_back(
        {{"keyframe", again}, {"frame", last_frame + 1 + (last - k)}, {"removed_points", json::array()}});
    for (const json& v : stream["views"]) {
      if (v["keyframe"] != k) continue;
      json w = v;
      w["viewId"] = max_view + 1 + w["viewId"].get<uint64_t>();
      w["keyframe"] = again;
      w["observations"] = json::array();
      for (const json& o : v["observations"]) {
        if (o.contains("keyframe")) continue;
        json x = o;
        x["X"][2] = x["X"][2].get<double>() + 0.3;
        w["observations"].push_back(x);
      }
      back["views"].push_back(w);
    }
  }
  WriteText(Case() / "back.json", back.dump());
  // The jump: centres and positions (observations at keyframe 20 and later) 1 km along x.
  json jump = stream;
  for (json& v : jump["views"]) {
    if (v["keyframe"].get<int64_t>() >= 20)
      v["extrinsic"]["center"][0] = v["extrinsic"]["center"][0].get<double>() + 1000.0;
    for (json& o : v["observations"])
      if (o.value("keyframe", v["keyframe"].get<int64_t>()) >= 20)
        o["X"][0] = o["X"][0].get<double>() + 1000.0;
  }
  WriteText(Case() / "jump.json", jump.dump());

  json j = EngineJob("slam_json", {"back.json", "jump.json"});
  j["engine"] = {{"forget", true}, {"forget_distance", 5}};
  const CommandResult r = Run(j);
  CheckEverySequenceOk(r, Case() / "runs", j, {"back.json", "jump.json"});
  for (const char* name : {"back.json", "jump.json"}) {
    SCOPED_TRACE(name);
    const json report = ReadJson(Case() / "runs" / name / "report.json");
    const json& forget = report["engine"]["forget"];
    const int64_t refused = forget["changes_refused_final"], blocked = forget["shrinks_blocked_final"],
                  ignored = forget["updates_of_forgotten_points"];
    EXPECT_GT(refused + blocked + ignored, 0) << forget.dump(2);
    EXPECT_GE(refused, forget["points_refused_final"].get<int64_t>());
    ASSERT_TRUE(report["warnings"].is_array()) << report.dump(2).substr(0, 2000);
    std::string warning;
    for (const json& w : report["warnings"])
      if (w.get<std::string>().find("forgetting (engine.forget) left input out of the mesh") == 0)
        warning = w;
    EXPECT_NE(warning, "") << report["warnings"].dump(2);
    if (ignored > 0) {
      EXPECT_NE(warning.find(std::to_string(ignored) + " updates (moves, removals) of points already "
                                                       "forgotten were ignored"),
                std::string::npos) << warning;
    }
    if (refused > 0) {
      EXPECT_NE(warning.find(std::to_string(refused) + " changes were refused"), std::string::npos)
          << warning;
    }
    if (blocked > 0) {
      EXPECT_NE(warning.find(std::to_string(blocked) + " moves and insertions next to it failed"),
                std::string::npos) << warning;
    }
    EXPECT_NE(warning.find("engine.forget_distance (5)"), std::string::npos) << warning;
    EXPECT_NE(r.err.find("warning: [" + std::string(name) + "] forgetting (engine.forget) left input out"),
              std::string::npos) << r.err;
  }
  // The drive back: the same points seen again after they were forgotten.
  EXPECT_GT(ReadJson(Case() / "runs/back.json/report.json")["engine"]["forget"]["updates_of_forgotten_points"]
                .get<int64_t>(), 0);
  // Without forgetting nothing is left out: no such warning (false: auto, the default, forgets
  // on these drives too).
  j["engine"] = {{"forget", false}};
  const CommandResult off = Run(j);
  CheckEverySequenceOk(off, Case() / "runs", j, {"back.json", "jump.json"});
  EXPECT_EQ(off.err.find("forgetting (engine.forget)"), std::string::npos) << off.err;
}

TEST_F(BadSfm, ImpossibleOrStaleInput) {
  // (a) Every point behind the cameras that see it (a stream re-imported with its points
  // mirrored through the cameras) meshed "ok" in the wrong place.
  json j = ReadJson(Fixture("slam/good.json"));
  for (json& v : j["views"]) {
    const json c = v["extrinsic"]["center"];
    for (json& o : v["observations"])
      for (int k = 0; k < 3; ++k) o["X"][k] = 2.0 * c[k].get<double>() - o["X"][k].get<double>();
  }
  WriteText(Case() / "bad.json", j.dump());
  ExpectOnlyTheBadSequenceFails(EngineJob("slam_json", {"bad.json", Fixture("slam/good.json")}),
                                "bad.json", "good.json",
                                {"observations of new points", "put the point behind the camera "
                                 "that sees it (first: point ", "are the points mirrored"});
  // (b) One view listing a point twice with two positions was accepted.
  j = ReadJson(Fixture("slam/good.json"));
  json& obs = j["views"][3]["observations"];
  json twice = obs[0];
  twice["X"][0] = twice["X"][0].get<double>() + 1.0;
  obs.push_back(twice);
  WriteText(Case() / "bad.json", j.dump());
  ExpectOnlyTheBadSequenceFails(EngineJob("slam_json", {"bad.json", Fixture("slam/good.json")}),
                                "bad.json", "good.json",
                                {(Case() / "bad.json").string(), "views[3].observations[" +
                                 std::to_string(obs.size() - 1) + "].pointId: point " +
                                 std::to_string(twice["pointId"].get<uint64_t>()) +
                                 " is listed twice in view", "a view sees a point once"});
  // (c) An input replaced at the same path was "skipped, up to date" with the old mesh,
  // although report.json holds the input's SHA-256: it is redone.
  fs::copy_file(Fixture("slam/good.json"), Case() / "in.json");
  const std::string mesh = "imr mesh --input in.json --format slam_json --out m.ply";
  CommandResult r = InCase(mesh.substr(4));
  ASSERT_EQ(r.status, 0) << r.out << r.err;
  r = InCase(mesh.substr(4));
  EXPECT_NE(r.err.find("skipped, up to date"), std::string::npos) << r.err;
  json k = ReadJson(Fixture("slam/good.json"));
  k["views"].erase(k["views"].end() - 3, k["views"].end());  // the last three views
  WriteText(Case() / "in.json", k.dump());
  r = InCase(mesh.substr(4));
  EXPECT_EQ(r.status, 0) << r.out << r.err;
  EXPECT_NE(r.err.find("running (its input " + (Case() / "in.json").string() +
                       " changed since the last run (SHA-256))"),
            std::string::npos) << r.err;
}

TEST_F(BadSfm, MeshOutThatWasNotWritten) {
  // `imr mesh` said "mesh: OUT" and exited 0 when OUT was never written (--out m/Mesh.PLY wrote
  // Mesh.ply; --set output.stem / output.formats wrote other files); --set output.directory
  // ended in a JSON parse error; --out '' or a folder: a filesystem exception or a full-size
  // .partial left behind.
  const std::string in = Fixture("slam/good.json").string();
  const std::string base = "mesh --input " + Quote(in) + " --format slam_json --work w ";
  fs::create_directories(Case() / "m");
  CommandResult r = InCase(base + "--out m/Mesh.PLY");
  ASSERT_EQ(r.status, 0) << r.out << r.err;
  EXPECT_NE(r.out.find("mesh: " + (Case() / "m/Mesh.PLY").string() + "\n"), std::string::npos) << r.out;
  EXPECT_GT(fs::file_size(Case() / "m/Mesh.PLY"), 0u);
  EXPECT_FALSE(fs::exists(Case() / "m/Mesh.ply"));
  for (const std::string set : {"output.stem=other", "output.formats=[\"glb\"]",
                                 "output.directory=ELSEWHERE", "output.formats[0]=obj"}) {
    r = InCase(base + "--out m/x.ply --set " + Quote(set));
    EXPECT_EQ(r.status, kExitUsage) << set << "\n" << r.out << r.err;
    EXPECT_NE(r.err.find("imr mesh: --set " + set + ": imr mesh sets output.directory, "
                         "output.stem and output.formats from --out"),
              std::string::npos) << r.err;
  }
  r = InCase(base + "--out ''");
  EXPECT_EQ(r.status, kExitUsage) << r.out << r.err;
  EXPECT_NE(r.err.find("imr mesh: --out: expected a mesh file name, got ''"), std::string::npos) << r.err;
  fs::create_directories(Case() / "d.ply");
  r = InCase(base + "--out d.ply");
  EXPECT_EQ(r.status, kExitUsage) << r.out << r.err;
  EXPECT_NE(r.err.find((Case() / "d.ply").string() + " is a folder; name the mesh file"), std::string::npos) << r.err;
  EXPECT_EQ(Leftovers(Case()), std::vector<std::string>{});
  // A full disk at --out: "No space left on device", 73 (the run succeeded), no .partial.
  TmpfsMount full(Case() / "full", 0, "size=16k");
  if (!full.SkipReason().empty()) GTEST_SKIP() << full.SkipReason();
  r = InCase(base + "--out full/mesh.ply");
  EXPECT_EQ(r.status, kExitCantCreate) << r.out << r.err;
  EXPECT_NE(r.err.find("imr mesh: cannot copy the mesh to --out: " + (Case() / "full/mesh.ply").string() +
                       ": write failed: No space left on device"),
            std::string::npos) << r.err;
  EXPECT_EQ(FilesUnder(Case() / "full"), std::vector<std::string>{});
  std::cout << "[ message  ] " << r.err.substr(r.err.find("imr mesh: ")) << "\n";
}

TEST_F(BadSfm, RenderNamesWhatItRead) {
  // A folder given as a SLAM JSON file: "basic_filebuf::underflow ... Is a directory" without
  // the path; a successful render printed "frame 5 ()".
  fs::create_directories(Case() / "folder");
  const fs::path mesh = *dir_ / "fixture-run/mesh.ply";
  const std::string out = " --out " + Quote((Case() / "r.png").string());
  CommandResult r = RunShell(Quote(kImr) + " render " + Quote(mesh.string()) + " --sequence " +
                             Quote((Case() / "folder").string()) + " --format slam_json --frame 0" + out);
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.err.find((Case() / "folder").string() + ": is a folder, expected a JSON file"),
            std::string::npos) << r.err;
  r = RunShell(Quote(kImr) + " render " + Quote(mesh.string()) + " --sequence " +
               Quote(Fixture("slam/good.json").string()) + " --format slam_json --frame 5" + out);
  EXPECT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.out.find(": frame 5 (view "), std::string::npos) << r.out;
  EXPECT_EQ(r.out.find("()"), std::string::npos) << r.out;
}

TEST_F(BadJob, MessagesThatSaidTheWrongThing) {
  // --stage-timeout -1 said "> 0" though 0 is accepted; --set engine=null said "got null null";
  // --max-rss 99999999999999999999G was accepted (it overflowed).
  ExpectJobRefused(GoodJob().dump(2),
                   {"--stage-timeout: expected a number of seconds >= 0 (0: no limit) and at most "
                    "31536000 (a year), got -1"},
                   "--stage-timeout=-1");
  ExpectJobRefused(GoodJob().dump(2), {"engine: expected object, got null\n"}, "--set engine=null");
  WriteText(Case() / "job.json", GoodJob().dump(2));
  const CommandResult r = InCase("validate job.json --set engine=null");
  EXPECT_EQ(r.err.find("null null"), std::string::npos) << r.err;
  ExpectJobRefused(GoodJob().dump(2), {"--max-rss: expected a size like 512M or 4G, got "
                                       "'99999999999999999999G' (at most 4 EiB)"},
                   "--max-rss 99999999999999999999G");
}

}  // namespace
}  // namespace imr::testing
