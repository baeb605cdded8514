// The Ceres refiner through the real shared object and the C ABI, on a KITTI-like synthetic
// drive: known 3D points on two facades and the ground, cameras moving forward 1 m per frame,
// observations with 0.5 px Gaussian noise, keyframes every 5 frames.
#include <imr/sdk/host.hpp>

#include <gtest/gtest.h>

#include "plugins/refiner_ceres/test_cameras.hpp"
#include "plugins/testing/plugin_fixture.h"

#include <Eigen/Core>
#include <algorithm>
#include <boost/dll/shared_library.hpp>
#include <chrono>
#include <cmath>
#include <functional>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <random>
#include <set>
#include <string>
#include <vector>

namespace {

using imr::ceres_refiner::testing::CameraAt;
using imr::ceres_refiner::testing::kCx;
using imr::ceres_refiner::testing::kCy;
using imr::ceres_refiner::testing::kFx;
using imr::ceres_refiner::testing::kHeight;
using imr::ceres_refiner::testing::kWidth;

// Pixel of X in frame `frame` (camera looks down +z, y down); empty when not visible.
std::optional<Eigen::Vector2d> Project(const Eigen::Vector3d& X, uint64_t frame) {
  const double z = X.z() - static_cast<double>(frame);
  if (z < 1.0) return std::nullopt;
  const Eigen::Vector2d p(kFx * X.x() / z + kCx, kFx * X.y() / z + kCy);
  if (p.x() < 0 || p.y() < 0 || p.x() > kWidth - 1 || p.y() > kHeight - 1) return std::nullopt;
  return p;
}

// Facades at x = -7 and x = +8, ground at y = 1.65 (camera height), from 6 m to 90 m ahead.
std::vector<Eigen::Vector3d> Street(int count, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<Eigen::Vector3d> pts;
  for (int i = 0; i < count; ++i) {
    const double z = 6.0 + 84.0 * u(rng);
    switch (i % 3) {
      case 0: pts.emplace_back(-7.0, -4.0 + 5.6 * u(rng), z); break;
      case 1: pts.emplace_back(8.0, -4.0 + 5.6 * u(rng), z); break;
      default: pts.emplace_back(-6.5 + 14.0 * u(rng), 1.65, z); break;
    }
  }
  return pts;
}

struct Reported {
  Eigen::Vector3d first, last;
  std::vector<uint64_t> cameras;
  int first_keyframe = 0;
};

class RefinerPlugin : public imr::testing::PluginFixture {
 protected:
  void SetUp() override {
    LoadPlugin(IMR_REFINER_SO);
  }

