#include "host/synthetic/stream.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <deque>
#include <random>
#include <sstream>
#include <stdexcept>

namespace imr::synthetic {

std::string ToString(SceneKind kind) {
  switch (kind) {
    case SceneKind::kStreet: return "street";
    case SceneKind::kRoom: return "room";
    case SceneKind::kPlane: return "plane";
  }
  return "street";
}

bool FromString(const std::string& s, SceneKind* kind) {
  if (s == "street") *kind = SceneKind::kStreet;
  else if (s == "room") *kind = SceneKind::kRoom;
  else if (s == "plane") *kind = SceneKind::kPlane;
  else return false;
  return true;
}

Vec3 StreetCameraCenter(int frame, double speed) {
  return {0.6 * std::sin(frame * 0.01), frame * speed, 1.65};
}

double StreetLength(int frames, double speed) { return frames * speed + 10.0; }

namespace {
constexpr double kPi = 3.14159265358979323846;
constexpr Vec3 kUp{0.0, 0.0, 1.0};
// The street (or plane) is built whole: the drive's length is bounded so a job cannot ask for a
// scene that does not fit in memory (200 km: ~210,000 rects, ~25 MB). The room, whose size does
// not follow the drive, is held to it too: one rule for every scene.
constexpr double kMaxStreetLength = 200000.0;
// Candidates for new tracks drawn per frame grow as track_density x max_range^2 (the dense street:
// 2.1 x 40^2 = 3,360); bounded so that no job makes a frame take minutes.
constexpr double kMaxTrackCandidates = 250000.0;
}  // namespace

std::string StreamOptions::Check() const {
  std::ostringstream m;
  if (frames < 1) m << "frames: expected >= 1, got " << frames;
  else if (keyframe_every < 1) m << "keyframe_every: expected >= 1, got " << keyframe_every;
  else if (!(speed > 0.0) || !std::isfinite(speed)) m << "speed: expected > 0, got " << speed;
  else if (frames * speed > kMaxStreetLength)
    m << "frames x speed: " << frames * speed << " m, expected at most " << kMaxStreetLength
      << " (the street and the plane are built whole, as long as the drive)";
  else if (points_per_keyframe < 0)
    m << "points_per_keyframe: expected >= 0, got " << points_per_keyframe;
  else if (!(max_range > 0.0) || max_range > 1000.0)
    m << "max_range: expected in (0, 1000] m, got " << max_range;
  else if (!(hfov_deg > 0.0 && hfov_deg < 180.0) || !(vfov_deg > 0.0 && vfov_deg < 180.0))
    m << "hfov_deg, vfov_deg: expected in (0, 180), got " << hfov_deg << ", " << vfov_deg;
  else if (!(noise_at_10m >= 0.0) || !std::isfinite(noise_at_10m))
    m << "noise_at_10m: expected >= 0, got " << noise_at_10m;
  else if (min_observations < 1) m << "min_observations: expected >= 1, got " << min_observations;
  else if (track_frames < 0) m << "track_frames: expected >= 0, got " << track_frames;
  else if (track_frames > 0 && track_frames < min_observations)
    m << "track_frames: expected 0 or >= min_observations (" << min_observations << "), got "
      << track_frames << " (no track would ever be reported)";
  else if (!(track_density >= 0.0) || track_density > 100.0)
    m << "track_density: expected in [0, 100] per m^2, got " << track_density;
  else if (track_frames > 0 && track_density * max_range * max_range > kMaxTrackCandidates)
    m << "track_density x max_range^2: " << track_density * max_range * max_range
      << ", expected at most " << kMaxTrackCandidates
      << " (new tracks are drawn each frame on the surface within max_range)";
  else if (!(angular_noise >= 0.0) || angular_noise > 0.1)
    m << "angular_noise: expected in [0, 0.1] rad, got " << angular_noise;
  return m.str();
}

struct SyntheticStream::Impl {
  // Block model: a point and the error of its first estimate.
  struct Point {
    uint64_t id = 0;
    Vec3 truth{};
    Vec3 error{};  // Error of the first estimate; refinement j scales it by convergence^j.
    int born = 0;  // Keyframe of insertion.
    Vec3 reported{};
  };
  // Tracked model: a track alive (observed in the last frame) or ended with observations still to
  // hand out at the next keyframe.
  struct Track {
    uint64_t id = 0;  // 0 until reported: ids are handed out in report order, 1, 2, ...
    Vec3 truth{};
    Vec3 error_sum{};  // Sum of the per-observation error draws.
    int observations = 0;
    bool ended = false;
    Vec3 first_estimate{};           // As first reported (frozen: every later report's).
    std::vector<uint64_t> pending;  // Observing frames not handed out yet.
  };

