// Colour and texture from keyframe images (issue 17), against imr-synth's known scene: the exact
// street (Scene::StreetCanyon, each rect cut into 0.5 m triangles) is seen by keyframes that the
// generator's own renderer draws (tools/synth, in memory), and what the exporter makes of them is
// compared with the colour the generator gives the scene there (Renderer::ColorToward: the
// texture filtered over a pixel, lit, before noise). First the algorithm itself (texturing.hpp),
// then the files through the real plugin (.so) driven with a host-services table that serves the
// images: glTF/GLB (Khronos validator, the embedded or beside-it atlas read back at the
// triangles), OBJ + MTL re-read by assimp with its texture, PLY colours read back, the upright
// root node, the job options (texture off, keyframe_step), engine-only inputs' point colours.
#include <imr/sdk/host.hpp>
#include <imr/sdk/plugin.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <assimp/Importer.hpp>
#include <assimp/material.h>
#include <assimp/scene.h>
#include <boost/dll/shared_library.hpp>
#include <cmath>
#include <filesystem>
#include <map>
#include <numeric>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <set>
#include <string>
#include <vector>

#include "host/synthetic/stream.h"
#include "streamed_colours.hpp"
#include "test_helpers.hpp"
#include "texturing.hpp"
#include "tools/synth/raycaster.h"
#include "tools/synth/renderer.h"
#include "tools/synth/rig.h"

namespace imr::exporter_assimp {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;
using synth::Vec3;
using namespace imr::exporter_assimp::testing;

constexpr int kFrames = 40, kKeyframeEvery = 4, kWidth = 621, kHeight = 188;
constexpr double kCell = 0.5;       // metres: the triangles' size
constexpr double kGreyLevels = 20;  // the issue's tolerance
constexpr double kShare = 0.90;     // ... at this share of the triangles / vertices

double Grey(double r, double g, double b) { return 0.299 * r + 0.587 * g + 0.114 * b; }

// The known scene, its keyframes (cameras and images) and its exact mesh.
struct KnownScene {
  synthetic::Scene scene = synthetic::Scene::StreetCanyon(synthetic::StreetLength(kFrames, 1.0), 7);
  synthetic::SceneTexture texture{scene, 7};
  synth::RayCaster caster{scene};
  synth::Rig rig = synth::Rig::Kitti(kWidth, kHeight);
  synth::Renderer renderer{scene, texture, caster, rig.camera, [] {
                             synth::RenderOptions o;
                             o.color = true;
                             return o;
                           }()};
  std::vector<Vec3> centers;
  std::vector<imr_camera> cameras;
  std::vector<cv::Mat> images;  // BGR
  std::vector<double> vertices;
  std::vector<uint32_t> faces;
  std::vector<int64_t> ids;
  std::vector<int> face_rect, vertex_rect;

  KnownScene() {
    const Vec3 offset = synth::SceneFromCamera(rig.CameraOffset(2));
    for (int f = 0; f < kFrames; ++f) {
      if (f % kKeyframeEvery != 0 && f + 1 != kFrames) continue;
      const Vec3 c = synthetic::Add(synthetic::StreetCameraCenter(f, 1.0), offset);
      centers.push_back(c);
      images.push_back(renderer.Render(c, f));
      // Every camera of the rig: x = scene x, y = -scene z, z = scene y; t = -R C.
      imr_camera cam{};
      cam.id = static_cast<uint64_t>(f);
      const double R[9] = {1, 0, 0, 0, 0, -1, 0, 1, 0};
      std::copy(R, R + 9, cam.R);
      for (int r = 0; r < 3; ++r) cam.t[r] = -(R[3 * r] * c[0] + R[3 * r + 1] * c[1] + R[3 * r + 2] * c[2]);
      const double K[9] = {rig.camera.fx, 0, rig.camera.cx, 0, rig.camera.fy, rig.camera.cy, 0, 0, 1};
      std::copy(K, K + 9, cam.K);
      cam.width = kWidth;
      cam.height = kHeight;
      cameras.push_back(cam);
    }
    // Each rect as a grid of triangles, counter-clockwise seen from the camera path's side.
    const auto& rects = scene.rects();
    for (std::size_t r = 0; r < rects.size(); ++r) {
      const synthetic::Rect& q = rects[r];
      const int nu = std::max(1, static_cast<int>(std::ceil(2 * q.half_u / kCell)));
      const int nv = std::max(1, static_cast<int>(std::ceil(2 * q.half_v / kCell)));
      const Vec3 toward = {0.0, std::clamp(q.center[1], 0.0, double{kFrames}), 1.65};
      const bool flip = synthetic::Dot(synthetic::Cross(q.u, q.v), synthetic::Sub(toward, q.center)) < 0;
      const auto base = static_cast<uint32_t>(vertices.size() / 3);
      for (int j = 0; j <= nv; ++j)
        for (int i = 0; i <= nu; ++i) {
          const Vec3 p = synthetic::Add(
              q.center, synthetic::Add(synthetic::Scale(q.u, (2.0 * i / nu - 1) * q.half_u),
                                       synthetic::Scale(q.v, (2.0 * j / nv - 1) * q.half_v)));
          vertices.insert(vertices.end(), p.begin(), p.end());
          ids.push_back(static_cast<int64_t>(ids.size()));
          vertex_rect.push_back(static_cast<int>(r));
        }
      for (int j = 0; j < nv; ++j)
        for (int i = 0; i < nu; ++i) {
          const uint32_t a = base + static_cast<uint32_t>(j * (nu + 1) + i), b = a + 1,
                         c = a + static_cast<uint32_t>(nu + 2), d = a + static_cast<uint32_t>(nu + 1);
          for (const std::array<uint32_t, 3> t : {std::array<uint32_t, 3>{a, b, c}, std::array<uint32_t, 3>{a, c, d}}) {
            if (flip) faces.insert(faces.end(), {t[0], t[2], t[1]});
            else faces.insert(faces.end(), t.begin(), t.end());
            face_rect.push_back(static_cast<int>(r));
          }
        }
    }
  }