  // Drives a drive of `frames` frames. Track id = 1000 + point index; `extra` adds observations of
  // injected tracks per frame. Keeps what the refiner reported, checking the update's structure.
  struct Run {
    std::map<uint64_t, Reported> points;  // currently reported points
    std::set<uint64_t> ever_new, removed;
    std::map<uint64_t, std::set<uint64_t>> observed_in;  // track -> frames that observed it
    std::vector<std::size_t> new_per_keyframe;
    std::size_t moved = 0, moved_below_min = 0;
    double keyframe_ms = 0.0;
    int keyframes = 0;
  };
  Run Drive(const std::string& params, const std::vector<Eigen::Vector3d>& truth, int frames,
            double sigma_px, double min_move_check,
            const std::function<void(uint64_t, std::vector<imr_track_observation>*)>& extra = {}) {
    imr::sdk::Instance inst(d_, params, nullptr);
    std::mt19937 rng(11);
    std::normal_distribution<double> noise(0.0, sigma_px);
    Run run;
    for (int f = 0; f < frames; ++f) {
      const uint64_t frame = static_cast<uint64_t>(f);
      std::vector<imr_track_observation> obs;
      for (std::size_t i = 0; i < truth.size(); ++i) {
        if (auto p = Project(truth[i], frame)) {
          obs.push_back({1000 + i, p->x() + noise(rng), p->y() + noise(rng)});
          run.observed_in[1000 + i].insert(frame);
        }
      }
      if (extra) extra(frame, &obs);
      const bool keyframe = f % 5 == 0;
      const auto t0 = std::chrono::steady_clock::now();
      const imr_refiner_update u = inst.AddFrame(CameraAt(frame), obs.data(), obs.size(), keyframe);
      if (keyframe) {
        run.keyframe_ms +=
            std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
        ++run.keyframes;
      } else {
        EXPECT_EQ(u.new_count + u.moved_count + u.removed_count + u.camera_id_count, 0u);
      }
      run.new_per_keyframe.push_back(u.new_count);
      for (uint64_t i = 0; i < u.new_count; ++i) {
        const imr_point_estimate& e = u.new_points[i];
        EXPECT_TRUE(run.ever_new.insert(e.id).second) << "point " << e.id << " new twice";
        EXPECT_LE(e.first_camera + e.camera_count, u.camera_id_count);
        Reported r;
        r.first = r.last = Eigen::Vector3d(e.position[0], e.position[1], e.position[2]);
        r.cameras.assign(u.camera_ids + e.first_camera, u.camera_ids + e.first_camera + e.camera_count);
        r.first_keyframe = f;
        run.points[e.id] = r;
      }
      for (uint64_t i = 0; i < u.moved_count; ++i) {
        const imr_point_estimate& e = u.moved_points[i];
        auto it = run.points.find(e.id);
        EXPECT_NE(it, run.points.end()) << "moved point " << e.id << " was never new";
        if (it == run.points.end()) continue;
        const Eigen::Vector3d p(e.position[0], e.position[1], e.position[2]);
        ++run.moved;
        if ((p - it->second.last).norm() <= min_move_check) ++run.moved_below_min;
        it->second.last = p;
      }
      for (uint64_t i = 0; i < u.removed_count; ++i) {
        EXPECT_EQ(run.points.erase(u.removed_ids[i]), 1u) << "removed an unknown point";
        run.removed.insert(u.removed_ids[i]);
      }
    }
    return run;
  }

};

double Median(std::vector<double> v) {
  if (v.empty()) return std::nan("");
  std::nth_element(v.begin(), v.begin() + static_cast<long>(v.size() / 2), v.end());
  return v[v.size() / 2];
}

TEST_F(RefinerPlugin, DescriptorAndSchema) {
  EXPECT_EQ(imr::sdk::CheckDescriptor(d_), "");
  EXPECT_EQ(d_->kind, IMR_KIND_REFINER);
  EXPECT_STREQ(d_->id, "org.imr.refiner.ceres");
  const auto schema = nlohmann::json::parse(d_->params_schema);
  for (const char* key : {"min_parallax_deg", "huber_px", "max_reprojection_error", "min_depth",
                          "max_distance", "min_move"})
    EXPECT_TRUE(schema.contains(key) && schema[key].contains("default")) << key;
}

// Measured (2000 points, 26 frames, 0.5 px noise): median 3D error of the first estimates about
// 0.8 m, after the last keyframe about 0.1 m; stated bounds: final median below the first
// estimates' median, and below 0.25 m.
TEST_F(RefinerPlugin, PointsAppearWithParallaxAndConvergeTowardTheTruth) {
  const std::vector<Eigen::Vector3d> truth = Street(2000, 5);
  const double min_move = 0.01;
  Run run = Drive("{}", truth, 26, 0.5, min_move);
  EXPECT_EQ(run.new_per_keyframe[0], 0u) << "one keyframe cannot triangulate";
  EXPECT_GT(run.new_per_keyframe[5], 200u) << "no points after the second keyframe";
  EXPECT_GT(run.points.size(), 1000u);

  std::vector<double> first_err, last_err;
  for (const auto& [id, r] : run.points) {
    const Eigen::Vector3d& X = truth[id - 1000];
    // Observing cameras: frames that saw the track, up to the keyframe of the report, with at
    // least two keyframes among them.
    const auto& seen = run.observed_in[id];
    int keyframes = 0;
    for (uint64_t c : r.cameras) {
      EXPECT_TRUE(seen.count(c)) << "point " << id << " reported with camera " << c;
      EXPECT_LE(c, static_cast<uint64_t>(r.first_keyframe));
      keyframes += c % 5 == 0 ? 1 : 0;
    }
    EXPECT_GE(keyframes, 2) << "point " << id;
    EXPECT_GE(r.cameras.size(), 6u) << "point " << id;
    // Points refined after their first estimate: compare first and final errors.
    if (r.first_keyframe <= 15 && *seen.rbegin() >= 20) {
      first_err.push_back((r.first - X).norm());
      last_err.push_back((r.last - X).norm());
    }
  }
  const double first = Median(first_err), last = Median(last_err);
  std::printf("%zu points (%zu removed); %zu refined after their first estimate: median 3D error "
              "%.3f m first, %.3f m after the last keyframe; %zu moves; %.1f ms per keyframe\n",
              run.points.size(), run.removed.size(), first_err.size(), first, last, run.moved,
              run.keyframe_ms / run.keyframes);
  ASSERT_GT(first_err.size(), 300u);
  EXPECT_LT(last, first);
  EXPECT_LT(last, 0.25);
  EXPECT_LT(run.removed.size(), truth.size() / 50) << "clean data should keep its points";
  EXPECT_EQ(run.moved_below_min, 0u);
}

TEST_F(RefinerPlugin, MovesAreReportedOnlyAboveMinMove) {
  const std::vector<Eigen::Vector3d> truth = Street(300, 6);
  const Run small = Drive(R"({"min_move": 0.05})", truth, 21, 0.5, 0.05);
  EXPECT_GT(small.moved, 20u);
  EXPECT_EQ(small.moved_below_min, 0u);
  const Run never = Drive(R"({"min_move": 1000})", truth, 21, 0.5, 1000);
  EXPECT_EQ(never.moved, 0u);
  EXPECT_GT(never.points.size(), 100u);
}

TEST_F(RefinerPlugin, InconsistentTracksAreNeverCreatedOrRemoved) {
  const std::vector<Eigen::Vector3d> truth = Street(200, 7);
  const Eigen::Vector3d a(-7.0, 0.0, 60.0);  // visible from frame 0 to 25
  std::mt19937 rng(3);
  std::normal_distribution<double> jitter(0.0, 15.0);
  auto extra = [&](uint64_t f, std::vector<imr_track_observation>* obs) {
    // Track 1: jitters 15 px around a point: no 3D point explains it.
    const Eigen::Vector2d p = *Project(a, f);
    obs->push_back({1, p.x() + jitter(rng), p.y() + jitter(rng)});
    // Track 2: follows `a` exactly until frame 10, then drifts off by tens of pixels.
    const double drift = f <= 10 ? 0.0 : 30.0 + 2.0 * jitter(rng);
    obs->push_back({2, p.x() + drift, p.y() - 0.5 * drift});
  };
  const Run run = Drive("{}", truth, 26, 0.5, 0.01, extra);
  EXPECT_FALSE(run.points.count(1)) << "the jittering track became a point";
  EXPECT_FALSE(run.ever_new.count(1) && !run.removed.count(1));
  EXPECT_TRUE(run.ever_new.count(2)) << "the good start of track 2 was never triangulated";
  EXPECT_TRUE(run.removed.count(2)) << "track 2 drifted off but its point was not removed";
  EXPECT_FALSE(run.points.count(2));
  EXPECT_GT(run.points.size(), 100u);
}

TEST_F(RefinerPlugin, AnEndedTrackIdThatReappearsGetsNoSecondPoint) {
  const std::vector<Eigen::Vector3d> truth = Street(100, 9);
  const Eigen::Vector3d a(-7.0, 0.0, 60.0);
  auto extra = [&](uint64_t f, std::vector<imr_track_observation>* obs) {
    if (f <= 12 || f >= 16) {  // ends before keyframe 15, comes back at frame 16
      const Eigen::Vector2d p = *Project(a, f);
      obs->push_back({3, p.x(), p.y()});
    }
  };
  const Run run = Drive("{}", truth, 26, 0.0, 0.01, extra);  // Drive fails on a second "new"
  ASSERT_TRUE(run.points.count(3));
  EXPECT_LT((run.points.at(3).last - a).norm(), 1e-3);
}

TEST_F(RefinerPlugin, PointsBehindTheCamerasAreRefused) {
  const std::vector<Eigen::Vector3d> truth = Street(100, 8);
  // Pixels of a point 10 m behind the first camera through a projection that ignores the sign of
  // the depth: DLT finds that point, which no camera can see.
  const Eigen::Vector3d behind(2.0, 0.5, -10.0);
  auto extra = [&](uint64_t f, std::vector<imr_track_observation>* obs) {
    const double z = behind.z() - static_cast<double>(f);
    obs->push_back({5, kFx * behind.x() / z + kCx, kFx * behind.y() / z + kCy});
  };
  const Run run = Drive("{}", truth, 26, 0.0, 0.01, extra);
  EXPECT_FALSE(run.ever_new.count(5)) << "a point behind the cameras was created";
  EXPECT_GT(run.points.size(), 50u);
}

TEST_F(RefinerPlugin, BadCamerasAndObservationsAreInvalidArguments) {
  struct Case {
    const char* needle;
    void (*edit)(imr_camera*, std::vector<imr_track_observation>*);
  };
  const Case cases[] = {
      {"observations[1]", [](imr_camera*, std::vector<imr_track_observation>* o) {
         (*o)[1].x = std::nan("");
       }},
      {"appears twice", [](imr_camera*, std::vector<imr_track_observation>* o) {
         (*o)[1].track_id = (*o)[0].track_id;
       }},
      {"camera.R", [](imr_camera* c, std::vector<imr_track_observation>*) { c->R[0] = 2.0; }},
      {"camera.K", [](imr_camera* c, std::vector<imr_track_observation>*) { c->K[0] = -1.0; }},
      {"camera.t", [](imr_camera* c, std::vector<imr_track_observation>*) {
         c->t[1] = std::numeric_limits<double>::infinity();
       }},
      {"camera.id", [](imr_camera* c, std::vector<imr_track_observation>*) { c->id = 0; }},
  };
  for (const Case& k : cases) {
    imr::sdk::Instance inst(d_, "{}", nullptr);
    std::vector<imr_track_observation> obs = {{1, 100, 100}, {2, 200, 100}};
    inst.AddFrame(CameraAt(0), obs.data(), obs.size(), true);
    imr_camera cam = CameraAt(1);
    k.edit(&cam, &obs);
    try {
      inst.AddFrame(cam, obs.data(), obs.size(), false);
      ADD_FAILURE() << k.needle << ": accepted";
    } catch (const imr::sdk::PluginCallError& e) {
      EXPECT_EQ(e.status(), IMR_INVALID_ARGUMENT) << e.what();
      EXPECT_NE(std::string(e.what()).find(k.needle), std::string::npos) << e.what();
    }
  }
  // Null observations with a non-zero count: refused by the SDK wrapper.
  imr::sdk::Instance inst(d_, "{}", nullptr);
  EXPECT_THROW(inst.AddFrame(CameraAt(0), nullptr, 3, true), imr::sdk::PluginCallError);
}

// A track that starts between keyframes (frames 1 to 9, keyframes every 5) has one keyframe at
// keyframe 5 (frames 1-5) and at keyframe 10, where it has ended (frames 1-9). min_keyframes 2
// never triangulates it; min_keyframes 1 does at keyframe 5 from its 5 views; min_views 6 makes
// it wait for keyframe 10 and its 9 views; min_views 10 refuses it.
TEST_F(RefinerPlugin, MinKeyframesOneAndMinViewsGateATrackBetweenKeyframes) {
  const Eigen::Vector3d X(4.0, 1.0, 15.0);
  const uint64_t id = 5000;
  const auto inject = [&](uint64_t frame, std::vector<imr_track_observation>* obs) {
    if (frame < 1 || frame > 9) return;
    const auto p = Project(X, frame);
    ASSERT_TRUE(p.has_value()) << frame;
    obs->push_back({id, p->x(), p->y()});
  };
  const auto run = [&](const std::string& params) { return Drive(params, {}, 11, 0.5, 0.0, inject); };
  EXPECT_EQ(run("{}").ever_new.count(id), 0u);
  Run r = run(R"({"min_keyframes": 1})");
  ASSERT_EQ(r.points.count(id), 1u);
  EXPECT_EQ(r.points[id].first_keyframe, 5);
  EXPECT_EQ(r.points[id].cameras, (std::vector<uint64_t>{1, 2, 3, 4, 5}));
  EXPECT_LT((r.points[id].first - X).norm(), 1e-6);
  r = run(R"({"min_keyframes": 1, "min_views": 6})");
  ASSERT_EQ(r.points.count(id), 1u);
  EXPECT_EQ(r.points[id].first_keyframe, 10);
  EXPECT_EQ(r.points[id].cameras.size(), 9u);
  EXPECT_EQ(run(R"({"min_keyframes": 1, "min_views": 10})").ever_new.count(id), 0u);
}

TEST_F(RefinerPlugin, BadParamsAreInvalidArgumentsNamingTheParam) {
  const std::pair<const char*, const char*> cases[] = {
      {R"({"min_keyframes": 0})", "params.min_keyframes"},
      {R"({"min_views": 1})", "params.min_views"},
      {R"({"min_parallax_deg": -1})", "params.min_parallax_deg"},
      {R"({"huber_px": "x"})", "params.huber_px"},
      {R"({"min_inlier_ratio": 1.5})", "params.min_inlier_ratio"},
      {R"({"max_distance": 0})", "params.max_distance"},
      {R"({"typo": 1})", "params.typo"},
  };
  for (const auto& [params, field] : cases) {
    std::string message;
    EXPECT_EQ(CreateStatus(params, &message), IMR_INVALID_ARGUMENT) << params;
    EXPECT_NE(message.find(field), std::string::npos) << message;
  }
  std::string message;
  EXPECT_EQ(CreateStatus(R"({"min_move": 0, "huber_px": 0, "max_iterations": 3})", &message), IMR_OK)
      << message;
}

}  // namespace
