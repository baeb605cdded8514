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

#include <sys/mount.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <iostream>
#include <map>
#include <sstream>

#include "host/io/image_io.h"
#include "test_util.h"

namespace imr::testing {
namespace {
namespace fs = std::filesystem;
using nlohmann::json;

const std::string kImr = IMR_EXE;
const std::string kSynth = IMR_SYNTH_EXE;
const std::string kTestPlugins = IMR_TEST_PLUGIN_DIR;

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
    return RunShell("cd " + Quote(Case().string()) + " && " + Quote(kImr) +
                    " run --jobs 2 job.json " + flags);
  }

  // The four guarantees for a job whose sequence `bad` is bad and `good` is fine; `error_has`:
  // what the failure must name (the file, the field or line, what was expected).
  void ExpectOnlyTheBadSequenceFails(const json& job, const std::string& bad,
                                     const std::string& good,
                                     const std::vector<std::string>& error_has,
                                     const std::string& flags = "", bool keep_runs = false) const {
    const CommandResult r = Run(job, flags, keep_runs);
    const fs::path batch = Case() / "runs";
    // (b) a non-zero status (not a particular one: `imr run` counts failures).
    EXPECT_NE(r.status, 0) << r.out << r.err;
    ASSERT_TRUE(fs::exists(batch / "summary.json")) << r.out << r.err;
    const json summary = ReadJson(batch / "summary.json");
    json bad_entry, good_entry;
    for (const json& s : summary["sequences"]) {
      if (s["name"] == bad) bad_entry = s;
      if (s["name"] == good) good_entry = s;
    }
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
    const fs::path good_out = batch / good;
    for (const json& f : job["output"]["formats"]) {
      const fs::path mesh = good_out / ("mesh." + f.get<std::string>());
      EXPECT_GT(fs::exists(mesh) ? fs::file_size(mesh) : 0u, 0u) << mesh << " missing or empty";
    }
    EXPECT_TRUE(fs::exists(good_out / "report.json")) << good_out;
    EXPECT_TRUE(fs::exists(good_out / "manifest.json")) << good_out;
    // (d) nothing of the bad sequence that could pass for output, no leftovers anywhere.
    EXPECT_EQ(FilesUnder(batch / bad), std::vector<std::string>{}) << "in " << batch / bad;
    EXPECT_EQ(Leftovers(batch), std::vector<std::string>{});
  }

  // A job refused as a whole: non-zero status, stderr names the job file and each of
  // `error_has` (the JSON path and what was expected), nothing ran, nothing was written.
  void ExpectJobRefused(const std::string& job_text, const std::vector<std::string>& error_has,
                        const std::string& flags = "") const {
    fs::remove_all(Case() / "runs");
    WriteText(Case() / "job.json", job_text);
    const CommandResult r = RunShell("cd " + Quote(Case().string()) + " && " + Quote(kImr) +
                                     " run job.json " + flags);
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
  static ScratchDir* dir_;
};
ScratchDir* BadSfm::dir_ = nullptr;

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
  const fs::path model = Case() / "bad";
  fs::copy(Fixture("colmap"), model, fs::copy_options::recursive);
  // The first point's first track entry: POINT3D_ID X Y Z R G B ERROR IMAGE_ID POINT2D_IDX ...
  std::istringstream in(ReadText(model / "points3D.txt"));
  std::string text;
  bool done = false;
  for (std::string line; std::getline(in, line);) {
    if (!done && !line.empty() && line[0] != '#') {
      std::istringstream words(line);
      std::vector<std::string> w;
      for (std::string x; words >> x;) w.push_back(x);
      w.at(8) = "99999";
      line.clear();
      for (const auto& x : w) line += (line.empty() ? "" : " ") + x;
      done = true;
    }
    text += line + "\n";
  }
  WriteText(model / "points3D.txt", text);
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
                               "input.options.frames: expected integer >= 1, got \"twenty\"",
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
                               "input.options.frames: expected integer >= 1 (a 32-bit integer"});
  std::string text = GoodJob().dump(2);
  text.insert(text.find("\"input\""), "\"engine\": {\"window\": 123456789012345678901234567890},\n  ");
  ExpectJobRefused(text, {"engine.window: expected integer >= 1, got 1.2345678901234568e+29"});
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

}  // namespace
}  // namespace imr::testing
