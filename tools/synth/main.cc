// imr-synth: renders the synthetic street scene into a KITTI odometry sequence (sequence.h).
#include <boost/program_options.hpp>
#include <csignal>
#include <cstdio>
#include <iostream>
#include <string>

#include "host/util/exit_status.h"
#include "tools/synth/sequence.h"

namespace po = boost::program_options;

namespace {

std::atomic<bool> g_cancel{false};
extern "C" void OnSignal(int) { g_cancel = true; }

constexpr const char* kUsage =
    "imr-synth --out DIR [options]\n"
    "Renders the synthetic street canyon of imr's engine tests (host/synthetic) into a KITTI\n"
    "odometry sequence: DIR/image_0/*.png (gray; --color: image_2/*.png, BGR, camera 2),\n"
    "calib.txt, times.txt, poses.txt, velodyne/*.bin, ground_truth/scene.{ply,json}.\n"
    "The folder is built as DIR.partial-<pid> and renamed to DIR when complete; a run that\n"
    "is killed leaves only that .partial folder (delete it). Same options, same bytes.\n"
    "Exit status: 0 done; 1 failed or interrupted; 64 bad usage or DIR exists (no --force), as\n"
    "imr's.\n";

}  // namespace

int main(int argc, char** argv) {
  imr::synth::SynthOptions o;
  std::string seed = "1";
  bool no_lidar = false, quiet = false;
  po::options_description desc("Options");
  desc.add_options()("help,h", "print this help")("out,o", po::value(&o.out),
                                                  "output folder (required; refused if it exists)")(
      "frames,n", po::value(&o.frames)->default_value(o.frames), "frames to render")(
      "seed", po::value(&seed)->default_value(seed), "scene and noise seed (non-negative integer)")(
      "width", po::value(&o.width)->default_value(o.width),
      "image width (intrinsics scale from KITTI's 1242)")(
      "height", po::value(&o.height)->default_value(o.height),
      "image height (intrinsics scale from KITTI's 375)")(
      "speed", po::value(&o.speed)->default_value(o.speed, "1.0"), "metres per frame")(
      "noise", po::value(&o.noise)->default_value(o.noise, "2.0"),
      "Gaussian image noise, grey levels (standard deviation)")(
      "color", po::bool_switch(&o.color), "colour images (image_2, BGR) instead of gray image_0")(
      "lidar-step", po::value(&o.lidar_step)->default_value(o.lidar_step, "0.2"),
      "Velodyne horizontal step, degrees")("no-lidar", po::bool_switch(&no_lidar),
                                           "write no velodyne/ scans")(
      "threads,j", po::value(&o.threads)->default_value(0), "worker threads (0: one per core)")(
      "force", po::bool_switch(&o.force), "replace an existing output folder")(
      "quiet,q", po::bool_switch(&quiet), "no progress lines")(
      "id-colors", po::bool_switch(&o.id_colors),
      "debug: pixel = index of the rect seen + 1 (BGR 24 bit with --color), 0 = sky; no "
      "shading, noise or anti-aliasing");
  po::variables_map vm;
  try {
    po::store(po::command_line_parser(argc, argv).options(desc).run(), vm);
    po::notify(vm);
  } catch (const po::error& e) {
    std::cerr << "imr-synth: " << e.what() << " (see --help)\n";
    return imr::kExitUsage;
  }
  if (vm.count("help")) {
    std::cout << kUsage << "\n" << desc << "\n";
    return 0;
  }
  if (!vm.count("out")) {
    std::cerr << "imr-synth: --out is required (see --help)\n";
    return imr::kExitUsage;
  }
  if (seed.empty() || seed.find_first_not_of("0123456789") != std::string::npos ||
      seed.size() > 20) {
    std::cerr << "imr-synth: --seed: expected a non-negative integer, got '" << seed << "'\n";
    return imr::kExitUsage;
  }
  try {
    o.seed = std::stoull(seed);
  } catch (const std::exception&) {
    std::cerr << "imr-synth: --seed: out of range: " << seed << "\n";
    return imr::kExitUsage;
  }
  o.lidar = !no_lidar;
  o.progress = !quiet;
  if (const std::string e = o.Check(); !e.empty()) {
    std::cerr << "imr-synth: " << e << "\n";
    return imr::kExitUsage;
  }

  std::signal(SIGINT, OnSignal);
  std::signal(SIGTERM, OnSignal);
  try {
    const imr::synth::SynthResult r = imr::synth::GenerateSequence(o, std::cout, &g_cancel);
    std::printf("imr-synth: %d frames, %dx%d %s, %.2f s, %.1f frames/s", r.frames, r.width,
                r.height, o.color ? "colour" : "gray", r.seconds, r.frames / r.seconds);
    if (o.lidar)
      std::printf(", %.0f lidar points/frame", static_cast<double>(r.lidar_points) / r.frames);
    std::printf(" -> %s\n", r.out.c_str());
    return 0;
  } catch (const imr::synth::OutputExistsError& e) {
    std::cerr << "imr-synth: " << e.what() << "\n";
    return imr::kExitUsage;
  } catch (const std::invalid_argument& e) {
    std::cerr << "imr-synth: " << e.what() << "\n";
    return imr::kExitUsage;
  } catch (const std::exception& e) {
    std::cerr << "imr-synth: " << e.what() << "\n";
    return imr::kExitFailed;
  }
}
