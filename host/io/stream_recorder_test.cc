#include "host/io/stream_recorder.h"

#include "host/io/colmap_model.h"
#include "host/io/slam_json.h"
#include "host/io/spool.h"
#include "host/io/testing/temp_dir.h"

#include <gtest/gtest.h>

#include <fstream>
#include <sstream>

namespace imr::io {
namespace {
namespace fs = std::filesystem;
using testing::TempDir;

std::string Read(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// What a source knows of the drive's cameras: two camera models (a COLMAP one, and an OpenMVG
// one whose pixels the COLMAP export shifts), image names, and keypoints for every third camera.
class DriveCameras : public KeyframeSource {
 public:
  bool Next(engine::KeyframeUpdate*, KeyframeInfo*) override { return false; }
  const CameraGeometry* Camera(uint64_t id) const override {
    auto [it, added] = cameras_.try_emplace(id);
    CameraGeometry& g = it->second;
    if (added) {
      g.id = id;
      g.name = "frame_" + std::to_string(id) + ".png";
      g.has_intrinsics = true;
      Intrinsics& k = g.intrinsics;
      k.source_model = id % 2 ? "PINHOLE" : "pinhole";
      k.width = 640, k.height = 480, k.fx = k.fy = 400.0, k.cx = 320.0, k.cy = 240.0;
      if (id % 2) k.source_params = {k.fx, k.fy, k.cx, k.cy};
      k.projectable = true;
      SetFromCenter(Identity3(), {static_cast<double>(id), 0.0, 0.0}, &g);
    }
    return &g;
  }
  bool Keypoint(uint64_t camera, uint64_t point, std::array<double, 2>* xy) const override {
    if (camera % 3 != 0) return false;
    *xy = {static_cast<double>(point % 640), 100.0};
    return true;
  }

 private:
  mutable std::map<uint64_t, CameraGeometry> cameras_;  // a test's few hundred cameras
};

constexpr int kPerKeyframe = 40;

// Keyframe k of a drive: camera k, 1 m after the one before; kPerKeyframe new points in front of
// it (a quarter seen by the camera before too); the points of the three keyframes before move
// and are seen by it (the last keyframe's with the camera they had as well), a quarter of the
// last keyframe's move with no new camera (a late observation of their last view); a third of
// the points of six keyframes before are removed. With `late`, every 25th keyframe also moves
// points of 30 keyframes before (an update naming a point again long after).
engine::KeyframeUpdate DriveUpdate(int k, bool late) {
  engine::KeyframeUpdate u;
  const uint64_t cam = static_cast<uint64_t>(k);
  u.cameras = {{cam, {static_cast<double>(k), 0.0, 0.0}}};
  auto id = [](int kf, int i) { return static_cast<uint64_t>(kf) * kPerKeyframe + static_cast<uint64_t>(i); };
  auto at = [](int kf, int i, double shift) {
    return Vec3{kf + 0.01 * i + shift, 1.0 + i % 5, 5.0 + i % 3};
  };
  for (int i = 0; i < kPerKeyframe; ++i) {
    engine::NewPoint p{id(k, i), at(k, i, 0.0), {cam}};
    if (i % 4 == 0 && k > 0) p.camera_ids.insert(p.camera_ids.begin(), cam - 1);
    u.new_points.push_back(std::move(p));
  }
  auto alive = [&](int kf, int i) { return kf >= 0 && i % 3 != 0; };  // not removed, or not yet
  for (int d = 1; d <= 3; ++d)
    for (int i = 0; i < kPerKeyframe; ++i) {
      if (!alive(k - d, i)) continue;
      if (i % 2 == 0) {
        engine::MovedPoint m{id(k - d, i), at(k - d, i, 0.001 * d), {cam}};
        if (d == 1) m.camera_ids.push_back(cam - 1);  // one it has
        u.moved_points.push_back(std::move(m));
      } else if (d == 1 && i % 4 == 1) {
        u.moved_points.push_back({id(k - d, i), at(k - d, i, 0.0005), {}});
      }
    }
  if (k >= 6)
    for (int i = 0; i < kPerKeyframe; i += 3) u.removed_points.push_back(id(k - 6, i));
  if (late && k >= 30 && k % 25 == 0)
    for (int i = 1; i < kPerKeyframe; i += 4)
      if (alive(k - 30, i)) u.moved_points.push_back({id(k - 30, i), at(k - 30, i, 0.01), {cam}});
  return u;
}

void Drive(StreamRecorder* recorder, int keyframes, bool late) {
  CanonicalOrder order;  // as the pipeline gives every update
  for (int k = 0; k < keyframes; ++k) {
    engine::KeyframeUpdate u = DriveUpdate(k, late);
    order.Apply(&u);
    recorder->Record(u, {k, 5 * k});
  }
}

TEST(StreamRecorder, HoldsNothingPerObservationOrView) {
  TempDir dir;
  DriveCameras cameras;
  int64_t held[2], observations[2];
  const int frames[2] = {200, 800};
  for (int r = 0; r < 2; ++r) {
    const fs::path spool = dir / ("spool" + std::to_string(r));
    fs::create_directories(spool);
    StreamRecorder recorder(&cameras, "test", {spool, 4096, 16});
    Drive(&recorder, frames[r], /*late=*/true);
    held[r] = recorder.HeldBytes();
    observations[r] = recorder.stats().observations;
    EXPECT_GT(recorder.stats().points_spooled, 0);
  }
  // Four times the drive: four times the observations recorded, the same bytes held (the sort's
  // buffer, the file buffers, the points of the last keyframes), ~100 bytes a point.
  EXPECT_GT(observations[1], 3 * observations[0] + observations[0] / 2);
  EXPECT_LE(held[1], held[0] + held[0] / 10) << held[0] << " bytes after " << frames[0]
                                             << " keyframes, " << held[1] << " after " << frames[1];
  EXPECT_LT(held[1], 1 << 20);
}

TEST(StreamRecorder, TheSpoolsSizesDoNotChangeTheFiles) {
  TempDir dir;
  DriveCameras cameras;
  // Tiny: sorted runs of 64 records, points out of memory after one keyframe unnamed (and back
  // when named again); large: everything in memory until the end.
  const StreamRecorderOptions tiny{dir / "tiny", 64, 1}, large{dir / "large", 1 << 20, 1 << 20};
  fs::create_directories(tiny.spool);
  fs::create_directories(large.spool);
  StreamRecorder a(&cameras, "test", tiny), b(&cameras, "test", large);
  Drive(&a, 120, /*late=*/true);
  Drive(&b, 120, /*late=*/true);
  EXPECT_GT(a.stats().points_spooled, 0);
  EXPECT_GT(a.stats().points_recovered, 0);
  EXPECT_EQ(b.stats().points_spooled, 0);
  for (auto [r, name] : {std::pair{&a, "a"}, std::pair{&b, "b"}}) {
    r->WriteSlamJson(dir / (std::string(name) + ".json"));
    fs::create_directories(dir / name);
    r->WriteColmap(dir / name);
  }
  const std::string json = Read(dir / "a.json");
  EXPECT_EQ(json, Read(dir / "b.json"));
  EXPECT_NE(json.find("\"keyframe\": 119, \"frame\": 595"), std::string::npos);
  for (const char* f : {"cameras.txt", "images.txt", "points3D.txt"})
    EXPECT_EQ(Read(dir / "a" / f), Read(dir / "b" / f)) << f;
  // Both files are whole: the stream replays every keyframe, the model's references hold.
  auto replay = OpenSlamJson(dir / "a.json", {});
  EXPECT_EQ(replay->KeyframeCount(), 120);
  const ColmapModel m = ReadColmapModel(dir / "a");
  EXPECT_NO_THROW(CheckColmapModel(m, "export"));
  EXPECT_EQ(m.images.size(), 120u);
  EXPECT_EQ(m.cameras.size(), 2u);  // the two models
}

TEST(StreamRecorder, AFailedWriteSaysWhichFile) {
  TempDir dir;
  fs::create_directories(dir / "spool");
  StreamRecorder recorder(nullptr, "test", {dir / "spool"});
  Drive(&recorder, 3, false);
  try {
    recorder.WriteSlamJson(dir / "missing" / "stream.json");
    FAIL() << "wrote into a folder that does not exist";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find((dir / "missing" / "stream.json").string()), std::string::npos) << e.what();
  }
  EXPECT_THROW(StreamRecorder(nullptr, "test", {dir / "nowhere"}), std::invalid_argument);
}

TEST(ExternalSort, MergesRunsStably) {
  TempDir dir;
  struct R {
    int key, order;
  };
  struct Less {
    bool operator()(const R& a, const R& b) const { return a.key < b.key; }
  };
  ExternalSort<R, Less> sort(dir.path(), "t", 5);
  for (int i = 0; i < 103; ++i) sort.Add({(i * 37) % 11, i});
  EXPECT_EQ(sort.runs(), 20u);  // 20 full runs, the rest still in memory
  for (int pass = 0; pass < 2; ++pass) {  // a sort reads again
    auto reader = sort.Read();
    R r{}, prev{-1, -1};
    int n = 0;
    while (reader->Next(&r)) {
      EXPECT_TRUE(prev.key < r.key || (prev.key == r.key && prev.order < r.order)) << n;
      prev = r;
      ++n;
    }
    EXPECT_EQ(n, 103);
  }
}

}  // namespace
}  // namespace imr::io
