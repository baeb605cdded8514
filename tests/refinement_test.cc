// The mesh_refiner stage end to end (SDK 1.4, issue 34): what the host sends a mesh refiner and
// keeps between calls, what it refuses of a refiner's answer, the job checks, and the photometric
// plugin on imr-synth's images.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <fstream>
#include <sstream>
#include <thread>

#include "host/eval/mesh_io.h"
#include "test_util.h"

namespace imr::testing {
namespace {
namespace fs = std::filesystem;
using nlohmann::json;

const std::string kImr = IMR_EXE;

json ReadJson(const fs::path& p) {
  std::ifstream in(p);
  json j;
  in >> j;
  return j;
}

std::vector<json> ReadLines(const fs::path& p) {
  std::vector<json> out;
  std::ifstream in(p);
  for (std::string line; std::getline(in, line);)
    if (!line.empty()) out.push_back(json::parse(line));
  return out;
}

class Refinement : public ::testing::Test {
 protected:
  Refinement() : dir_("refinement") {}

  // An engine-only job on the synthetic street with the test refiner as its mesh_refiner.
  json EngineJob(const json& refiner_params, int every_keyframes) const {
    json stage = {{"kind", "mesh_refiner"}, {"plugin", "org.imr.test.refine.shift"},
                  {"params", refiner_params}};
    if (every_keyframes > 0) stage["every_keyframes"] = every_keyframes;
    return {{"description", "refinement test"},
            {"sequences", {"street"}},
            {"input", {{"format", "synthetic"}, {"options", {{"frames", 40}, {"seed", 3}}}}},
            {"plugin_paths", {IMR_TEST_PLUGIN_DIR}},
            {"pipeline",
             {{{"kind", "weight_policy"}, {"plugin", "org.imr.policy.nearest"}},
              stage,
              {{"kind", "exporter"}, {"plugin", "org.imr.exporter.assimp"}}}},
            {"output", {{"directory", (dir_ / "runs/{sequence}").string()}, {"formats", {"ply"}}}}};
  }
  CommandResult Run(const json& job, const std::string& name = "job.json") {
    const fs::path p = dir_ / name;
    WriteText(p, job.dump(2));
    return RunShell(kImr + " run -q " + Quote(p.string()));
  }
  fs::path Report() const { return dir_ / "runs/street/report.json"; }