  // The rect a point of the surface lies on (the nearest; files do not say).
  int RectAt(const Vec3& p) const {
    int best = -1;
    double d = 1e300;
    for (std::size_t r = 0; r < scene.rects().size(); ++r) {
      const synthetic::Rect& q = scene.rects()[r];
      const Vec3 x = synthetic::Sub(p, q.center);
      const double a = std::clamp(synthetic::Dot(x, q.u), -q.half_u, q.half_u);
      const double b = std::clamp(synthetic::Dot(x, q.v), -q.half_v, q.half_v);
      const Vec3 e = synthetic::Sub(x, synthetic::Add(synthetic::Scale(q.u, a), synthetic::Scale(q.v, b)));
      if (const double dd = synthetic::Dot(e, e); dd < d) d = dd, best = static_cast<int>(r);
    }
    return best;
  }

  imr::sdk::MeshView View() const {
    return {{vertices.data(), vertices.size()}, {faces.data(), faces.size()}, {ids.data(), ids.size()}, {}, {}};
  }
  Vec3 Vertex(std::size_t i) const { return {vertices[3 * i], vertices[3 * i + 1], vertices[3 * i + 2]}; }
  Vec3 Centroid(std::size_t f) const {
    Vec3 c{};
    for (int k = 0; k < 3; ++k)
      for (int a = 0; a < 3; ++a) c[a] += vertices[3 * faces[3 * f + k] + a] / 3.0;
    return c;
  }
  // The scene's own grey level at p, a point of rect `rect`, as keyframe k sees it there (its
  // texture filtered over k's pixel, lit), whatever lies in front; -1 outside k's image. With
  // `unoccluded`, also -1 when something hides p from k.
  double TrueGrey(std::size_t k, const Vec3& p, int rect, bool unoccluded = false) const {
    const Vec3 d = synthetic::Sub(p, centers[k]);
    const Vec3 c = synth::CameraFromScene(d);
    if (!(c[2] > 0.1)) return -1;
    const double u = rig.camera.fx * c[0] / c[2] + rig.camera.cx, v = rig.camera.fy * c[1] / c[2] + rig.camera.cy;
    if (u < 0 || v < 0 || u > kWidth - 1 || v > kHeight - 1) return -1;
    synth::RayCaster::Hit hit;
    if (unoccluded && caster.Cast(centers[k], d, 1.0, &hit) && hit.rect != rect &&
        hit.t < 1.0 - 1e-3 / std::sqrt(synthetic::Dot(d, d)))
      return -1;
    int shaded = -1;
    const synthetic::Rgb rgb = renderer.ColorToward(centers[k], p, rect, &shaded);
    return 255.0 * Grey(rgb.r, rgb.g, rgb.b);
  }
};

const KnownScene& Scene() {
  static const KnownScene* s = new KnownScene();
  return *s;
}

// A host-services table serving the scene's images, counting what the plugin asks for.
struct FakeHost {
  const std::vector<cv::Mat>* images = nullptr;
  std::vector<int> acquired, held;
  imr_host_services services{};

