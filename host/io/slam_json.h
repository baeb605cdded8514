// The incremental SLAM JSON of the real-time manifold mesher of Piazza et al. 2018
// (slam_data_version 0.3; docs/interop.md), read as a keyframe stream and written by
// --export-stream (io/stream_recorder.h).
//
//   {"slam_data_version": "0.3", "root_path": "...",
//    "intrinsics": [{"intrinsicId": 0, "value": {"polymorphic_name": "pinhole",
//                    "ptr_wrapper": {"data": {"width", "height", "focal_length",
//                                             "principal_point": [cx, cy], "disto_*"}}}}],
//    "views": [{"viewId": 7, "id_intrinsic": 0, "filename": "...",
//               "extrinsic": {"rotation": R (world -> camera, rows), "center": C},
//               "observations": [{"pointId": 3, "X": [x, y, z]}, ...]}, ...]}
//
// Views come in order, each with a unique viewId; X is the point's estimate as of that view.
// Reading rule: a point enters (a new point) once min_views views have seen it, with all of
// them as its cameras and its latest X; afterwards a view that sees it adds its camera, and an X
// that differs from the last one by more than min_move is a move. A keyframe is
// views_per_keyframe consecutive views, unless the views carry "keyframe" numbers.
//
// imr extensions (written by --export-stream; other readers ignore them) make a replay exact:
//   - view "keyframe": k  - the views of one engine update share k;
//   - observation "keyframe": d  - the observation reached the engine at keyframe d, later than
//     its view's (a point that entered later, or a move that brought no new camera);
//   - top-level "imr_stream": {"min_views": 1, "keyframes": [{"keyframe", "frame",
//     "removed_points": [ids]}]}  - every update, even an empty one, and removals.
//
// Memory: the file is read in passes: at open a SAX pass (json_stream.h) keeps each view's camera
// and where its text lies, and each point's last keyframe (8 bytes a point, none per
// observation), and a dry run builds every update from the views read again one at a time, so
// that bad input fails at open; each update is then built the same way when it is asked for.
// What the reader holds is the tracks alive at a keyframe, not the file (PendingBytes).
#pragma once

#include "host/io/colmap_model.h"
#include "host/io/keyframe_source.h"

#include <filesystem>
#include <map>

namespace imr::io {

struct SlamJsonOptions {
  int min_views = 0;           // 0: 2, or what the file's imr_stream says (1 for imr exports)
  double min_move = 0.0;       // a later X closer than this to the current estimate is no move
  int views_per_keyframe = 5;  // used when the views carry no "keyframe" numbers
};
SlamJsonOptions SlamJsonOptionsFromJson(const nlohmann::json& options);
nlohmann::json SlamJsonOptionsSchema();

// Throws std::runtime_error naming the file and the JSON path or id: missing fields, a repeated
// viewId, a dangling id_intrinsic or removed point, a rotation that is not one, malformed or
// truncated JSON.
std::unique_ptr<KeyframeSource> OpenSlamJson(const std::filesystem::path& file,
                                             const SlamJsonOptions& options);

// Puts an update in imr's canonical order before the engine sees it: new, moved and removed
// points sorted by id, each point's camera ids without repeats and in camera arrival order.
// The pipeline applies it to every source, so a run and the replay of its exported stream give
// the engine the same input whatever the file layout.
class CanonicalOrder {
 public:
  void Apply(engine::KeyframeUpdate* update);
  // What it holds: a run per stretch of cameras that arrived with consecutive ids (one for a
  // source numbering its frames in order), not a record per camera, which grew with the drive.
  std::size_t runs() const { return runs_.size(); }

 private:
  void Arrive(uint64_t id);
  // The camera's place in arrival order; UINT64_MAX when it has not arrived.
  uint64_t Rank(uint64_t id) const;
  struct Run {
    uint64_t last_id;     // ids first..last_id arrived in that order,
    uint64_t first_rank;  // the first of them as the first_rank-th camera
  };
  std::map<uint64_t, Run> runs_;  // by first id
  uint64_t arrived_ = 0;
};

}  // namespace imr::io