  ScratchDir dir_;
};

// Every call gets the surface with what changed since the last one flagged; a vertex the engine
// did not move since keeps the position the refiner gave it, so moves accumulate over calls.
TEST_F(Refinement, TheHostKeepsRefinedPositionsBetweenCalls) {
  const fs::path log = dir_ / "calls.jsonl";
  const CommandResult r =
      Run(EngineJob({{"dz", 0.01}, {"only_changed", false}, {"log", log.string()}}, 2));
  ASSERT_EQ(r.status, 0) << r.out << r.err;
  const std::vector<json> calls = ReadLines(log);
  const json report = ReadJson(Report());
  const int64_t keyframes = report["engine"]["keyframes"].get<int64_t>();
  ASSERT_GE(keyframes, 4);
  // Every second keyframe (those with a surface), and the final call.
  ASSERT_GE(calls.size(), 2u);
  EXPECT_LE(calls.size(), static_cast<std::size_t>(keyframes / 2 + 1));
  EXPECT_EQ(report["refinement"]["calls"].get<std::size_t>(), calls.size());
  for (std::size_t i = 0; i < calls.size(); ++i) {
    EXPECT_EQ(calls[i]["final"].get<bool>(), i + 1 == calls.size()) << i;
    EXPECT_EQ(calls[i]["fixed"].get<int64_t>(), 0) << i;
    if (i > 0) {
      EXPECT_GE(calls[i]["recent_begin"].get<int64_t>(), calls[i - 1]["recent_begin"].get<int64_t>());
      EXPECT_EQ(calls[i]["recent_begin"].get<int64_t>(), calls[i - 1]["keyframes"].get<int64_t>());
    }
  }
  EXPECT_EQ(calls[0]["changed"], calls[0]["vertices"]);  // nothing refined before the first call
  EXPECT_EQ(calls[0]["recent_begin"].get<int64_t>(), 0);
  // Later calls: most of the surface did not change since the call before.
  EXPECT_LT(calls.back()["changed"].get<int64_t>(), calls.back()["vertices"].get<int64_t>());
  EXPECT_GT(report["refinement"]["vertices_kept"].get<int64_t>(), 0);
  // A vertex sent to k calls ends k * dz above the engine's position.
  EXPECT_GE(report["refinement"]["max_move"].get<double>(), 0.02 - 1e-9);
  EXPECT_GT(report["refinement"]["mean_move"].get<double>(), 0.01);
  EXPECT_TRUE(report["mesh"]["manifold"].get<bool>());
  EXPECT_GT(report["stage_seconds"]["mesh_refiner"].get<double>(), 0.0);
}

// Refining only what changed: each vertex moves once, by dz exactly.
TEST_F(Refinement, UnchangedVerticesAreNotSentAsChanged) {
  const CommandResult r = Run(EngineJob({{"dz", 0.01}, {"only_changed", true}}, 3));
  ASSERT_EQ(r.status, 0) << r.out << r.err;
  const json report = ReadJson(Report());
  EXPECT_NEAR(report["refinement"]["max_move"].get<double>(), 0.01, 1e-9);
  EXPECT_NEAR(report["refinement"]["mean_move"].get<double>(), 0.01, 1e-9);
}

// Ctrl-C while the surface is refined (issue 44): the refiner stops as asked, and the sequence is
// interrupted by SIGINT as at a keyframe, not "failed ... cancelled"; nothing is written.
TEST_F(Refinement, CtrlCWhileRefiningIsAnInterruption) {
  const fs::path log = dir_ / "calls.jsonl";
  json job = EngineJob({{"misbehave", "wait_for_cancel"}, {"log", log.string()}}, 0);
  const fs::path job_file = dir_ / "job.json";
  WriteText(job_file, job.dump(2));
  const fs::path err = dir_ / "stderr.txt";
  const pid_t pid = ::fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    ::setpgid(0, 0);  // its own group, as a shell's foreground job: Ctrl-C reaches all of it
    ::freopen("/dev/null", "w", stdout);
    ::freopen(err.c_str(), "w", stderr);
    ::execl(kImr.c_str(), kImr.c_str(), "run", "-v", job_file.c_str(), static_cast<char*>(nullptr));
    ::_exit(127);
  }
  ::setpgid(pid, pid);
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  while (std::chrono::steady_clock::now() < deadline && !fs::exists(log))
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  const bool refining = fs::exists(log);
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  ::kill(-pid, SIGINT);
  int status = 0;
  ::waitpid(pid, &status, 0);
  ASSERT_TRUE(refining) << ReadText(err);
  const std::string e = ReadText(err);
  ASSERT_TRUE(WIFEXITED(status)) << e;
  EXPECT_EQ(WEXITSTATUS(status), 1) << e;  // one sequence interrupted
  EXPECT_NE(e.find("sequence street interrupted by SIGINT (Ctrl-C): cancelled (signal) while "
                   "refining the surface after the last keyframe (pipeline[1] (mesh_refiner "
                   "org.imr.test.refine.shift))"),
            std::string::npos) << e;
  EXPECT_EQ(e.find("error:"), std::string::npos) << e;
  EXPECT_EQ(e.find("failed: "), std::string::npos) << e;
  const json summary = ReadJson(dir_ / "runs/summary.json");
  EXPECT_EQ(summary["sequences"][0]["status"], "interrupted") << summary.dump(2);
  EXPECT_FALSE(fs::exists(dir_ / "runs/street/mesh.ply"));
}

// A refiner's answer the host must not use fails the sequence, naming the stage and what broke;
// no mesh is written. A proper subdivision is taken.
TEST_F(Refinement, WhatTheHostRefusesOfARefiner) {
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"nan", "non-finite coordinate"},
      {"few", "vertices for"},
      {"bad_faces", "not a manifold"},
      {"throw", "failed on purpose"}};
  for (const auto& [misbehave, expected] : cases) {
    fs::remove_all(dir_ / "runs");
    const CommandResult r = Run(EngineJob({{"misbehave", misbehave}}, 0));
    EXPECT_NE(r.status, 0) << misbehave;
    EXPECT_NE(r.err.find("pipeline[1] (mesh_refiner org.imr.test.refine.shift)"), std::string::npos)
        << misbehave << ": " << r.err;
    EXPECT_NE(r.err.find(expected), std::string::npos) << misbehave << ": " << r.err;
    EXPECT_FALSE(fs::exists(dir_ / "runs/street/mesh.ply")) << misbehave;
  }
  fs::remove_all(dir_ / "runs");
  const CommandResult ok = Run(EngineJob({{"misbehave", "subdivide"}}, 0));
  ASSERT_EQ(ok.status, 0) << ok.err;
  const json report = ReadJson(Report());
  EXPECT_GT(report["refinement"]["vertices_added"].get<int64_t>(), 0);
  // One centroid per face of the engine's mesh, three faces in its place.
  EXPECT_EQ(report["refinement"]["vertices_added"].get<int64_t>() * 3,
            report["mesh"]["faces"].get<int64_t>());
  EXPECT_TRUE(report["mesh"]["manifold"].get<bool>());
}