  explicit FakeHost(const std::vector<cv::Mat>& im) : images(&im), acquired(im.size()), held(im.size()) {
    services.struct_size = sizeof(services);
    services.version = IMR_HOST_SERVICES_VERSION;
    services.host_data = this;
    services.keyframe_image = [](void* d, uint64_t i, imr_image_view* out, imr_error* e) -> imr_status {
      auto* h = static_cast<FakeHost*>(d);
      if (i >= h->images->size()) {
        std::snprintf(e->message, sizeof(e->message), "keyframe image %llu is out of range",
                      static_cast<unsigned long long>(i));
        return IMR_INVALID_ARGUMENT;
      }
      const cv::Mat& m = (*h->images)[i];
      *out = {sizeof(imr_image_view), m.cols, m.rows, m.channels(), static_cast<int64_t>(m.step), m.data};
      ++h->acquired[i];
      ++h->held[i];
      return IMR_OK;
    };
    services.release_keyframe_image = [](void* d, uint64_t i) {
      auto* h = static_cast<FakeHost*>(d);
      if (i < h->held.size() && h->held[i] > 0) --h->held[i];
    };
  }
  int Held() const { return std::accumulate(held.begin(), held.end(), 0); }
};

// Grey level of an RGB image at texture coordinates (u, v) (glTF's: origin top-left), bilinear.
double AtlasGrey(const cv::Mat& bgr, double u, double v) {
  const double x = u * bgr.cols - 0.5, y = v * bgr.rows - 0.5;
  const int x0 = std::clamp(static_cast<int>(std::floor(x)), 0, bgr.cols - 2);
  const int y0 = std::clamp(static_cast<int>(std::floor(y)), 0, bgr.rows - 2);
  const double fx = std::clamp(x - x0, 0.0, 1.0), fy = std::clamp(y - y0, 0.0, 1.0);
  double g = 0;
  for (int j = 0; j < 2; ++j)
    for (int i = 0; i < 2; ++i) {
      const cv::Vec3b p = bgr.at<cv::Vec3b>(y0 + j, x0 + i);
      g += (i ? fx : 1 - fx) * (j ? fy : 1 - fy) * Grey(p[2], p[1], p[0]);
    }
  return g;
}

struct Agreement {
  int compared = 0, within = 0;
  double Share() const { return compared > 0 ? static_cast<double>(within) / compared : 0.0; }
  void Add(double got, double want) {
    ++compared;
    within += std::fabs(got - want) <= kGreyLevels;
  }
};

// The atlas at each textured triangle's centroid against the scene seen from the triangle's view
// (every texture coordinate within its page, every centroid within its view's image).
Agreement AtlasAgreement(const KnownScene& s, const TexturedMesh& t) {
  std::vector<cv::Mat> pages;
  for (const AtlasPage& p : t.pages) {
    cv::Mat rgb(p.height, p.width, CV_8UC3, const_cast<uint8_t*>(p.rgb.data())), bgr;
    cv::cvtColor(rgb, bgr, cv::COLOR_RGB2BGR);
    pages.push_back(bgr);
  }
  Agreement agreement;
  for (std::size_t f = 0; f < s.faces.size() / 3; ++f) {
    if (t.face_page[f] < 0) continue;
    const double want = s.TrueGrey(static_cast<std::size_t>(t.face_view[f]), s.Centroid(f), s.face_rect[f]);
    EXPECT_GE(want, 0) << "face " << f << ": outside its view's image";
    double u = 0, v = 0;
    for (int k = 0; k < 3; ++k) {
      const float cu = t.face_uv[6 * f + 2 * k], cv = t.face_uv[6 * f + 2 * k + 1];
      EXPECT_TRUE(cu >= 0.0f && cu <= 1.0f && cv >= 0.0f && cv <= 1.0f) << "face " << f;
      u += cu / 3, v += cv / 3;
    }
    if (want >= 0) agreement.Add(AtlasGrey(pages[static_cast<std::size_t>(t.face_page[f])], u, v), want);
  }
  return agreement;
}

TEST(Texturing, AtlasAndVertexColoursMatchTheScenesOwnTexture) {
  const KnownScene& s = Scene();
  FakeHost host(s.images);
  const imr::sdk::Host h(&host.services);
  TexturingOptions o;
  o.atlas_size = 2048;
  const TexturedMesh t = ColorAndTexture(s.View(), s.cameras, [&](uint64_t i) { return h.GetKeyframeImage(i); }, o);
  const TexturingStats& st = t.stats;
  std::cout << "faces " << st.faces << ", textured " << st.faces_textured << ", patches " << st.patches
            << ", seams " << st.seams_best_view << " -> " << st.seams << " (" << st.seams_forced
            << " unavoidable), pages " << t.pages.size() << ", atlas " << st.atlas_pixels << " px, "
            << st.seconds_total << " s\n";
  EXPECT_EQ(st.views, static_cast<int>(s.cameras.size()));
  EXPECT_EQ(host.Held(), 0) << "every image is released";
  ASSERT_FALSE(t.pages.empty());
  // Once for visibility and colours, then once per page holding one of its patches.
  for (std::size_t k = 0; k < s.images.size(); ++k) {
    std::set<int32_t> pages_of_view;
    for (std::size_t f = 0; f < t.face_view.size(); ++f)
      if (t.face_view[f] == static_cast<int32_t>(k)) pages_of_view.insert(t.face_page[f]);
    EXPECT_LE(host.acquired[k], 1 + static_cast<int>(pages_of_view.size())) << "keyframe " << k;
  }
  // Much of the scene is textured; the smoothness term never adds seams (its effect is measured
  // where it shows: SmoothnessTermJoinsViewsOfEqualQuality).
  EXPECT_GT(st.faces_textured, st.faces / 3);
  EXPECT_LE(st.seams, st.seams_best_view);

  // The texture at each textured triangle's centroid against the scene seen from that view.
  const Agreement texture = AtlasAgreement(s, t);
  std::cout << "texture: " << texture.within << " of " << texture.compared << " centroids within "
            << kGreyLevels << " grey levels\n";
  EXPECT_GE(texture.Share(), kShare);

  // Vertex colours against the scene as the keyframes that see the vertex see it there, weighted
  // as the exporter weights its samples: by (cos(viewing angle) / depth)^2. Vertices on a rect's
  // border are left out: there the images show two surfaces at once (a car's edge over the road),
  // and one colour per vertex cannot be both.
  Agreement colours, border;
  for (std::size_t i = 0; i < s.vertices.size() / 3; ++i) {
    const Vec3 p = s.Vertex(i);
    const synthetic::Rect& q = s.scene.rects()[static_cast<std::size_t>(s.vertex_rect[i])];
    const Vec3 x = synthetic::Sub(p, q.center);
    const bool on_border = std::fabs(std::fabs(synthetic::Dot(x, q.u)) - q.half_u) < 1e-6 ||
                           std::fabs(std::fabs(synthetic::Dot(x, q.v)) - q.half_v) < 1e-6;
    const Vec3 n = synthetic::Cross(q.u, q.v);
    double sum = 0, weight = 0;
    for (std::size_t k = 0; k < s.centers.size(); ++k) {
      const double want = s.TrueGrey(k, p, s.vertex_rect[i], /*unoccluded=*/true);
      if (want < 0) continue;
      const Vec3 d = synthetic::Sub(s.centers[k], p);
      const double cosine = std::fabs(synthetic::Dot(n, d)) / std::sqrt(synthetic::Dot(d, d));
      const double z = synth::CameraFromScene(synthetic::Sub(p, s.centers[k]))[2];
      sum += want * (cosine / z) * (cosine / z);
      weight += (cosine / z) * (cosine / z);
    }
    if (!(weight > 0)) continue;
    const uint8_t* c = &t.vertex_rgb[3 * i];
    (on_border ? border : colours).Add(Grey(c[0], c[1], c[2]), sum / weight);
  }
  std::cout << "vertex colours on rect borders (not counted): " << border.within << " of "
            << border.compared << " within " << kGreyLevels << " grey levels\n";
  std::cout << "vertex colours: " << colours.within << " of " << colours.compared << " within "
            << kGreyLevels << " grey levels\n";
  EXPECT_GT(colours.compared, 1000);
  EXPECT_GE(colours.Share(), kShare);
}

// A level of detail's request (ABI 1.6 texel_size): each patch takes one texel per n x n pixels,
// n the whole pixels its view sees within the texel at its faces. The same views, an atlas of a
// fraction of the pixels, and the texture still the scene's; a texel smaller than every pixel
// changes nothing.
TEST(Texturing, ALevelOfDetailsCoarserTexelsStillShowTheScene) {
  const KnownScene& s = Scene();
  TexturingOptions o;
  o.atlas_size = 2048;
  auto texture = [&](double texel_size) {
    FakeHost host(s.images);
    const imr::sdk::Host h(&host.services);
    TexturingOptions with = o;
    with.texel_size = texel_size;
    return ColorAndTexture(s.View(), s.cameras, [&](uint64_t i) { return h.GetKeyframeImage(i); }, with);
  };
  const TexturedMesh full = texture(0.0);
  const TexturedMesh fine = texture(1e-6);  // under a pixel everywhere: step 1
  EXPECT_EQ(fine.face_uv, full.face_uv);
  ASSERT_EQ(fine.pages.size(), full.pages.size());
  for (std::size_t p = 0; p < full.pages.size(); ++p) EXPECT_TRUE(fine.pages[p].rgb == full.pages[p].rgb);

  const TexturedMesh coarse = texture(0.1);  // 10 cm: ~3 pixels at 10 m here
  std::cout << "atlas: " << full.stats.atlas_pixels << " px at the images' resolution, "
            << coarse.stats.atlas_pixels << " px with 10 cm texels (" << full.stats.patches << " and "
            << coarse.stats.patches << " patches)\n";
  EXPECT_EQ(coarse.face_view, full.face_view);
  EXPECT_GE(coarse.stats.patches, full.stats.patches);  // split where the step changes
  EXPECT_EQ(coarse.stats.faces_textured, full.stats.faces_textured);
  // Far faces (the street runs to 50 m, where a pixel is 14 cm) keep their pixels.
  EXPECT_LT(coarse.stats.atlas_pixels, full.stats.atlas_pixels / 2);
  const TexturedMesh coarser = texture(0.4);
  std::cout << "atlas with 40 cm texels: " << coarser.stats.atlas_pixels << " px\n";
  EXPECT_LT(coarser.stats.atlas_pixels, full.stats.atlas_pixels / 8);

  const Agreement agreement = AtlasAgreement(s, coarse);
  std::cout << "coarse texture: " << agreement.within << " of " << agreement.compared
            << " centroids within " << kGreyLevels << " grey levels\n";
  EXPECT_GE(agreement.Share(), kShare);
}

// The smoothness term on a 40 x 40 grid of quads seen by two views: where their qualities are
// equal up to noise (the best view flips at random from face to face), the labelling joins the
// faces into one view; where one view is clearly better (left half: view 0, right half: view 1),
// the data term wins and one seam line remains between the halves.
TEST(Texturing, SmoothnessTermJoinsViewsOfEqualQuality) {
  constexpr int n = 40;
  std::vector<double> vertices;
  std::vector<uint32_t> faces;
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) vertices.insert(vertices.end(), {double(i), double(j), 0.0});
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const auto a = static_cast<uint32_t>(j * (n + 1) + i);
      faces.insert(faces.end(), {a, a + 1, a + n + 2, a, a + n + 2, a + n + 1});
    }
  const imr::sdk::MeshView mesh{{vertices.data(), vertices.size()}, {faces.data(), faces.size()}, {}, {}, {}};
  uint32_t noise = 12345;
  auto jitter = [&] {
    noise = noise * 1664525u + 1013904223u;
    return 0.9f + 0.2f * static_cast<float>(noise >> 8) / static_cast<float>(1u << 24);
  };
  std::vector<ViewCandidate> equal, split;
  for (uint32_t f = 0; f < faces.size() / 3; ++f) {
    for (int32_t v = 0; v < 2; ++v) equal.push_back({f, v, 100.0f * jitter()});
    const bool left = (f / 2) % n < n / 2;
    split.push_back({f, 0, left ? 100.0f : 30.0f});
    split.push_back({f, 1, left ? 30.0f : 100.0f});
  }
  TexturingStats st;
  std::vector<int32_t> label = SelectViews(mesh, equal, 2, 1.0, &st);
  std::cout << "equal qualities: seams " << st.seams_best_view << " -> " << st.seams << "\n";
  EXPECT_GT(st.seams_best_view, 1000);  // ~half of the 4,720 interior edges
  EXPECT_EQ(st.seams, 0);
  EXPECT_EQ(std::count(label.begin(), label.end(), label[0]), static_cast<long>(label.size()));
  EXPECT_EQ(SelectViews(mesh, equal, 2, 0.0, &st), [&] {  // no smoothness: the best views
    std::vector<int32_t> best(faces.size() / 3);
    for (std::size_t f = 0; f < best.size(); ++f) best[f] = equal[2 * f].quality >= equal[2 * f + 1].quality ? 0 : 1;
    return best;
  }());
  label = SelectViews(mesh, split, 2, 1.0, &st);
  EXPECT_EQ(st.seams_best_view, n);  // one line of n quads' edges
  EXPECT_EQ(st.seams, n);
  for (uint32_t f = 0; f < label.size(); ++f) EXPECT_EQ(label[f], (f / 2) % n < n / 2 ? 0 : 1) << f;
}

