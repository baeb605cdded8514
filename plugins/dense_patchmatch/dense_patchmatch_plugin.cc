// org.imr.dense.patchmatch: dense 3D points from the keyframe images (SDK 1.5 dense kind).
// Per keyframe, a depth map of the keyframe before it against its neighbours on both sides
// (patch_match.cc), at a fraction of the image's resolution; pixels kept where the views agree at
// a triangulation angle wide enough to trust the depth, thinned to one point per cell of a 3D grid
// so that a surface seen again from the next keyframes is not sampled again. The plugin keeps the
// last few keyframes (at the working resolution) and the grid's cells within reach of the newest
// (point_cells.hpp), nothing else: bounded memory on any drive.
#include "patch_match.hpp"
#include "point_cells.hpp"

#include <imr/sdk/plugin.hpp>

#include <opencv2/imgproc.hpp>

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <deque>
#include <optional>
#include <string>
#include <thread>
#include <vector>

namespace {

using imr::dense::DepthMap;
using imr::dense::PatchMatchOptions;
using imr::dense::View;

bool HasIntrinsics(const imr_camera& c) { return c.K[0] > 0.0 && c.K[4] > 0.0; }

struct Frame {
  uint64_t id = 0;  // frame index (the camera id the host knows)
  View view;        // at the working resolution
  bool keyframe = false;  // a depth map is made of keyframes only
};

class DensePatchMatch : public imr::sdk::Dense {
 public:
  static constexpr const char* kId = "org.imr.dense.patchmatch";
  static constexpr const char* kVersion = "1.0.0";
  static constexpr const char* kDescription =
      "Dense 3D points from the keyframe images: a PatchMatch depth map per keyframe against "
      "its neighbours (slanted planes, ZNCC), kept where the views agree at a wide enough "
      "angle, one point per cell of a 3D grid";
  static constexpr const char* kParamsSchema = R"json({
    "scale": {"type": "number", "default": 0.25, "minimum": 0.05, "maximum": 1.0,
      "description": "working resolution, a fraction of the image's"},
    "near_frames": {"type": "integer", "default": 2, "minimum": 1, "maximum": 100,
      "description": "a keyframe's depth map is matched against the frames this many before and after it"},
    "far_frames": {"type": "integer", "default": 5, "minimum": 1, "maximum": 100,
      "description": "... and this many before and after it (wider baseline; its points come this many frames later)"},
    "iterations": {"type": "integer", "default": 3, "minimum": 1, "maximum": 32,
      "description": "PatchMatch red-black iterations"},
    "window_radius": {"type": "integer", "default": 3, "minimum": 1, "maximum": 16,
      "description": "patch half-size, working-resolution pixels"},
    "window_step": {"type": "integer", "default": 2, "minimum": 1, "maximum": 16,
      "description": "patch sample spacing, pixels (at most window_radius)"},
    "min_zncc": {"type": "number", "default": 0.7, "minimum": -1.0, "maximum": 1.0,
      "description": "a view agrees with a depth when its ZNCC reaches this"},
    "min_views": {"type": "integer", "default": 2, "minimum": 1, "maximum": 8,
      "description": "a depth is kept when this many views agree"},
    "min_texture": {"type": "number", "default": 2.0, "minimum": 0.0,
      "description": "grey standard deviation (0-255) a patch needs: no depth on blank sky or paint"},
    "min_angle_deg": {"type": "number", "default": 2.0, "minimum": 0.0, "maximum": 45.0,
      "description": "triangulation angle an agreeing view must make with the reference at the point"},
    "min_depth": {"type": "number", "default": 0.0, "minimum": 0.0,
      "description": "nearest depth searched, scene units (0: 0.4 keyframe baselines)"},
    "max_depth": {"type": "number", "default": 0.0, "minimum": 0.0,
      "description": "farthest depth searched, scene units (0: 40 keyframe baselines)"},
    "point_step": {"type": "integer", "default": 2, "minimum": 1, "maximum": 64,
      "description": "one candidate point per this many working-resolution pixels, each way"},
    "spacing": {"type": "number", "default": 0.0, "minimum": 0.0,
      "description": "3D grid cell, scene units: one point per cell (0: spacing_ratio times the first map's median depth)"},
    "spacing_ratio": {"type": "number", "default": 0.01, "minimum": 0.0001, "maximum": 1.0,
      "description": "the automatic spacing as a fraction of the median depth"},
    "consistency": {"type": "number", "default": 0.01, "minimum": 0.0, "maximum": 1.0,
      "description": "a depth is kept when the previous keyframe's depth map agrees within this fraction (0: no check)"},
    "threads": {"type": "integer", "default": 0, "minimum": 0, "maximum": 256,
      "description": "threads inside a call (0: the machine's cores)"}
  })json";

  DensePatchMatch(const imr::sdk::Params& p, const imr::sdk::Host& host) : host_(host) {
    scale_ = p.Get<double>("scale");
    near_ = p.Get<int>("near_frames");
    far_ = std::max(near_, p.Get<int>("far_frames"));
    o_.iterations = p.Get<int>("iterations");
    o_.window_radius = p.Get<int>("window_radius");
    o_.window_step = p.Get<int>("window_step");
    o_.min_zncc = p.Get<double>("min_zncc");
    o_.min_views = p.Get<int>("min_views");
    o_.min_texture = p.Get<double>("min_texture");
    min_angle_ = p.Get<double>("min_angle_deg") * M_PI / 180.0;
    min_depth_ = p.Get<double>("min_depth");
    max_depth_ = p.Get<double>("max_depth");
    if (min_depth_ > 0.0 && max_depth_ > 0.0 && !(max_depth_ > min_depth_))
      throw imr::sdk::InvalidArgument("max_depth: expected more than min_depth");
    point_step_ = p.Get<int>("point_step");
    spacing_ = p.Get<double>("spacing");
    cells_.SetSpacing(spacing_);
    spacing_ratio_ = p.Get<double>("spacing_ratio");
    consistency_ = p.Get<double>("consistency");
    const int threads = p.Get<int>("threads");
    o_.threads = threads > 0 ? threads : std::max(1u, std::thread::hardware_concurrency());
    std::string error;
    if (!o_.Check(&error)) throw imr::sdk::InvalidArgument(error);
  }

  void AddFrame(const imr::sdk::DenseRequest& r, imr::sdk::RefinerUpdate* update) override {
    const imr_camera& c = r.camera;
    if (!HasIntrinsics(c))
      throw imr::sdk::InvalidArgument("frame " + std::to_string(c.id) +
                                      ": no intrinsics (a dense depth map needs a pinhole camera)");
    if (r.image.width != c.width || r.image.height != c.height)
      throw imr::sdk::InvalidArgument("frame " + std::to_string(c.id) + ": image is " +
                                      std::to_string(r.image.width) + "x" +
                                      std::to_string(r.image.height) + ", its camera says " +
                                      std::to_string(c.width) + "x" + std::to_string(c.height));
    window_.push_back(Load(c, r.image, r.is_keyframe));
    // A keyframe's map waits for the frames `far_` after it; at the end, every keyframe not yet
    // made is made with the frames there are.
    for (int i = 0; i < static_cast<int>(window_.size()); ++i) {
      const Frame& k = window_[i];
      if (!k.keyframe || k.id < next_reference_) continue;
      if (k.id + far_ <= c.id || r.final_call) Densify(i);
    }
    while (!window_.empty() && window_.front().id + 2 * far_ < c.id) window_.pop_front();
    if (r.is_keyframe) {
      *update = std::move(pending_);
      pending_.Clear();
    }
  }

 private:
  Frame Load(const imr_camera& c, const imr_image_view& image, bool keyframe) const {
    const int type = image.channels == 3 ? CV_8UC3 : CV_8UC1;
    if (image.channels != 1 && image.channels != 3)
      throw imr::sdk::InvalidArgument("keyframe " + std::to_string(c.id) + ": image has " +
                                      std::to_string(image.channels) + " channels, expected 1 or 3");
    const cv::Mat raw(image.height, image.width, type, const_cast<uint8_t*>(image.pixels),
                      static_cast<std::size_t>(image.stride_bytes));
    cv::Mat gray8, gray;
    if (image.channels == 3)
      cv::cvtColor(raw, gray8, cv::COLOR_BGR2GRAY);
    else
      gray8 = raw;
    gray8.convertTo(gray, CV_32FC1);
    View full;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) {
        full.K(i, j) = c.K[3 * i + j];
        full.R(i, j) = c.R[3 * i + j];
      }
    full.t = Eigen::Vector3d(c.t[0], c.t[1], c.t[2]);
    full.gray = gray;
    Frame k;
    k.id = c.id;
    k.keyframe = keyframe;
    k.view = imr::dense::Downscaled(full, scale_);
    return k;
  }

  // The depth map of window_[ref] against the frames near_ and far_ before and after it, into
  // points (pending until the next keyframe).
  void Densify(int ref) {
    imr::sdk::RefinerUpdate* update = &pending_;
    const Frame& rk = window_[ref];
    next_reference_ = rk.id + 1;
    std::vector<View> nbs;
    std::vector<uint64_t> nb_ids;
    double baseline = 0.0;
    for (int i = 0; i < static_cast<int>(window_.size()); ++i) {
      const int64_t d = std::abs(static_cast<int64_t>(window_[i].id) - static_cast<int64_t>(rk.id));
      if (d != near_ && d != far_) continue;
      const double b = (window_[i].view.Center() - rk.view.Center()).norm();
      if (!(b > 0.0)) continue;  // a car standing still: no parallax
      nbs.push_back(window_[i].view);
      nb_ids.push_back(window_[i].id);
      baseline = std::max(baseline, b);
    }
    if (nbs.empty()) return;
    PatchMatchOptions o = o_;
    o.min_depth = min_depth_ > 0.0 ? min_depth_ : 0.4 * baseline;
    o.max_depth = max_depth_ > 0.0 ? max_depth_ : 40.0 * baseline;
    if (!(o.max_depth > o.min_depth)) o.max_depth = 100.0 * o.min_depth;
    o.seed = rk.id + 1;
    const DepthMap m = imr::dense::ComputeDepthMap(rk.view, nbs, o, [this] { return host_.IsCancelled(); });
    const Funnel f = ToPoints(rk, nbs, nb_ids, m, update);
    // Where a keyframe's depth goes (imr run -v): which step keeps too little on an input.
    host_.Debug("dense: keyframe " + std::to_string(rk.id) + " against " +
                std::to_string(nbs.size()) + " frames (baseline " + std::to_string(baseline) +
                "): " + std::to_string(m.kept) + " of " + std::to_string(m.depth.total()) +
                " pixels kept, " + std::to_string(f.candidates) + " candidates, " +
                std::to_string(f.consistent) + " consistent, " + std::to_string(f.seen) +
                " seen wide enough, " + std::to_string(f.inserted) + " in new cells");
    previous_ = Previous{rk.id, rk.view, m.depth};
    // The cells no map made from near here reaches (twice the farthest depth searched: a point
    // lies at most ~1.4 depths from its camera at the image's corners) go.
    reach_ = std::max(reach_, 2.0 * o.max_depth);
    cells_.Forget(rk.view.Center(), reach_);
  }

  // How many candidate points each check kept.
  struct Funnel {
    int64_t candidates = 0, consistent = 0, seen = 0, inserted = 0;
  };
  Funnel ToPoints(const Frame& rk, const std::vector<View>& nbs, const std::vector<uint64_t>& nb_ids,
                  const DepthMap& m, imr::sdk::RefinerUpdate* update) {
    Funnel f;
    const View& v = rk.view;
    const Eigen::Matrix3d Kinv = v.K.inverse();
    const Eigen::Matrix3d Rt = v.R.transpose();
    const Eigen::Vector3d c = v.Center();
    if (spacing_ <= 0.0) {
      std::vector<float> depths;
      for (int y = 0; y < m.depth.rows; ++y)
        for (int x = 0; x < m.depth.cols; ++x)
          if (m.depth.at<float>(y, x) > 0.0f) depths.push_back(m.depth.at<float>(y, x));
      if (depths.size() < 16) return f;  // too little to choose a spacing from
      std::nth_element(depths.begin(), depths.begin() + depths.size() / 2, depths.end());
      spacing_ = spacing_ratio_ * depths[depths.size() / 2];
      cells_.SetSpacing(spacing_);
    }
    const int step = point_step_;
    for (int y0 = 0; y0 < m.depth.rows; y0 += step)
      for (int x0 = 0; x0 < m.depth.cols; x0 += step) {
        // The best-scored pixel of the cell.
        int bx = -1, by = -1;
        float best = -2.0f;
        for (int y = y0; y < std::min(y0 + step, m.depth.rows); ++y)
          for (int x = x0; x < std::min(x0 + step, m.depth.cols); ++x)
            if (m.depth.at<float>(y, x) > 0.0f && m.score.at<float>(y, x) > best) {
              best = m.score.at<float>(y, x);
              bx = x;
              by = y;
            }
        if (bx < 0) continue;
        ++f.candidates;
        const double z = m.depth.at<float>(by, bx);
        const Eigen::Vector3d X = Rt * (z * (Kinv * Eigen::Vector3d(bx, by, 1.0)) - v.t);
        if (!X.allFinite()) continue;
        const int mask = m.views.at<int>(by, bx);
        std::vector<uint64_t> cams{rk.id};
        if (consistency_ > 0.0) {
          // Two depth maps must agree: random matches (a repeated pattern, a reflection) rarely
          // land on the same depth twice.
          if (!previous_) continue;
          if (!Consistent(*previous_, X)) continue;
          cams.push_back(previous_->id);
        }
        ++f.consistent;
        for (std::size_t k = 0; k < nbs.size(); ++k) {
          if (!(mask & (1 << k))) continue;
          const Eigen::Vector3d a = (c - X).normalized(), b = (nbs[k].Center() - X).normalized();
          if (std::acos(std::clamp(a.dot(b), -1.0, 1.0)) >= min_angle_) cams.push_back(nb_ids[k]);
        }
        if (static_cast<int>(cams.size()) - 1 < o_.min_views) continue;
        ++f.seen;
        if (!cells_.Insert(X)) continue;  // this part of the surface has a point
        ++f.inserted;
        std::sort(cams.begin(), cams.end());
        imr_point_estimate p{};
        p.id = next_id_++;
        p.position[0] = X.x();
        p.position[1] = X.y();
        p.position[2] = X.z();
        p.first_camera = update->camera_ids.size();
        p.camera_count = cams.size();
        update->camera_ids.insert(update->camera_ids.end(), cams.begin(), cams.end());
        update->new_points.push_back(p);
      }
    if (next_id_ >= (uint64_t{1} << 23))
      throw std::runtime_error("more than 2^23 dense points: raise spacing");
    return f;
  }

  struct Previous {
    uint64_t id = 0;
    View view;
    cv::Mat depth;
  };
  bool Consistent(const Previous& p, const Eigen::Vector3d& X) const {
    const Eigen::Vector3d x = p.view.R * X + p.view.t;
    if (x.z() <= 0.0) return false;
    const Eigen::Vector3d q = p.view.K * x;
    const int u = static_cast<int>(std::lround(q.x() / q.z())), v = static_cast<int>(std::lround(q.y() / q.z()));
    if (u < 0 || v < 0 || u >= p.depth.cols || v >= p.depth.rows) return false;
    const double d = p.depth.at<float>(v, u);
    return d > 0.0 && std::abs(d - x.z()) <= consistency_ * x.z();
  }

  imr::sdk::Host host_;
  double scale_ = 0.25;
  int near_ = 2, far_ = 5;
  imr::sdk::RefinerUpdate pending_;  // points made since the last keyframe
  PatchMatchOptions o_;
  double min_angle_ = 0.0, min_depth_ = 0.0, max_depth_ = 0.0;
  int point_step_ = 2;
  double spacing_ = 0.0, spacing_ratio_ = 0.01, consistency_ = 0.01;
  std::optional<Previous> previous_;  // the last depth map made, for the consistency check
  std::deque<Frame> window_;  // the last 2 far_ + 1 frames
  uint64_t next_reference_ = 0;  // the next keyframe id a depth map is owed for
  uint64_t next_id_ = 0;
  imr::dense::PointCells cells_;  // 3D grid cells holding a point, within reach_ of the newest map
  double reach_ = 0.0;
};

}  // namespace

IMR_PLUGIN_EXPORT(DensePatchMatch)