// The job's checks: the schedule belongs to mesh_refiner stages, one stage at most; a refiner's
// subdivision fails a run that writes its surface in parts.
TEST_F(Refinement, JobChecks) {
  json on_exporter = EngineJob({}, 0);
  on_exporter["pipeline"][2]["every_keyframes"] = 5;
  CommandResult r = Run(on_exporter);
  EXPECT_EQ(r.status, 64) << r.err;
  EXPECT_NE(r.err.find("pipeline[2].every_keyframes: only a mesh_refiner stage has a schedule"),
            std::string::npos) << r.err;

  json negative = EngineJob({}, 0);
  negative["pipeline"][1]["every_keyframes"] = -1;
  r = Run(negative);
  EXPECT_EQ(r.status, 64) << r.err;
  EXPECT_NE(r.err.find("pipeline[1].every_keyframes: expected an integer from 0"), std::string::npos)
      << r.err;

  json twice = EngineJob({}, 0);
  twice["pipeline"].insert(twice["pipeline"].begin() + 1, twice["pipeline"][1]);
  r = Run(twice);
  EXPECT_EQ(r.status, 64) << r.err;
  EXPECT_NE(r.err.find("at most one mesh_refiner stage, found 2"), std::string::npos) << r.err;

  // A surface written in parts cannot take a subdivision (its faces are written already).
  json subdivide = EngineJob({{"misbehave", "subdivide"}}, 0);
  subdivide["engine"] = {{"forget", true}};
  r = Run(subdivide);
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.err.find("which a run that writes it in parts (engine.forget, output.tiles) cannot take"),
            std::string::npos) << r.err;
}

