// `imr render`: the command line of host/render's RenderFiles.
#include "host/cli/command.h"
#include "host/render/render_files.h"
#include "host/util/exit_status.h"
#include "host/util/write_rule.h"

#include <charconv>
#include <cstdio>
#include <iostream>
#include <sstream>

namespace imr::cli {
namespace {

// A default as --help shows it: 0.6, not 0.59999999999999998.
std::string ShortNumber(double x) {
  char b[32];
  std::snprintf(b, sizeof b, "%g", x);
  return b;
}

namespace fs = std::filesystem;

const char* kSynopsis =
    "imr render MESH --sequence DIR --format kitti_odometry|kitti_raw|middlebury|slam_json|colmap|openmvg\n"
    "           [--camera K]\n"
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
    "direction unless --up gives it (it prints which). --format slam_json takes the cameras of a\n"
    "SLAM JSON stream (one frame per view, in order), colmap those of a COLMAP model folder and\n"
    "openmvg those of an sfm_data.json (one frame per posed view, by id); these draw on black\n"
    "(--no-image is implied).\n"
    "The PNG is written whole or not at all.\n"
    "Exit status: 0 written; 1 a file is missing or bad; 64 bad usage.\n";


// "0.5,1,-2" -> three numbers; false otherwise.
bool ParseVec3(const std::string& s, render::Vec3* out) {
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

int CmdRender(const std::vector<std::string>& args) {
  render::RenderOptions d;
  render::TopDownOptions td;
  po::options_description opts("imr render options");
  opts.add_options()(
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
  int status = kExitOk;
  if (!ParseCommand("render", std::string(kSynopsis) + "\n" + kNotes, opts, pos, args, &vm, &status))
    return status;
  auto usage = [](const std::string& what) {
    std::cerr << "imr render: " << what << " (imr render --help)\n";
    return kExitUsage;
  };

  render::RenderFilesRequest q;
  q.top_down = vm.count("top-down") > 0;
  const std::string mode = vm["mode"].as<std::string>();
  render::RenderOptions ro = q.top_down ? td.render : d;
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
  if (!q.top_down) ro.opacity = vm["opacity"].as<double>();
  if (const std::string p = ro.Check(); !p.empty()) return usage(p);

  const bool has_sequence = vm.count("sequence") > 0;
  if (has_sequence != (vm.count("format") > 0))
    return usage("--sequence and --format go together");
  if (!q.top_down && !has_sequence) return usage("give --sequence DIR --format F (or --top-down)");
  if (!q.top_down && !vm.count("frame")) return usage("give --frame N (the frame to draw into)");
  if (q.top_down && vm.count("frame")) return usage("--frame does not apply to --top-down");
  io::ImageSequenceOptions& so = q.sequence_options;
  if (vm.count("frames") && !io::ParseFrameSelection(vm["frames"].as<std::string>(), &so))
    return usage("--frames: expected FIRST[:COUNT[:STEP]], got '" + vm["frames"].as<std::string>() + "'");
  so.camera = vm["camera"].as<int>();
  if (has_sequence) {
    q.sequence = vm["sequence"].as<std::string>();
    q.format = vm["format"].as<std::string>();
    bool known = false;
    for (const char* f : render::kRenderSequenceFormats) known |= q.format == f;
    if (!known)
      return usage("--format: expected kitti_odometry, kitti_raw, middlebury, slam_json, colmap or "
                   "openmvg, got '" + q.format + "'");
    const bool model = q.format == "slam_json" || q.format == "colmap" || q.format == "openmvg";
    if ((q.format == "middlebury" || model) && !vm["camera"].defaulted())
      return usage("--camera does not apply to " + q.format + " (each view has its own camera)");
    if (model && vm.count("frames"))
      return usage("--frames does not apply to " + q.format + " (every view is a frame)");
  } else if (vm.count("frames") || !vm["camera"].defaulted()) {
    return usage("--frames and --camera need --sequence");
  }
  if (const std::string p = so.Check(); !p.empty()) return usage(p);
  q.keyframe_every = vm["keyframe-every"].as<int>();
  if (q.keyframe_every < 0) return usage("--keyframe-every must be >= 0");
  td.size = vm["size"].as<int>();
  td.render = ro;
  if (vm.count("up")) {
    render::Vec3 up{};
    if (!ParseVec3(vm["up"].as<std::string>(), &up))
      return usage("--up: expected X,Y,Z, got '" + vm["up"].as<std::string>() + "'");
    td.up = up;
  }
  if (q.top_down)
    if (const std::string p = td.Check(); !p.empty()) return usage(p);
  q.out = vm["out"].as<std::string>();
  if (q.out.extension() != ".png" && q.out.extension() != ".PNG")
    return usage("--out: the file must end in .png, got '" + q.out.string() + "'");
  q.mesh = vm["mesh"].as<std::string>();
  q.frame = vm.count("frame") ? vm["frame"].as<int>() : 0;
  q.no_image = vm.count("no-image") > 0;
  q.render = ro;
  q.top_down_options = td;
  NoteInput(q.mesh, "the mesh to draw");
  if (has_sequence) NoteInput(q.sequence, "the sequence (--sequence)");
  try {
    CheckWriteTarget(q.out);  // before the work: the rule refuses an input frame, a user's file
    std::cout << render::RenderFiles(q) << "\n";
    return kExitOk;
  } catch (const WriteRefused& e) {
    std::cerr << "imr render: " << e.what() << "\n";
    return kExitCantCreate;
  } catch (const render::FrameOutOfRange& e) {
    std::cerr << "imr render: " << e.what() << "\n";
    return kExitUsage;
  } catch (const std::exception& e) {
    std::cerr << "imr render: " << e.what() << "\n";
    return kExitFailed;
  }
}

}  // namespace

std::vector<Command> RenderCommands() {
  return {{"render", "render MESH",
           "draw a mesh into a camera of a sequence over its image (shaded and/or\n"
           "wireframe), or top-down with the camera path, as PNG",
           &CmdRender}};
}

}  // namespace imr::cli
