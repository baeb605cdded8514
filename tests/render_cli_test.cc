// `imr render` end to end (the imr executable): a hand-made
// Middlebury sequence and mesh (a vertex lands on its hand-projected pixel in the written PNG,
// over the frame's image; wireframe; the top-down view with the path), usage errors, and the
// whole camera convention on imr-synth's street: its ground-truth mesh drawn into a frame's
// camera shows, pixel for pixel, the scene rect that the generator's ray caster saw there.
#include "host/eval/mesh_io.h"
#include "host/io/image_io.h"
#include "host/io/image_sequence.h"
#include "host/render/rasterizer.h"
#include "test_util.h"

#include <gtest/gtest.h>

#include <array>
#include <cstdio>
#include <string>
#include <vector>

namespace imr::render {
namespace {

namespace fs = std::filesystem;
using imr::testing::Quote;
using imr::testing::RunShell;
using imr::testing::ScratchDir;
using imr::testing::WriteText;

struct Result {
  int status = -1;
  std::string out, err;
};

// `imr render` on these arguments, with its output captured.
Result Render(const std::vector<std::string>& args) {
  std::string command = std::string(IMR_EXE) + " render";
  for (const std::string& a : args) command += " " + imr::testing::Quote(a);
  const imr::testing::CommandResult c = RunShell(command);
  return {c.status, c.out, c.err};
}

std::array<uint8_t, 3> Bgr(const io::Image& im, int x, int y) {
  const uint8_t* p = im.pixels.data() + y * im.stride_bytes + 3 * x;
  return {p[0], p[1], p[2]};
}

// Two views of 101 x 81 pixels, gray 100, of a world with x forward, y left, z up (camera 0 at
// (1, 2, 1.5) looking along +x; camera 1 one metre further), and a 0.5 m square facing camera 0
// at x = 6 centred on (6, 1.5, 1): 4 triangles around its centre vertex.
class RenderCli : public ::testing::Test {
 protected:
  RenderCli() : dir_("render-cli") {
    io::Image gray;
    gray.width = 101;
    gray.height = 81;
    gray.channels = 1;
    gray.stride_bytes = 101;
    gray.pixels.assign(101 * 81, 100);
    io::WriteImage((dir_ / "view0.png").string(), gray);
    io::WriteImage((dir_ / "view1.png").string(), gray);
    // name, K (row-major), R (world -> camera), t = -R C.
    WriteText(dir_ / "tiny_par.txt",
              "2\n"
              "view0.png 100 0 50 0 100 40 0 0 1  0 -1 0 0 0 -1 1 0 0  2 1.5 -1\n"
              "view1.png 100 0 50 0 100 40 0 0 1  0 -1 0 0 0 -1 1 0 0  2 1.5 -2\n");
    WriteText(dir_ / "square.obj",
              "v 6 1.5 1\nv 6 1.25 0.75\nv 6 1.75 0.75\nv 6 1.75 1.25\nv 6 1.25 1.25\n"
              "f 1 3 2\nf 1 4 3\nf 1 5 4\nf 1 2 5\n");
  }
  std::vector<std::string> Base() const {
    return {(dir_ / "square.obj").string(), "--sequence", (dir_ / "tiny_par.txt").string(),
            "--format", "middlebury"};
  }
  ScratchDir dir_;
};

TEST_F(RenderCli, VertexLandsOnItsPixelOverTheFramesImage) {
  // Centre vertex (6, 1.5, 1): x_cam = (0.5, 0.5, 5) -> (u, v) = (60, 50); the square spans
  // u, v in [55, 65] x [45, 55].
  std::vector<std::string> args = Base();
  const fs::path out = dir_ / "shaded.png";
  args.insert(args.end(), {"--frame", "0", "--opacity", "1", "--out", out.string()});
  const Result r = Render(args);
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.out.find("4 of 4 triangles visible"), std::string::npos) << r.out;
  const io::Image im = io::ReadImage(out.string());
  ASSERT_EQ(im.width, 101);
  ASSERT_EQ(im.height, 81);
  ASSERT_EQ(im.channels, 3);
  const auto c = Bgr(im, 60, 50);
  EXPECT_GT(c[2], 200);  // orange: front faces
  EXPECT_LT(c[0], 100);
  EXPECT_EQ(Bgr(im, 54, 50), (std::array<uint8_t, 3>{100, 100, 100}));  // the image around it
  EXPECT_EQ(Bgr(im, 60, 44), (std::array<uint8_t, 3>{100, 100, 100}));
  EXPECT_NE(Bgr(im, 55, 45), (std::array<uint8_t, 3>{100, 100, 100}));
  // No temporary left beside it.
  int files = 0;
  for (const auto& e : fs::directory_iterator(dir_.path())) files += e.path().extension() == ".png";
  EXPECT_EQ(files, 3);

