// SfM models as users bring them (issue 16), end to end through `imr run`: a test set written
// with imr's own tools at test time (licence-clean; nothing committed): a synthetic street run
// exports a COLMAP model (--export-colmap), and each case rewrites it the way another tool would:
// every camera model COLMAP writes, in text and binary; duplicate observations, unused cameras,
// ids with gaps, cameras out of order or of different sizes, a third-party text writer, COLMAP
// 3.12's rigs and frames, several sub-models under one folder. Each must give the manifold mesh
// of the original model (the engine sees the same centres and points), and the camera model must
// reach the export. Refusals (no points, two images, OpenMVG without structure or in binary) are
// in bad_input_test.cc with the catalogue's [bad, good] checks.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include <cstdio>
#include <map>

#include "host/io/camera_model.h"
#include "host/io/colmap_model.h"
#include "test_util.h"

namespace imr::testing {
namespace {
namespace fs = std::filesystem;
using nlohmann::json;

const std::string kImr = IMR_EXE;

json ReadJson(const fs::path& p) { return json::parse(ReadText(p)); }

// A 10 m Steiner grid (default 5): half the engine's time on this street, the same test of the
// readers.
json ColmapJob(const std::vector<std::string>& sequences) {
  return {{"sequences", sequences},
          {"input", {{"format", "colmap"}}},
          {"engine", {{"steiner_spacing", 10}}},
          {"pipeline",
           {{{"kind", "weight_policy"}, {"plugin", "org.imr.policy.nearest"}},
            {{"kind", "exporter"}, {"plugin", "org.imr.exporter.assimp"}}}},
          {"output", {{"directory", "runs/{sequence}"}, {"formats", {"ply"}}}}};
}

// Every 2D point becomes the projection of its 3D point through its image's camera, as the SfM
// that wrote the model would have measured it (so a model with a new camera stays consistent).
void Reproject(io::ColmapModel* m) {
  std::map<uint32_t, const io::ColmapModel::Camera*> cams;
  for (const auto& c : m->cameras) cams[c.id] = &c;
  std::map<uint64_t, io::Vec3> xyz;
  for (const auto& p : m->points) xyz[p.id] = p.xyz;
  for (auto& im : m->images) {
    const auto& c = *cams.at(im.camera_id);
    io::CameraGeometry g;
    io::SetFromTranslation(io::QuaternionToRotation(im.qvec), im.tvec, &g);
    std::string error;
    ASSERT_TRUE(io::IntrinsicsFromColmap(c.model, c.params, static_cast<int>(c.width),
                                         static_cast<int>(c.height), &g.intrinsics, &error))
        << error;
    g.has_intrinsics = true;
    for (auto& q : im.points2d)
      if (q.point3d_id >= 0) {
        ASSERT_TRUE(io::Project(g, xyz.at(q.point3d_id), &q.x, &q.y)) << c.model;
      }
  }
}

void Save(const io::ColmapModel& m, const fs::path& dir, bool binary) {
  if (binary) io::WriteColmapBinary(m, dir);
  else io::WriteColmapText(m, dir);
}

// A writer that is not COLMAP's: no '#' lines, %E numbers with 3-digit exponents (as MSVC's
// printf wrote them), CRLF line ends, no newline at the end.
void WriteThirdPartyText(const io::ColmapModel& m, const fs::path& dir) {
  const auto num = [](double v) {
    char b[64];
    std::snprintf(b, sizeof(b), "%.17E", v);
    std::string s = b;
    const std::size_t e = s.find('E');
    if (s.size() - e == 4) s.insert(e + 2, "0");  // E+01 -> E+001
    return s;
  };
  const auto join = [](const std::vector<std::string>& lines) {
    std::string s;
    for (std::size_t i = 0; i < lines.size(); ++i) s += (i ? "\r\n" : "") + lines[i];
    return s;
  };
  std::vector<std::string> lines;
  for (const auto& c : m.cameras) {
    std::string l = std::to_string(c.id) + " " + c.model + " " + std::to_string(c.width) + " " +
                    std::to_string(c.height);
    for (double p : c.params) l += " " + num(p);
    lines.push_back(l);
  }
  WriteText(dir / "cameras.txt", join(lines));
  lines.clear();
  for (const auto& im : m.images) {
    std::string l = std::to_string(im.id);
    for (double q : im.qvec) l += " " + num(q);
    for (double t : im.tvec) l += " " + num(t);
    lines.push_back(l + " " + std::to_string(im.camera_id) + " " + im.name);
    l.clear();
    for (const auto& q : im.points2d)
      l += (l.empty() ? "" : " ") + num(q.x) + " " + num(q.y) + " " + std::to_string(q.point3d_id);
    lines.push_back(l);
  }
  WriteText(dir / "images.txt", join(lines));
  lines.clear();
  for (const auto& p : m.points) {
    std::string l = std::to_string(p.id);
    for (double x : p.xyz) l += " " + num(x);
    for (uint8_t c : p.rgb) l += " " + std::to_string(c);
    l += " " + num(p.error);
    for (const auto& e : p.track) l += " " + std::to_string(e.image_id) + " " + std::to_string(e.point2d_idx);
    lines.push_back(l);
  }
  WriteText(dir / "points3D.txt", join(lines));
}

class SfmModels : public ::testing::Test {
 protected:
  // The base model: a 20-frame synthetic street's engine input, exported by imr as COLMAP text
  // (image ids from 0), and the engine's figures when that model is meshed.
  static void SetUpTestSuite() {
    dir_ = new ScratchDir("sfm-models");
    json job = {{"sequences", {"street"}},
                {"input", {{"format", "synthetic"}, {"options", {{"frames", 20}, {"seed", 3}}}}},
                {"pipeline", ColmapJob({})["pipeline"]},
                {"output", {{"directory", "synthetic"}, {"formats", {"ply"}}}}};
    WriteText(*dir_ / "synthetic.json", job.dump(2));
    CommandResult r = RunShell("cd " + Quote(dir_->path().string()) + " && " + Quote(kImr) +
                               " run -q synthetic.json --export-colmap base");
    ASSERT_EQ(r.status, 0) << r.out << r.err;
    WriteText(*dir_ / "base.json", ColmapJob({"base"}).dump(2));
    r = RunShell("cd " + Quote(dir_->path().string()) + " && " + Quote(kImr) + " run -q base.json");
    ASSERT_EQ(r.status, 0) << r.out << r.err;
    base_report_ = new json(ReadJson(*dir_ / "runs/base/report.json"));
  }
  static void TearDownTestSuite() {
    delete base_report_;
    delete dir_;
    base_report_ = nullptr;
    dir_ = nullptr;
  }
  void SetUp() override { ASSERT_NE(base_report_, nullptr) << "no base model"; }

