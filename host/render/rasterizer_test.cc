// The rasteriser against projections worked out by hand: a vertex lands on its pixel with its
// depth, the nearer of two triangles wins whatever the drawing order, edges are drawn only where
// visible, triangles crossing the near plane are clipped, the top-down view shows the path with
// the direction of travel to the right.
#include "host/render/rasterizer.h"

#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>

namespace imr::render {
namespace {

// World: x forward, y left, z up (a vehicle's frame); the camera looks along +x from C.
// R maps world to camera: cam x = -world y, cam y = -world z, cam z = world x.
Camera TestCamera() {
  Camera c;
  c.width = 101;
  c.height = 81;
  c.fx = c.fy = 100.0;
  c.cx = 50.0;
  c.cy = 40.0;
  c.rotation = {{{0, -1, 0}, {0, 0, -1}, {1, 0, 0}}};
  // C = (1, 2, 1.5): t = -R C = -(-2, -1.5, 1).
  c.translation = {2.0, 1.5, -1.0};
  return c;
}

struct Mesh {
  std::vector<double> xyz;
  std::vector<uint32_t> faces;
  MeshRef ref() const { return MeshRefOf(xyz, faces); }
};

// Four triangles around `centre` in the plane x = centre.x, half-size h, normals toward -x
// (toward the camera).
Mesh FanFacingCamera(const Vec3& centre, double h) {
  Mesh m;
  m.xyz = {centre[0], centre[1], centre[2]};
  const double corners[4][2] = {{-h, -h}, {h, -h}, {h, h}, {-h, h}};  // (dy, dz)
  for (const auto& c : corners) m.xyz.insert(m.xyz.end(), {centre[0], centre[1] + c[0], centre[2] + c[1]});
  // Counter-clockwise seen from +x is (y, z) turning positive; from -x (the camera) we want the
  // normal (b - a) x (c - a) along -x: order corners clockwise in (y, z).
  for (uint32_t k = 0; k < 4; ++k) m.faces.insert(m.faces.end(), {0, 1 + (k + 1) % 4, 1 + k});
  return m;
}

std::size_t Pixel(const Rendering& r, int x, int y) {
  return static_cast<std::size_t>(y) * static_cast<std::size_t>(r.image.width) + static_cast<std::size_t>(x);
}

std::array<uint8_t, 3> Bgr(const Rendering& r, int x, int y) {
  const std::size_t i = 3 * Pixel(r, x, y);
  return {r.image.pixels[i], r.image.pixels[i + 1], r.image.pixels[i + 2]};
}

TEST(Rasterizer, VertexLandsOnItsHandProjectedPixelWithItsDepth) {
  // X = (6, 1.5, 1): x_cam = R X + t = (-1.5, -1, 6) + (2, 1.5, -1) = (0.5, 0.5, 5)
  // -> u = 100 * 0.5 / 5 + 50 = 60, v = 100 * 0.5 / 5 + 40 = 50.
  const Mesh m = FanFacingCamera({6.0, 1.5, 1.0}, 0.25);
  RenderOptions o;
  o.opacity = 1.0;
  const Rendering r = RenderIntoCamera(m.ref(), TestCamera(), nullptr, o);
  ASSERT_EQ(r.image.width, 101);
  ASSERT_EQ(r.image.height, 81);
  ASSERT_EQ(r.image.channels, 3);
  EXPECT_GE(r.face[Pixel(r, 60, 50)], 0);
  EXPECT_NEAR(r.depth[Pixel(r, 60, 50)], 5.0, 1e-5);
  // The fan spans 0.5 m at 5 m: 10 pixels, centred on (60, 50): u in [55, 65], v in [45, 55].
  EXPECT_GE(r.face[Pixel(r, 55, 45)], 0);  // top-left corner: on a top and a left edge
  EXPECT_GE(r.face[Pixel(r, 64, 54)], 0);
  EXPECT_EQ(r.face[Pixel(r, 54, 50)], -1);
  EXPECT_EQ(r.face[Pixel(r, 65, 50)], -1);  // right edge: not the fill rule's
  EXPECT_EQ(r.face[Pixel(r, 60, 44)], -1);
  EXPECT_EQ(r.face[Pixel(r, 60, 55)], -1);  // bottom edge: not the fill rule's
  EXPECT_EQ(r.faces_drawn, 4);
  // Facing the camera: the front colour (orange, BGR order), nearly fully lit.
  const auto c = Bgr(r, 60, 50);
  EXPECT_GT(c[2], c[0]);
  EXPECT_GT(c[2], 200);
  EXPECT_EQ(Bgr(r, 10, 10), (std::array<uint8_t, 3>{0, 0, 0}));
  EXPECT_TRUE(std::isinf(r.depth[Pixel(r, 10, 10)]));
  // 11 x 11 pixel centres in [55, 65] x [45, 55], minus the right and bottom edges.
  EXPECT_EQ(static_cast<long>(std::lround(r.Coverage() * 101 * 81)), 10 * 10);
}

TEST(Rasterizer, BackFacesGetTheBackColour) {
  Mesh m = FanFacingCamera({6.0, 1.5, 1.0}, 0.25);
  for (std::size_t f = 0; f < m.faces.size(); f += 3) std::swap(m.faces[f + 1], m.faces[f + 2]);
  RenderOptions o;
  o.opacity = 1.0;
  const Rendering r = RenderIntoCamera(m.ref(), TestCamera(), nullptr, o);
  const auto c = Bgr(r, 60, 50);
  EXPECT_GT(c[0], c[2]);  // blue
}

// The share of what the cameras see from behind: none for the fan facing them, all once it is
// flipped, and the visible half of a mix when a front fan hides a flipped one behind it.
TEST(Rasterizer, BackFacingShareCountsWhatTheCamerasSeeFromBehind) {
  Mesh m = FanFacingCamera({6.0, 1.5, 1.0}, 0.5);
  const std::vector<Camera> cameras = {TestCamera(), TestCamera()};
  BackFacing b = MeasureBackFacing(m.ref(), cameras, 0.5);
  EXPECT_EQ(b.views, 2);
  EXPECT_GT(b.pixels, 100);
  EXPECT_EQ(b.back_pixels, 0);
  for (std::size_t f = 0; f < m.faces.size(); f += 3) std::swap(m.faces[f + 1], m.faces[f + 2]);
  b = MeasureBackFacing(m.ref(), cameras, 1.0);
  EXPECT_EQ(b.back_pixels, b.pixels);
  EXPECT_DOUBLE_EQ(b.Share(), 1.0);
  // A small front-facing fan in front hides part of the flipped one behind it (10 of its 20
  // pixels across).
  const Mesh front = FanFacingCamera({4.0, 1.5, 1.0}, 0.15);
  Mesh both = m;
  const auto base = static_cast<uint32_t>(both.xyz.size() / 3);
  both.xyz.insert(both.xyz.end(), front.xyz.begin(), front.xyz.end());
  for (uint32_t i : front.faces) both.faces.push_back(base + i);
  b = MeasureBackFacing(both.ref(), cameras, 1.0);
  EXPECT_GT(b.pixels, 0);
  EXPECT_LT(b.Share(), 1.0);
  EXPECT_GT(b.Share(), 0.5);
  EXPECT_THROW(MeasureBackFacing(m.ref(), cameras, 0.0), std::invalid_argument);
}

// Per face: seen from behind by the cameras (visible and facing away, in more pixels than from
// the front); a face hidden behind a front-facing one is not, whichever way it faces; nor is a
// face out of every view, nor one a camera behind it sees from the front more than the first
// sees it from behind.
TEST(Rasterizer, FacesSeenFromBehindAreTheVisibleBackFaces) {
  const std::vector<Camera> cameras = {TestCamera()};
  const auto flipped_fan = [](const Vec3& centre, double h) {
    Mesh m = FanFacingCamera(centre, h);
    for (std::size_t f = 0; f < m.faces.size(); f += 3) std::swap(m.faces[f + 1], m.faces[f + 2]);
    return m;
  };
  const Mesh front = FanFacingCamera({4.0, 1.5, 1.0}, 0.5);   // 4 faces facing the camera
  const Mesh flipped = flipped_fan({8.0, 1.5, 1.0}, 0.2);     // behind it, wholly hidden
  const Mesh beside = flipped_fan({5.0, 2.9, 1.0}, 0.1);      // off to the side, in view
  const Mesh outside = flipped_fan({5.0, 40.0, 1.0}, 0.1);    // out of the view
  Mesh all;
  for (const Mesh* part : {&front, &flipped, &beside, &outside}) {
    const auto base = static_cast<uint32_t>(all.xyz.size() / 3);
    all.xyz.insert(all.xyz.end(), part->xyz.begin(), part->xyz.end());
    for (uint32_t i : part->faces) all.faces.push_back(base + i);
  }
  const std::vector<uint8_t> behind = FacesSeenFromBehind(all.ref(), cameras, 1.0);
  ASSERT_EQ(behind.size(), 16u);
  for (std::size_t f = 0; f < 16; ++f) EXPECT_EQ(behind[f], f >= 8 && f < 12 ? 1 : 0) << "face " << f;
  EXPECT_THROW(FacesSeenFromBehind(all.ref(), cameras, 1.5), std::invalid_argument);
  // A second camera on the far side (at x = 7, looking back along -x) sees the side fan from its
  // front, larger (it stands closer): the side fan stays.
  Camera back_camera = TestCamera();
  back_camera.rotation = {{{0, 1, 0}, {0, 0, -1}, {-1, 0, 0}}};
  // C = (7, 2, 1.5): t = -R C = -(2, -1.5, -7).
  back_camera.translation = {-2.0, 1.5, 7.0};
  const std::vector<uint8_t> both = FacesSeenFromBehind(all.ref(), {TestCamera(), back_camera}, 1.0);
  for (std::size_t f = 8; f < 12; ++f) EXPECT_EQ(both[f], 0) << "face " << f;
}

// The share over a mesh given in blocks (a long drive's spooled mesh): the whole mesh's figures,
// with triangles overlapping across blocks, exact ties (the same triangle twice, flipped: the
// first one drawn keeps its pixels) and triangles crossing the near plane.
TEST(Rasterizer, BackFacingInBlocksIsTheWholeMeshFigures) {
  Mesh m;
  uint32_t seed = 12345;
  auto uniform = [&seed](double lo, double hi) {  // a small LCG: the same soup everywhere
    seed = seed * 1664525u + 1013904223u;
    return lo + (hi - lo) * static_cast<double>(seed >> 8) / static_cast<double>(1u << 24);
  };
  for (uint32_t t = 0; t < 600; ++t) {
    const Vec3 c = {uniform(0.5, 12.0), uniform(-2.0, 6.0), uniform(-1.5, 4.5)};
    const auto base = static_cast<uint32_t>(m.xyz.size() / 3);
    for (int k = 0; k < 3; ++k)
      m.xyz.insert(m.xyz.end(), {c[0] + uniform(-1.0, 1.0), c[1] + uniform(-1.0, 1.0), c[2] + uniform(-1.0, 1.0)});
    m.faces.insert(m.faces.end(), {base, base + 1, base + 2});
    if (t % 7 == 0) m.faces.insert(m.faces.end(), {base, base + 2, base + 1});  // a tie, flipped
  }
  Camera other = TestCamera();
  other.translation = {1.0, 1.0, 0.5};
  const std::vector<Camera> cameras = {TestCamera(), other};
  for (const double scale : {1.0, 0.5}) {
    const BackFacing whole = MeasureBackFacing(m.ref(), cameras, scale);
    BackFacingInBlocks blocks(cameras, scale);
    int count = 0;
    for (std::size_t first = 0, n = 5; first < m.faces.size() / 3; first += n, n = 2 * n + 3, ++count) {
      const std::size_t k = std::min(n, m.faces.size() / 3 - first);
      Mesh block;  // its own vertices, numbered from 0
      for (std::size_t i = 3 * first; i < 3 * (first + k); ++i) {
        block.faces.push_back(static_cast<uint32_t>(block.xyz.size() / 3));
        const uint32_t v = m.faces[i];
        block.xyz.insert(block.xyz.end(), {m.xyz[3 * v], m.xyz[3 * v + 1], m.xyz[3 * v + 2]});
      }
      blocks.AddTriangles(block.ref());
    }
    ASSERT_GT(count, 4);
    const BackFacing b = blocks.Result();
    EXPECT_EQ(b.views, whole.views);
    EXPECT_EQ(b.pixels, whole.pixels) << scale;
    EXPECT_EQ(b.back_pixels, whole.back_pixels) << scale;
    EXPECT_GT(whole.back_pixels, 0);
    EXPECT_LT(whole.back_pixels, whole.pixels);
  }
  EXPECT_THROW(BackFacingInBlocks(cameras, 0.0), std::invalid_argument);
}

TEST(Rasterizer, NearTriangleHidesFarOneWhateverTheOrder) {
  const Mesh near_fan = FanFacingCamera({4.0, 1.5, 1.0}, 0.2);   // depth 3
  const Mesh far_fan = FanFacingCamera({9.0, 1.5, 1.0}, 1.0);    // depth 8, larger
  for (bool near_first : {true, false}) {
    Mesh both;
    const Mesh& a = near_first ? near_fan : far_fan;
    const Mesh& b = near_first ? far_fan : near_fan;
    both.xyz = a.xyz;
    both.xyz.insert(both.xyz.end(), b.xyz.begin(), b.xyz.end());
    both.faces = a.faces;
    for (uint32_t f : b.faces) both.faces.push_back(f + 5);
    const Rendering r = RenderIntoCamera(both.ref(), TestCamera(), nullptr, RenderOptions{});
    // Near: depth 3, offset 0.5 right and 0.5 down: u = 50 + 100 * 0.5 / 3 = 66.67, v = 56.67,
    // +-0.2 m = +-6.67 px. Far: depth 8, centre (56.25, 46.25), +-1 m = +-12.5 px.
    const int near_face_end = near_first ? 4 : 8;
    const int near_face_begin = near_face_end - 4;
    const int32_t f = r.face[Pixel(r, 67, 57)];
    EXPECT_GE(f, near_face_begin) << "near_first " << near_first;
    EXPECT_LT(f, near_face_end) << "near_first " << near_first;
    EXPECT_NEAR(r.depth[Pixel(r, 67, 57)], 3.0, 1e-5);
    // Outside the near fan, the far one: depth 8.
    EXPECT_NEAR(r.depth[Pixel(r, 50, 40)], 8.0, 1e-5);
  }
}

TEST(Rasterizer, WireframeDrawsVisibleEdgesOnly) {
  const Mesh m = FanFacingCamera({6.0, 1.5, 1.0}, 0.25);  // square u, v in [55, 65] x [45, 55]
  RenderOptions o;
  o.shaded = false;
  o.wireframe = true;
  const Rendering r = RenderIntoCamera(m.ref(), TestCamera(), nullptr, o);
  const std::array<uint8_t, 3> wire = {o.wire_color[2], o.wire_color[1], o.wire_color[0]};
  const std::array<uint8_t, 3> black = {0, 0, 0};
  // wire_width 2: pixels within 1 px of an edge. The outline, the diagonals, their crossing.
  EXPECT_EQ(Bgr(r, 55, 50), wire);   // on the left edge
  EXPECT_EQ(Bgr(r, 60, 54), wire);   // 1 px from the bottom edge v = 55
  EXPECT_EQ(Bgr(r, 60, 50), wire);   // the centre: every diagonal meets there
  EXPECT_EQ(Bgr(r, 57, 47), wire);   // on the diagonal (55, 45) - (65, 55)
  // 2 px from the top edge, 2.1 px from the diagonals: untouched, though covered.
  EXPECT_EQ(Bgr(r, 60, 47), black);
  EXPECT_GE(r.face[Pixel(r, 60, 47)], 0);

  // A small square nearer the camera, centred on (61, 50) at depth 2 (+-2 px), hides the far
  // fan's centre (60, 50); with thin lines (within 0.25 px) nothing of either is drawn there:
  // (60, 50) is 1 px from the near square's left edge and 0.7 px from its diagonals.
  RenderOptions thin = o;
  thin.wire_width = 0.5;
  EXPECT_EQ(Bgr(RenderIntoCamera(m.ref(), TestCamera(), nullptr, thin), 60, 50), wire);
  Mesh both = m;
  const Mesh front = FanFacingCamera({3.0, 1.78, 1.3}, 0.04);
  for (double x : front.xyz) both.xyz.push_back(x);
  for (uint32_t f : front.faces) both.faces.push_back(f + 5);
  const Rendering r2 = RenderIntoCamera(both.ref(), TestCamera(), nullptr, thin);
  EXPECT_GE(r2.face[Pixel(r2, 60, 50)], 4);
  EXPECT_NEAR(r2.depth[Pixel(r2, 60, 50)], 2.0, 1e-5);
  EXPECT_EQ(Bgr(r2, 60, 50), black);
  EXPECT_EQ(Bgr(r2, 59, 50), wire);  // the near square's own left edge
}

TEST(Rasterizer, BothModesShadeAndOutline) {
  const Mesh m = FanFacingCamera({6.0, 1.5, 1.0}, 0.25);
  RenderOptions o;
  o.wireframe = true;
  o.opacity = 1.0;
  const Rendering r = RenderIntoCamera(m.ref(), TestCamera(), nullptr, o);
  const std::array<uint8_t, 3> wire = {o.wire_color[2], o.wire_color[1], o.wire_color[0]};
  EXPECT_EQ(Bgr(r, 55, 50), wire);
  EXPECT_NE(Bgr(r, 60, 47), wire);
  EXPECT_GT(Bgr(r, 60, 47)[2], 200);
}

TEST(Rasterizer, BlendsOverTheImage) {
  const Mesh m = FanFacingCamera({6.0, 1.5, 1.0}, 0.25);
  io::Image gray;
  gray.width = 101;
  gray.height = 81;
  gray.channels = 1;
  gray.stride_bytes = 101;
  gray.pixels.assign(101 * 81, 100);
  RenderOptions o;
  o.opacity = 0.0;
  const Rendering r = RenderIntoCamera(m.ref(), TestCamera(), &gray, o);
  EXPECT_EQ(Bgr(r, 60, 50), (std::array<uint8_t, 3>{100, 100, 100}));
  o.opacity = 0.5;
  const Rendering half = RenderIntoCamera(m.ref(), TestCamera(), &gray, o);
  o.opacity = 1.0;
  const Rendering full = RenderIntoCamera(m.ref(), TestCamera(), &gray, o);
  for (int k = 0; k < 3; ++k)
    EXPECT_NEAR(Bgr(half, 60, 50)[k], 0.5 * Bgr(full, 60, 50)[k] + 50, 1.0);
  EXPECT_EQ(Bgr(half, 5, 5), (std::array<uint8_t, 3>{100, 100, 100}));
  gray.width = 100;
  EXPECT_THROW(RenderIntoCamera(m.ref(), TestCamera(), &gray, o), std::invalid_argument);
}

TEST(Rasterizer, TrianglesCrossingTheNearPlaneAreClipped) {
  // A floor below the camera from 0.5 m behind it to 20 m ahead: the image's lower part.
  Mesh floor;
  floor.xyz = {0.5, -10, 0, 21, -10, 0, 21, 10, 0, 0.5, 10, 0};
  floor.faces = {0, 1, 2, 0, 2, 3};  // normal +z (up, toward the camera above it)
  const Rendering r = RenderIntoCamera(floor.ref(), TestCamera(), nullptr, RenderOptions{});
  EXPECT_EQ(r.faces_clipped, 2);
  EXPECT_EQ(r.faces_behind, 0);
  // The horizon of a floor 1.5 m below: far edge at 20 m -> v = 40 + 100 * 1.5 / 20 = 47.5.
  EXPECT_EQ(r.face[Pixel(r, 50, 47)], -1);
  EXPECT_GE(r.face[Pixel(r, 50, 48)], 0);
  EXPECT_GE(r.face[Pixel(r, 50, 80)], 0);  // bottom row: 1.5 m below, 1.9 m ahead
  // Depth along the image's centre column: z = 100 * 1.5 / (v - 40).
  EXPECT_NEAR(r.depth[Pixel(r, 50, 70)], 100 * 1.5 / 30.0, 1e-4);
  // Wireframe: the far edge is drawn at the horizon, the diagonal (0.5, -10) - (21, 10) where
  // it is in view (at X = 11: u = 67.6, v = 55; it leaves the image at v = 59.4). Below it, where
  // the clipped triangles are, no edge of the mesh is in view, and none is made up (the cut is
  // no edge).
  RenderOptions w;
  w.shaded = false;
  w.wireframe = true;
  const Rendering rw = RenderIntoCamera(floor.ref(), TestCamera(), nullptr, w);
  EXPECT_GT(Bgr(rw, 50, 48)[1], 0);
  EXPECT_GT(Bgr(rw, 68, 55)[1], 0);
  int wire_low = 0;
  for (int y = 62; y < 81; ++y)
    for (int x = 0; x < 101; ++x) wire_low += Bgr(rw, x, y)[1] > 0 ? 1 : 0;
  EXPECT_EQ(wire_low, 0);

  // Wholly behind the camera: nothing drawn.
  Mesh behind;
  behind.xyz = {-1, 0, 0, -2, 1, 0, -2, 0, 1};
  behind.faces = {0, 1, 2};
  const Rendering rb = RenderIntoCamera(behind.ref(), TestCamera(), nullptr, RenderOptions{});
  EXPECT_EQ(rb.faces_behind, 1);
  EXPECT_EQ(rb.Coverage(), 0.0);
}

TEST(Rasterizer, TopDownShowsTheMeshAndThePathWithTravelToTheRight) {
  // A 40 x 10 m ground (z = 0) and cameras 1.5 m above it driving along +x.
  Mesh ground;
  ground.xyz = {0, -5, 0, 40, -5, 0, 40, 5, 0, 0, 5, 0};
  ground.faces = {0, 1, 2, 0, 2, 3};
  CameraPath path;
  for (int i = 0; i < 11; ++i) {
    Camera c = TestCamera();
    const Vec3 center = {2.0 + 3.0 * i, 0.0, 1.5};
    for (std::size_t r = 0; r < 3; ++r)
      c.translation[r] = -(c.rotation[r][0] * center[0] + c.rotation[r][1] * center[1] + c.rotation[r][2] * center[2]);
    path.cameras.push_back(c);
    path.keyframe.push_back(i % 5 == 0);
  }
  TopDownOptions o;
  o.size = 400;
  o.margin = 10;
  const TopDownRendering t = RenderTopDown(ground.ref(), path, o);
  const Rendering& r = t.rendering;
  // Up from the cameras: world +z. Travel (+x) to the right; left of travel (+y) up the image.
  EXPECT_NEAR(t.view.up[2], 1.0, 1e-12);
  EXPECT_NEAR(t.view.right[0], 1.0, 1e-12);
  EXPECT_NEAR(t.view.down[1], -1.0, 1e-12);
  // 40 m over 380 px: 9.5 px/m; the image is 400 x (10 * 9.5 + 20 + 1).
  EXPECT_NEAR(t.view.scale, 9.5, 1e-12);
  EXPECT_EQ(r.image.width, 401);
  EXPECT_EQ(r.image.height, 116);
  const auto first = t.view.ToPixel(path.cameras.front().Center());
  const auto last = t.view.ToPixel(path.cameras.back().Center());
  EXPECT_LT(first[0], last[0]);
  EXPECT_NEAR(first[1], last[1], 1e-9);
  // Path colour between two keyframes, keyframe colour on a keyframe, ground elsewhere.
  const auto mid = t.view.ToPixel({3.5, 0.0, 1.5});  // between cameras 0 and 1
  const std::array<uint8_t, 3> path_bgr = {o.path_color[2], o.path_color[1], o.path_color[0]};
  const std::array<uint8_t, 3> key_bgr = {o.keyframe_color[2], o.keyframe_color[1], o.keyframe_color[0]};
  EXPECT_EQ(Bgr(r, static_cast<int>(std::lround(mid[0])), static_cast<int>(std::lround(mid[1]))), path_bgr);
  const auto kf = t.view.ToPixel(path.cameras[5].Center());
  EXPECT_EQ(Bgr(r, static_cast<int>(std::lround(kf[0])), static_cast<int>(std::lround(kf[1]))), key_bgr);
  const auto ground_px = t.view.ToPixel({20.0, 3.0, 0.0});
  const int gx = static_cast<int>(std::lround(ground_px[0])), gy = static_cast<int>(std::lround(ground_px[1]));
  EXPECT_GE(r.face[Pixel(r, gx, gy)], 0);
  EXPECT_NEAR(r.depth[Pixel(r, gx, gy)], 0.0, 1e-6);  // the ground is the highest thing drawn
  EXPECT_GT(Bgr(r, gx, gy)[2], 150);                 // front colour: its normal points up
  EXPECT_EQ(Bgr(r, 2, 2), (std::array<uint8_t, 3>{255, 255, 255}));  // margin: background
  EXPECT_EQ(r.faces_drawn, 2);
}

TEST(Rasterizer, TopDownHidesLowerSurfacesUnderHigherOnes) {
  Mesh two;
  // A low square (z = 0) and a smaller high one (z = 3) over its middle.
  two.xyz = {0, 0, 0, 10, 0, 0, 10, 10, 0, 0, 10, 0, 4, 4, 3, 6, 4, 3, 6, 6, 3, 4, 6, 3};
  two.faces = {0, 1, 2, 0, 2, 3, 4, 5, 6, 4, 6, 7};
  TopDownOptions o;
  o.up = Vec3{0, 0, 1};
  o.size = 200;
  const TopDownRendering t = RenderTopDown(two.ref(), CameraPath{}, o);
  const auto p = t.view.ToPixel({5, 5, 0});
  const std::size_t centre = Pixel(t.rendering, static_cast<int>(std::lround(p[0])), static_cast<int>(std::lround(p[1])));
  EXPECT_GE(t.rendering.face[centre], 2);
  EXPECT_NEAR(t.rendering.depth[centre], 0.0, 1e-6);
  const auto q = t.view.ToPixel({1, 1, 0});
  const std::size_t corner = Pixel(t.rendering, static_cast<int>(std::lround(q[0])), static_cast<int>(std::lround(q[1])));
  EXPECT_LT(t.rendering.face[corner], 2);
  EXPECT_NEAR(t.rendering.depth[corner], 3.0, 1e-6);
}

TEST(Rasterizer, BadInputIsRefusedWithTheReason) {
  const Mesh m = FanFacingCamera({6.0, 1.5, 1.0}, 0.25);
  Camera c = TestCamera();
  c.fx = 0;
  EXPECT_THROW(RenderIntoCamera(m.ref(), c, nullptr, RenderOptions{}), std::invalid_argument);
  c = TestCamera();
  c.rotation[0] = {0, 1, 0};  // a reflection
  EXPECT_NE(c.Check().find("determinant -1"), std::string::npos) << c.Check();
  RenderOptions o;
  o.shaded = o.wireframe = false;
  EXPECT_NE(o.Check().find("nothing to draw"), std::string::npos);
  o = RenderOptions{};
  o.opacity = 2;
  EXPECT_NE(o.Check().find("opacity"), std::string::npos);
  Mesh bad = m;
  bad.faces[4] = 99;
  try {
    RenderIntoCamera(bad.ref(), TestCamera(), nullptr, RenderOptions{});
    FAIL() << "no throw";
  } catch (const std::invalid_argument& e) {
    EXPECT_STREQ(e.what(), "mesh: face 1 has vertex index 99 (5 vertices)");
  }
  bad = m;
  bad.xyz[4] = std::nan("");
  EXPECT_THROW(RenderTopDown(bad.ref(), CameraPath{}, TopDownOptions{}), std::invalid_argument);
  TopDownOptions t;
  t.size = 4;
  EXPECT_NE(t.Check().find("size"), std::string::npos);
}

}  // namespace
}  // namespace imr::render