  // Frame 1 is 1 m closer: depth 4, the square spans 12.5 px around (62.5, 52.5).
  args = Base();
  args.insert(args.end(), {"--frame", "1", "--opacity", "1", "--out", (dir_ / "f1.png").string()});
  ASSERT_EQ(Render(args).status, 0);
  const io::Image f1 = io::ReadImage((dir_ / "f1.png").string());
  EXPECT_GT(Bgr(f1, 68, 58)[2], 200);
  EXPECT_EQ(Bgr(f1, 70, 60), (std::array<uint8_t, 3>{100, 100, 100}));
}

TEST_F(RenderCli, SlamJsonCamerasOnBlack) {
  // The same two cameras as a SLAM JSON stream (rotation world -> camera, centre), the image
  // size on the views only (as some writers put it): frame 0 sees the centre vertex at (60, 50)
  // over black, no image read.
  WriteText(dir_ / "stream.json",
            R"({"slam_data_version": "0.3", "root_path": "/", "intrinsics": [{"intrinsicId": 0,
 "value": {"ptr_wrapper": {"data": {"focal_length": 100.0, "principal_point": [50.0, 40.0]}}}}],
 "views": [
 {"viewId": 0, "filename": "a.png", "width": 101, "height": 81, "id_intrinsic": 0,
  "extrinsic": {"center": [1, 2, 1.5], "rotation": [[0, -1, 0], [0, 0, -1], [1, 0, 0]]},
  "observations": []},
 {"viewId": 1, "filename": "b.png", "width": 101, "height": 81, "id_intrinsic": 0,
  "extrinsic": {"center": [2, 2, 1.5], "rotation": [[0, -1, 0], [0, 0, -1], [1, 0, 0]]},
  "observations": []}]})");
  const fs::path out = dir_ / "slam.png";
  const Result r = Render({(dir_ / "square.obj").string(), "--sequence",
                           (dir_ / "stream.json").string(), "--format", "slam_json", "--frame",
                           "0", "--out", out.string()});
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.out.find("4 of 4 triangles visible"), std::string::npos) << r.out;
  const io::Image im = io::ReadImage(out.string());
  ASSERT_EQ(im.width, 101);
  ASSERT_EQ(im.height, 81);
  EXPECT_GT(Bgr(im, 60, 50)[2], 100);  // orange, at the default opacity over black
  EXPECT_GT(Bgr(im, 60, 50)[2], Bgr(im, 60, 50)[0]);
  EXPECT_EQ(Bgr(im, 10, 10), (std::array<uint8_t, 3>{0, 0, 0}));
  // Frame 2 does not exist; --frames does not apply.
  EXPECT_EQ(Render({(dir_ / "square.obj").string(), "--sequence", (dir_ / "stream.json").string(),
                    "--format", "slam_json", "--frame", "2", "--out", out.string()})
                .status,
            64);
  EXPECT_EQ(Render({(dir_ / "square.obj").string(), "--sequence", (dir_ / "stream.json").string(),
                    "--format", "slam_json", "--frames", "0:1", "--frame", "0", "--out",
                    out.string()})
                .status,
            64);
}

