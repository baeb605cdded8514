#include "host/pipeline/front_end.h"

#include "host/io/image_io.h"
#include "host/synthetic/evaluation.h"
#include "host/util/clock.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <iterator>
#include <stdexcept>

namespace imr::pipeline {

int KeyframeCount(int frames, int keyframe_every) {
  if (frames <= 0 || keyframe_every < 1) return 0;
  const int last = frames - 1;
  return last / keyframe_every + 1 + (last % keyframe_every != 0 ? 1 : 0);
}

int ShortSequenceKeyframeEvery(int frames, int keyframe_every) {
  int k = keyframe_every;
  while (k > 1 && KeyframeCount(frames, k) < std::min(frames, kMinKeyframes)) --k;
  return k;
}
using nlohmann::json;

namespace {

engine::Camera ToEngineCamera(const io::CameraGeometry& g) {
  engine::Camera c;
  c.id = g.id;
  c.center = g.center;
  for (int r = 0; r < 3; ++r)
    for (int col = 0; col < 3; ++col) c.rotation[3 * r + col] = g.rotation[r][col];
  c.intrinsics = {g.intrinsics.fx, g.intrinsics.fy, g.intrinsics.cx, g.intrinsics.cy};
  return c;
}

// A point's observing cameras in the update of `stage` (the refiner's or the dense stage's).
std::vector<uint64_t> Slice(const imr_refiner_update& u, const imr_point_estimate& p,
                            const char* stage = "refiner") {
  if (p.camera_count == 0) return {};
  if (p.first_camera + p.camera_count > u.camera_id_count)
    throw std::runtime_error(std::string(stage) + ": point " + std::to_string(p.id) + " refers to cameras " +
                             std::to_string(p.first_camera) + ".." +
                             std::to_string(p.first_camera + p.camera_count - 1) + " of only " +
                             std::to_string(u.camera_id_count) + " camera ids");
  return {u.camera_ids + p.first_camera, u.camera_ids + p.first_camera + p.camera_count};
}

}  // namespace

imr_camera ToPluginCamera(const io::CameraGeometry& g, int width, int height) {
  imr_camera c{};
  c.id = g.id;
  const io::Intrinsics& k = g.intrinsics;
  if (g.has_intrinsics && k.projectable && k.fx > 0.0 && k.fy > 0.0) {
    const double K[9] = {k.fx, 0.0, k.cx, 0.0, k.fy, k.cy, 0.0, 0.0, 1.0};
    std::copy(std::begin(K), std::end(K), c.K);
  }
  for (int r = 0; r < 3; ++r) {
    for (int col = 0; col < 3; ++col) c.R[3 * r + col] = g.rotation[r][col];
    c.t[r] = g.translation[r];
  }
  c.width = width;
  c.height = height;
  return c;
}

std::string FrontEndOptions::Check() const {
  if (keyframe_every < 1) return "keyframe_every: expected >= 1";
  if (truth_pixel_step < 1) return "truth_pixel_step: expected >= 1";
  if (!(truth_range > 0.0)) return "truth_range: expected > 0";
  if (!(tau > 0.0)) return "tau: expected > 0";
  return {};
}

ImageFrontEndSource::ImageFrontEndSource(io::ImageSequence sequence,
                                         const imr::sdk::Instance& features,
                                         const imr::sdk::Instance& refiner,
                                         const FrontEndOptions& options)
    : sequence_(std::move(sequence)),
      features_(features),
      refiner_(refiner),
      options_(options),
      dense_errors_(options.tau) {
  if (const std::string e = options_.Check(); !e.empty())
    throw std::invalid_argument("front end options: " + e);
  if (sequence_.frames.empty())
    throw std::runtime_error(sequence_.root + ": the sequence has no frames");
  // Points need two views: one frame would run every plugin and then fail with "no surface".
  if (sequence_.frames.size() < 2)
    throw std::runtime_error(sequence_.root + ": one frame (" + sequence_.frames[0].image_path +
                             "); a sequence needs at least 2 frames to triangulate points");
  if (!sequence_.synthetic_scene.empty())
    truth_ = std::make_unique<SyntheticTruth>(ReadSyntheticTruth(sequence_.synthetic_scene));
}

ImageFrontEndSource::~ImageFrontEndSource() = default;

std::optional<StageWatch::Call> ImageFrontEndSource::Watched(const WatchedStage* stage) {
  if (watch_ == nullptr || stage == nullptr) return std::nullopt;
  return watch_->Enter(*stage);
}

std::pair<io::Image, double> ImageFrontEndSource::ReadFrame(std::size_t index) {
  auto read = [this](std::size_t f) {
    const auto t0 = std::chrono::steady_clock::now();
    io::Image image = io::ReadImage(sequence_.frames[f].image_path, sequence_.image_limits);
    return std::pair<io::Image, double>(std::move(image), SecondsSince(t0));
  };
  std::pair<io::Image, double> frame;
  if (ahead_.valid() && ahead_frame_ == index) {
    frame = ahead_.get();  // rethrows the read's error, naming the file as it would here
  } else {
    if (ahead_.valid()) ahead_.wait();
    frame = read(index);
  }
  if (options_.track_ahead && index + 1 < sequence_.frames.size()) {
    ahead_frame_ = index + 1;
    ahead_ = std::async(std::launch::async, read, ahead_frame_);
  }
  return frame;
}

bool ImageFrontEndSource::IsKeyframe(int frame) const {
  return frame % options_.keyframe_every == 0 ||
         frame + 1 == static_cast<int>(sequence_.frames.size());
}

int ImageFrontEndSource::KeyframeCount() const {
  int n = 0;
  for (std::size_t f = 0; f < sequence_.frames.size(); ++f) n += IsKeyframe(static_cast<int>(f));
  return n;
}

void ImageFrontEndSource::TrackPointError(uint64_t id, const io::Vec3& position, bool is_new) {
  if (!truth_) return;
  const double d = truth_->scene.Distance(truth_->ToScene(position));
  if (is_new)
    point_errors_.Add(id, d, next_keyframe_);
  else
    point_errors_.Move(id, d, next_keyframe_);
}

bool ImageFrontEndSource::TrackFrame(TrackedFrame* out) {
  if (tracked_frames_ >= sequence_.frames.size()) return false;
  const std::size_t f = tracked_frames_++;
  const io::ImageFrame& frame = sequence_.frames[f];
  const int index = static_cast<int>(f);
  out->index = f;
  out->keyframe = IsKeyframe(index);

  auto [image, read_seconds] = ReadFrame(f);
  if (width_ == 0) {
    width_ = image.width;
    height_ = image.height;
  } else if (image.width != width_ || image.height != height_) {
    throw std::runtime_error(frame.image_path + ": image is " + std::to_string(image.width) +
                             "x" + std::to_string(image.height) + ", the sequence's first is " +
                             std::to_string(width_) + "x" + std::to_string(height_));
  }
  out->read_seconds = read_seconds;

  out->camera = ToPluginCamera(frame.camera, width_, height_);
  imr_image_view view{};
  view.struct_size = sizeof(view);
  view.width = image.width;
  view.height = image.height;
  view.channels = image.channels;
  view.stride_bytes = image.stride_bytes;
  view.pixels = image.pixels.data();

  const auto t0 = std::chrono::steady_clock::now();
  imr_track_view tracks{};
  if (watch_ != nullptr) watch_->SetPosition("frame " + std::to_string(index));
  try {
    const auto call = Watched(watch_features_);
    tracks = features_.ProcessFrame(out->camera, view, out->keyframe);
  } catch (const std::exception& e) {
    throw std::runtime_error("frame " + std::to_string(index) + " (" + frame.image_path +
                             "): " + e.what());
  }
  out->features_seconds = SecondsSince(t0);
  if (tracks.count > 0 && tracks.observations == nullptr)
    throw std::runtime_error("features plugin returned " + std::to_string(tracks.count) +
                             " observations but no array");
  // The view is the plugin's until its next call, which may come before the refiner's.
  out->tracks.assign(tracks.observations, tracks.observations + tracks.count);
  if (dense_ != nullptr) out->image = std::move(image);
  return true;
}

bool ImageFrontEndSource::Next(engine::KeyframeUpdate* update, io::KeyframeInfo* info) {
  *update = engine::KeyframeUpdate{};
  if (options_.track_ahead && !tracker_)
    tracker_ = std::make_unique<Prefetcher<TrackedFrame>>(
        [this](TrackedFrame* f) { return TrackFrame(f); }, 2, track_lane_);
  TrackedFrame tracked;
  while (tracker_ ? tracker_->Take(&tracked) : TrackFrame(&tracked)) {
    const io::ImageFrame& frame = sequence_.frames[tracked.index];
    const int index = static_cast<int>(tracked.index);
    next_frame_ = tracked.index + 1;
    const bool keyframe = tracked.keyframe;
    const imr_camera& camera = tracked.camera;
    const imr_track_view tracks{tracked.tracks.data(), tracked.tracks.size()};
    stats_.read_seconds += tracked.read_seconds;
    stats_.features_seconds += tracked.features_seconds;
    stats_.observations += static_cast<int64_t>(tracks.count);

    if (keyframe) {
      // Track survival over the interval that ends here, then this keyframe's set.
      std::vector<uint64_t> ids(tracks.count);
      for (uint64_t i = 0; i < tracks.count; ++i) ids[i] = tracks.observations[i].track_id;
      std::sort(ids.begin(), ids.end());
      if (!keyframe_tracks_.empty() && index % options_.keyframe_every == 0) {
        std::vector<uint64_t> common;
        std::set_intersection(ids.begin(), ids.end(), keyframe_tracks_.begin(),
                              keyframe_tracks_.end(), std::back_inserter(common));
        stats_.tracks_at_keyframes += static_cast<int64_t>(keyframe_tracks_.size());
        stats_.tracks_surviving_interval += static_cast<int64_t>(common.size());
      }
      keyframe_tracks_ = std::move(ids);
    }

    if (watch_ != nullptr && tracker_) watch_->SetPosition("frame " + std::to_string(index));
    const auto t0 = std::chrono::steady_clock::now();
    imr_refiner_update out{};
    try {
      const auto call = Watched(watch_refiner_);
      out = refiner_.AddFrame(camera, tracks.observations, tracks.count, keyframe);
    } catch (const std::exception& e) {
      throw std::runtime_error("frame " + std::to_string(index) + ": " + e.what());
    }
    stats_.refiner_seconds += SecondsSince(t0);
    ++stats_.frames;

    update->cameras.push_back(ToEngineCamera(frame.camera));
    if (!keyframe) {
      if (dense_ != nullptr) AddDensePoints(tracked, update);
      continue;
    }

    for (uint64_t i = 0; i < out.new_count; ++i) {
      const imr_point_estimate& p = out.new_points[i];
      engine::NewPoint n;
      n.id = p.id;
      n.position = {p.position[0], p.position[1], p.position[2]};
      n.camera_ids = Slice(out, p);
      TrackPointError(n.id, n.position, true);
      update->new_points.push_back(std::move(n));
    }
    for (uint64_t i = 0; i < out.moved_count; ++i) {
      const imr_point_estimate& p = out.moved_points[i];
      engine::MovedPoint m;
      m.id = p.id;
      m.position = {p.position[0], p.position[1], p.position[2]};
      m.camera_ids = Slice(out, p);
      TrackPointError(m.id, m.position, false);
      update->moved_points.push_back(std::move(m));
    }
    update->removed_points.assign(out.removed_ids, out.removed_ids + out.removed_count);
    for (uint64_t id : update->removed_points) point_errors_.Remove(id);
    if (dense_ != nullptr) {
      for (const engine::NewPoint& n : update->new_points)
        if (n.id >= kDenseIdBase)
          throw std::runtime_error("frame " + std::to_string(index) + ": refiner point id " +
                                   std::to_string(n.id) + " is 2^23 or more: with a dense stage "
                                   "the refiner's ids stay below 2^23 (the dense points' are above)");
      AddDensePoints(tracked, update);
    }
    stats_.new_points += static_cast<int64_t>(out.new_count);
    stats_.moved_points += static_cast<int64_t>(out.moved_count);
    stats_.removed_points += static_cast<int64_t>(out.removed_count);
    if (truth_) point_errors_.EndKeyframe(next_keyframe_);
    *info = {next_keyframe_++, index};
    ++stats_.keyframes;
    return true;
  }
  return false;
}

void ImageFrontEndSource::AddDensePoints(const TrackedFrame& tracked,
                                         engine::KeyframeUpdate* update) {
  const int index = static_cast<int>(tracked.index);
  imr_image_view view{};
  view.struct_size = sizeof(view);
  view.width = tracked.image.width;
  view.height = tracked.image.height;
  view.channels = tracked.image.channels;
  view.stride_bytes = tracked.image.stride_bytes;
  view.pixels = tracked.image.pixels.data();
  imr_dense_request request{};
  request.camera = &tracked.camera;
  request.image = &view;
  request.is_keyframe = tracked.keyframe ? 1 : 0;
  request.final_call = tracked.index + 1 == sequence_.frames.size() ? 1 : 0;
  const auto t0 = std::chrono::steady_clock::now();
  imr_refiner_update out{};
  try {
    const auto call = Watched(watch_dense_);
    out = dense_->AddDenseFrame(&request);
  } catch (const std::exception& e) {
    throw std::runtime_error("frame " + std::to_string(index) + " (" +
                             sequence_.frames[tracked.index].image_path + "): " + e.what());
  }
  stats_.dense_seconds += SecondsSince(t0);
  auto id_of = [&](uint64_t id) {
    if (id >= kDenseIdBase)
      throw std::runtime_error("frame " + std::to_string(index) + ": dense point id " +
                               std::to_string(id) + " is 2^23 or more (plugin.h: a dense "
                               "plugin's ids stay below 2^23)");
    return id + kDenseIdBase;
  };
  if (!tracked.keyframe && (out.new_count > 0 || out.removed_count > 0))
    throw std::runtime_error("frame " + std::to_string(index) + " (not a keyframe): the dense "
                             "stage reported points (plugin.h: points come on keyframes only)");
  if (out.moved_count > 0)
    throw std::runtime_error("frame " + std::to_string(index) + ": the dense stage moved " +
                             std::to_string(out.moved_count) + " points (plugin.h: a dense "
                             "plugin reports new and removed points only)");
  update->new_points.reserve(update->new_points.size() + out.new_count);
  for (uint64_t i = 0; i < out.new_count; ++i) {
    const imr_point_estimate& p = out.new_points[i];
    engine::NewPoint n;
    n.id = id_of(p.id);
    n.position = {p.position[0], p.position[1], p.position[2]};
    n.camera_ids = Slice(out, p, "dense stage");
    for (uint64_t c : n.camera_ids)
      if (c > tracked.index)
        throw std::runtime_error("frame " + std::to_string(index) + ": dense point " +
                                 std::to_string(p.id) + " is seen from camera " +
                                 std::to_string(c) + ", not a frame given so far");
    if (truth_) dense_errors_.Add(truth_->scene.Distance(truth_->ToScene(n.position)));
    update->new_points.push_back(std::move(n));
  }
  for (uint64_t i = 0; i < out.removed_count; ++i)
    update->removed_points.push_back(id_of(out.removed_ids[i]));
  stats_.dense_new_points += static_cast<int64_t>(out.new_count);
  stats_.dense_removed_points += static_cast<int64_t>(out.removed_count);
}

const io::CameraGeometry* ImageFrontEndSource::Camera(uint64_t camera_id) const {
  if (camera_id >= sequence_.frames.size()) return nullptr;
  return &sequence_.frames[camera_id].camera;
}

json ImageFrontEndSource::Summary() const {
  const FrontEndStats& s = stats_;
  auto fps = [&](double seconds) { return seconds > 0.0 ? s.frames / seconds : 0.0; };
  json j = sequence_.summary;
  j["frames_processed"] = s.frames;
  j["keyframes"] = s.keyframes;
  j["keyframe_every"] = options_.keyframe_every;
  if (width_ > 0) j["image_size"] = {width_, height_};
  j["seconds"] = {{"read_images", s.read_seconds},
                  {"features", s.features_seconds},
                  {"refiner", s.refiner_seconds}};
  j["frames_per_second"] = {{"read_images", fps(s.read_seconds)},
                            {"features", fps(s.features_seconds)},
                            {"refiner", fps(s.refiner_seconds)}};
  if (dense_ != nullptr) {
    j["seconds"]["dense"] = s.dense_seconds;
    j["dense_points"] = {{"new", s.dense_new_points}, {"removed", s.dense_removed_points}};
    if (truth_ && dense_errors_.size() > 0) {
      const DistanceSample& e = dense_errors_;
      j["dense_points"]["error"] = {{"reference", "distance to the true synthetic surface, metres"},
                                    {"median", e.Quantile(0.5)}, {"p90", e.Quantile(0.9)},
                                    {"within_tau", static_cast<double>(e.below()) / static_cast<double>(e.size())}};
    }
  }
  j["observations"] = s.observations;
  j["observations_per_frame"] = s.frames > 0 ? static_cast<double>(s.observations) / s.frames : 0.0;
  j["points"] = {{"new", s.new_points}, {"moved", s.moved_points}, {"removed", s.removed_points}};
  j["track_survival"] = {
      {"tracks_at_keyframes", s.tracks_at_keyframes},
      {"surviving_one_interval", s.tracks_surviving_interval},
      {"ratio", s.tracks_at_keyframes > 0
                    ? static_cast<double>(s.tracks_surviving_interval) / s.tracks_at_keyframes
                    : 0.0}};
  if (truth_) {
    // The refiner's promise: estimates get closer to the true surface as observations accumulate.
    const PointErrorSummary::Figures f = point_errors_.Result();
    j["point_error"] = {{"reference", "distance to the true synthetic surface, metres"},
                        {"points", f.points},
                        {"median_first_estimate", f.median_first},
                        {"moved_points", f.moved},
                        {"moved_median_first_estimate", f.moved_median_first},
                        {"moved_median_latest_estimate", f.moved_median_latest}};
  }
  return j;
}

std::vector<io::Vec3> ImageFrontEndSource::TruthSamples() const {
  // Rays on a pixel grid from each keyframe, their first hit within range.
  std::vector<io::Vec3> truth;
  const io::Mat3 scene_from_world = io::Transpose(truth_->rotation);
  for (std::size_t f = 0; f < next_frame_; ++f) {
    if (!IsKeyframe(static_cast<int>(f))) continue;
    const io::CameraGeometry& g = sequence_.frames[f].camera;
    const io::Intrinsics& k = g.intrinsics;
    const io::Mat3 cam_to_world = io::Transpose(g.rotation);
    const io::Vec3 origin = truth_->ToScene(g.center);
    for (int v = options_.truth_pixel_step / 2; v < height_; v += options_.truth_pixel_step) {
      for (int u = options_.truth_pixel_step / 2; u < width_; u += options_.truth_pixel_step) {
        const io::Vec3 dc = {(u - k.cx) / k.fx, (v - k.cy) / k.fy, 1.0};
        const synthetic::Vec3 d =
            synthetic::Normalized(io::Mul(scene_from_world, io::Mul(cam_to_world, dc)));
        double t = 0.0;
        if (truth_->scene.Intersect(origin, d, options_.truth_range, &t))
          truth.push_back(synthetic::Add(origin, synthetic::Scale(d, t)));
      }
    }
  }
  return truth;
}

json ImageFrontEndSource::AccuracyJson(const synthetic::MeshAccuracy& a, std::size_t samples) const {
  return {{"reference", "known synthetic scene (" + sequence_.synthetic_scene + ")"},
          {"tau", a.tau},
          {"mean_mesh_to_scene", a.mean_mesh_to_scene},
          {"precision", a.precision},
          {"mean_truth_to_mesh", a.mean_truth_to_mesh},
          {"completeness", a.completeness},
          {"truth_samples", samples}};
}

namespace {

// Packed xyz from the sequence's world frame into the scene's, where the analytic distance lives.
std::vector<double> InScene(const SyntheticTruth& truth, const std::vector<double>& world) {
  std::vector<double> scene(world.size());
  for (std::size_t i = 0; i + 2 < world.size(); i += 3) {
    const io::Vec3 s = truth.ToScene({world[i], world[i + 1], world[i + 2]});
    std::copy(s.begin(), s.end(), scene.begin() + static_cast<std::ptrdiff_t>(i));
  }
  return scene;
}

}  // namespace

json ImageFrontEndSource::Evaluate(const engine::Mesh& mesh) const {
  if (!truth_) return nullptr;
  const std::vector<io::Vec3> truth = TruthSamples();
  const synthetic::MeshAccuracy a = synthetic::EvaluateMesh(
      truth_->scene, InScene(*truth_, mesh.vertices), mesh.faces, truth, options_.tau);
  return AccuracyJson(a, truth.size());
}

std::unique_ptr<io::BlockEvaluation> ImageFrontEndSource::EvaluateInBlocks() const {
  if (!truth_) return nullptr;
  class Blocks : public io::BlockEvaluation {
   public:
    explicit Blocks(const ImageFrontEndSource& s)
        : source_(s), acc_(s.truth_->scene, s.TruthSamples(), s.options_.tau) {}
    void AddTriangles(const std::vector<double>& vertices, const std::vector<uint32_t>& faces) override {
      acc_.AddTriangles(InScene(*source_.truth_, vertices), faces);
    }
    json Finish() const override { return source_.AccuracyJson(acc_.Result(), acc_.truth_size()); }

   private:
    const ImageFrontEndSource& source_;
    synthetic::MeshAccuracyInBlocks acc_;
  };
  return std::make_unique<Blocks>(*this);
}

}  // namespace imr::pipeline
