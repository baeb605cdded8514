#include "host/io/synthetic_source.h"

#include "host/synthetic/evaluation.h"
#include "host/synthetic/stream.h"

namespace imr::io {
namespace {

class SyntheticSource : public KeyframeSource {
 public:
  explicit SyntheticSource(const synthetic::StreamOptions& o) : stream_(o) {}

  bool Next(engine::KeyframeUpdate* u, KeyframeInfo* info) override {
    synthetic::StreamKeyframe kf;
    if (!stream_.Next(&kf)) return false;
    *u = engine::KeyframeUpdate{};
    for (const auto& c : kf.cameras) u->cameras.push_back({c.id, c.center});
    for (const auto& p : kf.new_points) u->new_points.push_back({p.id, p.position, p.camera_ids});
    for (const auto& p : kf.moved_points)
      u->moved_points.push_back({p.id, p.position, p.camera_ids});
    u->removed_points = kf.removed_points;
    *info = {kf.index, kf.frame};
    return true;
  }

  int KeyframeCount() const override { return stream_.keyframe_count(); }

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
  synthetic::SyntheticStream stream_;
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
