#include "host/render/render_cli.h"

#include "host/eval/mesh_io.h"
#include "host/io/image_io.h"
#include "host/io/image_sequence.h"
#include "host/io/slam_json.h"
#include "host/render/rasterizer.h"
#include "host/util/exit_status.h"

#include <boost/program_options.hpp>

#include <unistd.h>

#include <charconv>
#include <cstdio>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

namespace imr::render {
namespace {

// A default as --help shows it: 0.6, not 0.59999999999999998.
std::string ShortNumber(double x) {
  char b[32];
  std::snprintf(b, sizeof b, "%g", x);
  return b;
}

namespace fs = std::filesystem;
namespace po = boost::program_options;

using imr::kExitFailed;
using imr::kExitOk;
using imr::kExitUsage;

const char* kSynopsis =
    "imr render MESH --sequence DIR --format kitti_odometry|kitti_raw|middlebury|slam_json [--camera K]\n"
    "           [--frames FIRST[:COUNT[:STEP]]] --frame N [--mode shaded|wireframe|both]\n"
    "           [--opacity A] [--no-image] --out out.png\n"
    "imr render MESH --top-down [--sequence DIR --format F ...] [--keyframe-every N] [--size PX]\n"
    "           [--up X,Y,Z] [--mode shaded|wireframe|both] --out top.png\n";

const char* kNotes =
    "Draws MESH (.obj, .ply, .gltf, .glb) into frame N's camera over its image, with a z-buffer:\n"
    "faces shaded flat by their normal (orange: facing the camera, blue: seen from behind), edges\n"
    "in green (--mode wireframe or both; hidden edges are not drawn). Frames are numbered after\n"
    "--frames selects them, as in a job's input options. --top-down draws the whole mesh seen\n"
    "from above (orthographic; the direction of travel to the right), faces coloured by height\n"
    "(grey lowest, then blue, green, yellow, red highest), with the camera path: red line through\n"
    "the camera centres, blue discs at keyframes (every --keyframe-every frames, as the image\n"
    "front end picks them), a green ring at the first camera. Up is the cameras' mean up\n"
    "direction unless --up gives it. --format slam_json takes the cameras of a SLAM JSON stream\n"
    "(one frame per view, in order) and draws on black (--no-image is implied).\n"
    "The PNG is written whole or not at all.\n"
    "Exit status: 0 written; 1 a file is missing or bad; 64 bad usage.\n";

// "0.5,1,-2" -> three numbers; false otherwise.
bool ParseVec3(const std::string& s, Vec3* out) {
  std::stringstream ss(s);
  std::size_t n = 0;
  for (std::string item; std::getline(ss, item, ',');) {
    if (n == 3) return false;
    const auto r = std::from_chars(item.data(), item.data() + item.size(), (*out)[n]);
    if (r.ec != std::errc() || r.ptr != item.data() + item.size()) return false;
    ++n;
  }
  return n == 3;
}

Camera CameraOf(const io::CameraGeometry& g) {
  Camera c;
  const io::Intrinsics& k = g.intrinsics;
  c.width = k.width;
  c.height = k.height;
  c.fx = k.fx;
  c.fy = k.fy;
  c.cx = k.cx;
  c.cy = k.cy;
  c.rotation = g.rotation;
  c.translation = g.translation;
  return c;
}

// Writes the PNG under a temporary name beside `path` and renames it into place.
void WritePngAtomically(const fs::path& path, const io::Image& image) {
  const fs::path dir = path.has_parent_path() ? path.parent_path() : fs::path(".");
  const fs::path tmp = dir / ("." + path.stem().string() + ".partial-" + std::to_string(::getpid()) +
                              path.extension().string());
  try {
    io::WriteImage(tmp.string(), image);
    fs::rename(tmp, path);
  } catch (...) {
    std::error_code ec;
    fs::remove(tmp, ec);
    throw;
  }
}

std::string Percent(double share) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.1f%%", 100.0 * share);
  return buf;
}

// The cameras of a SLAM JSON stream as an image sequence without images: one frame per view, in
// the stream's order (every view its own keyframe, so each view's camera reaches the engine).
io::ImageSequence SlamJsonCameras(const std::string& file) {
  io::SlamJsonOptions o;
  o.min_views = 1;
  o.views_per_keyframe = 1;
  const std::unique_ptr<io::KeyframeSource> source = io::OpenSlamJson(file, o);
  io::ImageSequence seq;
  engine::KeyframeUpdate u;
  io::KeyframeInfo info;
  while (source->Next(&u, &info))
    for (const engine::Camera& c : u.cameras) {
      const io::CameraGeometry* g = source->Camera(c.id);
      if (g == nullptr || !g->has_intrinsics)
        throw std::runtime_error(file + ": view " + std::to_string(c.id) +
                                 " has no intrinsics: it cannot be drawn into");
      io::ImageFrame f;
      f.index = f.source_index = static_cast<int>(seq.frames.size());
      f.camera = *g;
      seq.frames.push_back(std::move(f));
    }
  return seq;
}

int Run(const std::vector<std::string>& args) {
  RenderOptions d;
  TopDownOptions td;
  po::options_description opts("imr render options");
  opts.add_options()("help,h", "show this help")(
      "mesh", po::value<std::string>()->required(), "mesh to draw (.obj, .ply, .gltf, .glb)")(
      "sequence", po::value<std::string>()->value_name("DIR"),
      "image sequence: a KITTI folder (odometry: with calib.txt; raw: a drive folder) or a "
      "Middlebury *_par.txt (or its folder)")(
      "format", po::value<std::string>()->value_name("FMT"),
      "the sequence's layout: kitti_odometry, kitti_raw, middlebury or slam_json (a stream file)")(
      "camera", po::value<int>()->default_value(-1), "KITTI camera 0..3 (-1: the lowest present)")(
      "frames", po::value<std::string>()->value_name("FIRST[:COUNT[:STEP]]"),
      "frames of the sequence to use, as the job's input options")(
      "frame", po::value<int>()->value_name("N"), "the frame to draw into (0-based, after --frames)")(
      "top-down", "draw the whole mesh from above, with the camera path")(
      "mode", po::value<std::string>()->default_value("shaded"), "shaded, wireframe or both")(
      "opacity", po::value<double>()->default_value(d.opacity, ShortNumber(d.opacity)),
      "mesh over the image: 0 = image only, 1 = mesh hides the image")(
      "no-image", "draw on black instead of the frame's image")(
      "keyframe-every", po::value<int>()->default_value(io::ImageSequenceOptions{}.keyframe_every),
      "top-down: mark every n-th frame as a keyframe (0: none)")(
      "size", po::value<int>()->default_value(td.size), "top-down: pixels along the longer side")(
      "up", po::value<std::string>()->value_name("X,Y,Z"),
      "top-down: the world's up direction (default: the cameras' mean up)")(
      "out,o", po::value<std::string>()->value_name("FILE")->required(), "the PNG to write");
  po::positional_options_description pos;
  pos.add("mesh", 1);
  po::variables_map vm;
  const std::string usage_text = std::string("Usage: ") + kSynopsis + "\n" + kNotes;
  try {
    po::store(po::command_line_parser(args).options(opts).positional(pos).run(), vm);
    if (vm.count("help")) {
      std::cout << usage_text << "\n" << opts << "\n";
      return kExitOk;
    }
    po::notify(vm);
  } catch (const po::error& e) {
    std::cerr << "imr render: " << e.what() << "\n\n" << usage_text << "\n" << opts << "\n";
    return kExitUsage;
  }
  auto usage = [](const std::string& what) {
    std::cerr << "imr render: " << what << " (imr render --help)\n";
    return kExitUsage;
  };

  const bool top_down = vm.count("top-down") > 0;
  const std::string mode = vm["mode"].as<std::string>();
  RenderOptions ro = top_down ? td.render : d;
  if (mode == "shaded") {
    ro.shaded = true;
    ro.wireframe = false;
  } else if (mode == "wireframe") {
    ro.shaded = false;
    ro.wireframe = true;
  } else if (mode == "both") {
    ro.shaded = ro.wireframe = true;
  } else {
    return usage("--mode: expected shaded, wireframe or both, got '" + mode + "'");
  }
  if (!top_down) ro.opacity = vm["opacity"].as<double>();
  if (const std::string p = ro.Check(); !p.empty()) return usage(p);

  const bool has_sequence = vm.count("sequence") > 0;
  if (has_sequence != (vm.count("format") > 0))
    return usage("--sequence and --format go together");
  if (!top_down && !has_sequence) return usage("give --sequence DIR --format F (or --top-down)");
  if (!top_down && !vm.count("frame")) return usage("give --frame N (the frame to draw into)");
  if (top_down && vm.count("frame")) return usage("--frame does not apply to --top-down");
  io::ImageSequenceOptions so;
  if (vm.count("frames") && !io::ParseFrameSelection(vm["frames"].as<std::string>(), &so))
    return usage("--frames: expected FIRST[:COUNT[:STEP]], got '" + vm["frames"].as<std::string>() + "'");
  so.camera = vm["camera"].as<int>();
  std::string format;
  if (has_sequence) {
    format = vm["format"].as<std::string>();
    if (format != "kitti_odometry" && format != "kitti_raw" && format != "middlebury" &&
        format != "slam_json")
      return usage("--format: expected kitti_odometry, kitti_raw, middlebury or slam_json, got '" +
                   format + "'");
    if ((format == "middlebury" || format == "slam_json") && !vm["camera"].defaulted())
      return usage("--camera does not apply to " + format + " (each view has its own camera)");
    if (format == "slam_json" && vm.count("frames"))
      return usage("--frames does not apply to slam_json (every view is a frame)");
  } else if (vm.count("frames") || !vm["camera"].defaulted()) {
    return usage("--frames and --camera need --sequence");
  }
  if (const std::string p = so.Check(); !p.empty()) return usage(p);
  const int keyframe_every = vm["keyframe-every"].as<int>();
  if (keyframe_every < 0) return usage("--keyframe-every must be >= 0");
  td.size = vm["size"].as<int>();
  td.render = ro;
  if (vm.count("up")) {
    Vec3 up{};
    if (!ParseVec3(vm["up"].as<std::string>(), &up))
      return usage("--up: expected X,Y,Z, got '" + vm["up"].as<std::string>() + "'");
    td.up = up;
  }
  if (top_down)
    if (const std::string p = td.Check(); !p.empty()) return usage(p);
  const fs::path out = vm["out"].as<std::string>();
  if (out.extension() != ".png" && out.extension() != ".PNG")
    return usage("--out: the file must end in .png, got '" + out.string() + "'");

  try {
    const fs::path out_dir = fs::absolute(out).parent_path();
    if (!fs::is_directory(out_dir)) throw std::runtime_error(out_dir.string() + ": no such folder (for --out)");
    io::ImageSequence seq;
    if (has_sequence) {
      const std::string root = vm["sequence"].as<std::string>();
      if (format == "middlebury") {
        seq = io::ReadMiddlebury(root, so);
      } else if (format == "slam_json") {
        seq = SlamJsonCameras(root);
      } else {
        seq = format == "kitti_odometry" ? io::ReadKittiOdometry(root, so) : io::ReadKittiRaw(root, so);
      }
    }
    const eval::TriangleMesh read = eval::ReadMesh(vm["mesh"].as<std::string>());
    std::vector<double> xyz;
    std::vector<uint32_t> faces;
    xyz.reserve(3 * read.vertices.size());
    for (const auto& v : read.vertices) xyz.insert(xyz.end(), v.begin(), v.end());
    faces.reserve(3 * read.triangles.size());
    for (const auto& t : read.triangles) faces.insert(faces.end(), t.begin(), t.end());
    const MeshRef mesh = MeshRefOf(xyz, faces);

    if (top_down) {
      CameraPath path;
      for (const io::ImageFrame& f : seq.frames) {
        path.cameras.push_back(CameraOf(f.camera));
        path.keyframe.push_back(keyframe_every > 0 && f.index % keyframe_every == 0);
      }
      const TopDownRendering r = RenderTopDown(mesh, path, td);
      WritePngAtomically(out, r.rendering.image);
      std::cout << out.string() << ": top-down " << r.rendering.image.width << "x"
                << r.rendering.image.height << ", " << r.rendering.faces_drawn << " of "
                << faces.size() / 3 << " triangles visible, " << path.cameras.size()
                << " cameras, " << r.view.scale << " px per unit\n";
      return kExitOk;
    }
    const int n = vm["frame"].as<int>();
    if (n < 0 || n >= static_cast<int>(seq.frames.size())) {
      std::cerr << "imr render: --frame " << n << ": the sequence has " << seq.frames.size()
                << " frames (0.." << seq.frames.size() - 1 << ")\n";
      return kExitUsage;
    }
    const io::ImageFrame& frame = seq.frames[static_cast<std::size_t>(n)];
    io::Image image;
    const bool no_image = vm.count("no-image") > 0 || format == "slam_json";
    if (!no_image) image = io::ReadImage(frame.image_path, seq.image_limits);
    const Camera camera = CameraOf(frame.camera);
    if (!no_image && (image.width != camera.width || image.height != camera.height))
      throw std::runtime_error(frame.image_path + ": image is " + std::to_string(image.width) + "x" +
                               std::to_string(image.height) + ", its camera " +
                               std::to_string(camera.width) + "x" + std::to_string(camera.height));
    const Rendering r = RenderIntoCamera(mesh, camera, no_image ? nullptr : &image, ro);
    WritePngAtomically(out, r.image);
    std::cout << out.string() << ": frame " << n << " (" << frame.image_path << "), "
              << r.image.width << "x" << r.image.height << ", " << r.faces_drawn << " of "
              << faces.size() / 3 << " triangles visible, " << Percent(r.Coverage())
              << " of the pixels covered\n";
    return kExitOk;
  } catch (const std::exception& e) {
    std::cerr << "imr render: " << e.what() << "\n";
    return kExitFailed;
  }
}

}  // namespace

int RenderMain(int argc, char** argv) {
  std::vector<std::string> args;
  for (int i = 1; i < argc; ++i) args.emplace_back(argv[i]);
  try {
    return Run(args);
  } catch (const std::exception& e) {
    std::cerr << "imr render: " << e.what() << "\n";
    return kExitFailed;
  }
}

}  // namespace imr::render