// ---- the files, through the plugin -----------------------------------------------------------

class TexturedFiles : public ::testing::Test {
 protected:
  void SetUp() override {
    lib_.load(IMR_EXPORTER_SO, boost::dll::load_mode::rtld_now);
    descriptor_ = lib_.get<const imr_plugin_descriptor*(uint32_t)>("imr_plugin_entry")(0);
    dir_ = fs::temp_directory_path() / ("imr_texture_test_" + std::to_string(::getpid()) + "_" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  // Exports the known scene in `formats` with one instance (as the host does); the main files.
  // `texel_size` goes in the request (ABI 1.6); `struct_size` (non-zero): the request as a host
  // of an older minor sends it, shorter than this SDK's.
  std::vector<fs::path> Export(FakeHost* host, const std::vector<std::string>& formats,
                               const std::string& params = "{}", const uint8_t* colors = nullptr,
                               bool images = true, double texel_size = 0.0, uint32_t struct_size = 0) {
    const KnownScene& s = Scene();
    imr::sdk::Instance inst(descriptor_, params, &host->services);
    imr_mesh_view view{};
    view.struct_size = sizeof(view);
    view.vertices = s.vertices.data();
    view.vertex_count = s.vertices.size() / 3;
    view.faces = s.faces.data();
    view.face_count = s.faces.size() / 3;
    view.point_ids = s.ids.data();
    view.vertex_colors = colors;
    std::vector<fs::path> files;
    const std::string d = dir_.string(), stem = "scene";
    for (const std::string& format : formats) {
      imr_export_request req{};
      req.mesh = &view;
      req.directory = d.c_str();
      req.stem = stem.c_str();
      req.format = format.c_str();
      req.keyframes = s.cameras.data();
      req.keyframe_count = s.cameras.size();
      req.keyframe_images = images ? 1 : 0;
      req.texel_size = texel_size;
      if (struct_size == 0) {
        inst.ExportMesh(&req);
      } else {
        req.struct_size = struct_size;
        imr_error e{};
        EXPECT_EQ(descriptor_->exporter->export_mesh(inst.handle(), &req, &e), IMR_OK) << e.message;
      }
      files.push_back(dir_ / (stem + "." + format));
    }
    return files;
  }

  boost::dll::shared_library lib_;
  const imr_plugin_descriptor* descriptor_ = nullptr;
  fs::path dir_;
};

// The textured triangles of a glTF (positions, texture coordinates, its atlas) against the scene:
// each centroid's texel against the scene seen from the keyframes that see it, the best match
// counting (the file does not say which view a triangle took; a wrong mapping matches none).
Agreement GltfTextureAgreement(const fs::path& file) {
  const KnownScene& s = Scene();
  const Gltf g = LoadGltf(file);
  const json& doc = g.doc;
  Agreement a;
  for (const json& prim : doc["meshes"][0]["primitives"]) {
    const json& attr = prim["attributes"];
    const json& material = doc["materials"][prim["material"].get<std::size_t>()];
    if (!attr.contains("TEXCOORD_0")) continue;
    const std::size_t tex = material["pbrMetallicRoughness"]["baseColorTexture"]["index"];
    const json& image = doc["images"][doc["textures"][tex]["source"].get<std::size_t>()];
    cv::Mat atlas;
    if (image.contains("bufferView")) {
      const json& bv = doc["bufferViews"][image["bufferView"].get<std::size_t>()];
      const std::vector<uint8_t> bytes(g.bin.begin() + bv.value("byteOffset", 0),
                                       g.bin.begin() + bv.value("byteOffset", 0) + bv["byteLength"].get<long>());
      atlas = cv::imdecode(bytes, cv::IMREAD_COLOR);
    } else {
      atlas = cv::imread((file.parent_path() / image["uri"].get<std::string>()).string(), cv::IMREAD_COLOR);
    }
    EXPECT_FALSE(atlas.empty()) << image.dump();
    if (atlas.empty()) continue;
    const std::vector<double> pos = AccessorValues(g, attr["POSITION"]);
    const std::vector<double> uv = AccessorValues(g, attr["TEXCOORD_0"]);
    const std::vector<double> idx = AccessorValues(g, prim["indices"]);
    for (std::size_t t = 0; t + 2 < idx.size(); t += 3) {
      Vec3 c{};
      double u = 0, v = 0;
      for (int k = 0; k < 3; ++k) {
        const auto i = static_cast<std::size_t>(idx[t + k]);
        for (int d = 0; d < 3; ++d) c[d] += pos[3 * i + d] / 3;
        u += uv[2 * i] / 3, v += uv[2 * i + 1] / 3;
      }
      const double got = AtlasGrey(atlas, u, v);
      double best = 1e9;
      const int rect = s.RectAt(c);
      for (std::size_t k = 0; k < s.centers.size(); ++k)
        if (const double want = s.TrueGrey(k, c, rect); want >= 0) best = std::min(best, std::fabs(got - want));
      a.Add(best, 0.0);
    }
  }
  return a;
}

// Texels of a glTF's atlas pages.
int64_t AtlasTexels(const fs::path& file) {
  const Gltf g = LoadGltf(file);
  int64_t texels = 0;
  for (const json& image : g.doc["images"]) {
    const json& bv = g.doc["bufferViews"][image["bufferView"].get<std::size_t>()];
    const std::vector<uint8_t> bytes(g.bin.begin() + bv.value("byteOffset", 0),
                                     g.bin.begin() + bv.value("byteOffset", 0) + bv["byteLength"].get<long>());
    const cv::Mat atlas = cv::imdecode(bytes, cv::IMREAD_COLOR);
    texels += static_cast<int64_t>(atlas.cols) * atlas.rows;
  }
  return texels;
}

// The request's texel_size (ABI 1.6, a level of detail's) through the plugin: a coarser atlas
// that still shows the scene; a 1.2-1.5 host's request, which ends before the field, is read
// without it whatever lies beyond (the images' resolution, as before).
TEST_F(TexturedFiles, ALevelOfDetailsTexelSizeAndAnOlderHostsRequest) {
  const KnownScene& s = Scene();
  FakeHost host(s.images);
  const int64_t full = AtlasTexels(Export(&host, {"glb"})[0]);
  const fs::path coarse = Export(&host, {"glb"}, "{}", nullptr, true, 0.2)[0];
  ExpectValidGltf(coarse);
  const int64_t coarse_texels = AtlasTexels(coarse);
  const Agreement a = GltfTextureAgreement(coarse);
  std::cout << "atlas " << full << " texels, with 20 cm texels " << coarse_texels << "; " << a.within
            << " of " << a.compared << " centroids within " << kGreyLevels << " grey levels\n";
  EXPECT_LT(coarse_texels, full / 3);  // 29 %: the far street keeps its pixels (texture_test above)
  EXPECT_GE(a.Share(), kShare);
  const fs::path older = Export(&host, {"glb"}, "{}", nullptr, true, 0.2, IMR_EXPORT_REQUEST_SIZE_1_2)[0];
  EXPECT_EQ(AtlasTexels(older), full);
  EXPECT_EQ(host.Held(), 0);
}

TEST_F(TexturedFiles, GltfGlbObjAndPlyCarryTheTextureAndColours) {
  const KnownScene& s = Scene();
  FakeHost host(s.images);
  const std::vector<fs::path> files = Export(&host, {"glb", "gltf", "obj", "ply"});
  EXPECT_EQ(host.Held(), 0);
  for (std::size_t k = 0; k < s.images.size(); ++k)
    EXPECT_LE(host.acquired[k], 2) << "keyframe " << k << ": texturing runs once for all formats";

  // glTF and GLB: valid, textured, upright, the texture right at the triangles.
  for (const fs::path& file : {files[0], files[1]}) {
    SCOPED_TRACE(file.filename().string());
    ExpectValidGltf(file);
    const json doc = LoadGltf(file).doc;
    ASSERT_TRUE(doc.contains("images"));
    EXPECT_EQ(doc["images"][0].contains("bufferView"), file.extension() == ".glb") << "embedded in GLB only";
    if (file.extension() == ".gltf") {
      EXPECT_TRUE(fs::exists(dir_ / doc["images"][0]["uri"].get<std::string>()));
    }
    const Agreement a = GltfTextureAgreement(file);
    std::cout << file.filename() << ": " << a.within << " of " << a.compared << " centroids within "
              << kGreyLevels << " grey levels\n";
    EXPECT_GT(a.compared, 1000);
    EXPECT_GE(a.Share(), kShare);
    // Upright: the cameras' up (scene +z) is glTF's +Y, their viewing direction (scene +y) is -Z.
    const json& root = doc["nodes"][doc["scenes"][0]["nodes"][0].get<std::size_t>()];
    EXPECT_EQ(root["name"], "imr_upright");
    const std::vector<double> m = root["matrix"];  // column-major
    const double want[16] = {1, 0, 0, 0, 0, 0, -1, 0, 0, 1, 0, 0, 0, 0, 0, 1};
    for (int i = 0; i < 16; ++i) EXPECT_NEAR(m[static_cast<std::size_t>(i)], want[i], 1e-9) << i;
    // Faces nobody sees keep vertex colours (a second primitive with COLOR_0, no texture).
    bool colored = false;
    for (const json& prim : doc["meshes"][0]["primitives"])
      colored = colored || (prim["attributes"].contains("COLOR_0") && !prim["attributes"].contains("TEXCOORD_0"));
    EXPECT_TRUE(colored);
  }

  // OBJ + MTL: assimp reads the material's texture and the texture coordinates back.
  {
    Assimp::Importer importer;
    const aiScene* scene = importer.ReadFile(files[2].string(), 0);
    ASSERT_NE(scene, nullptr) << importer.GetErrorString();
    int textured = 0;
    for (unsigned i = 0; i < scene->mNumMeshes; ++i) {
      const aiMesh& m = *scene->mMeshes[i];
      aiString path;
      if (scene->mMaterials[m.mMaterialIndex]->Get(AI_MATKEY_TEXTURE_DIFFUSE(0), path) != AI_SUCCESS) continue;
      ++textured;
      EXPECT_TRUE(m.HasTextureCoords(0));
      const cv::Mat atlas = cv::imread((dir_ / path.C_Str()).string(), cv::IMREAD_COLOR);
      ASSERT_FALSE(atlas.empty()) << path.C_Str();
      Agreement a;
      for (unsigned f = 0; f < m.mNumFaces; ++f) {
        Vec3 c{};
        double u = 0, v = 0;
        for (int k = 0; k < 3; ++k) {
          const unsigned i2 = m.mFaces[f].mIndices[k];
          c[0] += m.mVertices[i2].x / 3.0, c[1] += m.mVertices[i2].y / 3.0, c[2] += m.mVertices[i2].z / 3.0;
          u += m.mTextureCoords[0][i2].x / 3.0, v += (1.0 - m.mTextureCoords[0][i2].y) / 3.0;  // OBJ: v up
        }
        double best = 1e9;
        const int rect = s.RectAt(c);
        for (std::size_t k = 0; k < s.centers.size(); ++k)
          if (const double want = s.TrueGrey(k, c, rect); want >= 0)
            best = std::min(best, std::fabs(AtlasGrey(atlas, u, v) - want));
        a.Add(best, 0.0);
      }
      std::cout << "obj " << path.C_Str() << ": " << a.within << " of " << a.compared << " within\n";
      EXPECT_GE(a.Share(), kShare);
    }
    EXPECT_GE(textured, 1);
  }

  // PLY: red green blue per vertex, read back; equal to the algorithm's colours.
  {
    FakeHost again(s.images);
    const imr::sdk::Host h(&again.services);
    const TexturedMesh t = ColorAndTexture(s.View(), s.cameras, [&](uint64_t i) { return h.GetKeyframeImage(i); }, {});
    const std::vector<uint8_t> bytes = Slurp(files[3]);
    const std::string text(bytes.begin(), bytes.end());
    const std::size_t end = text.find("end_header\n") + 11;
    EXPECT_NE(text.find("property int point_id\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n"),
              std::string::npos) << text.substr(0, end);
    const std::size_t record = 6 * 4 + 4 + 3, nv = s.vertices.size() / 3;
    ASSERT_EQ(bytes.size(), end + nv * record + s.faces.size() / 3 * 13);
    int same = 0;
    for (std::size_t i = 0; i < nv; ++i) {
      const uint8_t* r = bytes.data() + end + i * record;
      const auto id = static_cast<std::size_t>(LoadLE<int32_t>(r + 24));  // the vertex, by its id
      same += std::equal(r + 28, r + 31, t.vertex_rgb.begin() + static_cast<std::ptrdiff_t>(3 * id));
    }
    EXPECT_EQ(same, static_cast<int>(nv));
  }
}

// The pages are filled one after the other, each handed over whole: a sink that takes the
// pixels (as the exporter does, encoding each page at once) gets the same pages, in order.
TEST(Texturing, PagesAreHandedOverOneAtATimeAndWhole) {
  const KnownScene& s = Scene();
  TexturingOptions o;
  o.atlas_size = 256;  // several pages
  FakeHost whole_host(s.images);
  const imr::sdk::Host wh(&whole_host.services);
  const TexturedMesh whole =
      ColorAndTexture(s.View(), s.cameras, [&](uint64_t i) { return wh.GetKeyframeImage(i); }, o);
  ASSERT_GE(whole.pages.size(), 3u);

  FakeHost sink_host(s.images);
  const imr::sdk::Host sh(&sink_host.services);
  std::vector<std::vector<uint8_t>> taken;
  const TexturedMesh handed = ColorAndTexture(
      s.View(), s.cameras, [&](uint64_t i) { return sh.GetKeyframeImage(i); }, o, {},
      [&](std::size_t index, AtlasPage& page) {
        EXPECT_EQ(index, taken.size()) << "pages in order";
        EXPECT_EQ(page.rgb.size(), static_cast<std::size_t>(page.width) * page.height * 3);
        taken.push_back(std::move(page.rgb));
        page.rgb.clear();
      });
  ASSERT_EQ(handed.pages.size(), whole.pages.size());
  ASSERT_EQ(taken.size(), whole.pages.size());
  for (std::size_t p = 0; p < whole.pages.size(); ++p) {
    EXPECT_EQ(handed.pages[p].width, whole.pages[p].width);
    EXPECT_EQ(handed.pages[p].height, whole.pages[p].height);
    EXPECT_TRUE(handed.pages[p].rgb.empty());
    EXPECT_TRUE(taken[p] == whole.pages[p].rgb) << "page " << p;
  }
  EXPECT_EQ(handed.face_uv, whole.face_uv);
  EXPECT_EQ(handed.vertex_rgb, whole.vertex_rgb);
}

// A keyframe at (0, y, 1.5) looking along +y (x = X, y = -Z, z = Y), 160 x 120 pixels.
imr_camera AlongTheRoad(double y, double focal) {
  imr_camera c{};
  const double R[9] = {1, 0, 0, 0, 0, -1, 0, 1, 0};
  const double centre[3] = {0.0, y, 1.5};
  std::copy(R, R + 9, c.R);
  for (int r = 0; r < 3; ++r) c.t[r] = -(R[3 * r] * centre[0] + R[3 * r + 1] * centre[1] + R[3 * r + 2] * centre[2]);
  const double K[9] = {focal, 0, 80, 0, focal, 60, 0, 0, 1};
  std::copy(K, K + 9, c.K);
  c.width = 160;
  c.height = 120;
  return c;
}

// Vertex colours made block by block from a mesh read in blocks (a long drive's single mesh) are
// the whole mesh's where a keyframe sees the vertex: each block's piece holds every face that can
// hide its vertices.
TEST(Texturing, VertexColoursInBlocksAreTheWholeMeshs) {
  const KnownScene& s = Scene();
  TexturingOptions o;
  o.texture = false;
  FakeHost host(s.images);
  const imr::sdk::Host h(&host.services);
  const auto fetch = [&](uint64_t i) { return h.GetKeyframeImage(i); };
  const TexturedMesh whole = ColorAndTexture(s.View(), s.cameras, fetch, o);
  StreamedTestMesh stream(s.vertices, s.faces, s.ids);
  const imr_mesh_stream raw = stream.Stream();
  const imr::sdk::MeshStream mesh(raw);
  StreamedVertexColours blocks(mesh, s.cameras, fetch, o);
  const std::size_t nv = s.vertices.size() / 3;
  std::vector<uint8_t> rgb(3 * nv, 0);
  constexpr std::size_t kBlockVertices = 257;
  for (std::size_t first = 0; first < nv; first += kBlockVertices)
    blocks.Colour(first, std::min(kBlockVertices, nv - first), &rgb[3 * first]);
  ASSERT_EQ(whole.vertex_rgb.size(), rgb.size());
  ASSERT_EQ(whole.vertex_seen.size(), nv);
  // Every vertex a keyframe sees has the whole mesh's colour; one none sees takes its neighbours'
  // within its block's piece (the whole mesh's can come from farther: here the street behind the
  // first keyframe, 40 m of ground no view sees, takes the colour of the nearest ground seen).
  std::size_t seen = 0, seen_same = 0, unseen_same = 0;
  for (std::size_t i = 0; i < nv; ++i) {
    const bool same = std::equal(&rgb[3 * i], &rgb[3 * i] + 3, &whole.vertex_rgb[3 * i]);
    if (whole.vertex_seen[i] == 1) ++seen, seen_same += same;
    else unseen_same += same;
  }
  EXPECT_GT(seen, nv / 3);
  EXPECT_EQ(seen_same, seen);
  const StreamedColourStats& st = blocks.stats();
  std::cout << "vertex colours in blocks: " << seen << " of " << nv << " vertices seen, all the same; "
            << unseen_same << " of the others the same; " << st.blocks << " blocks, pieces of "
            << st.max_piece_faces << " faces at most of " << s.faces.size() / 3 << "\n";
  EXPECT_EQ(host.Held(), 0);
}

// A 1.5 km road with a wall beside it and fins on the wall, seen by a camera driving along it
// every 5 m (each keyframe's image one flat colour): the blocks' colours are the whole mesh's, and
// a block needs only the road and keyframes within the colour reach (40 steps: 200 m) of it.
TEST(Texturing, VertexColoursInBlocksOfALongRoadNeedOnlyWhatIsNearThem) {
  constexpr double kLength = 1500.0, kStep = 5.0, kCellSize = 2.0;
  std::vector<double> vertices;
  std::vector<uint32_t> faces;
  // A grid from `o` along u (nu cells) and v (nv cells), counter-clockwise seen from u x v.
  auto grid = [&](const Vec3& o, const Vec3& u, const Vec3& v, int nu, int nv) {
    const auto base = static_cast<uint32_t>(vertices.size() / 3);
    for (int j = 0; j <= nv; ++j)
      for (int i = 0; i <= nu; ++i)
        for (int k = 0; k < 3; ++k) vertices.push_back(o[k] + i * u[k] + j * v[k]);
    for (int j = 0; j < nv; ++j)
      for (int i = 0; i < nu; ++i) {
        const uint32_t a = base + static_cast<uint32_t>(j * (nu + 1) + i), b = a + 1,
                       c = a + static_cast<uint32_t>(nu + 2), d = a + static_cast<uint32_t>(nu + 1);
        faces.insert(faces.end(), {a, b, c, a, c, d});
      }
  };
  const int cells = static_cast<int>(kLength / kCellSize);
  grid({-4, 0, 0}, {kCellSize, 0, 0}, {0, kCellSize, 0}, 4, cells);   // the road, facing up
  grid({-4, 0, 0}, {0, kCellSize, 0}, {0, 0, kCellSize}, cells, 3);   // the wall, facing +x
  for (double y = 30; y < kLength; y += 30)                             // fins facing -y
    grid({-4, y, 0}, {3, 0, 0}, {0, 0, 3}, 1, 1);
  // Faces along the road, vertices numbered as the faces first name them (a spool's order).
  std::vector<std::size_t> order(faces.size() / 3);
  std::iota(order.begin(), order.end(), 0);
  auto y_of = [&](std::size_t f) {
    return vertices[3 * faces[3 * f] + 1] + vertices[3 * faces[3 * f + 1] + 1] + vertices[3 * faces[3 * f + 2] + 1];
  };
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return y_of(a) < y_of(b); });
  std::vector<double> v2;
  std::vector<uint32_t> f2, index(vertices.size() / 3, UINT32_MAX);
  for (std::size_t f : order)
    for (int k = 0; k < 3; ++k) {
      uint32_t& i = index[faces[3 * f + static_cast<std::size_t>(k)]];
      if (i == UINT32_MAX) {
        i = static_cast<uint32_t>(v2.size() / 3);
        v2.insert(v2.end(), &vertices[3 * faces[3 * f + static_cast<std::size_t>(k)]],
                  &vertices[3 * faces[3 * f + static_cast<std::size_t>(k)]] + 3);
      }
      f2.push_back(i);
    }
  std::vector<imr_camera> cameras;
  std::vector<cv::Mat> images;
  for (double y = 0; y <= kLength; y += kStep) {
    cameras.push_back(AlongTheRoad(y, 100));
    const auto k = static_cast<int>(images.size());
    images.emplace_back(120, 160, CV_8UC3, cv::Scalar((k * 53) % 256, (k * 97) % 256, (k * 151) % 256));
  }
  TexturingOptions o;
  o.texture = false;
  FakeHost host(images);
  const imr::sdk::Host h(&host.services);
  const auto fetch = [&](uint64_t i) { return h.GetKeyframeImage(i); };
  const std::vector<int64_t> no_ids;
  const imr::sdk::MeshView view{{v2.data(), v2.size()}, {f2.data(), f2.size()}, {}, {}, {}};
  const TexturedMesh whole = ColorAndTexture(view, cameras, fetch, o);
  StreamedTestMesh stream(v2, f2, no_ids);
  const imr_mesh_stream raw = stream.Stream();
  const imr::sdk::MeshStream mesh(raw);
  StreamedVertexColours blocks(mesh, cameras, fetch, o);
  const std::size_t nv = v2.size() / 3, nf = f2.size() / 3;
  std::vector<uint8_t> rgb(3 * nv, 0);
  constexpr std::size_t kBlockVertices = 1000;
  for (std::size_t first = 0; first < nv; first += kBlockVertices)
    blocks.Colour(first, std::min(kBlockVertices, nv - first), &rgb[3 * first]);
  std::size_t same = 0;
  for (std::size_t i = 0; i < nv; ++i)
    same += std::equal(&rgb[3 * i], &rgb[3 * i] + 3, &whole.vertex_rgb[3 * i]);
  EXPECT_EQ(same, nv);
  const StreamedColourStats& st = blocks.stats();
  std::cout << "a long road: " << st.blocks << " blocks, pieces of " << st.max_piece_faces
            << " faces at most of " << nf << ", " << st.views / st.blocks << " of " << cameras.size()
            << " keyframes per block\n";
  EXPECT_LT(st.max_piece_faces, static_cast<int64_t>(nf) / 3);
  EXPECT_LT(st.views / st.blocks, static_cast<int64_t>(cameras.size()) / 3);
  EXPECT_EQ(host.Held(), 0);
}

