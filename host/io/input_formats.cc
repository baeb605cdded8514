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
        {"frames", {{"type", "integer"}, {"default", 200}, {"minimum", 1}, {"maximum", 200000},
                    {"description", "frames in the sequence (frames x speed at most 200 km: the "
                                    "street and the plane are built whole)"}}},
        {"seed", {{"type", "integer"}, {"default", 1}, {"minimum", 0},
                  {"description", "everything random derives from it"}}},
        {"keyframe_every", {{"type", "integer"}, {"default", d.keyframe_every}, {"minimum", 1},
                            {"maximum", 10000},
                            {"description", "a keyframe every this many frames (paper: 5); each "
                                            "update carries the frames since the last one"}}},
        {"speed", {{"type", "number"}, {"default", d.speed}, {"minimum", 0.01}, {"maximum", 100.0},
                   {"unit", "m/frame"}, {"description", "camera motion per frame"}}},
        {"max_range", {{"type", "number"}, {"default", d.max_range}, {"minimum", 1.0},
                       {"maximum", 1000.0}, {"unit", "m"},
                       {"description", "a camera sees no point farther than this"}}},
        {"points_per_keyframe", {{"type", "integer"}, {"default", d.points_per_keyframe},
                                 {"minimum", 1}, {"maximum", 100000},
                                 {"description", "block model (track_frames 0): new points per "
                                                 "keyframe"}}},
        {"noise_at_10m", {{"type", "number"}, {"default", d.noise_at_10m}, {"minimum", 0.0},
                          {"maximum", 100.0}, {"unit", "m"},
                          {"description", "depth error at 10 m (grows with depth^2): block model, "
                                          "of a first estimate; tracked model, of one "
                                          "observation (0.2 is ../shared/data/street-stream's "
                                          "0.002 depth^2)"}}},
        {"frozen", {{"type", "boolean"}, {"default", false},
                    {"description", "points keep their first estimate (no moves; tracked model: "
                                    "moves keep the position and bring the new cameras)"}}},
        {"track_frames", {{"type", "integer"}, {"default", d.track_frames}, {"minimum", 0},
                          {"maximum", 10000},
                          {"description", "0: the block model (each keyframe's new points seen by "
                                          "its own frames, refined 3 keyframes). > 0: the tracked "
                                          "model, a SLAM stream: every frame observes its tracks "
                                          "until one has this many observations or is lost; a "
                                          "track is a new point from its 2nd observation, then "
                                          "moves at each keyframe to the mean of its "
                                          "observations' errors (configs/dense-street.json: 17)"}}},
        {"track_density", {{"type", "number"}, {"default", d.track_density}, {"minimum", 0.0},
                           {"maximum", 100.0}, {"unit", "1/m^2"},
                           {"description", "tracked model: new tracks per m^2 of surface coming "
                                           "into view (2.1 with track_frames 17, max_range 40: "
                                           "~1,270 observations per frame on the street)"}}},
        {"angular_noise", {{"type", "number"}, {"default", d.angular_noise}, {"minimum", 0.0},
                           {"maximum", 0.1}, {"unit", "rad"},
                           {"description", "tracked model: error of one observation across its "
                                           "viewing ray (0.002: 1 px of the exported pinhole)"}}},
        {"keep_truth", {{"type", "boolean"}, {"default", d.keep_truth},
                        {"description", "keep every reported point's true position for the "
                                        "report's completeness; false keeps the generator's "
                                        "memory flat on long drives (the report then gives "
                                        "precision only, and says why)"}}}};
    s.open = &OpenSyntheticSource;
    s.check = &CheckSyntheticOptions;
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
