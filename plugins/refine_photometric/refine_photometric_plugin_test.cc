// org.imr.refine.photometric through its shared object, as the host drives it: a keyframe image
// the host cannot give fails the call naming it, or is left out with a warning (missing_image
// "skip"); the answer keeps the request's vertices; an input without images is refused; how deep a
// keyframe refines follows the pixels an edge spans there, not the edges between; remesh changes
// triangles at the final call only, and never in a run that writes its surface in parts.
#include "plugins/testing/plugin_fixture.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>
#include <string>
#include <vector>

namespace imr::testing {
namespace {

// Host services serving noise images of 64 x 48, except keyframe `broken`, which fails as a file
// that does not decode does.
struct FakeHost {
  uint64_t broken = UINT64_MAX;
  int images_read = 0;
  std::vector<std::string> warnings;
  std::vector<uint8_t> pixels;
  imr_host_services services{};

  FakeHost() {
    std::mt19937 rng(7);
    pixels.resize(64 * 48);
    for (uint8_t& p : pixels) p = static_cast<uint8_t>(rng() & 0xff);
    services.struct_size = sizeof(services);
    services.version = IMR_HOST_SERVICES_VERSION;
    services.host_data = this;
    services.log = [](void* self, int32_t level, const char* m) {
      if (level == IMR_LOG_WARNING) static_cast<FakeHost*>(self)->warnings.push_back(m);
    };
    services.progress = [](void*, double, const char*) {};
    services.is_cancelled = [](void*) -> int32_t { return 0; };
    services.keyframe_image = [](void* self, uint64_t index, imr_image_view* out, imr_error* e) -> imr_status {
      FakeHost* h = static_cast<FakeHost*>(self);
      ++h->images_read;
      if (index == h->broken) {
        // The host's words (host/plugin/keyframe_images.cc): the keyframe, its file, why.
        std::snprintf(e->message, sizeof(e->message),
                      "keyframe image %llu: /data/seq/image_2/%06llu.png: cannot decode",
                      static_cast<unsigned long long>(index), static_cast<unsigned long long>(index * 5));
        return IMR_ERROR;
      }
      *out = imr_image_view{sizeof(imr_image_view), 64, 48, 1, 64, h->pixels.data()};
      return IMR_OK;
    };
    services.release_keyframe_image = [](void*, uint64_t) {};
  }
};

// Looking down +z from (x, 0, -distance); at the defaults the 1 m square spans 20 pixels.
imr_camera Camera(double x, double distance = 5, double focal = 100) {
  imr_camera c{};
  const double K[9] = {focal, 0, 31.5, 0, focal, 23.5, 0, 0, 1};
  const double R[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  std::memcpy(c.K, K, sizeof(K));
  std::memcpy(c.R, R, sizeof(R));
  c.t[0] = -x, c.t[1] = 0, c.t[2] = distance;
  c.width = 64, c.height = 48;
  return c;
}

class PhotometricPlugin : public PluginFixture {
 protected:
  void SetUp() override { LoadPlugin(IMR_REFINE_PHOTOMETRIC_SO); }

  // One refine call on a 1 m square facing the cameras; the status and the message.
  imr_status Refine(const std::string& params, FakeHost* host, bool images, std::string* message,
                    uint64_t* vertex_count = nullptr, double distance = 5, double focal = 100) {
    imr::sdk::Instance inst(d_, params, &host->services);
    const double v[12] = {-0.5, -0.5, 0, 0.5, -0.5, 0, 0.5, 0.5, 0, -0.5, 0.5, 0};
    const uint32_t f[6] = {0, 2, 1, 0, 3, 2};  // normals toward -z, the cameras
    const int64_t ids[4] = {1, 2, 3, 4};
    const uint8_t flags[4] = {IMR_REFINE_VERTEX_CHANGED, IMR_REFINE_VERTEX_CHANGED,
                              IMR_REFINE_VERTEX_CHANGED, IMR_REFINE_VERTEX_CHANGED};
    const double spread = 10 * distance / focal;  // 10 pixels apart in the image
    const imr_camera cams[3] = {Camera(-spread, distance, focal), Camera(0.0, distance, focal),
                                Camera(spread, distance, focal)};
    imr_mesh_view mesh{};
    mesh.struct_size = sizeof(mesh);
    mesh.vertices = v, mesh.vertex_count = 4, mesh.faces = f, mesh.face_count = 2, mesh.point_ids = ids;
    imr_refine_request r{};
    r.mesh = &mesh, r.vertex_flags = flags, r.keyframes = cams, r.keyframe_count = 3;
    r.keyframe_images = images ? 1 : 0, r.final_call = 1;
    imr_refine_result out{};
    try {
      inst.Refine(&r, &out);
    } catch (const imr::sdk::PluginCallError& e) {
      *message = e.what();
      return e.status();
    }
    if (vertex_count != nullptr) *vertex_count = out.vertex_count;
    return IMR_OK;
  }
};

TEST_F(PhotometricPlugin, DescribesItselfAsAMeshRefiner) {
  EXPECT_EQ(imr::sdk::CheckDescriptor(d_), "");
  EXPECT_EQ(d_->kind, IMR_KIND_MESH_REFINER);
  EXPECT_STREQ(d_->id, "org.imr.refine.photometric");
  std::string message;
  EXPECT_EQ(CreateStatus(R"({"patch_size": 4})", &message), IMR_INVALID_ARGUMENT);
  EXPECT_NE(message.find("patch_size"), std::string::npos) << message;
  EXPECT_EQ(CreateStatus(R"({"missing_image": "ignore"})", &message), IMR_INVALID_ARGUMENT);
}

TEST_F(PhotometricPlugin, AnUnreadableImageFailsTheCallNamingIt) {
  FakeHost host;
  host.broken = 1;
  std::string message;
  EXPECT_EQ(Refine("{}", &host, true, &message), IMR_ERROR);
  EXPECT_NE(message.find("keyframe image 1: /data/seq/image_2/000005.png: cannot decode"),
            std::string::npos) << message;
  // Said once: the stage does not prefix the host's message again (issue 44).
  EXPECT_EQ(message.find("keyframe image"), message.rfind("keyframe image")) << message;
}

TEST_F(PhotometricPlugin, OrLeavesItOutWithAWarning) {
  FakeHost host;
  host.broken = 1;
  std::string message;
  uint64_t vertices = 0;
  // Patches that fit the 64 x 48 images: the keyframe left out is the only thing to say.
  EXPECT_EQ(Refine(R"({"missing_image": "skip", "patch_size": 3, "patch_pixels": 1})", &host, true,
                   &message, &vertices),
            IMR_OK) << message;
  EXPECT_EQ(vertices, 4u);
  ASSERT_EQ(host.warnings.size(), 1u);
  const std::string& w = host.warnings[0];
  EXPECT_NE(w.find("keyframe image 1: /data/seq/image_2/000005.png: cannot decode; that keyframe "
                   "is left out"), std::string::npos) << w;
  EXPECT_EQ(w.find("keyframe image"), w.rfind("keyframe image")) << w;
}

// A ring of close-up views around an object stands ~100 edges from it, a street camera refines
// ~40 edges deep: both see their surface at some tens of pixels per edge (min_edge_pixels 18).
TEST_F(PhotometricPlugin, HowDeepAKeyframeRefinesFollowsThePixelsAnEdgeSpans) {
  std::string message;
  FakeHost near;  // 5 m (5 edges), 20 pixels per edge
  ASSERT_EQ(Refine("{}", &near, true, &message), IMR_OK) << message;
  EXPECT_EQ(near.images_read, 3);
  FakeHost telephoto;  // 100 m (100 edges), 30 pixels per edge
  ASSERT_EQ(Refine("{}", &telephoto, true, &message, nullptr, 100, 3000), IMR_OK) << message;
  EXPECT_EQ(telephoto.images_read, 3);
  FakeHost coarse;  // 100 m, 3 pixels per edge: too coarse to compare
  ASSERT_EQ(Refine("{}", &coarse, true, &message, nullptr, 100, 300), IMR_OK) << message;
  EXPECT_EQ(coarse.images_read, 0);
  FakeHost limited;  // max_depth, in edges, still applies when a job sets it
  ASSERT_EQ(Refine(R"({"max_depth": 40})", &limited, true, &message, nullptr, 100, 3000), IMR_OK)
      << message;
  EXPECT_EQ(limited.images_read, 0);
  FakeHost unlimited;
  ASSERT_EQ(Refine(R"({"min_edge_pixels": 0})", &unlimited, true, &message, nullptr, 100, 300), IMR_OK)
      << message;
  EXPECT_EQ(unlimited.images_read, 3);
}

// Settings that leave nothing to compare, or nothing to move, are said at the final call, naming
// them (issue 44): the call used to answer with the surface unchanged, without a word.
TEST_F(PhotometricPlugin, SettingsThatExcludeEveryVertexAreSaid) {
  std::string message;
  FakeHost fits;  // 3-pixel patches on the 20-pixel square: compared, nothing to say
  ASSERT_EQ(Refine(R"({"patch_size": 3, "patch_pixels": 1})", &fits, true, &message), IMR_OK) << message;
  EXPECT_TRUE(fits.warnings.empty()) << fits.warnings[0];
  // Patches of 31 samples 20 pixels apart: 620 pixels, wider than the 64 x 48 images.
  FakeHost wide;
  ASSERT_EQ(Refine(R"({"patch_size": 31, "patch_pixels": 20})", &wide, true, &message), IMR_OK) << message;
  ASSERT_EQ(wide.warnings.size(), 1u);
  EXPECT_NE(wide.warnings[0].find("compared no patch"), std::string::npos) << wide.warnings[0];
  EXPECT_NE(wide.warnings[0].find("patch_size 31 x patch_pixels 20 = 620 pixels"), std::string::npos)
      << wide.warnings[0];
  // 100 m away at a focal of 300: 3 pixels per edge, under min_edge_pixels 18.
  FakeHost coarse;
  ASSERT_EQ(Refine("{}", &coarse, true, &message, nullptr, 100, 300), IMR_OK) << message;
  ASSERT_EQ(coarse.warnings.size(), 1u);
  EXPECT_NE(coarse.warnings[0].find("within their depth limit (max_depth 0 median edges, "
                                    "min_edge_pixels 18 pixels per median edge)"),
            std::string::npos) << coarse.warnings[0];
  // A grid of 36 vertices (4 pixels per edge) compared, no match can reach min_zncc 1.
  FakeHost strict;
  imr::sdk::Instance inst(
      d_, R"({"min_zncc": 1, "min_gain": 0, "patch_size": 3, "patch_pixels": 1, "min_edge_pixels": 0})",
      &strict.services);
  std::vector<double> v;
  std::vector<uint32_t> f;
  std::vector<int64_t> ids;
  constexpr int kSide = 6;
  for (int y = 0; y < kSide; ++y)
    for (int x = 0; x < kSide; ++x) {
      v.insert(v.end(), {-0.5 + x / (kSide - 1.0), -0.5 + y / (kSide - 1.0), 0.0});
      ids.push_back(static_cast<int64_t>(ids.size()) + 1);
    }
  for (uint32_t y = 0; y + 1 < kSide; ++y)
    for (uint32_t x = 0; x + 1 < kSide; ++x) {
      const uint32_t a = y * kSide + x, b = a + 1, c = a + kSide, d = c + 1;
      f.insert(f.end(), {a, d, b, a, c, d});  // normals toward -z, the cameras
    }
  const std::vector<uint8_t> flags(ids.size(), IMR_REFINE_VERTEX_CHANGED);
  const imr_camera cams[3] = {Camera(-0.5), Camera(0.0), Camera(0.5)};
  imr_mesh_view mesh{};
  mesh.struct_size = sizeof(mesh);
  mesh.vertices = v.data(), mesh.vertex_count = ids.size(), mesh.faces = f.data();
  mesh.face_count = f.size() / 3, mesh.point_ids = ids.data();
  imr_refine_request r{};
  r.mesh = &mesh, r.vertex_flags = flags.data(), r.keyframes = cams, r.keyframe_count = 3;
  r.keyframe_images = 1, r.final_call = 1;
  imr_refine_result out{};
  ASSERT_NO_THROW(inst.Refine(&r, &out));
  ASSERT_EQ(strict.warnings.size(), 1u);
  EXPECT_NE(strict.warnings[0].find("no vertex found a match"), std::string::npos) << strict.warnings[0];
  EXPECT_NE(strict.warnings[0].find("min_zncc 1"), std::string::npos) << strict.warnings[0];
}

// A 6 x 6 grid of a roof whose ridge runs along x = y, every cell cut across it (the diagonal
// b-c), refined with the vertices held within a millimetre (max_move): which faces come back.
struct RoofAnswer {
  bool faces_returned = false;
  double off_roof = 0.0;  // the largest distance of a face's centroid from the roof, metres
  std::vector<std::string> warnings;
};

RoofAnswer RefineRoof(const imr_plugin_descriptor* descriptor, const std::string& params, bool final_call,
                      bool first_fixed) {
  FakeHost host;
  imr::sdk::Instance inst(descriptor, params, &host.services);
  constexpr int kSide = 6;
  auto roof = [](double x, double y) { return -0.25 * std::abs(x - y); };
  std::vector<double> v;
  std::vector<uint32_t> f;
  std::vector<int64_t> ids;
  for (int y = 0; y < kSide; ++y)
    for (int x = 0; x < kSide; ++x) {
      const double X = -0.5 + x / (kSide - 1.0), Y = -0.5 + y / (kSide - 1.0);
      v.insert(v.end(), {X, Y, roof(X, Y)});
      ids.push_back(static_cast<int64_t>(ids.size()) + 1);
    }
  for (uint32_t y = 0; y + 1 < kSide; ++y)
    for (uint32_t x = 0; x + 1 < kSide; ++x) {
      const uint32_t a = y * kSide + x, b = a + 1, c = a + kSide, d = c + 1;
      f.insert(f.end(), {a, c, b, b, c, d});  // normals toward -z, the cameras
    }
  std::vector<uint8_t> flags(ids.size(), IMR_REFINE_VERTEX_CHANGED);
  if (first_fixed) flags[0] = IMR_REFINE_VERTEX_FIXED;
  const imr_camera cams[3] = {Camera(-0.5), Camera(0.0), Camera(0.5)};
  imr_mesh_view mesh{};
  mesh.struct_size = sizeof(mesh);
  mesh.vertices = v.data(), mesh.vertex_count = ids.size(), mesh.faces = f.data();
  mesh.face_count = f.size() / 3, mesh.point_ids = ids.data();
  imr_refine_request r{};
  r.mesh = &mesh, r.vertex_flags = flags.data(), r.keyframes = cams, r.keyframe_count = 3;
  r.keyframe_images = 1, r.final_call = final_call ? 1 : 0;
  imr_refine_result out{};
  inst.Refine(&r, &out);
  RoofAnswer answer;
  answer.warnings = host.warnings;
  answer.faces_returned = out.faces != nullptr;
  const uint32_t* faces = out.faces != nullptr ? out.faces : f.data();
  const uint64_t count = out.faces != nullptr ? out.face_count : f.size() / 3;
  EXPECT_EQ(out.vertex_count, ids.size());  // flips only: no vertex added
  for (uint64_t i = 0; i < count; ++i) {
    double c[3] = {0, 0, 0};
    for (int k = 0; k < 3; ++k)
      for (int j = 0; j < 3; ++j) c[j] += out.vertices[3 * faces[3 * i + k] + j] / 3.0;
    answer.off_roof = std::max(answer.off_roof, std::abs(c[2] - roof(c[0], c[1])));
  }
  return answer;
}

TEST_F(PhotometricPlugin, RemeshFlipsTheTrianglesBackOntoTheRoofAtTheFinalCall) {
  const std::string held = R"({"max_move": 0.001, "patch_size": 3, "patch_pixels": 1)";
  const RoofAnswer off = RefineRoof(d_, held + "}", true, false);
  EXPECT_FALSE(off.faces_returned);  // the default: the request's faces, the same bytes
  EXPECT_GT(off.off_roof, 0.02);
  const RoofAnswer on = RefineRoof(d_, held + R"(, "remesh": true})", true, false);
  EXPECT_TRUE(on.faces_returned);
  EXPECT_LT(on.off_roof, 0.002);  // the vertices moved at most 0.2 mm
  // During the run the host rebuilds the faces from the engine at the next call: none changed.
  const RoofAnswer during = RefineRoof(d_, held + R"(, "remesh": true})", false, false);
  EXPECT_FALSE(during.faces_returned);
  // A FIXED vertex: a run writing its surface in parts, whose faces are written already.
  const RoofAnswer parts = RefineRoof(d_, held + R"(, "remesh": true})", true, true);
  EXPECT_FALSE(parts.faces_returned);
  ASSERT_FALSE(parts.warnings.empty());
  EXPECT_NE(parts.warnings.back().find("remesh skipped"), std::string::npos) << parts.warnings.back();
  std::string message;
  EXPECT_EQ(CreateStatus(R"({"remesh_corner_deg": 0})", &message), IMR_INVALID_ARGUMENT);
  EXPECT_NE(message.find("remesh_corner_deg"), std::string::npos) << message;
}

TEST_F(PhotometricPlugin, AnInputWithoutImagesIsRefused) {
  FakeHost host;
  std::string message;
  EXPECT_EQ(Refine("{}", &host, false, &message), IMR_INVALID_ARGUMENT);
  EXPECT_NE(message.find("needs the keyframe images"), std::string::npos) << message;
}

}  // namespace
}  // namespace imr::testing
