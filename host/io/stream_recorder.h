// --export-stream and --export-colmap: the updates that reached the engine, recorded as the run
// goes and written at its end as SLAM JSON 0.3 (io/slam_json.h, with imr's extensions: the
// replay reproduces the run) or as a COLMAP text model of the final points.
//
// Memory (issue 46): nothing per observation or per view stays in memory. What the recorder is
// given goes to spool files in a folder its owner gives (and removes): each view's camera, each
// observation as a fixed-size record (an external sort, spool.h, puts them in view order at the
// end: an observation may reach an earlier view, the "keyframe": d extension), each keyframe's
// line. A point's state (estimate, cameras) stays in memory while updates name it; a point no
// update named for `evict_after_keyframes` keyframes goes to the spool, and comes back (one
// read of that spool) if an update names it again, which also widens the window. The files are
// then written streamed, never whole in memory: the bytes are those the whole model would give.
#pragma once

#include "host/io/colmap_model.h"
#include "host/io/keyframe_source.h"
#include "host/io/spool.h"

#include <filesystem>
#include <map>
#include <memory>
#include <string>
#include <unordered_map>
#include <vector>

namespace imr::io {

struct StreamRecorderOptions {
  std::filesystem::path spool;            // an existing folder for the spool files (required)
  std::size_t sort_run_records = 1 << 17;  // records per sorted run (48 bytes each: 6 MB)
  int evict_after_keyframes = 16;         // a point no update named this long leaves memory
  // Empty when valid, else what is wrong ("spool: ...").
  std::string Check() const;
};

class StreamRecorder {
 public:
  // Throws std::invalid_argument when the options are not valid.
  StreamRecorder(const KeyframeSource* source, std::string written_by, StreamRecorderOptions options);
  ~StreamRecorder();
  StreamRecorder(const StreamRecorder&) = delete;
  StreamRecorder& operator=(const StreamRecorder&) = delete;

  void Record(const engine::KeyframeUpdate& update, const KeyframeInfo& info);

  // Writes the SLAM JSON to `file` (created or replaced: the caller stages it and commits it
  // atomically). Throws naming the file when a write fails.
  void WriteSlamJson(const std::filesystem::path& file);
  // Writes cameras.txt, images.txt and points3D.txt into the existing folder `dir` (a staging
  // folder). Live points (not removed, seen by a camera) at their last estimate; every view
  // becomes an image, every track entry indexes one of its 2D points: the source's keypoint
  // (Keypoint), else the projection of the estimate the view saw when it observed the point,
  // else that of the final estimate (0 0 where none projects). A point's ERROR is the mean
  // distance from its 2D points to the final estimate's projections (-1 when none has both).
  // Pixels in COLMAP's convention (cameras from other formats shifted by half a pixel).
  void WriteColmap(const std::filesystem::path& dir);

  // Points that entered with no camera: a SLAM JSON file cannot hold them (replay then differs).
  int64_t unrepresentable() const { return unrepresentable_; }
  // Bytes held in memory: the points' states in memory, the buffers, the camera tables. Bounded
  // for a drive whatever its length (what it records is on disk).
  int64_t HeldBytes() const;
  struct Stats {
    int64_t views = 0;
    int64_t observations = 0;
    int64_t points_spooled = 0;    // point states written to the spool
    int64_t points_recovered = 0;  // brought back by a later update
    int64_t spool_scans = 0;       // reads of the point spool to bring them back
    int evict_after_keyframes = 0;  // the window now (widened by each recovery)
  };
  Stats stats() const;

 private:
  struct PointState {
    Vec3 position{};
    std::vector<uint64_t> cameras;
    bool removed = false;
    int64_t named = 0;  // the last keyframe an update named it
  };
  // View ids -> their index in arrival order, as runs of consecutive ids (frame numbers: one run).
  class ViewIndex {
   public:
    int64_t Find(uint64_t id) const;  // -1 when not a view
    void Add(uint64_t id, uint64_t index);
    std::size_t runs() const { return runs_.size(); }

   private:
    struct Run {
      uint64_t count;
      uint64_t first_index;
    };
    std::map<uint64_t, Run> runs_;  // first id -> run
  };
  struct ObservationRecord;
  struct ObservationLess {
    bool operator()(const ObservationRecord& a, const ObservationRecord& b) const;
  };
  struct ViewHead;

  void AddView(const engine::Camera& camera, int64_t keyframe);
  void Recover(const engine::KeyframeUpdate& update);
  void Evict(int64_t keyframe);
  // Calls `f(id, state)` for every point, in id order (the spool's latest state of each point,
  // else memory's).
  template <class F>
  void ForEachPoint(F f);
  bool ReadViewHead(SpoolReader* in, ViewHead* v) const;

  const KeyframeSource* source_;
  std::string written_by_;
  StreamRecorderOptions options_;
  int evict_after_;
  int64_t keyframes_ = 0;
  int64_t views_ = 0;
  ViewIndex view_index_;
  bool ids_fit_ = true;  // every view id fits COLMAP's 32 bits
  // Distinct intrinsics: every field (the projection's), and their first-use classes as the
  // SLAM JSON (unshifted) and COLMAP (shifted) files list them; views' indices into them spool.
  std::vector<Intrinsics> full_;
  std::vector<std::size_t> slam_of_full_, colmap_of_full_;
  std::vector<Intrinsics> slam_intrinsics_, colmap_intrinsics_;
  std::vector<ColmapModel::Camera> colmap_cameras_;
  bool placeholder_ = false;

  std::unordered_map<uint64_t, PointState> points_;
  int64_t evictions_ = 0;
  Stats stats_;
  std::unique_ptr<SpoolWriter> views_out_, keyframes_out_, points_out_;
  std::unique_ptr<ExternalSort<ObservationRecord, ObservationLess>> observations_;
  int64_t unrepresentable_ = 0;
};

}  // namespace imr::io
