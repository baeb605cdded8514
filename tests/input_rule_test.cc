// The open rule end to end (issue 44; host/util/input_file.h, docs/reliability.md "Reading"): for
// every reader, a FIFO where it expects a file, and the real command (imr run, mesh, validate,
// evaluate, render, tiles merge) under a 5 s watchdog. Each must exit non-zero at once with a
// message naming the FIFO; before the rule, most of them waited on it until killed, through
// --stage-timeout and SIGTERM. The same table holds the rule's wording findings (a device, a
// folder, a file where a folder is expected).
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include <sys/stat.h>

#include <algorithm>
#include <functional>
#include <iostream>
#include <string>
#include <vector>

#include "test_util.h"

namespace imr::testing {
namespace {
namespace fs = std::filesystem;
using nlohmann::json;

const std::string kImr = IMR_EXE;
const std::string kSynth = IMR_SYNTH_EXE;

std::string FifoWords(const fs::path& p) { return p.string() + ": is not a regular file (a FIFO)"; }

void MakeFifo(const fs::path& p) {
  std::error_code ec;
  fs::remove_all(p, ec);
  ASSERT_EQ(::mkfifo(p.c_str(), 0600), 0) << p;
}

json EngineJob(const std::string& format, const std::string& sequence) {
  return {{"sequences", {sequence}},
          {"input", {{"format", format}}},
          {"pipeline", {{{"kind", "exporter"}, {"plugin", "org.imr.exporter.assimp"}}}},
          {"output", {{"directory", "runs/{sequence}"}, {"formats", {"ply"}}}}};
}

// The image pipeline on one sequence of `format` (kitti_odometry, middlebury).
json ImageJob(const std::string& format, const std::string& sequence) {
  return {{"sequences", {sequence}},
          {"input", {{"format", format}}},
          {"pipeline",
           {{{"kind", "features"}, {"plugin", "org.imr.features.edge_klt"}},
            {{"kind", "refiner"}, {"plugin", "org.imr.refiner.ceres"}},
            {{"kind", "exporter"}, {"plugin", "org.imr.exporter.assimp"}}}},
          {"output", {{"directory", "runs/{sequence}"}, {"formats", {"ply"}}}}};
}

// The suite's inputs, made once: a synthetic run with tiles, its stream (SLAM JSON) and COLMAP
// model, and a small imr-synth image sequence (KITTI odometry layout, with Velodyne scans).
class InputRule : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new ScratchDir("input-rule");
    const json job = {
        {"sequences", {"street"}},
        {"input", {{"format", "synthetic"}, {"options", {{"frames", 30}, {"seed", 3}}}}},
        {"pipeline", {{{"kind", "exporter"}, {"plugin", "org.imr.exporter.assimp"}}}},
        {"output",
         {{"directory", "runs/{sequence}"}, {"formats", {"ply"}}, {"tiles", {{"size", 20}}}}}};
    WriteText(Root() / "fixture.json", job.dump(2));
    const CommandResult r =
        RunShell("cd " + Quote(Root().string()) + " && " + Quote(kImr) +
                 " run -q fixture.json --export-stream slam.json --export-colmap colmap");
    ASSERT_EQ(r.status, 0) << r.out << r.err;
    const CommandResult s = RunShell(Quote(kSynth) + " --out " + Quote((Root() / "kitti").string()) +
                                     " --frames 6 --width 414 --height 125 --lidar-step 2 -q");
    ASSERT_EQ(s.status, 0) << s.out << s.err;
  }
  static void TearDownTestSuite() {
    delete dir_;
    dir_ = nullptr;
  }
  void SetUp() override {
    ASSERT_TRUE(fs::exists(Root() / "runs/street/tileset.json")) << "no fixture run";
    ASSERT_TRUE(fs::exists(Root() / "kitti/poses.txt")) << "no fixture sequence";
  }
  static fs::path Root() { return dir_->path(); }
  static fs::path Run() { return Root() / "runs/street"; }
  static fs::path Mesh() { return Run() / "mesh.ply"; }
  // A copy of a fixture folder under `work`.
  static fs::path Copy(const fs::path& from, const fs::path& work, const std::string& name) {
    fs::copy(from, work / name, fs::copy_options::recursive);
    return work / name;
  }
  // The first file of the sequence's first image folder (image_0 .. image_3), by name.
  static fs::path SomeImage(const fs::path& seq) {
    for (const char* d : {"image_0", "image_1", "image_2", "image_3"}) {
      if (!fs::is_directory(seq / d)) continue;
      std::vector<fs::path> files;
      for (const auto& e : fs::directory_iterator(seq / d)) files.push_back(e.path());
      std::sort(files.begin(), files.end());
      if (files.size() > 1) return files[1];
    }
    return {};
  }
  static fs::path SomeScan(const fs::path& seq) {
    for (const auto& e : fs::recursive_directory_iterator(seq))
      if (e.path().extension() == ".bin") return e.path();
    return {};
  }
  static fs::path FirstTile(const fs::path& run) {
    std::vector<fs::path> tiles;
    for (const auto& e : fs::directory_iterator(run / "tiles"))
      if (e.path().filename().string().rfind("tile_", 0) == 0) tiles.push_back(e.path());
    std::sort(tiles.begin(), tiles.end());
    return tiles.empty() ? fs::path() : tiles.front();
  }
  static ScratchDir* dir_;
};
ScratchDir* InputRule::dir_ = nullptr;

