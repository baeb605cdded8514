#include "host/io/synthetic_source.h"

#include "host/synthetic/evaluation.h"
#include "host/synthetic/stream.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <stdexcept>
#include <unordered_map>

namespace imr::io {
namespace {

class SyntheticSource : public KeyframeSource {
 public:
  explicit SyntheticSource(const synthetic::StreamOptions& o)
      : stream_(o), reach_(2 * (std::max(o.track_frames, 0) + o.keyframe_every)) {
    // A pinhole with the stream's horizontal field of view, 1000 pixels wide (for exports).
    const double kPi = 3.14159265358979323846;
    intrinsics_.source_model = "pinhole";
    intrinsics_.width = 1000;
    intrinsics_.fx = intrinsics_.fy = 500.0 / std::tan(0.5 * o.hfov_deg * kPi / 180.0);
    intrinsics_.height = static_cast<int>(
        std::round(2.0 * intrinsics_.fy * std::tan(0.5 * o.vfov_deg * kPi / 180.0)));
    intrinsics_.cx = 500.0;
    intrinsics_.cy = 0.5 * intrinsics_.height;
    intrinsics_.projectable = true;
  }

  bool Next(engine::KeyframeUpdate* u, KeyframeInfo* info) override {
    synthetic::StreamKeyframe kf;
    if (!stream_.Next(&kf)) return false;
    *u = engine::KeyframeUpdate{};
    for (const auto& c : kf.cameras) {
      u->cameras.push_back({c.id, c.center});
      AddGeometry(c);
    }
    // A point names the frames that observed it: a block's (the update's own cameras) or a
    // track's (at most track_frames back). Older cameras' geometry goes: a record per camera
    // would grow with the drive (issue 46).
    if (!kf.cameras.empty())
      while (!cameras_.empty() && cameras_.begin()->first + reach_ < kf.cameras.front().id)
        cameras_.erase(cameras_.begin());
    for (const auto& p : kf.new_points) u->new_points.push_back({p.id, p.position, p.camera_ids});
    for (const auto& p : kf.moved_points)
      u->moved_points.push_back({p.id, p.position, p.camera_ids});
    u->removed_points = kf.removed_points;
    *info = {kf.index, kf.frame};
    return true;
  }

  int KeyframeCount() const override { return stream_.keyframe_count(); }

  const CameraGeometry* Camera(uint64_t id) const override {
    auto it = cameras_.find(id);
    return it == cameras_.end() ? nullptr : &it->second;
  }

  bool CanEvaluate() const override { return true; }
  nlohmann::json Evaluate(const engine::Mesh& mesh) const override {
    const bool truth = stream_.options().keep_truth;
    // Mesh -> scene needs only the scene; truth -> mesh needs every point the stream reported.
    return AccuracyJson(synthetic::EvaluateMesh(stream_.scene(), mesh.vertices, mesh.faces,
                                                truth ? stream_.TruePoints() : std::vector<Vec3>{},
                                                kTau));
  }
  // Mesh -> scene triangle by triangle; truth -> mesh as each true point's running minimum over
  // the blocks (synthetic::MeshAccuracyInBlocks): Evaluate's figures without the mesh whole.
  std::unique_ptr<BlockEvaluation> EvaluateInBlocks() const override {
    class Blocks : public BlockEvaluation {
     public:
      explicit Blocks(const SyntheticSource& s)
          : source_(s),
            acc_(s.stream_.scene(),
                 s.stream_.options().keep_truth ? s.stream_.TruePoints() : std::vector<Vec3>{}, kTau) {}
      void AddTriangles(const std::vector<double>& vertices, const std::vector<uint32_t>& faces) override {
        acc_.AddTriangles(vertices, faces);
      }
      nlohmann::json Finish() const override { return source_.AccuracyJson(acc_.Result()); }

     private:
      const SyntheticSource& source_;
      synthetic::MeshAccuracyInBlocks acc_;
    };
    return std::make_unique<Blocks>(*this);
  }

 private:
  static constexpr double kTau = 0.2;  // metres
  nlohmann::json AccuracyJson(const synthetic::MeshAccuracy& a) const {
    const bool truth = stream_.options().keep_truth;
    nlohmann::json j = {{"reference", "known synthetic scene"},
                        {"tau", a.tau},
                        {"mean_mesh_to_scene", a.mean_mesh_to_scene},
                        {"precision", a.precision}};
    if (truth) {
      j["mean_truth_to_mesh"] = a.mean_truth_to_mesh;
      j["completeness"] = a.completeness;
    } else {
      j["completeness_omitted"] =
          "input.options.keep_truth is false: the stream did not keep the true positions of the "
          "points it reported (memory flat in the drive's length), and completeness is measured "
          "against them";
    }
    return j;
  }