  static io::ColmapModel Base() { return io::ReadColmapText(*dir_ / "base"); }
  fs::path Case() const { return case_.path(); }

  // `imr run` on `job` in this test's folder; `flags` after the job.
  CommandResult Run(const json& job, const std::string& flags = "") const {
    WriteText(Case() / "job.json", job.dump(2));
    return RunShell("cd " + Quote(Case().string()) + " && timeout -k 5 120 " + Quote(kImr) +
                    " run -q --jobs 2 job.json " + flags);
  }

  // Sequence `name` finished with a manifold mesh, meshing the base model's points the same way.
  void ExpectSameMeshAsTheBase(const std::string& name) const {
    SCOPED_TRACE(name);
    const fs::path report = Case() / "runs" / name / "report.json";
    ASSERT_TRUE(fs::exists(report)) << ReadText(Case() / "runs/summary.md");
    const json r = ReadJson(report);
    EXPECT_EQ(r["mesh"]["manifold"], true);
    EXPECT_GT(r["mesh"]["faces"].get<int>(), 100);
    for (const char* k : {"points_inserted", "rays_cast", "cells_in_o"})
      EXPECT_EQ(r["engine"][k], (*base_report_)["engine"][k]) << k;
    EXPECT_EQ(r["mesh"]["faces"], (*base_report_)["mesh"]["faces"]);
  }