// Snapshots show the surface as refined so far: the snapshot after a refine call has the call's
// positions (the shift refiner lifts what it refines by dz, once); without the stage, the same
// snapshot has the engine's.
TEST_F(Refinement, SnapshotsAreRefinedToo) {
  json job = EngineJob({{"dz", 0.01}, {"only_changed", true}}, 4);
  job["output"]["snapshot_every"] = 4;
  json plain = job;
  plain["pipeline"].erase(1);
  plain["output"]["directory"] = (dir_ / "plain/{sequence}").string();
  CommandResult r = Run(plain, "plain.json");
  ASSERT_EQ(r.status, 0) << r.err;
  r = Run(job);
  ASSERT_EQ(r.status, 0) << r.err;
  const json snaps = ReadJson(Report())["snapshots"];
  ASSERT_GE(snaps.size(), 2u) << snaps.dump();
  for (const json& s : snaps) {
    const std::string file = s["stem"].get<std::string>() + ".ply";
    const eval::TriangleMesh refined = eval::ReadMesh(dir_ / "runs/street" / file);
    const eval::TriangleMesh unrefined = eval::ReadMesh(dir_ / "plain/street" / file);
    ASSERT_EQ(refined.vertices.size(), unrefined.vertices.size()) << file;
    std::size_t raised = 0;
    for (std::size_t i = 0; i < refined.vertices.size(); ++i) {
      const double dz = refined.vertices[i][2] - unrefined.vertices[i][2];
      ASSERT_TRUE(std::abs(dz) < 1e-4 || std::abs(dz - 0.01) < 1e-4) << file << " vertex " << i << ": " << dz;
      raised += dz > 0.005 ? 1 : 0;
    }
    EXPECT_GT(raised, refined.vertices.size() / 2) << file;
  }
}

// Issue 34 item 3: a run that writes its surface in parts (engine.forget, output.tiles) refines
// each part before it is written. The shift refiner lifts each vertex it refines by dz, once
// (only_changed); a vertex written already is FIXED in later calls. The mesh written is the
// unrefined run's, each vertex where it was or dz above, most above; its tiles merge into a
// 2-manifold with the mesh's vertices (the same position for a vertex in every tile).
TEST_F(Refinement, ARunThatWritesItsSurfaceInPartsWritesItRefined) {
  const fs::path log = dir_ / "calls.jsonl";
  json job = EngineJob({{"dz", 0.01}, {"only_changed", true}, {"log", log.string()}}, 4);
  job["input"]["options"]["frames"] = 300;
  job["engine"] = {{"forget", true}};
  json plain = job;
  plain["pipeline"].erase(1);
  plain["output"]["directory"] = (dir_ / "plain/{sequence}").string();
  CommandResult r = Run(plain, "plain.json");
  ASSERT_EQ(r.status, 0) << r.err;
  job["output"]["tiles"] = true;
  job["output"]["formats"] = {"ply", "glb"};
  r = Run(job);
  ASSERT_EQ(r.status, 0) << r.err;
  const json report = ReadJson(Report());
  EXPECT_GE(report["engine"]["forget"]["parts"].get<int>(), 3) << "nothing handed out on the way";
  EXPECT_TRUE(report["mesh"]["manifold"].get<bool>());
  const std::vector<json> calls = ReadLines(log);
  ASSERT_GE(calls.size(), 3u);
  int64_t fixed = 0;
  for (const json& c : calls) fixed += c["fixed"].get<int64_t>();
  EXPECT_GT(fixed, 0) << "no vertex written already was sent FIXED";
  EXPECT_TRUE(calls.back()["final"].get<bool>());

  const eval::TriangleMesh refined = eval::ReadMesh(dir_ / "runs/street/mesh.ply");
  const eval::TriangleMesh unrefined = eval::ReadMesh(dir_ / "plain/street/mesh.ply");
  ASSERT_EQ(refined.vertices.size(), unrefined.vertices.size());
  EXPECT_EQ(refined.triangles, unrefined.triangles);
  std::size_t raised = 0;
  for (std::size_t i = 0; i < refined.vertices.size(); ++i) {
    const auto& a = refined.vertices[i];
    const auto& b = unrefined.vertices[i];
    ASSERT_NEAR(a[0], b[0], 1e-4) << i;
    ASSERT_NEAR(a[1], b[1], 1e-4) << i;
    const double dz = a[2] - b[2];
    ASSERT_TRUE(std::abs(dz) < 1e-4 || std::abs(dz - 0.01) < 1e-4) << "vertex " << i << " lifted by " << dz;
    raised += dz > 0.005 ? 1 : 0;
  }
  EXPECT_GT(raised, refined.vertices.size() / 2);

  r = RunShell(kImr + " tiles merge " + Quote((dir_ / "runs/street").string()) + " --out " +
               Quote((dir_ / "merged.ply").string()));
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.out.find("a 2-manifold with boundary"), std::string::npos) << r.out;
  EXPECT_EQ(eval::ReadMesh(dir_ / "merged.ply").vertices.size(), refined.vertices.size());
}