TEST_F(RenderCli, ColmapModelCamerasOnBlackAndTheUpItUsed) {
  // The same two cameras as a COLMAP text model (issue 37: imr render could not draw COLMAP
  // models): q = (0.5, 0.5, -0.5, 0.5) is the rotation above, t = -R C.
  const fs::path model = dir_ / "colmap-model";
  WriteText(model / "cameras.txt", "# Camera list\n1 PINHOLE 101 81 100 100 50.5 40.5\n");
  WriteText(model / "images.txt",
            "# Image list\n1 0.5 0.5 -0.5 0.5 2 1.5 -1 1 a.png\n\n"
            "2 0.5 0.5 -0.5 0.5 2 2.5 -1 1 b.png\n\n");
  WriteText(model / "points3D.txt", "# 3D point list\n");
  const fs::path out = dir_ / "colmap.png";
  const Result r = Render({(dir_ / "square.obj").string(), "--sequence", model.string(), "--format",
                           "colmap", "--frame", "0", "--out", out.string()});
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.out.find("4 of 4 triangles visible"), std::string::npos) << r.out;
  const io::Image im = io::ReadImage(out.string());
  ASSERT_EQ(im.width, 101);
  ASSERT_EQ(im.height, 81);
  EXPECT_GT(Bgr(im, 60, 50)[2], 100);  // the square, orange over black
  EXPECT_EQ(Bgr(im, 10, 10), (std::array<uint8_t, 3>{0, 0, 0}));
  // From above: up from the cameras (their -y axes: +z here), and the output says which.
  WriteText(dir_ / "ground.obj", "v 0 0 0\nv 8 0 0\nv 8 4 0\nv 0 4 0\nf 1 2 3\nf 1 3 4\n");
  const Result top = Render({(dir_ / "ground.obj").string(), "--sequence", model.string(), "--format",
                             "colmap", "--top-down", "--size", "200", "--out", (dir_ / "ctop.png").string()});
  ASSERT_EQ(top.status, 0) << top.err;
  EXPECT_NE(top.out.find("2 cameras"), std::string::npos) << top.out;
  EXPECT_NE(top.out.find("up (0, 0, 1) (the cameras' mean up)"), std::string::npos) << top.out;
  EXPECT_EQ(Render({(dir_ / "square.obj").string(), "--sequence", model.string(), "--format", "colmap",
                    "--camera", "1", "--frame", "0", "--out", out.string()})
                .status,
            64);
}

TEST_F(RenderCli, WireframeAndBothModes) {
  std::vector<std::string> args = Base();
  args.insert(args.end(), {"--frame", "0", "--mode", "wireframe", "--out", (dir_ / "w.png").string()});
  ASSERT_EQ(Render(args).status, 0);
  const io::Image w = io::ReadImage((dir_ / "w.png").string());
  const RenderOptions d;
  const std::array<uint8_t, 3> wire = {d.wire_color[2], d.wire_color[1], d.wire_color[0]};
  EXPECT_EQ(Bgr(w, 55, 50), wire);  // left edge
  EXPECT_EQ(Bgr(w, 57, 47), wire);  // diagonal
  EXPECT_EQ(Bgr(w, 60, 47), (std::array<uint8_t, 3>{100, 100, 100}));  // inside, off the edges

  args = Base();
  args.insert(args.end(), {"--frame", "0", "--mode", "both", "--opacity", "1", "--out", (dir_ / "b.png").string()});
  ASSERT_EQ(Render(args).status, 0);
  const io::Image b = io::ReadImage((dir_ / "b.png").string());
  EXPECT_EQ(Bgr(b, 55, 50), wire);
  EXPECT_GT(Bgr(b, 60, 47)[2], 200);

  // --no-image: black around the mesh.
  args = Base();
  args.insert(args.end(), {"--frame", "0", "--no-image", "--out", (dir_ / "n.png").string()});
  ASSERT_EQ(Render(args).status, 0);
  EXPECT_EQ(Bgr(io::ReadImage((dir_ / "n.png").string()), 5, 5), (std::array<uint8_t, 3>{0, 0, 0}));
}

