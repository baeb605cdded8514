#include "tools/bench/peers/piazza.h"

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <system_error>

#include "tools/bench/common/subprocess.h"

namespace imr::bench {

namespace fs = std::filesystem;
using nlohmann::json;

std::string FindPiazza(const std::string& given) {
  if (!given.empty()) return given;
  if (const char* e = std::getenv("IMR_PIAZZA"); e && *e) return e;
  const char* xdg = std::getenv("XDG_CACHE_HOME");
  const char* home = std::getenv("HOME");
  const fs::path cache = xdg && *xdg ? fs::path(xdg) / "imr-peers"
                                     : fs::path(home ? home : "/tmp") / ".cache/imr-peers";
  const fs::path bin = cache / "piazza-6e2a6af/build/slamReconstructor";
  std::error_code ec;
  return fs::is_regular_file(bin, ec) ? bin.string() : "";
}

json PiazzaKittiConfig(bool moves_on, const std::string& stats_id) {
  return {
      // Visibility and carving: the authors' KITTI values (../shared/peers/README.md).
      {"maxDistanceCamFeature", 40.0},
      {"steinerGridStepLength", 20.0},
      {"manifold_update_every", 10},
      {"initial_manifold_update_skip", 2},
      {"freeVoteThreshold", 100.0},
      {"w_1", 10.0},
      {"w_2", 2.0},
      {"w_3", 1.0},
      {"w_m", 1.0},
      {"inverseConicEnabled", true},
      {"enableRayMistrust", false},
      {"maxSteinerVerticesPerTriangle", 4},
      {"rayRemovalThreshold", 1e8},
      {"vertexRemovalThreshold", 1e8},
      {"primary_points_visibility_threshold", 2},
      {"maxPointsPerCamera", 200000},
      {"outlierFilteringThreshold", 0.25},
      {"minDistancePointPositionUpdate", 0.0},
      {"update_points_position", moves_on},
      // Output: the final mesh only, timings on.
      {"save_manifold_every", 1000000},
      {"time_stats_output", true},
      {"all_sort_of_output", false},
      {"fake_points_multiplier", 0},
      {"output_folder", "output/"},
      {"time_stats_folder", "stats/"},
      {"count_stats_folder", "stats/"},
      {"statsId", stats_id}};
}

PiazzaResult RunPiazza(const std::string& binary, const std::string& slam_json,
                       const std::string& work_dir, bool moves_on, double timeout_seconds) {
  PiazzaResult r;
  std::error_code ec;
  if (binary.empty() || !fs::is_regular_file(binary, ec)) {
    r.error = "no Piazza binary at '" + binary + "' (build it with tools/bench/peers/build_piazza.sh)";
    return r;
  }
  if (!fs::is_regular_file(slam_json, ec)) {
    r.error = "no SLAM JSON stream at '" + slam_json + "'";
    return r;
  }
  const std::string stats_id = "imr-bench";
  const fs::path work = fs::absolute(work_dir, ec);
  const fs::path mesh = work / "output" / ("manifold_" + stats_id + ".off");
  const fs::path log = work / "piazza.log";
  r.log_path = log.string();
  fs::create_directories(work / "output", ec);
  if (!ec) fs::create_directories(work / "stats", ec);
  if (ec) {
    r.error = "cannot create " + work.string() + ": " + ec.message();
    return r;
  }
  fs::remove(mesh, ec);  // never report an earlier run's mesh
  fs::remove(log, ec);
  const fs::path config = work / "config.json";
  {
    std::ofstream out(config);
    out << PiazzaKittiConfig(moves_on, stats_id).dump(2) << "\n";
    if (!out) {
      r.error = "cannot write " + config.string();
      return r;
    }
  }
  // The peer resolves its relative output folders against its working directory.
  const ProcessResult p = RunProcess(
      {fs::absolute(binary, ec).string(), fs::absolute(slam_json, ec).string(), config.string()},
      work, log, timeout_seconds);
  r.seconds = p.seconds;
  r.peak_rss_mb = static_cast<double>(p.peak_rss_kb) / 1024.0;
  if (!p.ok()) {
    r.error = "slamReconstructor " + p.error + " (log: " + log.string() + ")";
    return r;
  }
  if (!fs::is_regular_file(mesh, ec) || fs::file_size(mesh, ec) == 0) {
    r.error = "slamReconstructor exited 0 but wrote no mesh at " + mesh.string() + " (log: " +
              log.string() + ")";
    return r;
  }
  r.ok = true;
  r.mesh_path = mesh.string();
  return r;
}

}  // namespace imr::bench