// One row: makes the bad input under `work` and returns the command's arguments (run in
// `work`) and the words the refusal must hold.
struct Row {
  std::string name;
  std::function<std::pair<std::string, std::string>(const fs::path& work)> make;
};

TEST_F(InputRule, EveryReaderRefusesAFifoAtOnceNamingIt) {
  const auto job_with = [](const fs::path& work, const json& job) {
    WriteText(work / "job.json", job.dump(2));
    return std::string("run -q job.json");
  };
  const std::vector<Row> rows = {
      {"run: a SLAM JSON sequence",
       [&](const fs::path& w) {
         MakeFifo(w / "stream.json");
         return std::pair{job_with(w, EngineJob("slam_json", (w / "stream.json").string())),
                          FifoWords(w / "stream.json")};
       }},
      {"run: an OpenMVG sfm_data",
       [&](const fs::path& w) {
         MakeFifo(w / "sfm_data.json");
         return std::pair{job_with(w, EngineJob("openmvg", (w / "sfm_data.json").string())),
                          FifoWords(w / "sfm_data.json")};
       }},
      {"run: a COLMAP text model's images.txt",
       [&](const fs::path& w) {
         const fs::path m = Copy(Root() / "colmap", w, "model");
         MakeFifo(m / "images.txt");
         return std::pair{job_with(w, EngineJob("colmap", m.string())), FifoWords(m / "images.txt")};
       }},
      {"run: a COLMAP binary model",
       [&](const fs::path& w) {
         fs::create_directories(w / "model");
         for (const char* f : {"cameras.bin", "images.bin", "points3D.bin"}) MakeFifo(w / "model" / f);
         return std::pair{job_with(w, EngineJob("colmap", (w / "model").string())),
                          FifoWords(w / "model/cameras.bin")};
       }},
      {"run: KITTI calib.txt",
       [&](const fs::path& w) {
         const fs::path s = Copy(Root() / "kitti", w, "seq");
         MakeFifo(s / "calib.txt");
         return std::pair{job_with(w, ImageJob("kitti_odometry", s.string())), FifoWords(s / "calib.txt")};
       }},
      {"run: KITTI times.txt",
       [&](const fs::path& w) {
         const fs::path s = Copy(Root() / "kitti", w, "seq");
         MakeFifo(s / "times.txt");
         return std::pair{job_with(w, ImageJob("kitti_odometry", s.string())), FifoWords(s / "times.txt")};
       }},
      {"run: KITTI poses.txt",
       [&](const fs::path& w) {
         const fs::path s = Copy(Root() / "kitti", w, "seq");
         MakeFifo(s / "poses.txt");
         return std::pair{job_with(w, ImageJob("kitti_odometry", s.string())), FifoWords(s / "poses.txt")};
       }},
      {"run: a frame's image",
       [&](const fs::path& w) {
         const fs::path s = Copy(Root() / "kitti", w, "seq");
         const fs::path image = SomeImage(s);
         MakeFifo(image);
         return std::pair{job_with(w, ImageJob("kitti_odometry", s.string())), FifoWords(image)};
       }},
      {"run: a Middlebury *_par.txt",
       [&](const fs::path& w) {
         fs::create_directories(w / "mb");
         MakeFifo(w / "mb/scene_par.txt");
         return std::pair{job_with(w, ImageJob("middlebury", (w / "mb").string())),
                          FifoWords(w / "mb/scene_par.txt")};
       }},
      {"run: the job file",
       [&](const fs::path& w) {
         MakeFifo(w / "job.json");
         return std::pair{std::string("run -q ") + Quote((w / "job.json").string()), FifoWords(w / "job.json")};
       }},
      {"validate: the job file",
       [&](const fs::path& w) {
         MakeFifo(w / "job.json");
         return std::pair{std::string("validate ") + Quote((w / "job.json").string()),
                          FifoWords(w / "job.json")};
       }},
      {"validate: a device as the job file",
       [&](const fs::path&) {
         return std::pair{std::string("validate /dev/zero"),
                          std::string("/dev/zero: is not a regular file (a character device)")};
       }},
      {"run: --sequences-from",
       [&](const fs::path& w) {
         MakeFifo(w / "list.txt");
         json job = EngineJob("slam_json", (Root() / "slam.json").string());
         return std::pair{job_with(w, job) + " --sequences-from " + Quote((w / "list.txt").string()),
                          FifoWords(w / "list.txt")};
       }},
      {"validate: the job's evaluation.truth",
       [&](const fs::path& w) {
         MakeFifo(w / "truth.ply");
         json job = EngineJob("slam_json", (Root() / "slam.json").string());
         job["evaluation"] = {{"truth", (w / "truth.ply").string()}};
         WriteText(w / "job.json", job.dump(2));
         return std::pair{std::string("validate job.json"), FifoWords(w / "truth.ply")};
       }},
      {"mesh: a SLAM JSON input",
       [&](const fs::path& w) {
         MakeFifo(w / "stream.json");
         return std::pair{"mesh -q --input " + Quote((w / "stream.json").string()) +
                              " --format slam_json --out " + Quote((w / "out.ply").string()),
                          FifoWords(w / "stream.json")};
       }},
      {"evaluate: the mesh",
       [&](const fs::path& w) {
         MakeFifo(w / "mesh.ply");
         return std::pair{"evaluate " + Quote((w / "mesh.ply").string()) + " --truth " +
                              Quote(Mesh().string()),
                          FifoWords(w / "mesh.ply")};
       }},
      {"evaluate: the ground truth",
       [&](const fs::path& w) {
         MakeFifo(w / "truth.ply");
         return std::pair{"evaluate " + Quote(Mesh().string()) + " --truth " +
                              Quote((w / "truth.ply").string()) + " --no-crop",
                          FifoWords(w / "truth.ply")};
       }},
      {"evaluate: a Velodyne scan",
       [&](const fs::path& w) {
         const fs::path s = Copy(Root() / "kitti", w, "seq");
         const fs::path scan = SomeScan(s);
         MakeFifo(scan);
         return std::pair{"evaluate " + Quote(Mesh().string()) + " --velodyne-seq " + Quote(s.string()),
                          FifoWords(scan)};
       }},
      {"render: the mesh",
       [&](const fs::path& w) {
         MakeFifo(w / "mesh.ply");
         return std::pair{"render " + Quote((w / "mesh.ply").string()) + " --sequence " +
                              Quote((Root() / "kitti").string()) + " --format kitti_odometry --frame 0 --out " +
                              Quote((w / "out.png").string()),
                          FifoWords(w / "mesh.ply")};
       }},
      {"render: the frame's image",
       [&](const fs::path& w) {
         const fs::path s = Copy(Root() / "kitti", w, "seq");
         const fs::path image = SomeImage(s);
         MakeFifo(image);
         return std::pair{"render " + Quote(Mesh().string()) + " --sequence " + Quote(s.string()) +
                              " --format kitti_odometry --frame 1 --out " + Quote((w / "out.png").string()),
                          FifoWords(image)};
       }},
      {"tiles merge: tileset.json",
       [&](const fs::path& w) {
         const fs::path run = Copy(Run(), w, "run");
         MakeFifo(run / "tileset.json");
         return std::pair{"tiles merge " + Quote(run.string()) + " --out " + Quote((w / "m.ply").string()),
                          FifoWords(run / "tileset.json")};
       }},
      {"tiles merge: a tile",
       [&](const fs::path& w) {
         const fs::path run = Copy(Run(), w, "run");
         const fs::path tile = FirstTile(run);
         MakeFifo(tile);
         return std::pair{"tiles merge " + Quote(run.string()) + " --out " + Quote((w / "m.ply").string()),
                          FifoWords(tile)};
       }},
      {"tiles merge: tileset.json a link to /dev/zero",
       [&](const fs::path& w) {
         const fs::path run = Copy(Run(), w, "run");
         fs::remove(run / "tileset.json");
         fs::create_symlink("/dev/zero", run / "tileset.json");
         return std::pair{"tiles merge " + Quote(run.string()) + " --out " + Quote((w / "m.ply").string()),
                          (run / "tileset.json").string() + ": is not a regular file (a character device)"};
       }},
      {"tiles merge: a folder named like a tile",
       [&](const fs::path& w) {
         const fs::path run = Copy(Run(), w, "run");
         const fs::path tile = FirstTile(run);
         fs::remove(tile);
         fs::create_directories(tile);
         return std::pair{"tiles merge " + Quote(run.string()) + " --out " + Quote((w / "m.ply").string()),
                          tile.string() + ": is a folder, expected a GLB tile"};
       }},
      {"tiles merge: a file named as the run folder",
       [&](const fs::path& w) {
         return std::pair{"tiles merge " + Quote(Mesh().string()) + " --out " + Quote((w / "m.ply").string()),
                          Mesh().string() + ": is a file, not a run folder"};
       }},
  };
  int n = 0;
  for (const Row& row : rows) {
    SCOPED_TRACE(row.name);
    const fs::path work = Root() / ("case-" + std::to_string(n++));
    fs::create_directories(work);
    const auto [args, words] = row.make(work);
    if (::testing::Test::HasFatalFailure()) return;
    // SIGKILL after 5 s: a reader that waits on the FIFO is killed, and the test says so.
    const CommandResult r = RunShell("cd " + Quote(work.string()) + " && timeout -s KILL 5 " +
                                     Quote(kImr) + " " + args);
    EXPECT_NE(r.status, 128 + 9) << row.name << ": still running after 5 s (waiting on the FIFO?)";
    EXPECT_NE(r.status, 0) << row.name;
    const std::string said = r.out + r.err;
    EXPECT_NE(said.find(words), std::string::npos)
        << row.name << ": expected \"" << words << "\" in\n" << said.substr(0, 2000);
    if (const std::size_t at = said.find(words); at != std::string::npos) {
      const std::size_t begin = said.rfind('\n', at) == std::string::npos ? 0 : said.rfind('\n', at) + 1;
      std::cout << "[ message  ] " << row.name << " (exit " << r.status
                << "): " << said.substr(begin, said.find('\n', at) - begin) << "\n";
    }
  }
}

}  // namespace
}  // namespace imr::testing
