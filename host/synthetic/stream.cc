#include "host/synthetic/stream.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <unordered_map>

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
}  // namespace

struct SyntheticStream::Impl {
  struct Point {
    uint64_t id = 0;
    Vec3 truth{};
    Vec3 error{};  // Error of the first estimate; refinement j scales it by convergence^j.
    int born = 0;  // Keyframe of insertion.
    Vec3 reported{};
  };

  StreamOptions opt;
  Scene scene;
  std::mt19937_64 rng;
  int next_keyframe = 0;
  uint64_t next_point_id = 1;
  std::vector<Point> points;
  std::unordered_map<uint64_t, size_t> index;

  explicit Impl(const StreamOptions& o) : opt(o), rng(o.seed * 0x9E3779B97F4A7C15ull + 17) {
    switch (opt.scene) {
      case SceneKind::kStreet:
        scene = Scene::StreetCanyon(StreetLength(opt.frames, opt.speed), opt.seed);
        break;
      case SceneKind::kRoom: scene = Scene::ClosedRoom({-5, -4, 0}, {5, 4, 3}); break;
      case SceneKind::kPlane: scene = Scene::Plane(opt.frames * opt.speed + 60.0, 0.0); break;
    }
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

  bool Sees(int f, const Vec3& x) const {
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
    return scene.Visible(c, x, 1e-3);
  }

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

  bool Next(StreamKeyframe* kf) {
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
      index[p.id] = points.size();
      points.push_back(p);
      kf->new_points.push_back({p.id, p.reported, std::move(obs)});
      ++made;
    }
    return true;
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
Vec3 SyntheticStream::TruePosition(uint64_t point_id) const {
  auto it = impl_->index.find(point_id);
  return it == impl_->index.end() ? Vec3{} : impl_->points[it->second].truth;
}
Vec3 SyntheticStream::CameraCenter(int frame) const { return impl_->Center(frame); }
Vec3 SyntheticStream::CameraForward(int frame) const { return impl_->Forward(frame); }
bool SyntheticStream::Sees(int frame, const Vec3& x) const { return impl_->Sees(frame, x); }
std::vector<Vec3> SyntheticStream::TruePoints() const {
  std::vector<Vec3> out;
  out.reserve(impl_->points.size());
  for (const auto& p : impl_->points) out.push_back(p.truth);
  return out;
}

}  // namespace imr::synthetic
