// `imr evaluate`: a mesh's accuracy against ground truth (host/eval).
#include "host/cli/command.h"
#include "host/eval/evaluate.h"
#include "host/util/atomic_file.h"
#include "host/util/exit_status.h"
#include "host/util/write_rule.h"

#include <charconv>
#include <iostream>
#include <sstream>

namespace imr::cli {
namespace {

namespace fs = std::filesystem;

const char* kEvaluateNotes =
    "MESH: .obj, .ply, .gltf or .glb (what the exporter writes), or ASCII .off (other meshers).\n"
    "Ground truth: --truth FILE, a point cloud (.ply without faces, .xyz/.txt/.asc: x y z per\n"
    "line, more columns ignored) or a reference mesh (sampled uniformly by area at\n"
    "--truth-density), or --velodyne-seq DIR alone: the Velodyne scans of a KITTI sequence\n"
    "(odometry: a folder with calib.txt; raw: a drive folder) placed in its world frame. With\n"
    "--velodyne-seq the ground truth (and the mesh samples of precision) are cropped to what the\n"
    "cameras saw: inside a camera's frustum and within --max-ray-length of its centre; without\n"
    "cameras nothing is cropped, and the report says so. Distances: ground truth -> nearest mesh\n"
    "triangle (the paper's mean; CloudCompare's cloud-to-mesh distance). Completeness(tau): share\n"
    "of ground-truth points within tau of the mesh; precision(tau): share of mesh area\n"
    "(--precision-samples samples) within tau of the ground truth. The JSON keys are documented\n"
    "in host/eval/README.md.\n"
    "Exit status: 0 evaluated; 1 a file is missing or bad, or nothing is left to evaluate;\n"
    "64 bad usage.\n";

// "0.05,0.1" -> {0.05, 0.1}; false on anything else.
bool ParseList(const std::string& s, std::vector<double>* out) {
  out->clear();
  std::stringstream ss(s);
  for (std::string item; std::getline(ss, item, ',');) {
    double v = 0.0;
    const auto r = std::from_chars(item.data(), item.data() + item.size(), v);
    if (r.ec != std::errc() || r.ptr != item.data() + item.size()) return false;
    out->push_back(v);
  }
  return !out->empty();
}

int CmdEvaluate(const std::vector<std::string>& args) {
  imr::eval::EvaluationOptions d;  // the defaults, for the help text
  po::options_description opts("imr evaluate options");
  opts.add_options()("mesh", po::value<std::string>()->required(), "mesh to evaluate")(
      "truth", po::value<std::string>()->value_name("FILE"),
      "ground truth: point cloud (.ply, .xyz) or reference mesh (.ply, .obj, .gltf, .glb, .off)")(
      "velodyne-seq", po::value<std::string>()->value_name("DIR"),
      "KITTI sequence: its cameras crop the ground truth; its Velodyne scans are the ground "
      "truth when --truth is not given")(
      "tau", po::value<std::string>()->default_value("0.05,0.1,0.2,0.5"),
      "thresholds of completeness and precision, comma-separated (scene units)")(
      "max-ray-length", po::value<double>()->default_value(d.max_ray_length),
      "crop: greatest distance from the camera that sees a point (<= 0: no limit)")(
      "no-crop", "do not crop to the cameras' view")(
      "frames", po::value<std::string>()->value_name("FIRST[:COUNT[:STEP]]"),
      "frames of --velodyne-seq to use (cameras and scans), as the job's input options")(
      "camera", po::value<int>()->default_value(-1), "KITTI camera 0..3 (-1: the lowest present)")(
      "scan-step", po::value<int>()->default_value(1),
      "Velodyne ground truth: every n-th frame's scan")(
      "truth-density", po::value<double>()->default_value(d.truth_density),
      "reference-mesh ground truth: samples per unit area")(
      "precision-samples", po::value<std::size_t>()->default_value(d.precision_samples),
      "mesh samples for precision")(
      "seed", po::value<uint64_t>()->default_value(d.seed), "seed of the samplings")(
      "per-point", po::value<std::string>()->value_name("FILE"),
      "write each ground-truth point's distance, one per line in input order (nan: cropped)")(
      "out,o", po::value<std::string>()->value_name("FILE"), "write the report as JSON")(
      "threads,j", po::value<int>()->default_value(0), "worker threads (0: all cores)");
  po::positional_options_description pos;
  pos.add("mesh", 1);
  po::variables_map vm;
  int status = kExitOk;
  const std::string synopsis =
      std::string("imr evaluate MESH (--truth FILE | --velodyne-seq DIR) [--tau LIST]\n"
                  "       [--max-ray-length L] [--out report.json] [--per-point FILE] [--threads N]\n\n") +
      kEvaluateNotes;
  if (!ParseCommand("evaluate", synopsis, opts, pos, args, &vm, &status)) return status;

  auto usage = [](const std::string& what) {
    std::cerr << "imr evaluate: " << what << " (imr evaluate --help)\n";
    return kExitUsage;
  };
  imr::eval::EvaluationInputs in;
  in.mesh = vm["mesh"].as<std::string>();
  if (vm.count("truth")) in.truth = vm["truth"].as<std::string>();
  if (vm.count("velodyne-seq")) in.sequence = vm["velodyne-seq"].as<std::string>();
  if (in.truth.empty() && in.sequence.empty())
    return usage("no ground truth: give --truth FILE or --velodyne-seq DIR");
  if (vm.count("frames") &&
      !imr::io::ParseFrameSelection(vm["frames"].as<std::string>(), &in.sequence_options))
    return usage("--frames: expected FIRST[:COUNT[:STEP]], got '" + vm["frames"].as<std::string>() + "'");
  if ((vm.count("frames") || !vm["camera"].defaulted()) && in.sequence.empty())
    return usage("--frames and --camera need --velodyne-seq");
  in.sequence_options.camera = vm["camera"].as<int>();
  const std::string problem = in.sequence_options.Check();
  if (!problem.empty()) return usage(problem);
  in.scan_step = vm["scan-step"].as<int>();
  if (in.scan_step < 1) return usage("--scan-step must be at least 1");
  if (vm.count("per-point")) in.per_point = vm["per-point"].as<std::string>();

  imr::eval::EvaluationOptions o;
  if (!ParseList(vm["tau"].as<std::string>(), &o.taus))
    return usage("--tau: expected numbers separated by commas, got '" + vm["tau"].as<std::string>() + "'");
  o.max_ray_length = vm["max-ray-length"].as<double>();
  o.crop = !vm.count("no-crop");
  o.truth_density = vm["truth-density"].as<double>();
  o.precision_samples = vm["precision-samples"].as<std::size_t>();
  o.seed = vm["seed"].as<uint64_t>();
  o.threads = vm["threads"].as<int>();
  if (const std::string p = o.Check(); !p.empty()) return usage(p);

  // Output folders first: a missing one should not cost a whole evaluation.
  const std::string out = vm.count("out") ? vm["out"].as<std::string>() : "";
  imr::NoteInput(in.mesh, "the mesh to evaluate");
  imr::NoteInput(in.truth, "the ground truth (--truth)");
  imr::NoteInput(in.sequence, "the KITTI sequence (--velodyne-seq)");
  for (const std::string& f : {out, in.per_point})
    if (!f.empty()) {
      imr::EnsureWritableDirectory(fs::absolute(f).parent_path());
      imr::CheckWriteTarget(f);
    }

  const nlohmann::json report = imr::eval::EvaluateFiles(in, o, &imr::eval::ReadKittiSequence);
  std::cout << imr::eval::FormatReport(report);
  if (!out.empty()) {
    imr::WriteFileAtomically(out, report.dump(2) + "\n");
    std::cout << "report written to " << out << "\n";
  }
  return kExitOk;
}

}  // namespace

std::vector<Command> EvaluateCommands() {
  return {{"evaluate", "evaluate MESH",
           "accuracy of a mesh against ground truth (points, a reference mesh or\n"
           "KITTI Velodyne scans): distances, completeness, precision, as JSON",
           &CmdEvaluate}};
}

}  // namespace imr::cli
