#include "host/synthetic/texture.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "host/synthetic/stream.h"

namespace imr::synthetic {
namespace {

TEST(SceneMaterialTest, StreetRectsSayWhatTheyAre) {
  const Scene s = Scene::StreetCanyon(100.0, 2);
  const auto& r = s.rects();
  ASSERT_GT(r.size(), 3u);
  EXPECT_EQ(r[0].material, Material::kGround);
  EXPECT_EQ(r[1].material, Material::kFacade);
  EXPECT_EQ(r[1].group, 0);
  EXPECT_EQ(r[2].material, Material::kFacade);
  EXPECT_EQ(r[2].group, 1);
  int last_group = -1;
  for (size_t i = 3; i < r.size(); ++i) {
    const Vec3 n = Cross(r[i].u, r[i].v);
    const Material want = std::abs(n[2]) > 0.5   ? Material::kBoxTop
                          : std::abs(n[0]) > 0.5 ? Material::kBoxSide
                                                 : Material::kBoxEnd;
    EXPECT_EQ(r[i].material, want) << i;
    EXPECT_EQ(r[i].group, static_cast<int>((i - 3) / 5)) << "five faces per box";
    last_group = r[i].group;
  }
  EXPECT_EQ(static_cast<size_t>(last_group + 1) * 5, r.size() - 3);
  const Scene room = Scene::ClosedRoom({0, 0, 0}, {1, 1, 1});
  for (const Rect& q : room.rects()) EXPECT_EQ(q.material, Material::kPlain);
  EXPECT_EQ(ToString(Material::kBoxEnd), "box_end");
}

TEST(StreetPathTest, SharedWithTheStream) {
  StreamOptions o;
  o.speed = 1.3;
  o.frames = 50;
  const SyntheticStream stream(o);
  for (int f = 0; f < 50; ++f) {
    const Vec3 a = stream.CameraCenter(f), b = StreetCameraCenter(f, 1.3);
    for (int i = 0; i < 3; ++i) EXPECT_EQ(a[i], b[i]);
  }
  EXPECT_EQ(stream.scene().rects().size(),
            Scene::StreetCanyon(StreetLength(50, 1.3), 1).rects().size());
}

// Points on the street's surfaces with footprint vectors along their texture axes.
struct Probe {
  int rect;
  Vec3 p, ds, dt;
};

std::vector<Probe> Probes(int count, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> y(5.0, 95.0), u01(0.0, 1.0);
  std::vector<Probe> out;
  for (int i = 0; i < count; ++i) {
    switch (i % 3) {
      case 0:  // Ground, anywhere across the street.
        out.push_back({0, {-7.9 + 15.8 * u01(rng), y(rng), 0.0}, {1, 0, 0}, {0, 1, 0}});
        break;
      case 1:  // Left facade.
        out.push_back({1, {-8.0, y(rng), 11.8 * u01(rng)}, {0, 1, 0}, {0, 0, 1}});
        break;
      default:  // Right facade.
        out.push_back({2, {8.0, y(rng), 11.8 * u01(rng)}, {0, 1, 0}, {0, 0, 1}});
        break;
    }
  }
  return out;
}

TEST(SceneTextureTest, DeterministicBySeed) {
  const Scene scene = Scene::StreetCanyon(100.0, 1);
  const SceneTexture a(scene, 1), b(scene, 1), c(scene, 2);
  int differ = 0;
  for (const Probe& q : Probes(300, 5)) {
    const Rgb x = a.Albedo(q.rect, q.p, Scale(q.ds, 0.01), Scale(q.dt, 0.01));
    const Rgb y = b.Albedo(q.rect, q.p, Scale(q.ds, 0.01), Scale(q.dt, 0.01));
    const Rgb z = c.Albedo(q.rect, q.p, Scale(q.ds, 0.01), Scale(q.dt, 0.01));
    EXPECT_EQ(x.r, y.r);
    EXPECT_EQ(x.g, y.g);
    EXPECT_EQ(x.b, y.b);
    for (float v : {x.r, x.g, x.b}) {
      EXPECT_GE(v, 0.0f);
      EXPECT_LE(v, 1.0f);
    }
    differ += std::abs(x.g - z.g) > 1e-4f;
  }
  EXPECT_GT(differ, 200);
}

// Band limit: the albedo over a footprint is close to the mean of the point values over it (the
// rectangular patterns are box-filtered exactly; noise octaves finer than the footprint fade out
// a little earlier than a box filter would remove them).
TEST(SceneTextureTest, FootprintAveragesThePointValues) {
  const Scene scene = Scene::StreetCanyon(100.0, 1);
  const SceneTexture tex(scene, 1);
  for (double size : {0.05, 0.3, 1.5}) {
    int good = 0, total = 0;
    double contrast = 0.0, error = 0.0;
    for (const Probe& q : Probes(150, 11)) {
      const Rgb f = tex.Albedo(q.rect, q.p, Scale(q.ds, size), Scale(q.dt, size));
      double mean = 0.0, lo = 1.0, hi = 0.0;
      const int n = 24;
      for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j) {
          const Vec3 p = Add(q.p, Add(Scale(q.ds, size * ((i + 0.5) / n - 0.5)),
                                      Scale(q.dt, size * ((j + 0.5) / n - 0.5))));
          const double v = SceneTexture::Luminance(tex.Albedo(q.rect, p, {}, {}));
          mean += v / (n * n);
          lo = std::min(lo, v), hi = std::max(hi, v);
        }
      const double e = std::abs(SceneTexture::Luminance(f) - mean);
      ++total;
      good += e < 0.05;
      error += e;
      contrast += hi - lo;
    }
    EXPECT_GE(good, 0.9 * total) << "footprint " << size << " m";
    EXPECT_LT(error / total, 0.025) << "footprint " << size << " m";
    EXPECT_GT(contrast / total, 0.05) << "the probes see texture";
  }
}

// No shimmer: when the footprint moves by a quarter of its size (a camera moving by a quarter
// pixel), the filtered albedo changes several times less than the point values (unfiltered
// sampling) do; that is what keeps a moving camera's pixels stable.
TEST(SceneTextureTest, FilteredAlbedoIsStableUnderSubPixelShifts) {
  const Scene scene = Scene::StreetCanyon(100.0, 1);
  const SceneTexture tex(scene, 1);
  for (double size : {0.3, 1.5}) {
    double filtered = 0.0, point = 0.0;
    for (const Probe& q : Probes(300, 23)) {
      const Vec3 shift = Add(Scale(q.ds, 0.25 * size), Scale(q.dt, 0.25 * size));
      const Vec3 ds = Scale(q.ds, size), dt = Scale(q.dt, size);
      filtered += std::abs(SceneTexture::Luminance(tex.Albedo(q.rect, q.p, ds, dt)) -
                           SceneTexture::Luminance(tex.Albedo(q.rect, Add(q.p, shift), ds, dt)));
      point += std::abs(SceneTexture::Luminance(tex.Albedo(q.rect, q.p, {}, {})) -
                        SceneTexture::Luminance(tex.Albedo(q.rect, Add(q.p, shift), {}, {})));
    }
    EXPECT_LT(filtered, 0.4 * point) << "footprint " << size << " m";
  }
}

}  // namespace
}  // namespace imr::synthetic