// A camera creeping toward a wall 60 m ahead (keyframes 0.1 m apart: a colour reach of 4 m): no
// keyframe is within the reach of the wall, and the wall takes its colours from those beyond it
// rather than none.
TEST(Texturing, VerticesNoKeyframeWithinTheReachSeesTakeThoseBeyondIt) {
  std::vector<double> vertices;
  std::vector<uint32_t> faces;
  for (int j = 0; j <= 10; ++j)
    for (int i = 0; i <= 10; ++i) vertices.insert(vertices.end(), {-5.0 + i, 60.0, -2.0 + j});
  for (uint32_t j = 0; j < 10; ++j)
    for (uint32_t i = 0; i < 10; ++i) {
      const uint32_t a = j * 11 + i, b = a + 1, c = a + 12, d = a + 11;
      faces.insert(faces.end(), {a, b, c, a, c, d});  // facing -y, toward the cameras
    }
  std::vector<imr_camera> cameras;
  std::vector<cv::Mat> images;
  for (int k = 0; k < 10; ++k) {
    cameras.push_back(AlongTheRoad(0.1 * k, 400));
    images.emplace_back(120, 160, CV_8UC3, cv::Scalar(50, 100, 200));  // BGR
  }
  TexturingOptions o;
  o.texture = false;
  FakeHost host(images);
  const imr::sdk::Host h(&host.services);
  const imr::sdk::MeshView view{{vertices.data(), vertices.size()}, {faces.data(), faces.size()}, {}, {}, {}};
  const TexturedMesh m = ColorAndTexture(view, cameras, [&](uint64_t i) { return h.GetKeyframeImage(i); }, o);
  const std::size_t nv = vertices.size() / 3;
  EXPECT_EQ(std::count(m.vertex_seen.begin(), m.vertex_seen.end(), 2), static_cast<long>(nv));
  for (std::size_t i = 0; i < nv; ++i) {
    EXPECT_EQ(m.vertex_rgb[3 * i], 200) << i;
    EXPECT_EQ(m.vertex_rgb[3 * i + 1], 100) << i;
    EXPECT_EQ(m.vertex_rgb[3 * i + 2], 50) << i;
  }
}