  StreamOptions opt;
  Scene scene;
  std::mt19937_64 rng;
  int next_keyframe = 0;
  uint64_t next_point_id = 1;
  // Block model: the points in id order (ids are consecutive), from first_point_id on; without
  // keep_truth, those no longer refined are dropped from the front.
  std::deque<Point> points;
  uint64_t first_point_id = 1;
  // Tracked model: the live tracks, in start order; truths[id - 1] with keep_truth.
  std::vector<Track> tracks;
  std::vector<Vec3> truths;
  StreamStats stats;

  explicit Impl(const StreamOptions& o) : opt(o), rng(o.seed * 0x9E3779B97F4A7C15ull + 17) {
    if (const std::string problem = opt.Check(); !problem.empty())
      throw std::invalid_argument("synthetic stream: " + problem);
    switch (opt.scene) {
      case SceneKind::kStreet:
        scene = Scene::StreetCanyon(StreetLength(opt.frames, opt.speed), opt.seed);
        break;
      case SceneKind::kRoom: scene = Scene::ClosedRoom({-5, -4, 0}, {5, 4, 3}); break;
      case SceneKind::kPlane: scene = Scene::Plane(opt.frames * opt.speed + 60.0, 0.0); break;
    }
    if (opt.track_frames > 0) stats.track_lengths.assign(opt.track_frames + 1, 0);
  }

  Vec3 Center(int f) const {
    switch (opt.scene) {
      case SceneKind::kStreet: return StreetCameraCenter(f, opt.speed);
      case SceneKind::kRoom: {
        const double a = f * 0.1 * opt.speed / 2.0;
        return {2.0 * std::cos(a), 1.5 * std::sin(a), 1.5 + 0.2 * std::sin(3 * a)};
      }
      case SceneKind::kPlane: return {0.0, f * opt.speed, 3.0};
    }
    return {};
  }

  Vec3 Forward(int f) const {
    switch (opt.scene) {
      case SceneKind::kStreet: return {0.0, 1.0, 0.0};
      case SceneKind::kRoom: {
        // Tangent to the circle, turned 40 degrees outwards: the camera sweeps the walls.
        const double a = f * 0.1 * opt.speed / 2.0;
        const Vec3 t = Normalized({-2.0 * std::sin(a), 1.5 * std::cos(a), 0.0});
        const Vec3 out = Normalized({std::cos(a), std::sin(a), 0.0});
        return Normalized(Add(Scale(t, std::cos(0.7)), Scale(out, std::sin(0.7))));
      }
      case SceneKind::kPlane: return Normalized({0.0, 1.0, -0.5});
    }
    return {0, 1, 0};
  }

  double Vfov() const { return opt.scene == SceneKind::kRoom ? 70.0 : opt.vfov_deg; }

  // Range and field of view only (no occlusion): arithmetic, no ray cast.
  bool InView(int f, const Vec3& x) const {
    const Vec3 c = Center(f);
    const Vec3 d = Sub(x, c);
    const double dist = Norm(d);
    if (dist > opt.max_range || dist < 1e-6) return false;
    const Vec3 fw = Forward(f);
    const Vec3 right = Normalized(Cross(fw, kUp));
    const Vec3 up = Cross(right, fw);
    const double z = Dot(d, fw);
    if (z <= 0.0) return false;
    if (std::abs(std::atan2(Dot(d, right), z)) > 0.5 * opt.hfov_deg * kPi / 180.0) return false;
    if (std::abs(std::atan2(Dot(d, up), z)) > 0.5 * Vfov() * kPi / 180.0) return false;
    return true;
  }