  // Each camera model meshes like the base, and reaches --export-colmap unchanged (the same
  // model and parameters, every 2D point at its projection through that model) and
  // --export-stream (the COLMAP camera beside the OpenMVG intrinsic).
  void CheckCameraModels(bool binary) const;

  static ScratchDir* dir_;
  static json* base_report_;
  ScratchDir case_{"sfm-models-case"};
};
ScratchDir* SfmModels::dir_ = nullptr;
json* SfmModels::base_report_ = nullptr;

struct CameraCase {
  const char* model;
  std::vector<double> params;
};
// Every model COLMAP's reconstruction writes, for the base model's 1000 x 364 images.
const CameraCase kCameraCases[] = {
    {"SIMPLE_PINHOLE", {500, 500, 182}},
    {"PINHOLE", {500, 505, 500, 182}},
    {"SIMPLE_RADIAL", {500, 500, 182, 0.05}},
    {"RADIAL", {500, 500, 182, 0.05, -0.02}},
    {"OPENCV", {500, 505, 500, 182, 0.05, -0.02, 0.001, 0.002}},
    {"OPENCV_FISHEYE", {300, 305, 500, 182, 0.05, -0.02, 0.003, -0.001}},
    {"FULL_OPENCV", {500, 505, 500, 182, 0.05, -0.02, 0.001, 0.002, 0.01, 0.02, -0.01, 0.005}},
    {"FOV", {400, 405, 500, 182, 0.9}},
    {"SIMPLE_RADIAL_FISHEYE", {300, 500, 182, 0.05}},
    {"RADIAL_FISHEYE", {300, 500, 182, 0.05, -0.02}},
    {"THIN_PRISM_FISHEYE", {300, 305, 500, 182, 0.05, -0.02, 0.001, 0.002, 0.003, -0.001, 0.0005, -0.0004}},
};

void SfmModels::CheckCameraModels(bool binary) const {
  std::map<std::string, io::ColmapModel> written;
  for (const CameraCase& c : kCameraCases) {
    io::ColmapModel m = Base();
    ASSERT_EQ(m.cameras.size(), 1u);
    m.cameras[0].model = c.model;
    m.cameras[0].params = c.params;
    Reproject(&m);
    Save(m, Case() / "models" / c.model, binary);
    written[c.model] = std::move(m);
  }
  const CommandResult r = Run(ColmapJob({"models/*/"}),
                              "--export-colmap '{output}/colmap' --export-stream '{output}/stream.json'");
  ASSERT_EQ(r.status, 0) << r.out << r.err;
  for (const auto& [name, model] : written) {
    SCOPED_TRACE(name);
    ExpectSameMeshAsTheBase(name);
    const io::ColmapModel e = io::ReadColmapModel(Case() / "runs" / name / "colmap");
    ASSERT_EQ(e.cameras.size(), 1u);
    EXPECT_EQ(e.cameras[0].model, name);
    EXPECT_EQ(e.cameras[0].params, model.cameras[0].params);
    EXPECT_EQ(e.cameras[0].width, 1000u);
    // Pixels of (image, point) pairs: those of the model that was read.
    std::map<std::pair<uint32_t, int64_t>, std::array<double, 2>> pixel;
    for (const auto& im : model.images)
      for (const auto& q : im.points2d) pixel[{im.id, q.point3d_id}] = {q.x, q.y};
    std::size_t compared = 0;
    for (const auto& im : e.images)
      for (const auto& q : im.points2d) {
        auto it = pixel.find({im.id, q.point3d_id});
        ASSERT_NE(it, pixel.end()) << "image " << im.id << " point " << q.point3d_id;
        EXPECT_NEAR(q.x, it->second[0], 1e-6);
        EXPECT_NEAR(q.y, it->second[1], 1e-6);
        ++compared;
      }
    EXPECT_GT(compared, 500u);
    // The stream export's OpenMVG intrinsic carries the COLMAP camera whole.
    const json stream = ReadJson(Case() / "runs" / name / "stream.json");
    ASSERT_EQ(stream["intrinsics"].size(), 1u);
    const json& data = stream["intrinsics"][0]["value"]["ptr_wrapper"]["data"];
    EXPECT_EQ(data.value("colmap_model", ""), name);
    EXPECT_EQ(data.value("colmap_params", std::vector<double>{}), model.cameras[0].params);
  }
}

TEST_F(SfmModels, EveryCameraModelInTextMeshesAndReachesTheExport) { CheckCameraModels(false); }

TEST_F(SfmModels, EveryCameraModelInBinaryMeshesAndReachesTheExport) { CheckCameraModels(true); }

TEST_F(SfmModels, QuirksOfRealModelsMeshLikeTheOriginal) {
  std::vector<std::string> names;
  const auto both = [&](const std::string& name, const io::ColmapModel& m) {
    Save(m, Case() / "quirks" / name, false);
    Save(m, Case() / "quirks" / (name + "-bin"), true);
    names.push_back(name);
    names.push_back(name + "-bin");
  };
  // The same point observed twice by one image: a second 2D point of every fifth point, in the
  // first image that sees it (COLMAP keeps such tracks after merging).
  {
    io::ColmapModel m = Base();
    std::map<uint32_t, std::size_t> image_at;
    for (std::size_t i = 0; i < m.images.size(); ++i) image_at[m.images[i].id] = i;
    int doubled = 0;
    for (auto& p : m.points) {
      if (p.id % 5 != 0 || p.track.empty()) continue;
      auto& im = m.images[image_at.at(p.track[0].image_id)];
      const auto q = im.points2d[p.track[0].point2d_idx];
      im.points2d.push_back({q.x + 0.5, q.y - 0.5, q.point3d_id});
      p.track.push_back({im.id, static_cast<uint32_t>(im.points2d.size() - 1)});
      ++doubled;
    }
    ASSERT_GT(doubled, 50);
    both("duplicate-observations", m);
  }
  // Unused cameras, listed first.
  {
    io::ColmapModel m = Base();
    m.cameras.insert(m.cameras.begin(), {7, "SIMPLE_RADIAL", 10, 10, {5, 5, 5, 0.1}});
    m.cameras.push_back({8, "OPENCV_FISHEYE", 4000, 3000, {900, 900, 2000, 1500, 0, 0, 0, 0}});
    both("unused-cameras", m);
  }
  // Ids with gaps, not starting at 1 (monotonic: the engine sees the same order).
  {
    io::ColmapModel m = Base();
    m.cameras[0].id = 42;
    for (auto& im : m.images) im.id = 1000 + 7 * im.id, im.camera_id = 42;
    for (auto& im : m.images)
      for (auto& q : im.points2d)
        if (q.point3d_id >= 0) q.point3d_id = 5 + 3 * q.point3d_id;
    for (auto& p : m.points) {
      p.id = 5 + 3 * p.id;
      for (auto& e : p.track) e.image_id = 1000 + 7 * e.image_id;
    }
    both("id-gaps", m);
  }
  // Per-image cameras of different sizes and models (odd images: a 1280 x 720 PINHOLE), listed
  // out of order (camera 2 first), 2D points measured through each.
  {
    io::ColmapModel m = Base();
    m.cameras.insert(m.cameras.begin(), {2, "PINHOLE", 1280, 720, {640, 650, 640, 360}});
    for (std::size_t i = 1; i < m.images.size(); i += 2) m.images[i].camera_id = 2;
    Reproject(&m);
    both("cameras-of-different-sizes-out-of-order", m);
  }
  // A third-party writer (text only: the quirks are in the text).
  fs::create_directories(Case() / "quirks/third-party-text");
  WriteThirdPartyText(Base(), Case() / "quirks/third-party-text");
  names.push_back("third-party-text");
  // COLMAP >= 3.12: rigs and frames beside the three files (one rig, one frame per image).
  {
    const io::ColmapModel m = Base();
    both("colmap-3.12-rigs-frames", m);
    std::string rigs = "# Rig calib list with one line of data per calib:\n# Number of rigs: 1\n1 1 CAMERA 1\n";
    std::string frames = "# Frame list with one line of data per frame:\n# Number of frames: " +
                         std::to_string(m.images.size()) + "\n";
    for (const auto& im : m.images) {
      frames += std::to_string(im.id + 1) + " 1";
      for (double q : im.qvec) frames += " " + io::ExactNumber(q);
      for (double x : im.tvec) frames += " " + io::ExactNumber(x);
      frames += " 1 CAMERA 1 " + std::to_string(im.id) + "\n";
    }
    const fs::path text = Case() / "quirks/colmap-3.12-rigs-frames";
    WriteText(text / "rigs.txt", rigs);
    WriteText(text / "frames.txt", frames);
    // The binary folder: rigs.bin/frames.bin with the same content in COLMAP's binary layout
    // is not needed to show they are ignored; their presence is: a header-only pair.
    const fs::path bin = Case() / "quirks/colmap-3.12-rigs-frames-bin";
    WriteText(bin / "rigs.bin", std::string("\x01\0\0\0\0\0\0\0\x01\0\0\0\x01\0\0\0\0\0\0\0\x01\0\0\0", 24));
    WriteText(bin / "frames.bin", std::string(8, '\0'));
  }
  const CommandResult r = Run(ColmapJob({"quirks/*/"}));
  ASSERT_EQ(r.status, 0) << r.out << r.err;
  for (const std::string& name : names) ExpectSameMeshAsTheBase(name);
}

TEST_F(SfmModels, AFolderOfSubModelsRunsEachAsItsOwnSequence) {
  // COLMAP's mapper writes sparse/0, sparse/1, ... when it splits a scene: "sparse/*/" is one
  // sequence per sub-model, named by the folder (0, 1), with outputs in runs/0, runs/1.
  io::ColmapModel m = Base();
  Save(m, Case() / "sparse/0", /*binary=*/true);
  Save(m, Case() / "sparse/1", /*binary=*/false);
  WriteText(Case() / "sparse/project.ini", "not a model\n");  // files beside them are not matched
  const json job = ColmapJob({"sparse/*/"});
  WriteText(Case() / "job.json", job.dump(2));
  const CommandResult v = RunShell("cd " + Quote(Case().string()) + " && " + Quote(kImr) + " validate job.json");
  EXPECT_EQ(v.status, 0) << v.out << v.err;
  EXPECT_NE(v.out.find("0 -> " + (Case() / "runs/0").string()), std::string::npos) << v.out;
  const CommandResult r = Run(job);
  ASSERT_EQ(r.status, 0) << r.out << r.err;
  const json summary = ReadJson(Case() / "runs/summary.json");
  ASSERT_EQ(summary["sequences"].size(), 2u) << summary.dump(2);
  ExpectSameMeshAsTheBase("0");
  ExpectSameMeshAsTheBase("1");
}

// A share of the model collapsed to one spot (issue 37: 46 of 137 cameras and 1,362 of 3,091
// points within 1 mm, a failed merge): left out, with a warning in the log and report.json.
TEST_F(SfmModels, ACollapsedShareOfTheModelIsLeftOutWithAWarning) {
  io::ColmapModel m = Base();
  ASSERT_GE(m.images.size(), 9u);
  // Every third image at image 0's pose (no baseline), every third point at one spot.
  std::size_t cams = 0, pts = 0;
  for (std::size_t i = 3; i < m.images.size(); i += 3, ++cams) {
    m.images[i].qvec = m.images[0].qvec;
    m.images[i].tvec = m.images[0].tvec;
  }
  const Vec3 spot = m.points[0].xyz;
  for (std::size_t i = 3; i < m.points.size(); i += 3, ++pts)
    m.points[i].xyz = {spot[0] + 1e-9 * static_cast<double>(i), spot[1], spot[2]};
  Save(m, Case() / "collapsed", /*binary=*/false);
  const CommandResult r = Run(ColmapJob({"collapsed"}));
  ASSERT_EQ(r.status, 0) << r.out << r.err;
  const json report = ReadJson(Case() / "runs/collapsed/report.json");
  const std::string warnings = report["warnings"].dump();
  EXPECT_NE(warnings.find("sit at one spot"), std::string::npos) << warnings;
  EXPECT_NE(warnings.find("they were left out"), std::string::npos) << warnings;
  EXPECT_NE(r.err.find("sit at one spot"), std::string::npos) << r.err;
  const json c = report["input"]["summary"]["collapsed"];
  ASSERT_TRUE(c.is_object()) << report["input"].dump(2);
  // Image 0 is at the spot too: cams + 1 views; the points: pts plus point 0.
  EXPECT_EQ(c["views"]["left_out"], cams + 1) << c.dump();
  EXPECT_EQ(c["points"]["left_out"], pts + 1) << c.dump();
  // The model as it was meshes without a word about it.
  Save(Base(), Case() / "whole", /*binary=*/false);
  const CommandResult w = Run(ColmapJob({"whole"}));
  ASSERT_EQ(w.status, 0) << w.out << w.err;
  EXPECT_EQ(w.err.find("sit at one spot"), std::string::npos) << w.err;
}

// imr mesh on what is not a model (issue 37): a usage error (64) that names --input, says what
// the folder is and what to do, and writes nothing (no WORK folder beside --out).
TEST_F(SfmModels, MeshOnWhatIsNotAModelSaysWhatItIsAndWritesNothing) {
  io::ColmapModel m = Base();
  Save(m, Case() / "sparse/0", /*binary=*/true);
  Save(m, Case() / "sparse/1", /*binary=*/false);
  for (int i = 0; i < 3; ++i) WriteText(Case() / "photos" / ("IMG_00" + std::to_string(i) + ".JPG"), "x");
  auto mesh = [&](const std::string& input) {
    return RunShell("cd " + Quote(Case().string()) + " && " + Quote(kImr) + " mesh --input " +
                    Quote(input) + " --format colmap --out out/mesh.ply");
  };
  const CommandResult sub = mesh("sparse");
  EXPECT_EQ(sub.status, 64) << sub.out << sub.err;
  EXPECT_NE(sub.err.find("--input: " + (Case() / "sparse").string()), std::string::npos) << sub.err;
  EXPECT_NE(sub.err.find("2 COLMAP sub-models (0, 1)"), std::string::npos) << sub.err;
  EXPECT_NE(sub.err.find((Case() / "sparse/0").string()), std::string::npos) << sub.err;
  const CommandResult photos = mesh("photos");
  EXPECT_EQ(photos.status, 64) << photos.out << photos.err;
  EXPECT_NE(photos.err.find("3 images"), std::string::npos) << photos.err;
  EXPECT_NE(photos.err.find("automatic_reconstructor"), std::string::npos) << photos.err;
  const CommandResult none = mesh("no-such-model");
  EXPECT_EQ(none.status, 64) << none.out << none.err;
  EXPECT_NE(none.err.find("--input: " + (Case() / "no-such-model").string() + " does not exist"),
            std::string::npos) << none.err;
  EXPECT_EQ(none.err.find("job.json"), std::string::npos) << none.err;
  EXPECT_FALSE(fs::exists(Case() / "out")) << "imr mesh created its output folder";
  // The same folders through a job: the sequence's error says the same.
  const CommandResult run = Run(ColmapJob({"sparse", "photos"}));
  EXPECT_NE(run.status, 0);
  const json summary = ReadJson(Case() / "runs/summary.json");
  const std::string all = summary.dump();
  EXPECT_NE(all.find("2 COLMAP sub-models (0, 1)"), std::string::npos) << all;
  EXPECT_NE(all.find("automatic_reconstructor"), std::string::npos) << all;
}

}  // namespace
}  // namespace imr::testing