TEST_F(TexturedFiles, OptionsTextureOffAndKeyframeStep) {
  const KnownScene& s = Scene();
  FakeHost plain(s.images);
  const fs::path glb = Export(&plain, {"glb"}, R"({"texture": false})")[0];
  ExpectValidGltf(glb);
  const json doc = LoadGltf(glb).doc;
  EXPECT_FALSE(doc.contains("images"));
  EXPECT_TRUE(doc["meshes"][0]["primitives"][0]["attributes"].contains("COLOR_0"));
  for (std::size_t k = 0; k < s.images.size(); ++k) EXPECT_EQ(plain.acquired[k], 1) << k;

  FakeHost step(s.images);
  Export(&step, {"glb"}, R"({"keyframe_step": 3})");
  for (std::size_t k = 0; k < s.images.size(); ++k)
    EXPECT_EQ(step.acquired[k] > 0, k % 3 == 0 || k + 1 == s.images.size()) << k;
}

// Engine-only inputs: no images, the points' own colours (e.g. COLMAP's) in PLY and glTF.
TEST_F(TexturedFiles, InputPointColoursWithoutImages) {
  const KnownScene& s = Scene();
  FakeHost host(s.images);
  std::vector<uint8_t> colors(s.vertices.size());
  for (std::size_t i = 0; i < colors.size(); ++i) colors[i] = static_cast<uint8_t>((i * 37) % 251);
  const std::vector<fs::path> files = Export(&host, {"ply", "glb"}, "{}", colors.data(), false);
  EXPECT_EQ(std::accumulate(host.acquired.begin(), host.acquired.end(), 0), 0);
  const std::vector<uint8_t> bytes = Slurp(files[0]);
  const std::size_t end = std::string(bytes.begin(), bytes.end()).find("end_header\n") + 11;
  const std::size_t record = 6 * 4 + 4 + 3;
  for (std::size_t i = 0; i < s.vertices.size() / 3; ++i) {
    const uint8_t* r = bytes.data() + end + i * record;
    const auto id = static_cast<std::size_t>(LoadLE<int32_t>(r + 24));
    ASSERT_TRUE(std::equal(r + 28, r + 31, colors.begin() + static_cast<std::ptrdiff_t>(3 * id))) << i;
  }
  ExpectValidGltf(files[1]);
  const json doc = LoadGltf(files[1]).doc;
  EXPECT_FALSE(doc.contains("images"));
  EXPECT_TRUE(doc["meshes"][0]["primitives"][0]["attributes"].contains("COLOR_0"));
}

}  // namespace
}  // namespace imr::exporter_assimp