 public:
  // What the stream generated: observations per frame, moves, and in the tracked model the
  // tracks' lengths; the generator's own time (without the engine).
  nlohmann::json Summary() const override {
    const synthetic::StreamStats& s = stream_.stats();
    const synthetic::StreamOptions& o = stream_.options();
    const double frames = std::max<double>(1.0, static_cast<double>(s.frames));
    nlohmann::json j = {
        {"model", o.track_frames > 0 ? "tracked" : "block"},
        {"frames", s.frames},
        {"keyframes", s.keyframes},
        {"observations", s.observations},
        {"observations_per_frame", s.observations / frames},
        {"points", {{"new", s.new_points}, {"moved", s.moved_points}}},
        {"new_points_per_frame", s.new_points / frames},
        {"moves_per_frame", s.moved_points / frames},
        {"true_points_kept", s.kept_truths},
        {"generator_seconds", s.seconds},
        {"generator_ms_per_frame", 1e3 * s.seconds / frames}};
    if (o.track_frames > 0) {
      int64_t ended = 0, sum = 0, reported = 0, reported_sum = 0;
      for (size_t n = 1; n < s.track_lengths.size(); ++n) {
        ended += s.track_lengths[n];
        sum += static_cast<int64_t>(n) * s.track_lengths[n];
        if (static_cast<int>(n) >= o.min_observations) {
          reported += s.track_lengths[n];
          reported_sum += static_cast<int64_t>(n) * s.track_lengths[n];
        }
      }
      j["tracks"] = {
          {"started", s.tracks_started},
          {"ended", s.tracks_ended},
          {"lost_before_track_frames", s.tracks_lost},
          {"mean_length", ended > 0 ? static_cast<double>(sum) / ended : 0.0},
          {"mean_length_reported",
           reported > 0 ? static_cast<double>(reported_sum) / reported : 0.0},
          {"length_histogram", s.track_lengths},  // [n]: ended tracks of n observations
          {"active_at_end", s.active_tracks},
          {"active_max", s.max_active_tracks}};
    }
    return j;
  }

 private:
  // Camera frame: x right, y down, z forward (the scene's up is +z).
  void AddGeometry(const synthetic::StreamCamera& c) {
    const Vec3& f = c.forward;
    Vec3 r = {f[1], -f[0], 0.0};  // forward x up(0, 0, 1)
    const double n = std::hypot(r[0], r[1]);
    if (n < 1e-12) return;  // looking straight up or down: no frame
    r = {r[0] / n, r[1] / n, 0.0};
    const Vec3 up = {r[1] * f[2] - r[2] * f[1], r[2] * f[0] - r[0] * f[2], r[0] * f[1] - r[1] * f[0]};
    CameraGeometry g;
    g.id = c.id;
    g.name = "frame_" + std::to_string(c.id);
    SetFromCenter({{{r[0], r[1], r[2]}, {-up[0], -up[1], -up[2]}, {f[0], f[1], f[2]}}}, c.center, &g);
    g.has_intrinsics = true;
    g.intrinsics = intrinsics_;
    cameras_[c.id] = g;
  }

  synthetic::SyntheticStream stream_;
  Intrinsics intrinsics_;
  uint64_t reach_;  // frames back a point may still name
  std::map<uint64_t, CameraGeometry> cameras_;  // the cameras within reach_ of the newest
};

}  // namespace

namespace {

synthetic::StreamOptions StreamOptionsFromJson(const nlohmann::json& o) {
  synthetic::StreamOptions s;
  s.frames = o.at("frames");
  s.seed = o.at("seed");
  s.keyframe_every = o.at("keyframe_every");
  s.speed = o.at("speed");
  s.points_per_keyframe = o.at("points_per_keyframe");
  s.noise_at_10m = o.at("noise_at_10m");
  s.frozen = o.at("frozen");
  s.max_range = o.at("max_range");
  s.track_frames = o.at("track_frames");
  s.track_density = o.at("track_density");
  s.angular_noise = o.at("angular_noise");
  s.keep_truth = o.at("keep_truth");
  return s;
}

}  // namespace

std::vector<std::string> CheckSyntheticOptions(const nlohmann::json& o) {
  const std::string problem = StreamOptionsFromJson(o).Check();
  if (problem.empty()) return {};
  return {problem};
}

std::unique_ptr<KeyframeSource> OpenSyntheticSource(const std::string& scene,
                                                    const nlohmann::json& o) {
  synthetic::StreamOptions s = StreamOptionsFromJson(o);
  if (!synthetic::FromString(scene, &s.scene))
    throw std::runtime_error("unknown synthetic scene '" + scene + "'");
  // Validation refuses what the options break together (CheckSyntheticOptions); a caller that
  // skipped it still gets the field named.
  if (const std::string problem = s.Check(); !problem.empty())
    throw std::runtime_error("input.options: " + problem);
  return std::make_unique<SyntheticSource>(s);
}

}  // namespace imr::io