  bool Sees(int f, const Vec3& x) const {
    return InView(f, x) && scene.Visible(Center(f), x, 1e-3);
  }

  // ---- Block model (track_frames == 0) ----

  Vec3 Estimate(const Point& p, int refinement) const {
    if (opt.frozen) refinement = 0;
    return Add(p.truth, Scale(p.error, std::pow(opt.convergence, refinement)));
  }

  std::vector<uint64_t> Observers(int first_frame, int last_frame, const Vec3& x) const {
    std::vector<uint64_t> ids;
    for (int f = first_frame; f <= last_frame; ++f)
      if (Sees(f, x)) ids.push_back(static_cast<uint64_t>(f));
    return ids;
  }

  void NextBlock(int k, int first, int frame, StreamKeyframe* kf) {
    // Moves: points born in the last refine_keyframes keyframes get a better estimate.
    if (!opt.frozen) {
      for (auto it = points.rbegin(); it != points.rend(); ++it) {
        Point& p = *it;
        const int j = k - p.born;
        if (j > opt.refine_keyframes) break;
        if (j <= 0) continue;
        const Vec3 e = Estimate(p, j);
        if (Norm(Sub(e, p.reported)) < opt.min_move) continue;
        p.reported = e;
        kf->moved_points.push_back({p.id, e, Observers(first, frame, p.truth)});
      }
      std::reverse(kf->moved_points.begin(), kf->moved_points.end());
    }

    // New points: sample directions in the keyframe camera's frustum, hit the scene.
    const Vec3 c = Center(frame), fw = Forward(frame);
    const Vec3 right = Normalized(Cross(fw, kUp));
    const Vec3 up = Cross(right, fw);
    std::uniform_real_distribution<double> uh(-0.5 * opt.hfov_deg, 0.5 * opt.hfov_deg);
    std::uniform_real_distribution<double> uv(-0.5 * Vfov(), 0.5 * Vfov());
    std::normal_distribution<double> gauss(0.0, 1.0);
    int made = 0;
    for (int attempt = 0; attempt < 20 * opt.points_per_keyframe && made < opt.points_per_keyframe;
         ++attempt) {
      const double h = std::tan(uh(rng) * kPi / 180.0), v = std::tan(uv(rng) * kPi / 180.0);
      const Vec3 dir = Normalized(Add(fw, Add(Scale(right, h), Scale(up, v))));
      double t;
      if (!scene.Intersect(c, dir, opt.max_range, &t)) continue;
      Point p;
      p.truth = Add(c, Scale(dir, t * (1.0 - 1e-9)));
      std::vector<uint64_t> obs = Observers(first, frame, p.truth);
      if (static_cast<int>(obs.size()) < opt.min_observations) continue;
      const double sigma = opt.noise_at_10m * (t / 10.0) * (t / 10.0);
      const Vec3 lateral = Add(Scale(right, gauss(rng)), Scale(up, gauss(rng)));
      p.error = Add(Scale(dir, sigma * gauss(rng)), Scale(lateral, 0.2 * sigma));
      p.id = next_point_id++;
      p.born = k;
      p.reported = Estimate(p, 0);
      points.push_back(p);
      kf->new_points.push_back({p.id, p.reported, std::move(obs)});
      ++made;
    }
    // Without keep_truth only the points a later keyframe still refines stay.
    if (!opt.keep_truth)
      while (!points.empty() && k + 1 - points.front().born > opt.refine_keyframes) {
        points.pop_front();
        ++first_point_id;
      }
    stats.kept_truths = points.size();
  }

  // ---- Tracked model (track_frames > 0) ----