TEST_F(RenderCli, TopDownShowsThePath) {
  // The square is vertical: from above it has no area. A ground (normal up) under the cameras.
  WriteText(dir_ / "ground.obj", "v 0 0 0\nv 8 0 0\nv 8 4 0\nv 0 4 0\nf 1 2 3\nf 1 3 4\n");
  std::vector<std::string> args = Base();
  args[0] = (dir_ / "ground.obj").string();
  args.insert(args.end(), {"--top-down", "--size", "300", "--keyframe-every", "1", "--out", (dir_ / "top.png").string()});
  const Result r = Render(args);
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.out.find("2 cameras"), std::string::npos) << r.out;
  const io::Image im = io::ReadImage((dir_ / "top.png").string());
  const TopDownOptions d;
  int path = 0, keyframe = 0, mesh = 0;
  for (int y = 0; y < im.height; ++y)
    for (int x = 0; x < im.width; ++x) {
      const auto c = Bgr(im, x, y);
      path += c == std::array<uint8_t, 3>{d.path_color[2], d.path_color[1], d.path_color[0]};
      keyframe += c == std::array<uint8_t, 3>{d.keyframe_color[2], d.keyframe_color[1], d.keyframe_color[0]};
      mesh += c != std::array<uint8_t, 3>{255, 255, 255} &&
              c != std::array<uint8_t, 3>{d.path_color[2], d.path_color[1], d.path_color[0]} &&
              c != std::array<uint8_t, 3>{d.keyframe_color[2], d.keyframe_color[1], d.keyframe_color[0]} &&
              c != std::array<uint8_t, 3>{d.start_color[2], d.start_color[1], d.start_color[0]};
    }
  EXPECT_GT(path, 0);
  EXPECT_GT(keyframe, 10);
  EXPECT_GT(mesh, 200 * 100);  // the ground: 8 x 4 m at 31.5 px/m, less the path drawn over it
}

TEST_F(RenderCli, UsageAndFileErrors) {
  auto with = [&](std::vector<std::string> extra) {
    std::vector<std::string> a = Base();
    a.insert(a.end(), extra.begin(), extra.end());
    return Render(a);
  };
  const std::string out = (dir_ / "x.png").string();
  Result r = with({"--frame", "2", "--out", out});
  EXPECT_EQ(r.status, 64);
  EXPECT_NE(r.err.find("--frame 2: the sequence has 2 frames (0..1)"), std::string::npos) << r.err;
  r = with({"--frame", "0", "--mode", "solid", "--out", out});
  EXPECT_EQ(r.status, 64);
  EXPECT_NE(r.err.find("--mode: expected shaded, wireframe or both, got 'solid'"), std::string::npos);
  r = with({"--out", out});
  EXPECT_EQ(r.status, 64);
  EXPECT_NE(r.err.find("give --frame N"), std::string::npos) << r.err;
  r = with({"--frame", "0", "--out", (dir_ / "x.jpg").string()});
  EXPECT_EQ(r.status, 64);
  r = with({"--frame", "0", "--camera", "2", "--out", out});
  EXPECT_EQ(r.status, 64);
  EXPECT_NE(r.err.find("--camera does not apply to middlebury"), std::string::npos) << r.err;
  r = with({"--frame", "0", "--out", (dir_ / "no" / "x.png").string()});
  EXPECT_EQ(r.status, 1);
  EXPECT_NE(r.err.find("no such folder"), std::string::npos) << r.err;
  r = Render({(dir_ / "missing.ply").string(), "--sequence", (dir_ / "tiny_par.txt").string(),
              "--format", "middlebury", "--frame", "0", "--out", out});
  EXPECT_EQ(r.status, 1);
  EXPECT_NE(r.err.find("missing.ply"), std::string::npos) << r.err;
  r = Render({(dir_ / "square.obj").string(), "--frame", "0", "--out", out});
  EXPECT_EQ(r.status, 64);
  r = Render({"--help"});
  EXPECT_EQ(r.status, 0);
  EXPECT_NE(r.out.find("imr render MESH --sequence DIR"), std::string::npos);
  EXPECT_FALSE(fs::exists(out));
}

