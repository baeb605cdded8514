#include "host/io/synthetic_source.h"

#include "host/synthetic/evaluation.h"
#include "host/synthetic/stream.h"

#include <cmath>
#include <unordered_map>

namespace imr::io {
namespace {

class SyntheticSource : public KeyframeSource {
 public:
  explicit SyntheticSource(const synthetic::StreamOptions& o) : stream_(o) {
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

  nlohmann::json Evaluate(const engine::Mesh& mesh) const override {
    const double tau = 0.2;  // metres
    const synthetic::MeshAccuracy a = synthetic::EvaluateMesh(
        stream_.scene(), mesh.vertices, mesh.faces, stream_.TruePoints(), tau);
    return {{"reference", "known synthetic scene"},
            {"tau", a.tau},
            {"mean_mesh_to_scene", a.mean_mesh_to_scene},
            {"precision", a.precision},
            {"mean_truth_to_mesh", a.mean_truth_to_mesh},
            {"completeness", a.completeness}};
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
  std::unordered_map<uint64_t, CameraGeometry> cameras_;
};

}  // namespace

std::unique_ptr<KeyframeSource> OpenSyntheticSource(const std::string& scene,
                                                    const nlohmann::json& o) {
  synthetic::StreamOptions s;
  if (!synthetic::FromString(scene, &s.scene))
    throw std::runtime_error("unknown synthetic scene '" + scene + "'");
  s.frames = o.at("frames");
  s.seed = o.at("seed");
  s.keyframe_every = o.at("keyframe_every");
  s.speed = o.at("speed");
  s.points_per_keyframe = o.at("points_per_keyframe");
  s.noise_at_10m = o.at("noise_at_10m");
  s.frozen = o.at("frozen");
  return std::make_unique<SyntheticSource>(s);
}

}  // namespace imr::io
