// What the keyframe loop does after the engine applied a keyframe, one observer per concern
// (COLMAP's controller callbacks): the stream recorder, the invariant check, the trace, the
// snapshots and the progress. host/pipeline/run.cc makes the list the run options ask for and
// calls it in order after every keyframe; an observer that throws fails the sequence.
#pragma once

#include "host/engine/engine.h"
#include "host/io/keyframe_source.h"
#include "host/io/stream_recorder.h"
#include "host/pipeline/mesh_export.h"
#include "host/pipeline/run.h"

#include <nlohmann/json.hpp>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <functional>
#include <string>
#include <vector>

#include "host/util/atomic_file.h"
#include "host/util/clock.h"

namespace imr::pipeline {

// One applied keyframe, as the observers see it.
struct KeyframeEvent {
  const engine::KeyframeUpdate& update;  // in canonical order, as the engine got it
  const io::KeyframeInfo& info;
  int keyframes = 0;            // keyframes applied so far, this one included
  double engine_seconds = 0.0;  // this keyframe's ApplyUpdate
  // The invariant check's time when it ran after this keyframe, -1 otherwise: InvariantCheck
  // sets it, the trace (after it in the list) writes it.
  double check_seconds = -1.0;
};

class KeyframeObserver {
 public:
  virtual ~KeyframeObserver() = default;
  virtual void OnKeyframe(KeyframeEvent& event) = 0;
};

// --export-stream / --export-colmap: every update as the engine got it, for the SLAM JSON stream
// and the COLMAP model written when the sequence ends. What it records is spooled to a staging
// folder in `spool_beside` (removed with everything in it when the recording ends, written or not;
// a killed run's is removed by the next run's leftover sweep of that folder).
class StreamRecording : public KeyframeObserver {
 public:
  StreamRecording(const io::KeyframeSource* source, std::string written_by,
                  const std::filesystem::path& spool_beside)
      : spool_(spool_beside), recorder_(source, std::move(written_by), {spool_.path()}) {}
  void OnKeyframe(KeyframeEvent& event) override { recorder_.Record(event.update, event.info); }
  io::StreamRecorder& recorder() { return recorder_; }
  const io::StreamRecorder& recorder() const { return recorder_; }

 private:
  StagingDirectory spool_;  // before the recorder: its files close before the folder goes
  io::StreamRecorder recorder_;
};

// --check-invariants-every N: the engine's full check after every N-th keyframe; a failure
// throws, naming the keyframe.
class InvariantCheck : public KeyframeObserver {
 public:
  InvariantCheck(const engine::Engine& engine, int every) : engine_(engine), every_(every) {}
  void OnKeyframe(KeyframeEvent& event) override;
  int every() const { return every_; }
  int count() const { return count_; }
  double seconds() const { return seconds_; }

 private:
  const engine::Engine& engine_;
  int every_;
  int count_ = 0;
  double seconds_ = 0.0;
};

// --trace: one JSON line per keyframe, flushed as it goes (a long run can be watched), under
// <path>.partial until Finish renames it: a killed run never leaves a trace that looks complete.
class TraceWriter : public KeyframeObserver {
 public:
  // Keyframes apart of the lines that carry engine_bytes (the engine's Memory().Total()).
  static constexpr int kEngineBytesEvery = 10;
  TraceWriter(std::filesystem::path path, const engine::Engine& engine);
  ~TraceWriter() override { Finish(); }
  void OnKeyframe(KeyframeEvent& event) override;
  // Closes and renames the file (once; also from the destructor when the sequence fails).
  const std::filesystem::path& Finish();

 private:
  std::filesystem::path path_, partial_;
  const engine::Engine& engine_;
  std::ofstream out_;
  const std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now();
};

// output.snapshot_every: the mesh after every N-th keyframe, exported at once into
// <output>/snapshots (whole files), so a running job can be watched.
class Snapshots : public KeyframeObserver {
 public:
  struct Target {
    const ExportContext* context;
    const std::vector<std::string>* formats;
    const Exporters* exporters;
    std::filesystem::path directory;  // the sequence's output folder
    std::string stem;                 // the job's output stem
    StageWatch* watch;
    double stage_timeout;
    std::vector<std::filesystem::path>* written;  // each file committed is added here
    // Puts a snapshot at the mesh_refiner stage's positions; empty: no such stage.
    std::function<void(engine::Mesh*)> refined;
  };
  Snapshots(const engine::Engine& engine, int every, Target target)
      : engine_(engine), every_(every), target_(std::move(target)) {}
  void OnKeyframe(KeyframeEvent& event) override;
  // One entry per snapshot written: keyframe, frame, stem (relative to the output folder), faces.
  const nlohmann::json& list() const { return list_; }
  double seconds() const { return seconds_; }

 private:
  const engine::Engine& engine_;
  int every_;
  Target target_;
  nlohmann::json list_ = nlohmann::json::array();
  double seconds_ = 0.0;
};

// The run options' progress callback after every keyframe, and a log line every 20 keyframes
// and after the last.
class Progress : public KeyframeObserver {
 public:
  Progress(std::string sequence, int total_keyframes,
           std::function<void(const SequenceProgress&)> callback);
  void OnKeyframe(KeyframeEvent& event) override;

 private:
  std::string sequence_;
  int total_keyframes_;  // -1: not known in advance
  std::string of_total_;
  std::function<void(const SequenceProgress&)> callback_;
};

}  // namespace imr::pipeline
