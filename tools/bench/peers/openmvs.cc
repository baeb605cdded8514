#include "tools/bench/peers/openmvs.h"

#include <algorithm>
#include <cstdint>
#include <fstream>
#include <set>
#include <stdexcept>
#include <system_error>

#include "host/eval/mesh_io.h"
#include "host/io/colmap_model.h"
#include "tools/bench/common/subprocess.h"

namespace imr::bench {

namespace fs = std::filesystem;

// OpenMVS takes every core: below the other work on a shared machine. nice execs the program, so
// wait4's peak RSS is still the program's own.
constexpr const char* kNice = "/usr/bin/nice";

std::string PrepareOpenMvsColmap(const fs::path& model, const std::vector<fs::path>& image_dirs,
                                 const fs::path& out, int keyframe_every) {
  std::error_code ec;
  fs::remove_all(out / "sparse", ec);
  fs::remove_all(out / "images", ec);
  fs::create_directories(out / "sparse", ec);
  fs::create_directories(out / "images", ec);
  if (ec) return "cannot create " + (out / "images").string() + ": " + ec.message();
  try {
    io::ColmapModel m = io::ReadColmapText(model);
    // Cameras: PINHOLE fx fy cx cy.
    for (io::ColmapModel::Camera& c : m.cameras) {
      if (c.model == "SIMPLE_PINHOLE" && c.params.size() == 3)
        c.model = "PINHOLE", c.params = {c.params[0], c.params[0], c.params[1], c.params[2]};
      else if (c.model != "PINHOLE")
        return "camera " + std::to_string(c.id) + " is " + c.model +
               ": OpenMVS's InterfaceCOLMAP takes undistorted PINHOLE cameras only";
    }
    // Images: by id, the kept ones' id + 1, each linked from the first folder that has it.
    std::sort(m.images.begin(), m.images.end(),
              [](const auto& a, const auto& b) { return a.id < b.id; });
    std::set<uint32_t> kept;
    std::vector<io::ColmapModel::Image> images;
    for (std::size_t k = 0; k < m.images.size(); ++k) {
      if (keyframe_every > 1 && k % static_cast<std::size_t>(keyframe_every) != 0 &&
          k + 1 != m.images.size())
        continue;
      io::ColmapModel::Image& im = m.images[k];
      kept.insert(im.id);
      fs::path found;
      for (const fs::path& d : image_dirs)
        if (fs::is_regular_file(d / im.name, ec)) {
          found = fs::absolute(d / im.name, ec);
          break;
        }
      if (found.empty()) return "image " + im.name + " is in none of the image folders";
      fs::create_directories((out / "images" / im.name).parent_path(), ec);
      fs::create_symlink(found, out / "images" / im.name, ec);
      if (ec) return "cannot link " + (out / "images" / im.name).string() + ": " + ec.message();
      ++im.id;
      images.push_back(std::move(im));
    }
    m.images = std::move(images);
    // Points: the kept images' track entries, their ids + 1; a point with none goes
    // (InterfaceCOLMAP stops reading at a point without views).
    std::vector<io::ColmapModel::Point3D> points;
    for (io::ColmapModel::Point3D& p : m.points) {
      std::vector<io::ColmapModel::TrackElement> track;
      for (io::ColmapModel::TrackElement e : p.track)
        if (kept.count(e.image_id)) ++e.image_id, track.push_back(e);
      if (track.empty()) continue;
      p.track = std::move(track);
      points.push_back(std::move(p));
    }
    m.points = std::move(points);
    io::WriteColmapText(m, out / "sparse");
  } catch (const std::exception& e) {
    return e.what();
  }
  return "";
}

void WriteOpenMvsPly(const fs::path& in, const fs::path& out) {
  const eval::TriangleMesh m = eval::ReadMesh(in);
  std::ofstream o(out, std::ios::binary);
  o << "ply\nformat binary_little_endian 1.0\nelement vertex " << m.vertices.size()
    << "\nproperty float x\nproperty float y\nproperty float z\nelement face " << m.triangles.size()
    << "\nproperty list uchar uint vertex_indices\nend_header\n";
  for (const auto& v : m.vertices) {
    const float xyz[3] = {static_cast<float>(v[0]), static_cast<float>(v[1]), static_cast<float>(v[2])};
    o.write(reinterpret_cast<const char*>(xyz), sizeof(xyz));
  }
  for (const auto& t : m.triangles) {
    const uint8_t n = 3;
    o.write(reinterpret_cast<const char*>(&n), 1);
    o.write(reinterpret_cast<const char*>(t.data()), 3 * sizeof(uint32_t));
  }
  o.close();
  if (!o) throw std::runtime_error(out.string() + ": cannot write");
}

OpenMvsResult RunOpenMvs(const fs::path& bin_dir, const fs::path& work, const fs::path& mesh,
                         const std::vector<std::string>& extra_args, double timeout_seconds) {
  OpenMvsResult r;
  std::error_code ec;
  const fs::path log = work / "openmvs.log";
  fs::remove(log, ec);
  fs::remove(work / "refined.ply", ec);
  const std::string interface = (fs::absolute(bin_dir, ec) / "InterfaceCOLMAP").string();
  const std::string refine = (fs::absolute(bin_dir, ec) / "RefineMesh").string();
  const ProcessResult a =
      RunProcess({kNice, "-n", "10", interface, "-i", fs::absolute(work, ec).string(), "-o", "scene.mvs",
                  "--image-folder", "images/"},
                 work, log, timeout_seconds);
  r.interface_seconds = a.seconds;
  r.peak_rss_mb = static_cast<double>(a.peak_rss_kb) / 1024.0;
  if (!a.ok() || !fs::is_regular_file(work / "scene.mvs", ec)) {
    r.error = "InterfaceCOLMAP " + (a.ok() ? std::string("wrote no scene.mvs") : a.error) +
              " (log: " + log.string() + ")";
    return r;
  }
  std::vector<std::string> argv = {kNice, "-n", "10", refine, "scene.mvs", "--mesh-file",
                                   fs::absolute(mesh, ec).string(), "-o", "refined.mvs"};
  argv.insert(argv.end(), extra_args.begin(), extra_args.end());
  for (const std::string& s : argv) r.refine_command += (r.refine_command.empty() ? "" : " ") + Quote(s);
  const ProcessResult b = RunProcess(argv, work, log, timeout_seconds);
  r.refine_seconds = b.seconds;
  r.peak_rss_mb = std::max(r.peak_rss_mb, static_cast<double>(b.peak_rss_kb) / 1024.0);
  if (!b.ok() || !fs::is_regular_file(work / "refined.ply", ec)) {
    r.error = "RefineMesh " + (b.ok() ? std::string("wrote no refined.ply") : b.error) + " (log: " +
              log.string() + ")";
    return r;
  }
  r.ok = true;
  r.mesh = work / "refined.ply";
  return r;
}

std::string OpenMvsPipelineOptions::Check() const {
  if (resolution_level < 0 || resolution_level > 4)
    return "resolution_level: expected 0 to 4, got " + std::to_string(resolution_level);
  if (min_resolution < 16) return "min_resolution: expected >= 16, got " + std::to_string(min_resolution);
  if (!(timeout_seconds > 0.0)) return "timeout_seconds: expected > 0";
  return "";
}

std::string OpenMvsPipelineOptions::Describe() const {
  auto join = [](const std::vector<std::string>& v) {
    std::string s;
    for (const std::string& a : v) s += " " + Quote(a);
    return s;
  };
  const std::string level = "--resolution-level " + std::to_string(resolution_level) +
                            " --min-resolution " + std::to_string(min_resolution);
  return "DensifyPointCloud " + level + (no_tower ? " --tower-mode 0" : "") + join(densify_args) +
         "; ReconstructMesh" + (reconstruct_args.empty() ? " (defaults)" : join(reconstruct_args)) +
         "; RefineMesh " + level + join(refine_args) + "; each nice -n 10";
}

double OpenMvsPipelineResult::Seconds() const {
  double s = 0.0;
  for (const Step& step : steps) s += step.seconds;
  return s;
}

double OpenMvsPipelineResult::PeakRssMb() const {
  double m = 0.0;
  for (const Step& step : steps) m = std::max(m, step.peak_rss_mb);
  return m;
}

OpenMvsPipelineResult RunOpenMvsPipeline(const fs::path& bin_dir, const fs::path& work,
                                         const OpenMvsPipelineOptions& options) {
  OpenMvsPipelineResult r;
  if (const std::string e = options.Check(); !e.empty()) {
    r.error = "OpenMvsPipelineOptions: " + e;
    return r;
  }
  std::error_code ec;
  const fs::path log = work / "openmvs-pipeline.log";
  fs::remove(log, ec);
  for (const char* f : {"scene.mvs", "dense.mvs", "dense.ply", "mesh.mvs", "mesh.ply", "refined.ply"})
    fs::remove(work / f, ec);
  const fs::path bin = fs::absolute(bin_dir, ec);
  const std::vector<std::string> level = {"--resolution-level", std::to_string(options.resolution_level),
                                          "--min-resolution", std::to_string(options.min_resolution)};
  struct Plan {
    const char* name;
    std::vector<std::string> args;
    const char* writes;  // the file the next step needs
  };
  std::vector<Plan> plan = {
      {"InterfaceCOLMAP", {"-i", fs::absolute(work, ec).string(), "-o", "scene.mvs", "--image-folder", "images/"}, "scene.mvs"},
      {"DensifyPointCloud", {"scene.mvs", "-o", "dense.mvs"}, "dense.mvs"},
      {"ReconstructMesh", {"dense.mvs", "-o", "mesh.mvs"}, "mesh.ply"},
      {"RefineMesh", {"dense.mvs", "--mesh-file", "mesh.ply", "-o", "refined.mvs"}, "refined.ply"}};
  plan[1].args.insert(plan[1].args.end(), level.begin(), level.end());
  if (options.no_tower) plan[1].args.insert(plan[1].args.end(), {"--tower-mode", "0"});
  plan[1].args.insert(plan[1].args.end(), options.densify_args.begin(), options.densify_args.end());
  plan[2].args.insert(plan[2].args.end(), options.reconstruct_args.begin(), options.reconstruct_args.end());
  plan[3].args.insert(plan[3].args.end(), level.begin(), level.end());
  plan[3].args.insert(plan[3].args.end(), options.refine_args.begin(), options.refine_args.end());
  for (const Plan& p : plan) {
    std::vector<std::string> argv = {kNice, "-n", "10", (bin / p.name).string()};
    argv.insert(argv.end(), p.args.begin(), p.args.end());
    OpenMvsPipelineResult::Step step;
    step.name = p.name;
    for (const std::string& s : argv) step.command += (step.command.empty() ? "" : " ") + Quote(s);
    const ProcessResult run = RunProcess(argv, work, log, options.timeout_seconds);
    step.seconds = run.seconds;
    step.peak_rss_mb = static_cast<double>(run.peak_rss_kb) / 1024.0;
    r.steps.push_back(step);
    if (!run.ok() || !fs::is_regular_file(work / p.writes, ec)) {
      r.error = std::string(p.name) + " " + (run.ok() ? "wrote no " + std::string(p.writes) : run.error) +
                " (log: " + log.string() + ")";
      return r;
    }
  }
  r.ok = true;
  r.mesh = work / "refined.ply";
  return r;
}

}  // namespace imr::bench
