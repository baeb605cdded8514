// A finished SfM reconstruction (OpenMVG sfm_data, COLMAP model) as a keyframe stream: either one
// batch update with every camera and point, or a replay in view order (a point enters once
// min_views of the views replayed so far see it; later views add their observations to it).
// Points of a finished reconstruction never move.
#pragma once

#include "host/io/keyframe_source.h"

#include <array>
#include <cstdint>
#include <map>
#include <string>
#include <vector>

namespace imr::io {

struct SfmObservation {
  uint64_t view_id = 0;
  double x = 0.0, y = 0.0;  // pixel, as the file writes it
};

struct SfmPoint {
  uint64_t id = 0;
  Vec3 position{};
  std::vector<SfmObservation> observations;
  bool has_rgb = false;            // the file gives the point's colour (COLMAP points3D)
  std::array<uint8_t, 3> rgb{};    // red, green, blue
};

// What both readers deliver, in the convention of camera_model.h.
struct SfmModel {
  std::string file;                  // for messages
  std::string points_file;           // where the points are, for messages (e.g. .../points3D.bin)
  std::string views_file;            // where the posed views are, for messages
  std::string no_points_hint;        // the format's advice when there are no points ("; run ...")
  std::vector<CameraGeometry> views;  // posed views, sorted by id
  std::vector<SfmPoint> points;       // sorted by id
  int64_t views_without_pose = 0;     // views the file lists but did not register (skipped)
  int64_t observations_skipped = 0;   // observations in views without a pose (skipped)
};

struct SfmReplayOptions {
  bool replay = false;           // false: one batch update
  bool order_by_name = false;    // replay order: view id (false) or image name (true)
  int views_per_keyframe = 1;    // replay: views per update
  int min_views = 2;             // a point enters once this many of its views have been seen
};
// From a format's options (keys "mode", "order", "views_per_keyframe", "min_views").
SfmReplayOptions SfmReplayOptionsFromJson(const nlohmann::json& options);
// Schema rows for those options, shared by the openmvg and colmap formats.
nlohmann::json SfmReplayOptionsSchema();

// Fewer posed views than this is nothing to mesh: two viewpoints (a model of its initial pair
// only) carve two fans of rays, not a surface.
inline constexpr std::size_t kMinViewsToMesh = 3;

// Throws std::runtime_error "<file>: nothing to mesh: <why>" when the model has no points, fewer
// than kMinViewsToMesh posed views, or no point seen by options.min_views of them; so a sequence
// fails on reading, with the reason, before anything that could look like a result is written.
std::unique_ptr<KeyframeSource> MakeSfmSource(SfmModel model, const SfmReplayOptions& options);

}  // namespace imr::io
