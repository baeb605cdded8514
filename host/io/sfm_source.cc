#include "host/io/sfm_source.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <unordered_set>
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
    const SfmPoint* p = Find(id);
    if (p == nullptr || !p->has_rgb) return false;
    *rgb = p->rgb;
    return true;
  }
  bool Keypoint(uint64_t view_id, uint64_t point_id, std::array<double, 2>* xy) const override {
    const SfmPoint* p = Find(point_id);
    if (p == nullptr) return false;
    for (const SfmObservation& o : p->observations)
      if (o.view_id == view_id) {
        *xy = {o.x, o.y};
        return true;
      }
    return false;
  }
  json Summary() const override { return summary_; }

 private:
  // A share of the model collapsed to one spot (a failed merge in the SfM run: cameras with no
  // baseline, points on top of each other) is left out, and said in the summary ("collapsed"):
  // meshed, it is a blob of zero-area triangles. The spot: the grid cell of 1e-4 of the scene's
  // diagonal that holds the most points (or camera centres); what lies within two cells of its
  // mean is collapsed when it is at least 20 points and 5 % of them (3 centres and 10 %). The
  // scene's diagonal is that of its 2nd to 98th percentiles.
  json RemoveCollapsed() {
    std::vector<Vec3> all;
    for (const SfmPoint& p : model_.points) all.push_back(p.position);
    for (const CameraGeometry& g : model_.views) all.push_back(g.center);
    if (all.size() < 2) return nullptr;
    // The extent without its outliers (2nd to 98th percentile per axis): a few far points must
    // not make the cells large enough to hold a real object.
    Vec3 lo{}, hi{};
    std::vector<double> axis(all.size());
    for (int a = 0; a < 3; ++a) {
      for (std::size_t i = 0; i < all.size(); ++i) axis[i] = all[i][a];
      std::sort(axis.begin(), axis.end());
      lo[a] = axis[axis.size() * 2 / 100];
      hi[a] = axis[axis.size() * 98 / 100];
    }
    const double diagonal = std::sqrt((hi[0] - lo[0]) * (hi[0] - lo[0]) +
                                      (hi[1] - lo[1]) * (hi[1] - lo[1]) +
                                      (hi[2] - lo[2]) * (hi[2] - lo[2]));
    if (!(diagonal > 0.0) || !std::isfinite(diagonal)) return nullptr;
    const double cell = 1e-4 * diagonal;
    // The spot where most of `points` sit, and how many are within two cells of it.
    auto spot = [&](const std::vector<Vec3>& points, Vec3* at) {
      std::map<std::array<int64_t, 3>, std::pair<std::size_t, Vec3>> grid;
      for (const Vec3& p : points) {
        std::array<int64_t, 3> k;
        for (int a = 0; a < 3; ++a) k[a] = static_cast<int64_t>(std::floor((p[a] - lo[a]) / cell));
        auto& [count, sum] = grid[k];
        ++count;
        for (int a = 0; a < 3; ++a) sum[a] += p[a];
      }
      std::size_t best = 0;
      for (const auto& [k, v] : grid)
        if (v.first > best) {
          best = v.first;
          for (int a = 0; a < 3; ++a) (*at)[a] = v.second[a] / static_cast<double>(v.first);
        }
      std::size_t near = 0;
      for (const Vec3& p : points) near += Near(p, *at, 2.0 * cell) ? 1 : 0;
      return near;
    };
    std::vector<Vec3> centres, positions;
    for (const CameraGeometry& g : model_.views) centres.push_back(g.center);
    for (const SfmPoint& p : model_.points) positions.push_back(p.position);
    Vec3 camera_spot{}, point_spot{};
    const std::size_t cams = spot(centres, &camera_spot);
    const std::size_t pts = spot(positions, &point_spot);
    const bool cams_collapsed = cams >= 3 && 10 * cams >= centres.size();
    const bool pts_collapsed = pts >= 20 && 20 * pts >= positions.size();
    if (!cams_collapsed && !pts_collapsed) return nullptr;
    std::unordered_set<uint64_t> gone_views;
    if (cams_collapsed)
      for (const CameraGeometry& g : model_.views)
        if (Near(g.center, camera_spot, 2.0 * cell)) gone_views.insert(g.id);
    const std::size_t views_before = model_.views.size(), points_before = model_.points.size();
    model_.views.erase(std::remove_if(model_.views.begin(), model_.views.end(),
                                      [&](const CameraGeometry& g) { return gone_views.count(g.id) > 0; }),
                       model_.views.end());
    std::size_t points_gone = 0;
    std::vector<SfmPoint> kept;
    for (SfmPoint& p : model_.points) {
      if (pts_collapsed && Near(p.position, point_spot, 2.0 * cell)) {
        ++points_gone;
        continue;
      }
      p.observations.erase(std::remove_if(p.observations.begin(), p.observations.end(),
                                          [&](const SfmObservation& o) { return gone_views.count(o.view_id) > 0; }),
                           p.observations.end());
      kept.push_back(std::move(p));
    }
    model_.points = std::move(kept);
    json c = {{"within", 2.0 * cell}};
    if (cams_collapsed)
      c["views"] = {{"left_out", gone_views.size()}, {"of", views_before},
                    {"at", {camera_spot[0], camera_spot[1], camera_spot[2]}}};
    if (pts_collapsed)
      c["points"] = {{"left_out", points_gone}, {"of", points_before},
                     {"at", {point_spot[0], point_spot[1], point_spot[2]}}};
    return c;
  }
  const SfmPoint* Find(uint64_t id) const {
    auto it = std::lower_bound(model_.points.begin(), model_.points.end(), id,
                               [](const SfmPoint& p, uint64_t v) { return p.id < v; });
    return it == model_.points.end() || it->id != id ? nullptr : &*it;
  }
  static bool Near(const Vec3& p, const Vec3& q, double r) {
    const double dx = p[0] - q[0], dy = p[1] - q[1], dz = p[2] - q[2];
    return dx * dx + dy * dy + dz * dz <= r * r;
  }

  void Build() {
    std::stable_sort(model_.points.begin(), model_.points.end(),
                     [](const SfmPoint& a, const SfmPoint& b) { return a.id < b.id; });
    const json collapsed = RemoveCollapsed();
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
    if (!collapsed.is_null()) summary_["collapsed"] = collapsed;
    // The points stay (sorted by id) for their colours and keypoints; the updates hold the rest.
  }

  SfmModel model_;
  SfmReplayOptions opt_;
  std::unordered_map<uint64_t, std::size_t> by_id_;
  json summary_;
};

}  // namespace

std::unique_ptr<KeyframeSource> MakeSfmSource(SfmModel model, const SfmReplayOptions& options) {
  return std::make_unique<SfmSource>(std::move(model), options);
}

}  // namespace imr::io
