// The real-time manifold mesher of Piazza, Romanoni & Matteucci (RA-L 2018), run as a peer on the
// same SLAM JSON 0.3 stream imr reads (`../shared/data/street-stream/slam.json`, or what
// `imr run --export-stream` writes). The peer is GPL-3: it is built outside the repository by
// tools/bench/peers/build_piazza.sh and only ever run as a separate process; none of its code is
// here. Its output is an ASCII OFF mesh (host/eval/mesh_io.h reads it).
#pragma once

#include <string>

#include <nlohmann/json.hpp>

namespace imr::bench {

// The slamReconstructor binary: `given` when not empty, else $IMR_PIAZZA when set, else the
// cache of build_piazza.sh (${XDG_CACHE_HOME:-~/.cache}/imr-peers/piazza-6e2a6af/build/
// slamReconstructor) when it exists there; "" otherwise. A given or $IMR_PIAZZA path is returned
// as it is (RunPiazza says when it cannot run it).
std::string FindPiazza(const std::string& given);

// The peer's config: its authors' KITTI parameters (../shared/peers/README.md), no intermediate
// meshes, outputs in output/ and stats/ of the working folder. `moves_on` is the peer's
// update_points_position (points move when the stream moves them). Floats are written as JSON
// doubles and counts as integers: the peer's parser (rapidjson) refuses 40 where it wants 40.0.
nlohmann::json PiazzaKittiConfig(bool moves_on, const std::string& stats_id = "imr-bench");

struct PiazzaResult {
  bool ok = false;           // the peer exited 0 and wrote its mesh
  std::string error;         // why not, naming the log to read
  double seconds = 0.0;      // wall time of the peer's process (reading the stream included)
  double peak_rss_mb = 0.0;  // its peak resident set, MiB (wait4)
  std::string mesh_path;     // <work_dir>/output/manifold_imr-bench.off when ok
  std::string log_path;      // <work_dir>/piazza.log: the peer's stdout and stderr
};

// Runs `binary` on `slam_json` in `work_dir` (created; it gets config.json, output/, stats/ and
// piazza.log; an earlier mesh there is removed first), killed after `timeout_seconds` (<= 0: no
// limit; the peer's memory grows with the sequence, about 0.8 GB at 150 frames). Never throws.
PiazzaResult RunPiazza(const std::string& binary, const std::string& slam_json,
                       const std::string& work_dir, bool moves_on,
                       double timeout_seconds = 1800.0);

}  // namespace imr::bench
