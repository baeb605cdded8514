#include "host/pipeline/keyframe_observers.h"

#include "host/util/atomic_file.h"
#include "host/util/json_text.h"
#include "host/util/log.h"
#include "host/util/process_memory.h"
#include "host/util/write_rule.h"

#include <unistd.h>

#include <cstdio>
#include <stdexcept>

namespace imr::pipeline {
namespace fs = std::filesystem;
using nlohmann::json;

void InvariantCheck::OnKeyframe(KeyframeEvent& e) {
  if (every_ <= 0 || e.keyframes % every_ != 0) return;
  const auto start = std::chrono::steady_clock::now();
  const engine::ManifoldCheckResult r = engine_.CheckInvariants();
  e.check_seconds = SecondsSince(start);
  seconds_ += e.check_seconds;
  ++count_;
  if (!r.ok)
    throw std::runtime_error("keyframe " + std::to_string(e.info.index) + " (frame " +
                             std::to_string(e.info.frame) + "): invariant check failed: " +
                             r.message);
}

TraceWriter::TraceWriter(fs::path path, const engine::Engine& engine)
    : path_(std::move(path)), engine_(engine) {
  // Written under a temporary of imr's own (a leftover of a kill is removed as the atomic
  // writes' are) and renamed into place at the end, under the write rule.
  partial_ = path_.parent_path() /
             ("." + path_.filename().string() + ".tmp-" + std::to_string(::getpid()));
  if (path_.has_parent_path()) EnsureWritableDirectory(path_.parent_path());
  CheckWriteTarget(path_);
  out_.open(partial_, std::ios::trunc);
  if (!out_) throw std::runtime_error(partial_.string() + ": cannot write the trace");
}

void TraceWriter::OnKeyframe(KeyframeEvent& e) {
  const engine::EngineStats& es = engine_.Stats();
  json line = {{"keyframe", e.keyframes},        {"frame", e.info.frame},
               {"points", engine_.NumPoints()},  {"vertices", es.vertices},
               {"cells", es.cells},              {"cells_in_o", es.cells_in_o},
               {"rss_bytes", ResidentBytes()},   {"engine_seconds", e.engine_seconds},
               {"seconds", SecondsSince(start_)}};
  if (e.check_seconds >= 0.0) line["check_seconds"] = e.check_seconds;
  // The engine's bytes beside the RSS show what the host holds beyond the engine; Memory() walks
  // every cell (milliseconds), so only every kEngineBytesEvery-th keyframe and the first.
  if (e.keyframes == 1 || e.keyframes % kEngineBytesEvery == 0) {
    line["engine_bytes"] = engine_.Memory().Total();
    // And the allocator's: what the heap holds beyond the engine, what freeing kept resident.
    const HeapBytes heap = CurrentHeapBytes();
    if (!heap.allocator.empty())
      line["heap_bytes"] = {{"allocated", heap.allocated}, {"resident", heap.resident}};
  }
  out_ << DumpJson(line) << '\n';
  out_.flush();
  if (!out_) throw std::runtime_error(partial_.string() + ": cannot write the trace");
}

const fs::path& TraceWriter::Finish() {
  if (out_.is_open()) {
    out_.close();
    std::error_code ec;
    try {
      CheckWriteTarget(path_);
      RecordWrittenFile(partial_, path_);
    } catch (const std::exception& e) {
      LogWarning(std::string("cannot finish the trace: ") + e.what());
      fs::remove(partial_, ec);
      return path_;
    }
    fs::rename(partial_, path_, ec);
    if (ec) LogWarning(path_.string() + ": cannot finish the trace: " + ec.message());
  }
  return path_;
}

void Snapshots::OnKeyframe(KeyframeEvent& e) {
  if (every_ <= 0 || e.keyframes % every_ != 0) return;
  const auto start = std::chrono::steady_clock::now();
  engine::Mesh snap = engine_.ExtractMesh();
  if (target_.refined) target_.refined(&snap);
  if (!snap.faces.empty()) {
    char suffix[64];
    std::snprintf(suffix, sizeof(suffix), "_kf%06d", e.keyframes);
    const std::string stem = target_.stem + suffix;
    StagingDirectory dir(target_.directory / "snapshots");
    target_.watch->SetPosition("snapshot after keyframe " + std::to_string(e.info.index));
    ExportMesh(snap, *target_.context, *target_.formats, *target_.exporters, dir.path(), stem,
               *target_.watch, target_.stage_timeout);
    for (auto& f : dir.Commit()) target_.written->push_back(std::move(f));
    list_.push_back({{"keyframe", e.keyframes}, {"frame", e.info.frame},
                     {"stem", "snapshots/" + stem}, {"faces", snap.faces.size() / 3}});
  }
  seconds_ += SecondsSince(start);
}

Progress::Progress(std::string sequence, int total_keyframes,
                   std::function<void(const SequenceProgress&)> callback)
    : sequence_(std::move(sequence)),
      total_keyframes_(total_keyframes),
      of_total_(total_keyframes > 0 ? "/" + std::to_string(total_keyframes) : ""),
      callback_(std::move(callback)) {}

void Progress::OnKeyframe(KeyframeEvent& e) {
  if (callback_) callback_({e.keyframes, total_keyframes_, e.info.frame});
  if (e.keyframes % 20 == 0 || e.keyframes == total_keyframes_)
    LogInfo("[" + sequence_ + "] keyframe " + std::to_string(e.keyframes) + of_total_);
}

}  // namespace imr::pipeline