  // One observation's error from camera centre c: along the viewing ray with the stereo-like
  // sigma noise_at_10m * (depth / 10)^2, and angular_noise * depth across it on both axes.
  Vec3 DrawError(const Vec3& c, const Vec3& x) {
    std::normal_distribution<double> gauss(0.0, 1.0);
    const Vec3 d = Sub(x, c);
    const double depth = Norm(d);
    const Vec3 ray = Scale(d, 1.0 / depth);
    Vec3 a = Cross(ray, kUp);
    if (Norm(a) < 1e-9) a = Cross(ray, Vec3{1.0, 0.0, 0.0});  // looking straight up or down
    a = Normalized(a);
    const Vec3 b = Cross(a, ray);
    const double along = opt.noise_at_10m * (depth / 10.0) * (depth / 10.0);
    const double across = opt.angular_noise * depth;
    const double g0 = gauss(rng), g1 = gauss(rng), g2 = gauss(rng);
    return Add(Scale(ray, along * g0), Add(Scale(a, across * g1), Scale(b, across * g2)));
  }

  void Observe(Track& t, int f) {
    t.error_sum = Add(t.error_sum, DrawError(Center(f), t.truth));
    ++t.observations;
    t.pending.push_back(static_cast<uint64_t>(f));
    if (t.observations >= opt.track_frames) End(t, false);
  }

  void End(Track& t, bool lost) {
    t.ended = true;
    ++stats.tracks_ended;
    if (lost) ++stats.tracks_lost;
    ++stats.track_lengths[t.observations];
  }

  // Points of the surface in view of frame f that frame f - 1 did not see: a Poisson process of
  // track_density per m^2 over each rect near the camera (restricted to the disc of max_range
  // around the camera's foot on the rect's plane), thinned to what f sees and f - 1 did not.
  // Re-sampling each frame is the same in law as fixing the points once: a patch is new in one
  // frame only (until it leaves the view and comes back: a new track, as a SLAM front end would
  // start).
  void StartTracks(int f) {
    if (opt.track_density <= 0.0) return;
    const Vec3 c = Center(f);
    const double r = opt.max_range;
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    for (int i : scene.RectsNear(c[0] - r, c[1] - r, c[0] + r, c[1] + r)) {
      const Rect& q = scene.rects()[i];
      const Vec3 rel = Sub(c, q.center);
      const double dn = Dot(rel, Cross(q.u, q.v));
      if (std::abs(dn) >= r) continue;
      const double disc = std::sqrt(r * r - dn * dn);
      const double su = Dot(rel, q.u), sv = Dot(rel, q.v);
      const double u0 = std::max(-q.half_u, su - disc), u1 = std::min(q.half_u, su + disc);
      const double v0 = std::max(-q.half_v, sv - disc), v1 = std::min(q.half_v, sv + disc);
      if (!(u0 < u1 && v0 < v1)) continue;
      std::poisson_distribution<int64_t> count(opt.track_density * (u1 - u0) * (v1 - v0));
      for (int64_t n = count(rng); n > 0; --n) {
        const double s = u0 + (u1 - u0) * unit(rng), t = v0 + (v1 - v0) * unit(rng);
        const Vec3 x = Add(q.center, Add(Scale(q.u, s), Scale(q.v, t)));
        if (!InView(f, x)) continue;
        if (f > 0 && Sees(f - 1, x)) continue;  // seen before: tracked already, or ended
        if (!scene.Visible(c, x, 1e-3)) continue;
        Track tr;
        tr.truth = x;
        ++stats.tracks_started;
        tracks.push_back(std::move(tr));
        Observe(tracks.back(), f);
      }
    }
  }

  void TrackFrame(int f) {
    for (Track& t : tracks) {
      if (t.ended) continue;
      if (Sees(f, t.truth)) Observe(t, f);
      else End(t, true);
    }
    StartTracks(f);
    ++stats.frames;
  }

  Vec3 TrackEstimate(const Track& t) const {
    if (opt.frozen && t.id != 0) return t.first_estimate;
    return Add(t.truth, Scale(t.error_sum, 1.0 / t.observations));
  }

