#include "tools/bench/peers/openmvs.h"

#include <algorithm>
#include <cstdint>
#include <fstream>
#include <set>
#include <sstream>
#include <stdexcept>
#include <system_error>

#include "host/eval/mesh_io.h"
#include "tools/bench/common/subprocess.h"

namespace imr::bench {

namespace fs = std::filesystem;

namespace {

// The lines of a COLMAP text file that are not comments (an empty line is kept: in images.txt it
// is an image without 2D points).
bool DataLines(const fs::path& file, std::vector<std::string>* lines) {
  std::ifstream in(file);
  if (!in) return false;
  for (std::string line; std::getline(in, line);) {
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (!line.empty() && line[0] == '#') continue;
    lines->push_back(line);
  }
  return true;
}

std::vector<std::string> Words(const std::string& line) {
  std::istringstream in(line);
  std::vector<std::string> w;
  for (std::string s; in >> s;) w.push_back(s);
  return w;
}

std::string Join(const std::vector<std::string>& w) {
  std::string s;
  for (const std::string& x : w) s += (s.empty() ? "" : " ") + x;
  return s;
}

}  // namespace

std::string PrepareOpenMvsColmap(const fs::path& model, const std::vector<fs::path>& image_dirs,
                                 const fs::path& out, int keyframe_every) {
  std::error_code ec;
  fs::remove_all(out / "sparse", ec);
  fs::remove_all(out / "images", ec);
  fs::create_directories(out / "sparse", ec);
  fs::create_directories(out / "images", ec);
  if (ec) return "cannot create " + (out / "images").string() + ": " + ec.message();

  // Cameras: PINHOLE fx fy cx cy.
  std::vector<std::string> lines;
  if (!DataLines(model / "cameras.txt", &lines)) return "cannot read " + (model / "cameras.txt").string();
  std::ofstream cameras(out / "sparse/cameras.txt");
  for (const std::string& line : lines) {
    std::vector<std::string> w = Words(line);
    if (w.empty()) continue;
    if (w.size() == 7 && w[1] == "SIMPLE_PINHOLE") w = {w[0], "PINHOLE", w[2], w[3], w[4], w[4], w[5], w[6]};
    else if (w.size() != 8 || w[1] != "PINHOLE")
      return "camera " + w[0] + " is " + (w.size() > 1 ? w[1] : "?") +
             ": OpenMVS's InterfaceCOLMAP takes undistorted PINHOLE cameras only";
    cameras << Join(w) << "\n";
  }

  // Images: two lines each, by id; the kept ones' id + 1; each image linked from the first
  // folder that has it.
  lines.clear();
  if (!DataLines(model / "images.txt", &lines)) return "cannot read " + (model / "images.txt").string();
  std::vector<std::pair<unsigned long long, std::size_t>> by_id;  // id, line
  for (std::size_t i = 0; i < lines.size(); i += 2) {
    const std::vector<std::string> w = Words(lines[i]);
    if (w.empty() && i + 1 >= lines.size()) break;  // a trailing empty line
    if (w.size() < 10) return "images.txt: a line of " + std::to_string(w.size()) + " fields: " + lines[i];
    by_id.emplace_back(std::stoull(w[0]), i);
  }
  std::sort(by_id.begin(), by_id.end());
  std::set<unsigned long long> kept;
  std::ofstream images(out / "sparse/images.txt");
  for (std::size_t k = 0; k < by_id.size(); ++k) {
    if (keyframe_every > 1 && k % static_cast<std::size_t>(keyframe_every) != 0 && k + 1 != by_id.size())
      continue;
    const std::size_t i = by_id[k].second;
    kept.insert(by_id[k].first);
    std::vector<std::string> w = Words(lines[i]);
    w[0] = std::to_string(by_id[k].first + 1);
    const std::string name = w[9];
    fs::path found;
    for (const fs::path& d : image_dirs)
      if (fs::is_regular_file(d / name, ec)) {
        found = fs::absolute(d / name, ec);
        break;
      }
    if (found.empty()) return "image " + name + " is in none of the image folders";
    fs::create_directories((out / "images" / name).parent_path(), ec);
    fs::create_symlink(found, out / "images" / name, ec);
    if (ec) return "cannot link " + (out / "images" / name).string() + ": " + ec.message();
    images << Join(w) << "\n" << (i + 1 < lines.size() ? lines[i + 1] : "") << "\n";
  }

  // Points: the track's image ids + 1.
  lines.clear();
  if (!DataLines(model / "points3D.txt", &lines)) return "cannot read " + (model / "points3D.txt").string();
  std::ofstream points(out / "sparse/points3D.txt");
  for (const std::string& line : lines) {
    std::vector<std::string> w = Words(line);
    if (w.empty()) continue;
    if (w.size() < 8 || (w.size() - 8) % 2 != 0) return "points3D.txt: a malformed line: " + line;
    std::vector<std::string> track;
    for (std::size_t k = 8; k < w.size(); k += 2)
      if (const unsigned long long id = std::stoull(w[k]); kept.count(id))
        track.insert(track.end(), {std::to_string(id + 1), w[k + 1]});
    if (track.empty()) continue;  // InterfaceCOLMAP stops reading at a point without views
    w.resize(8);
    w.insert(w.end(), track.begin(), track.end());
    points << Join(w) << "\n";
  }
  cameras.close(), images.close(), points.close();
  if (!cameras || !images || !points) return "cannot write " + (out / "sparse").string();
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
      RunProcess({interface, "-i", fs::absolute(work, ec).string(), "-o", "scene.mvs",
                  "--image-folder", "images/"},
                 work, log, timeout_seconds);
  r.interface_seconds = a.seconds;
  r.peak_rss_mb = static_cast<double>(a.peak_rss_kb) / 1024.0;
  if (!a.ok() || !fs::is_regular_file(work / "scene.mvs", ec)) {
    r.error = "InterfaceCOLMAP " + (a.ok() ? std::string("wrote no scene.mvs") : a.error) +
              " (log: " + log.string() + ")";
    return r;
  }
  std::vector<std::string> argv = {refine, "scene.mvs", "--mesh-file",
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

}  // namespace imr::bench
