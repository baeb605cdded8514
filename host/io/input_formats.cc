#include "host/io/input_formats.h"

#include "host/io/colmap_model.h"
#include "host/io/openmvg_reader.h"
#include "host/io/slam_json.h"
#include "host/io/synthetic_source.h"
#include "host/synthetic/stream.h"

namespace imr::io {
using nlohmann::json;

const std::vector<InputFormat>& InputFormats() {
  static const std::vector<InputFormat> formats = [] {
    std::vector<InputFormat> f;
    const synthetic::StreamOptions d;
    InputFormat s;
    s.name = "synthetic";
    s.description = "synthetic observation stream over a known scene (no images; engine only)";
    s.sequences_are_paths = false;
    for (auto k : {synthetic::SceneKind::kStreet, synthetic::SceneKind::kRoom,
                   synthetic::SceneKind::kPlane})
      s.sequence_names.push_back(synthetic::ToString(k));
    s.needs_front_end = false;
    s.options_schema = {
        {"frames", {{"type", "integer"}, {"default", 200}, {"minimum", 1},
                    {"description", "frames in the sequence"}}},
        {"seed", {{"type", "integer"}, {"default", 1}, {"minimum", 0},
                  {"description", "everything random derives from it"}}},
        {"keyframe_every", {{"type", "integer"}, {"default", d.keyframe_every}, {"minimum", 1},
                            {"description", "a keyframe every this many frames (paper: 5)"}}},
        {"speed", {{"type", "number"}, {"default", d.speed}, {"minimum", 0.01},
                   {"description", "camera motion per frame, metres"}}},
        {"points_per_keyframe", {{"type", "integer"}, {"default", d.points_per_keyframe},
                                 {"minimum", 1}, {"description", "new points per keyframe"}}},
        {"noise_at_10m", {{"type", "number"}, {"default", d.noise_at_10m}, {"minimum", 0.0},
                          {"description", "depth error of a first estimate at 10 m, metres"}}},
        {"frozen", {{"type", "boolean"}, {"default", false},
                    {"description", "points keep their first estimate (no moves)"}}}};
    s.open = &OpenSyntheticSource;
    f.push_back(s);

    InputFormat mvg;
    mvg.name = "openmvg";
    mvg.description = "OpenMVG sfm_data.json (views, intrinsics, extrinsics, structure); engine only";
    mvg.needs_front_end = false;
    mvg.options_schema = SfmReplayOptionsSchema();
    mvg.open = [](const std::string& path, const json& o) {
      return MakeSfmSource(ReadOpenMvg(path), SfmReplayOptionsFromJson(o));
    };
    f.push_back(mvg);

    InputFormat colmap;
    colmap.name = "colmap";
    colmap.description = "COLMAP sparse model folder (cameras, images, points3D; .bin wins over "
                         ".txt); engine only";
    colmap.needs_front_end = false;
    colmap.options_schema = SfmReplayOptionsSchema();
    colmap.open = [](const std::string& path, const json& o) {
      return MakeSfmSource(ColmapToSfm(ReadColmapModel(path), path), SfmReplayOptionsFromJson(o));
    };
    f.push_back(colmap);

    InputFormat slam;
    slam.name = "slam_json";
    slam.description = "incremental SLAM JSON (slam_data_version 0.3, Piazza et al. 2018; also "
                       "what --export-stream writes): keyframes with moving points; engine only";
    slam.needs_front_end = false;
    slam.options_schema = SlamJsonOptionsSchema();
    slam.open = [](const std::string& path, const json& o) {
      return OpenSlamJson(path, SlamJsonOptionsFromJson(o));
    };
    f.push_back(slam);

    // Image sequences with known poses: run through the features and refiner plugins.
    const auto image_format = [](const std::string& name, const std::string& description,
                                 ImageSequence (*read)(const std::string&,
                                                       const ImageSequenceOptions&)) {
      InputFormat i;
      i.name = name;
      i.description = description;
      i.needs_front_end = true;
      i.sequences_are_paths = true;
      i.options_schema = ImageSequenceOptionsSchema();
      i.open_images = [read](const std::string& path, const json& o) {
        return read(path, ImageSequenceOptionsFromJson(o));
      };
      return i;
    };
    f.push_back(image_format("kitti_odometry",
                             "KITTI odometry sequence folder (image_0..3, calib.txt, times.txt; "
                             "poses file: camera i -> camera 0)",
                             &ReadKittiOdometry));
    f.push_back(image_format("kitti_raw",
                             "KITTI raw drive folder (<date>/<date>_drive_NNNN_sync: "
                             "image_0X/data, calibration in the date folder; poses from "
                             "poses*.txt or oxts)",
                             &ReadKittiRaw));
    f.push_back(image_format("middlebury",
                             "Middlebury multi-view *_par.txt (or its folder): K, R, t per view",
                             &ReadMiddlebury));
    return f;
  }();
  return formats;
}

const InputFormat* FindInputFormat(const std::string& name) {
  for (const auto& f : InputFormats())
    if (f.name == name) return &f;
  return nullptr;
}

}  // namespace imr::io