  void NextTracked(int first, int frame, StreamKeyframe* kf) {
    for (int f = first; f <= frame; ++f) TrackFrame(f);
    // Hand out what the frames observed: a track's first report is a new point with every frame
    // that observed it, later ones are moves with the frames since.
    for (Track& t : tracks) {
      if (t.observations < opt.min_observations || t.pending.empty()) continue;
      if (t.id == 0) {
        t.id = next_point_id++;
        t.first_estimate = TrackEstimate(t);
        if (opt.keep_truth) truths.push_back(t.truth);
        kf->new_points.push_back({t.id, t.first_estimate, std::move(t.pending)});
      } else {
        kf->moved_points.push_back({t.id, TrackEstimate(t), std::move(t.pending)});
      }
      t.pending.clear();
    }
    stats.max_active_tracks = std::max(stats.max_active_tracks, tracks.size());
    tracks.erase(
        std::remove_if(tracks.begin(), tracks.end(), [](const Track& t) { return t.ended; }),
        tracks.end());
    stats.active_tracks = tracks.size();
    stats.kept_truths = truths.size();
  }

  bool Next(StreamKeyframe* kf) {
    const auto start = std::chrono::steady_clock::now();
    const int ke = opt.keyframe_every;
    const int k = next_keyframe;
    const int frame = (k + 1) * ke - 1;
    if (frame >= opt.frames) return false;
    ++next_keyframe;
    *kf = StreamKeyframe{};
    kf->index = k;
    kf->frame = frame;
    const int first = k * ke;
    for (int f = first; f <= frame; ++f)
      kf->cameras.push_back({static_cast<uint64_t>(f), Center(f), Forward(f)});
    if (opt.track_frames > 0) {
      NextTracked(first, frame, kf);
    } else {
      NextBlock(k, first, frame, kf);
      stats.frames += frame - first + 1;
    }
    ++stats.keyframes;
    stats.new_points += static_cast<int64_t>(kf->new_points.size());
    stats.moved_points += static_cast<int64_t>(kf->moved_points.size());
    for (const auto* list : {&kf->new_points, &kf->moved_points})
      for (const StreamPoint& p : *list)
        stats.observations += static_cast<int64_t>(p.camera_ids.size());
    const auto end = std::chrono::steady_clock::now();
    stats.seconds += std::chrono::duration<double>(end - start).count();
    return true;
  }

  Vec3 TruePosition(uint64_t id) const {
    if (opt.track_frames == 0) {
      if (id < first_point_id || id - first_point_id >= points.size()) return {};
      return points[id - first_point_id].truth;
    }
    if (id >= 1 && id <= truths.size()) return truths[id - 1];
    for (const Track& t : tracks)
      if (t.id == id) return t.truth;
    return {};
  }

  std::vector<Vec3> TruePoints() const {
    if (opt.track_frames > 0) {
      if (opt.keep_truth) return truths;
      std::vector<Vec3> out;
      for (const Track& t : tracks)
        if (t.id != 0) out.push_back(t.truth);
      return out;
    }
    std::vector<Vec3> out;
    out.reserve(points.size());
    for (const auto& p : points) out.push_back(p.truth);
    return out;
  }
};

SyntheticStream::SyntheticStream(const StreamOptions& options)
    : impl_(std::make_unique<Impl>(options)) {}
SyntheticStream::~SyntheticStream() = default;
bool SyntheticStream::Next(StreamKeyframe* keyframe) { return impl_->Next(keyframe); }
const Scene& SyntheticStream::scene() const { return impl_->scene; }
const StreamOptions& SyntheticStream::options() const { return impl_->opt; }
int SyntheticStream::keyframe_count() const {
  return impl_->opt.frames / impl_->opt.keyframe_every;
}
const StreamStats& SyntheticStream::stats() const { return impl_->stats; }
Vec3 SyntheticStream::TruePosition(uint64_t point_id) const {
  return impl_->TruePosition(point_id);
}
Vec3 SyntheticStream::CameraCenter(int frame) const { return impl_->Center(frame); }
Vec3 SyntheticStream::CameraForward(int frame) const { return impl_->Forward(frame); }
bool SyntheticStream::Sees(int frame, const Vec3& x) const { return impl_->Sees(frame, x); }
std::vector<Vec3> SyntheticStream::TruePoints() const { return impl_->TruePoints(); }

}  // namespace imr::synthetic