// The photometric refiner needs images: an engine-only input fails the sequence saying so.
TEST_F(Refinement, PhotometricRefinerOnAnInputWithoutImages) {
  json job = EngineJob({}, 0);
  job["pipeline"][1] = {{"kind", "mesh_refiner"}, {"plugin", "org.imr.refine.photometric"}};
  const CommandResult r = Run(job);
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.err.find("org.imr.refine.photometric needs the keyframe images"), std::string::npos)
      << r.err;
  EXPECT_FALSE(fs::exists(dir_ / "runs/street/mesh.ply"));
}

// imr-synth's street through the image pipeline with the photometric refiner every 4 keyframes
// and at the end: the refined surface is still a manifold, and it is no further from the known
// scene than the same run's surface unrefined.
TEST_F(Refinement, PhotometricRefinerOnImrSynth) {
  const fs::path seq = dir_ / "street";
  const CommandResult synth = RunShell(Quote(IMR_SYNTH_EXE) + " --out " + Quote(seq.string()) +
                                       " --frames 60 --width 828 --height 250 --no-lidar -q");
  ASSERT_EQ(synth.status, 0) << synth.err;
  auto job = [&](bool refine, const std::string& out) {
    json j = {{"description", "refinement test"},
              {"sequences", {seq.string()}},
              {"input", {{"format", "kitti_odometry"}, {"options", {{"keyframe_every", 5}}}}},
              {"engine", {{"steiner_export", "any_steiner"}}},
              {"pipeline",
               {{{"kind", "features"}, {"plugin", "org.imr.features.edge_klt"}},
                {{"kind", "refiner"}, {"plugin", "org.imr.refiner.ceres"}},
                {{"kind", "exporter"}, {"plugin", "org.imr.exporter.assimp"}}}},
              {"output", {{"directory", (dir_ / out / "{sequence}").string()}, {"formats", {"ply"}}}}};
    if (refine)
      j["pipeline"].insert(j["pipeline"].begin() + 2,
                           json{{"kind", "mesh_refiner"}, {"plugin", "org.imr.refine.photometric"},
                                {"every_keyframes", 4}});
    return j;
  };
  const CommandResult plain = Run(job(false, "plain"), "plain.json");
  ASSERT_EQ(plain.status, 0) << plain.err;
  const CommandResult refined = Run(job(true, "refined"), "refined.json");
  ASSERT_EQ(refined.status, 0) << refined.err;
  const json a = ReadJson(dir_ / "plain/street/report.json");
  const json b = ReadJson(dir_ / "refined/street/report.json");
  EXPECT_GE(b["refinement"]["calls"].get<int>(), 3);  // 13 keyframes: after 4, 8, 12 and at the end
  EXPECT_GT(b["refinement"]["vertices_moved"].get<int64_t>(), 0);
  EXPECT_GT(b["refinement"]["vertices_kept"].get<int64_t>(), 0);
  EXPECT_TRUE(b["mesh"]["manifold"].get<bool>());
  EXPECT_EQ(b["mesh"]["stats"]["boundary_loops"], a["mesh"]["stats"]["boundary_loops"]);
  EXPECT_EQ(b["mesh"]["faces"], a["mesh"]["faces"]);  // no subdivision by default
  const double pa = a["accuracy"]["precision"].get<double>(), pb = b["accuracy"]["precision"].get<double>();
  const double ca = a["accuracy"]["completeness"].get<double>(), cb = b["accuracy"]["completeness"].get<double>();
  EXPECT_GE(pb, pa - 0.01) << "precision " << pa << " -> " << pb;
  EXPECT_GE(cb, ca - 0.01) << "completeness " << ca << " -> " << cb;
}

}  // namespace
}  // namespace imr::testing
