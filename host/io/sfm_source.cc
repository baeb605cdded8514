#include "host/io/sfm_source.h"

#include <algorithm>
#include <stdexcept>
#include <unordered_map>

namespace imr::io {
using nlohmann::json;

SfmReplayOptions SfmReplayOptionsFromJson(const json& o) {
  SfmReplayOptions r;
  r.replay = o.at("mode").get<std::string>() == "replay";
  r.order_by_name = o.at("order").get<std::string>() == "name";
  r.views_per_keyframe = o.at("views_per_keyframe");
  r.min_views = o.at("min_views");
  return r;
}

json SfmReplayOptionsSchema() {
  const SfmReplayOptions d;
  return {
      {"mode", {{"type", "string"}, {"default", "batch"}, {"enum", {"batch", "replay"}},
                {"description", "batch: one update with every camera and point; replay: views "
                                "in order, a keyframe every views_per_keyframe views"}}},
      {"order", {{"type", "string"}, {"default", "id"}, {"enum", {"id", "name"}},
                 {"description", "replay order of the views: by view/image id or image name"}}},
      {"views_per_keyframe", {{"type", "integer"}, {"default", d.views_per_keyframe},
                              {"minimum", 1}, {"description", "replay: views per keyframe"}}},
      {"min_views", {{"type", "integer"}, {"default", d.min_views}, {"minimum", 1},
                     {"description", "a point enters once this many views (replayed so far) see "
                                     "it; points seen by fewer are skipped"}}}};
}

namespace {

class SfmSource : public PrecomputedKeyframeSource {
 public:
  SfmSource(SfmModel model, const SfmReplayOptions& o) : model_(std::move(model)), opt_(o) {
    Build();
  }

  const CameraGeometry* Camera(uint64_t id) const override {
    auto it = by_id_.find(id);
    return it == by_id_.end() ? nullptr : &model_.views[it->second];
  }
  bool PointColor(uint64_t id, std::array<uint8_t, 3>* rgb) const override {
    auto it = colors_.find(id);
    if (it == colors_.end()) return false;
    *rgb = it->second;
    return true;
  }
  json Summary() const override { return summary_; }

 private:
  void Build() {
    const std::size_t n = model_.views.size();
    const auto nothing = [](const std::string& where, const std::string& why) {
      throw std::runtime_error(where + ": nothing to mesh: " + why);
    };
    const std::string& points_file = model_.points_file.empty() ? model_.file : model_.points_file;
    if (model_.points.empty())
      nothing(points_file, "the model has no 3D points" + model_.no_points_hint);
    if (n < kMinViewsToMesh)
      nothing(model_.views_file.empty() ? model_.file : model_.views_file,
              "only " + std::to_string(n) + " posed view" + (n == 1 ? "" : "s") +
                  " (images with a pose); a mesh needs rays from at least " +
                  std::to_string(kMinViewsToMesh) + " (a model of the initial pair only?): register "
                  "more images (COLMAP: image_registrator, or mapper with more overlap between "
                  "images; with COLMAP 3.12 rigs, every image of each frame), then mesh again");
    std::vector<std::size_t> order(n);
    for (std::size_t i = 0; i < n; ++i) {
      order[i] = i;
      by_id_[model_.views[i].id] = i;
    }
    if (opt_.order_by_name)
      std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
        return model_.views[a].name < model_.views[b].name;
      });
    const std::size_t per = opt_.replay ? static_cast<std::size_t>(opt_.views_per_keyframe)
                                        : std::max<std::size_t>(n, 1);
    std::unordered_map<uint64_t, std::size_t> rank;
    for (std::size_t r = 0; r < n; ++r) rank[model_.views[order[r]].id] = r;
    const std::size_t keyframes = n == 0 ? 0 : (n + per - 1) / per;
    updates_.resize(keyframes);
    frames_.resize(keyframes);
    for (std::size_t r = 0; r < n; ++r) {
      const CameraGeometry& g = model_.views[order[r]];
      updates_[r / per].cameras.push_back({g.id, g.center});
      frames_[r / per] = static_cast<int>(r);
    }
    int64_t skipped = 0, observations = 0;
    // Moves that only add cameras, per keyframe, in point order.
    std::vector<std::vector<engine::MovedPoint>> adds(keyframes);
    for (const SfmPoint& p : model_.points) {
      std::vector<std::size_t> ranks;
      for (const SfmObservation& o : p.observations) ranks.push_back(rank.at(o.view_id));
      std::sort(ranks.begin(), ranks.end());
      ranks.erase(std::unique(ranks.begin(), ranks.end()), ranks.end());
      observations += static_cast<int64_t>(ranks.size());
      if (static_cast<int>(ranks.size()) < opt_.min_views) {
        ++skipped;
        continue;
      }
      const std::size_t enter = ranks[opt_.min_views - 1] / per;
      engine::NewPoint np{p.id, p.position, {}};
      for (std::size_t r : ranks) {
        const uint64_t cam = model_.views[order[r]].id;
        const std::size_t k = r / per;
        if (k <= enter) {
          np.camera_ids.push_back(cam);
        } else {
          if (adds[k].empty() || adds[k].back().id != p.id)
            adds[k].push_back({p.id, p.position, {}});
          adds[k].back().camera_ids.push_back(cam);
        }
      }
      updates_[enter].new_points.push_back(std::move(np));
    }
    if (skipped == static_cast<int64_t>(model_.points.size()))
      nothing(points_file, "none of the " + std::to_string(skipped) + " 3D points is seen by " +
                               std::to_string(opt_.min_views) + " posed views (input option "
                               "min_views)");
    for (std::size_t k = 0; k < keyframes; ++k) updates_[k].moved_points = std::move(adds[k]);
    summary_ = {{"file", model_.file},
                {"mode", opt_.replay ? "replay" : "batch"},
                {"views", n},
                {"views_without_pose", model_.views_without_pose},
                {"points", model_.points.size()},
                {"observations", observations},
                {"observations_skipped_unposed_view", model_.observations_skipped},
                {"points_skipped_too_few_views", skipped},
                {"min_views", opt_.min_views},
                {"keyframes", keyframes}};
    for (const SfmPoint& p : model_.points)
      if (p.has_rgb) colors_[p.id] = p.rgb;
    model_.points = {};  // everything needed is in the updates now (and the colours)
  }

  SfmModel model_;
  SfmReplayOptions opt_;
  std::unordered_map<uint64_t, std::size_t> by_id_;
  std::unordered_map<uint64_t, std::array<uint8_t, 3>> colors_;  // points the file coloured
  json summary_;
};

}  // namespace

std::unique_ptr<KeyframeSource> MakeSfmSource(SfmModel model, const SfmReplayOptions& options) {
  return std::make_unique<SfmSource>(std::move(model), options);
}

}  // namespace imr::io