// imr-synth's street: ground_truth/scene.ply (faces 2i, 2i+1 = scene rect i, in the poses'
// world frame) drawn into frame k's camera must show, at every pixel, the rect the generator's
// own ray caster hit through that pixel's centre (its --id-colors images: B + 256 G + 65536 R =
// rect + 1, 0 = sky). This checks the whole chain: KITTI calibration and poses as the reader
// converts them, pixel centres at integers, R world -> camera, the depth test.
TEST(RenderSynth, GroundTruthMeshCoversExactlyWhatTheGeneratorSaw) {
#ifndef IMR_SYNTH_EXE
  GTEST_SKIP() << "imr-synth is not part of this build";
#else
  ScratchDir dir("render-synth");
  const fs::path seq = dir / "street";
  const auto gen = RunShell(std::string(IMR_SYNTH_EXE) + " --out " + Quote(seq.string()) +
                            " --frames 12 --width 414 --height 125 --no-lidar --id-colors --color -q");
  ASSERT_EQ(gen.status, 0) << gen.err;
  const io::ImageSequence s = io::ReadKittiOdometry(seq.string(), io::ImageSequenceOptions{});
  ASSERT_EQ(s.frames.size(), 12u);
  const eval::TriangleMesh truth = eval::ReadMesh(seq / "ground_truth" / "scene.ply");
  std::vector<double> xyz;
  std::vector<uint32_t> faces;
  for (const auto& v : truth.vertices) xyz.insert(xyz.end(), v.begin(), v.end());
  for (const auto& t : truth.triangles) faces.insert(faces.end(), t.begin(), t.end());
  for (int k : {0, 5, 11}) {
    const io::ImageFrame& f = s.frames[static_cast<std::size_t>(k)];
    const io::Image ids = io::ReadImage(f.image_path);
    Camera cam;
    cam.width = f.camera.intrinsics.width;
    cam.height = f.camera.intrinsics.height;
    cam.fx = f.camera.intrinsics.fx;
    cam.fy = f.camera.intrinsics.fy;
    cam.cx = f.camera.intrinsics.cx;
    cam.cy = f.camera.intrinsics.cy;
    cam.rotation = f.camera.rotation;
    cam.translation = f.camera.translation;
    const Rendering r = RenderIntoCamera(MeshRefOf(xyz, faces), cam, nullptr, RenderOptions{});
    ASSERT_EQ(ids.width, r.image.width);
    ASSERT_EQ(ids.height, r.image.height);
    int64_t same = 0, sky = 0, covered_sky = 0, total = 0;
    for (int y = 0; y < ids.height; ++y)
      for (int x = 0; x < ids.width; ++x) {
        const auto c = Bgr(ids, x, y);
        const int64_t id = c[0] + 256 * c[1] + 65536 * c[2];
        const int32_t face = r.face[static_cast<std::size_t>(y * ids.width + x)];
        const int64_t drawn = face < 0 ? 0 : face / 2 + 1;
        same += drawn == id;
        sky += id == 0;
        covered_sky += id == 0 && face >= 0;
        ++total;
      }
    // Pixel centres within float rounding of a rect's edge may go either way.
    EXPECT_GE(static_cast<double>(same) / static_cast<double>(total), 0.998)
        << "frame " << k << ": " << total - same << " of " << total << " pixels differ";
    EXPECT_GT(sky, 0) << "frame " << k;
    EXPECT_LT(covered_sky, total / 1000) << "frame " << k;
  }
  // The CLI over the same frame: the mesh drawn on black covers every non-sky pixel.
  const fs::path out = dir / "frame5.png";
  const Result cli = Render({(seq / "ground_truth" / "scene.ply").string(), "--sequence", seq.string(),
                             "--format", "kitti_odometry", "--frame", "5", "--no-image", "--out",
                             out.string()});
  ASSERT_EQ(cli.status, 0) << cli.err;
  const io::Image drawn = io::ReadImage(out.string());
  const io::Image ids = io::ReadImage(s.frames[5].image_path);
  int64_t agree = 0;
  for (int y = 0; y < ids.height; ++y)
    for (int x = 0; x < ids.width; ++x)
      agree += (Bgr(ids, x, y) == std::array<uint8_t, 3>{0, 0, 0}) ==
               (Bgr(drawn, x, y) == std::array<uint8_t, 3>{0, 0, 0});
  EXPECT_GE(static_cast<double>(agree) / (ids.width * ids.height), 0.998);
#endif
}

}  // namespace
}  // namespace imr::render
