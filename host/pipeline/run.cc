// The run of one sequence as a controller (COLMAP's controllers/incremental_pipeline: Run() and
// its callbacks). SequenceRun::Run reads as the steps, in order, and the steps follow it in this
// file: instantiate the stages, open the source, decide the scale and start the engine, the
// keyframe loop (the engine, then the observers of keyframe_observers.h), finish (checks,
// warnings, exports, evaluation, the mesh through mesh_export.h, the report of report.h).
#include "host/pipeline/run.h"

#include "host/engine/mesh_passes.h"
#include "host/io/input_formats.h"
#include "host/io/slam_json.h"
#include "host/pipeline/front_end.h"
#include "host/pipeline/in_front_check.h"
#include "host/pipeline/keyframe_observers.h"
#include "host/pipeline/mesh_export.h"
#include "host/pipeline/prefetch.h"
#include "host/pipeline/report.h"
#include "host/pipeline/scale.h"
#include "host/pipeline/stage_watch.h"
#include "host/pipeline/streamed_surface.h"
#include "host/pipeline/tiles.h"
#include "host/plugin/host_services.h"
#include "host/plugin/policy_adapter.h"
#include "host/util/atomic_file.h"
#include "host/util/json_text.h"
#include "host/util/log.h"
#include "host/util/process_memory.h"
#include "host/util/thread_pool.h"
#include "host/util/write_rule.h"

#include <chrono>
#include <csignal>
#include <cstdio>
#include <deque>
#include <functional>
#include <future>
#include <map>
#include <memory>
#include <optional>
#include <set>

namespace imr::pipeline {
namespace fs = std::filesystem;
using nlohmann::json;

const char* Version() { return IMR_VERSION; }

namespace {

class SequenceRun {
 public:
  SequenceRun(const ValidatedJob& v, const plugin::PluginRegistry& registry,
              const RunOptions& options, const SequenceRef& seq, SequenceResult* result)
      : v_(v), job_(v.job), registry_(registry), options_(options), seq_(seq), result_(result),
        watch_(options.on_stage_timeout) {
    result_->output_directory = job_.OutputDirectory(seq.name);
    // Only the image front end is overlapped with the engine: its keyframes cost time to make,
    // and it reads no engine state (its cameras, which the exports ask for during the loop, are
    // fixed when it opens).
    overlap_ = options_.overlap && util::AvailableCores() >= 2 &&
               io::FindInputFormat(job_.input.format)->needs_front_end;
  }
  // The front end's threads stop first; then the features and refiner instances are destroyed
  // on the lanes that made and called them.
  ~SequenceRun() {
    prefetch_.reset();
    source_.reset();
    if (refiner_lane_) refiner_lane_->Run([&] {
      dense_.reset();
      refiner_.reset();
    });
    if (features_lane_) features_lane_->Run([&] { features_.reset(); });
  }
  SequenceRun(const SequenceRun&) = delete;
  SequenceRun& operator=(const SequenceRun&) = delete;

  // Throws, naming the keyframe, file or stage, when the sequence fails.
  void Run() {
    try {
      InstantiateStages();
      OpenSource();
      StartEngine();
      StartStreamedSurface();
      AddObservers();
      ProcessKeyframes();
      Finish();
    } catch (const std::exception& e) {
      // The tiles written stay (each whole); their tileset says the sequence failed.
      if (tiles_) tiles_->MarkFailed(e.what());
      throw;
    }
  }

 private:
  void InstantiateStages();
  void OpenSource();
  void StartEngine();
  void StartStreamedSurface();
  void WriteTile(const TileMesh& tile, const fs::path& dir, const std::string& stem);
  void AddObservers();
  void ProcessKeyframes();
  bool NextKeyframe(engine::KeyframeUpdate* update, io::KeyframeInfo* info);
  void Finish();
  void ReleaseFrontEnd();
  engine::Mesh CheckedMesh();
  void FinishStreamedSurface();
  const engine::Mesh& WholeMesh();
  const engine::EngineStats& EngineStats() const { return engine_ ? engine_->Stats() : engine_stats_; }
  // Whether the engine forgot (engine.forget), kept too: a streamed run's ends after it is gone.
  bool Forgot() const { return engine_ ? engine_->forgetting() : engine_forgot_; }
  void WarnAbout();
  void DropBackFaces();
  void Warn(const std::string& warning);
  void Note(const std::string& line);
  void WriteStreamExports();
  void EvaluateMesh(const engine::Mesh& mesh);
  void WriteMeshAndReport(std::future<void>* evaluation);

  const ValidatedJob& v_;
  const io::JobSpec& job_;
  const plugin::PluginRegistry& registry_;
  const RunOptions& options_;
  const SequenceRef& seq_;
  SequenceResult* result_;
  const std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now();

  // With the overlap (RunOptions::overlap, image inputs, 2 cores or more), the features and the
  // refiner instances each live on a lane of their own (prefetch.h): made, called and destroyed
  // there. The engine, the policy and the exporters stay on this thread.
  bool overlap_ = false;
  std::optional<Lane> features_lane_, refiner_lane_;

  // The stages: one policy (weights mode), the exporters, the image front end's two plugins.
  std::optional<plugin::PluginWeightPolicy> policy_;
  Exporters exporters_;
  std::optional<plugin::LoadedInstance> features_, refiner_;
  // The dense stage (optional): called by the front end after the refiner, on its lane.
  std::optional<plugin::LoadedInstance> dense_;
  // The mesh_refiner stage (surface_refinement.h): during the run on its schedule, and at the end.
  std::optional<SurfaceRefinement> refinement_;
  // Every call into a plugin is watched against its stage's timeout: a hung plugin fails the
  // sequence (stage_watch.h). Declared before the source, the policy adapter and the engine,
  // which call plugins through it.
  StageWatch watch_;
  std::vector<WatchedStage> watched_;  // per stage of the job
  // The engine's work on one keyframe, watched under --stage-timeout too: a runaway update
  // (a grid or loop too large to finish) fails the sequence like a hung plugin.
  WatchedStage engine_stage_;
  std::size_t policy_stage_ = 0, features_stage_ = 0, refiner_stage_ = 0, dense_stage_ = 0;

  // The source.
  const io::InputFormat* format_ = nullptr;
  std::unique_ptr<io::KeyframeSource> source_;
  const ImageFrontEndSource* front_end_ = nullptr;  // image inputs: the source itself
  // The front end overlapped with the engine (RunOptions::overlap): keyframes are taken from it
  // instead of source_. Declared after the source and the stages, so that its thread is joined
  // before they go, on every path.
  std::optional<PrefetchingSource> prefetch_;
  io::KeyframeSource& Input() { return prefetch_ ? *prefetch_ : *source_; }
  std::optional<WatchedPolicy> watched_policy_;

  // New points seen from behind the cameras that see them (in_front_check.h).
  InFrontCheck in_front_;

  // The scene's scale (scale.h) and the engine.
  ScaleMode scale_mode_ = ScaleMode::kMetric;
  std::set<std::string> explicit_keys_;  // engine options the job sets
  ScaleProbe probe_;
  ScaleEstimate scale_;
  engine::EngineOptions engine_options_;
  // Keyframes read to decide the scale (auto mode), given to the engine before the rest.
  std::deque<std::pair<engine::KeyframeUpdate, io::KeyframeInfo>> early_;
  std::optional<engine::Engine> engine_;

  // The surface taken in parts as the engine hands them out (engine.forget or output.tiles:
  // streamed_surface.h), its tiles, and the spool the single mesh is read back from (in a
  // staging folder of the output folder: removed on every path).
  std::optional<TileWriter> tiles_;
  std::optional<geo::GeoAnchor> geo_anchor_;  // the input's place on the Earth (KITTI raw oxts)
  std::optional<StagingDirectory> spool_dir_;
  std::optional<StreamedSurface> streamed_;
  ExportImageStats tile_images_;          // summed over the tiles' exports
  engine::EngineStats engine_stats_;      // the engine's, kept when it is destroyed early
  bool engine_forgot_ = false;            // the same
  // The last mesh in memory: ExtractMesh's, or the streamed surface's read back whole (WholeMesh)
  // when something needs it whole; a forgetting run's single mesh is otherwise exported in blocks
  // from the spool and never held (ExportStreamedMesh).
  std::optional<engine::Mesh> mesh_;

  // The keyframe loop.
  io::CanonicalOrder canonical_;
  ExportContext export_context_;
  std::vector<std::unique_ptr<KeyframeObserver>> observers_;  // called in this order
  StreamRecording* recording_ = nullptr;  // the observers the report reads; null: not asked
  InvariantCheck* checks_ = nullptr;
  TraceWriter* trace_ = nullptr;
  Snapshots* snapshots_ = nullptr;
  int keyframes_ = 0;
  double engine_seconds_ = 0.0;

  // Gathered by Finish for the report.
  ReportInputs report_;
};

// The signal that asked to stop, as a user reads it.
std::string SignalWord(int signal) {
  switch (signal) {
    case SIGINT: return "SIGINT (Ctrl-C)";
    case SIGTERM: return "SIGTERM";
    case SIGHUP: return "SIGHUP";
    default: return signal != 0 ? "signal " + std::to_string(signal) : "a stop request";
  }
}

}  // namespace

void NoteJobInputs(const ValidatedJob& v, const SequenceRef& seq, InputScope* inputs) {
  inputs->Add(v.job.file, "the job file");
  const io::InputFormat* format = io::FindInputFormat(v.job.input.format);
  if (format != nullptr && format->sequences_are_paths)
    inputs->Add(seq.source, "the input of sequence '" + seq.name + "'");
  if (v.evaluation.is_object())
    if (const std::string truth = v.evaluation.value("truth", ""); !truth.empty())
      inputs->Add(truth, "the evaluation's ground truth");
}

std::string WhyNotWritableOutputs(const ValidatedJob& v, const RunOptions& options,
                                  const SequenceRef& seq) {
  const fs::path out = v.job.OutputDirectory(seq.name);
  std::vector<fs::path> targets = {out / "report.json", out / "manifest.json"};
  for (const std::string& f : v.job.output.formats) targets.push_back(out / (v.job.output.stem + "." + f));
  if (!options.export_stream.empty())
    targets.push_back(ExpandExportPath(options.export_stream, v, seq.name));
  if (!options.trace.empty()) targets.push_back(ExpandExportPath(options.trace, v, seq.name));
  if (!options.export_colmap.empty()) {
    const fs::path colmap = ExpandExportPath(options.export_colmap, v, seq.name);
    for (const char* f : {"cameras.txt", "images.txt", "points3D.txt"}) targets.push_back(colmap / f);
  }
  for (const fs::path& t : targets)
    if (std::string why = WhyNotWritable(t); !why.empty()) return t.string() + ": " + why;
  return {};
}

SequenceResult RunOneSequence(const ValidatedJob& v, const plugin::PluginRegistry& registry,
                              const RunOptions& options, const SequenceRef& seq) {
  SequenceResult r;
  r.name = seq.name;
  const auto start = std::chrono::steady_clock::now();
  try {
    // What this sequence reads is never what it writes (host/util/write_rule.h); the readers add
    // every file they open.
    InputScope inputs;
    NoteJobInputs(v, seq, &inputs);
    if (const std::string why = WhyNotWritableOutputs(v, options, seq); !why.empty())
      throw WriteRefused(why + "; nothing ran");
    SequenceRun(v, registry, options, seq, &r).Run();
  } catch (const std::exception& e) {
    r.ok = false;
    r.error = e.what();
    r.seconds = SecondsSince(start);
    // Stopped by Ctrl-C, SIGTERM or SIGHUP, in whichever stage: interrupted, as the batch
    // counts it, not an error of the sequence.
    r.interrupted = plugin::CancelRequested();
    if (r.interrupted)
      LogInfo("sequence " + seq.name + " interrupted by " + SignalWord(plugin::CancelSignal()) +
              ": " + r.error);
    else
      LogError("sequence " + seq.name + " failed: " + r.error);
  }
  return r;
}

namespace {

std::optional<render::BackFacing> BackFacingInKeyframes(const engine::Mesh& mesh, const ExportContext& context);
std::optional<render::BackFacing> BackFacingInKeyframes(const StreamedSurface& mesh, const ExportContext& context);
std::vector<render::Camera> BackFacingCameras(const ExportContext& context, std::size_t max_views = 60);
constexpr double kBackFacingScale = 0.25;

// Creates one instance per stage of the job, each creation watched against its stage's timeout.
void SequenceRun::InstantiateStages() {
  for (const io::StageSpec& stage : job_.pipeline)
    watched_.push_back(WatchedStageOf(stage, options_.stage_timeout));
  report_.plugins = json::array();
  watch_.SetPosition("creating the plugin instances");
  for (std::size_t i = 0; i < job_.pipeline.size(); ++i) {
    const io::StageSpec& stage = job_.pipeline[i];
    const plugin::PluginInfo* info = registry_.Find(stage.plugin);
    report_.plugins.push_back(PluginJson(*info, v_.stage_params[i]));
    std::optional<plugin::LoadedInstance> instance;
    auto create = [&] {
      const StageWatch::Call call = watch_.Enter(watched_[i]);
      try {
        instance.emplace(plugin::CreateInstance(*info, v_.stage_params[i]));
      } catch (const std::exception& e) {  // name the stage: its params are in the job there
        throw std::runtime_error(stage.json_path + " (" + stage.kind + "): " + e.what());
      }
    };
    // The dense stage is called where the refiner is (the front end's keyframe loop).
    Lane* lane = !overlap_                  ? nullptr
                 : stage.kind == "features" ? &features_lane_.emplace()
                 : stage.kind == "refiner" || stage.kind == "dense"
                     ? (refiner_lane_ ? &*refiner_lane_ : &refiner_lane_.emplace())
                     : nullptr;
    if (lane != nullptr)
      lane->Run([&] {
        watch_.SetPosition("creating the plugin instances");
        create();
      });
    else
      create();
    if (stage.kind == "weight_policy") {
      policy_.emplace(std::move(*instance), info->id());
      policy_stage_ = i;
    } else if (stage.kind == "exporter") {
      exporters_.emplace_back(&stage, std::move(*instance));
    } else if (stage.kind == "features") {
      features_.emplace(std::move(*instance));
      features_stage_ = i;
    } else if (stage.kind == "refiner") {
      refiner_.emplace(std::move(*instance));
      refiner_stage_ = i;
    } else if (stage.kind == "dense") {
      dense_.emplace(std::move(*instance));
      dense_stage_ = i;
    } else if (stage.kind == "mesh_refiner") {
      refinement_.emplace(stage, std::move(*instance), watched_[i]);
    }
  }
}

// The input format's reader, or for images the front end around the features and refiner
// plugins (validation checked both exist); the policy, watched.
void SequenceRun::OpenSource() {
  format_ = io::FindInputFormat(job_.input.format);
  if (format_->needs_front_end) {
    FrontEndOptions fo;
    fo.keyframe_every = io::ImageSequenceOptionsFromJson(v_.input_options).keyframe_every;
    fo.track_ahead = overlap_;
    io::ImageSequence images = format_->open_images(seq_.source, v_.input_options);
    geo_anchor_ = images.geo;
    // A trimmed sequence (the first lines of longer times/poses files used): said now, and a
    // warning in report.json.
    if (const auto t = images.summary.find("trimmed"); t != images.summary.end())
      for (const json& note : *t) {
        Note(note.get<std::string>());
        result_->warnings.push_back(note.get<std::string>());
      }
    // A short image set (a Middlebury ring of 16) at the default keyframe_every would give the
    // engine too few keyframes to mesh: unless the job chose it, fewer frames between keyframes.
    if (!job_.input.options.contains("keyframe_every")) {
      const int frames = static_cast<int>(images.frames.size());
      const int chosen = ShortSequenceKeyframeEvery(frames, fo.keyframe_every);
      if (chosen != fo.keyframe_every)
        LogInfo("[" + seq_.name + "] " + std::to_string(frames) + " frames: a keyframe every " +
                std::to_string(chosen) + " (keyframe_every " + std::to_string(fo.keyframe_every) +
                " would give " + std::to_string(KeyframeCount(frames, fo.keyframe_every)) +
                " keyframes; input.options.keyframe_every chooses)");
      fo.keyframe_every = chosen;
    }
    auto fe = std::make_unique<ImageFrontEndSource>(std::move(images), features_->instance,
                                                    refiner_->instance, fo);
    fe->Watch(&watch_, &watched_[features_stage_], &watched_[refiner_stage_]);
    if (dense_) fe->SetDense(&dense_->instance, &watched_[dense_stage_]);
    if (overlap_) fe->TrackOn(&*features_lane_);
    front_end_ = fe.get();
    source_ = std::move(fe);
    // Two keyframes ahead absorb the engine's uneven keyframes.
    if (overlap_) prefetch_.emplace(source_.get(), 2, &*refiner_lane_);
  } else {
    source_ = format_->open(seq_.source, v_.input_options);
  }
  export_context_.source = source_.get();
  if (policy_) watched_policy_.emplace(&*policy_, &watch_, watched_[policy_stage_]);
  if (policy_ && v_.engine_options.visibility_mode == engine::VisibilityMode::kExact)
    LogInfo("[" + seq_.name + "] visibility_mode 'exact' keeps exact weights: the weight_policy "
            "stage (" + job_.pipeline[policy_stage_].plugin + ") is not called");
}

// The scene's scale (scale.h): in auto mode the first keyframes are read, measured and kept
// for the engine, which starts with the lengths they give.
void SequenceRun::StartEngine() {
  scale_mode_ = ScaleModeOf(job_.engine, job_.input.format);
  if (job_.engine.is_object())
    for (const auto& item : job_.engine.items()) explicit_keys_.insert(item.key());
  engine_options_ = v_.engine_options;
  if (scale_mode_ == ScaleMode::kAuto) {
    while (!probe_.Enough()) {
      if (plugin::CancelRequested()) throw std::runtime_error("cancelled (signal)");
      engine::KeyframeUpdate u;
      io::KeyframeInfo i;
      if (!Input().Next(&u, &i)) break;
      probe_.Add(u);
      early_.emplace_back(std::move(u), i);
    }
    scale_ = probe_.Estimate();
    std::string line;
    engine_options_ = AutoScaledOptions(v_.engine_options, scale_, explicit_keys_, &line);
    if (scale_.rays == 0) LogWarning("[" + JsonText(seq_.name) + "] " + line);
    else Note(line);
  }
  if (options_.threads > 0) engine_options_.num_threads = options_.threads;  // --threads
  engine_.emplace(engine_options_, watched_policy_ ? &*watched_policy_ : nullptr);
  if (!engine_->init_status().ok())
    throw std::runtime_error("engine: " + engine_->init_status().message());
  // A signal (Ctrl-C, SIGTERM) reaches the engine's long loops, not only the keyframe loop.
  engine_->SetStopCheck([] { return plugin::CancelRequested(); });
  if (options_.stage_timeout > 0.0)
    engine_stage_ = {"engine", "", "engine", options_.stage_timeout, "--stage-timeout"};
}

// With forgetting or tiles, the surface is taken in parts as the engine hands them out: through
// the surface stream to the tiles and to a spool for the single mesh (streamed_surface.h).
void SequenceRun::StartStreamedSurface() {
  const TilesOptions tiles = TilesOptionsFromJson(v_.tiles);
  // Today's path, ExtractMesh at the end, until the engine forgets (engine.forget auto decides
  // on the way: before, it handed nothing out).
  if (streamed_ || (!engine_->forgetting() && !tiles.enabled)) return;
  const fs::path out = result_->output_directory;
  if (tiles.enabled) {
    const std::string job = fs::absolute(job_.file).lexically_normal().string();
    if (const std::string foreign = ForeignTiles(out, job, seq_.name); !foreign.empty())
      throw std::runtime_error("tiles: " + foreign);
    TilesOptions o = tiles;
    // The Steiner spacing as used is known now (auto scaling); the validation checked a fixed one.
    if (const std::string e = o.CheckSize(engine_options_.steiner_spacing); !e.empty())
      throw std::runtime_error("output.tiles.size: " + e);
    if (o.size == 0.0) o.size = 10.0 * engine_options_.steiner_spacing;
    auto frame = [this] {
      std::vector<std::array<double, 9>> rotations;
      for (const imr_camera& c : export_context_.keyframes) {
        std::array<double, 9> r;
        std::copy(c.R, c.R + 9, r.begin());
        rotations.push_back(r);
      }
      return TilesetFrame(rotations);
    };
    // Geo-referenced: the job's origin, else the input's place (its GNSS), said once in the log.
    auto say = [this](const TilesOrigin& g, const std::string& extra) {
      char line[320];
      std::snprintf(line, sizeof(line), "tiles geo-referenced: origin latitude %.8f, longitude %.8f, "
                    "height %.3f m, heading %.3f deg%s (from %s)", g.latitude, g.longitude, g.height,
                    g.heading, extra.c_str(), g.source.c_str());
      Note(line);
    };
    TileWriter::OriginFor origin_for;
    if (o.origin.given) {
      say(o.origin, "");
    } else if (geo_anchor_) {
      origin_for = [say, anchor = *geo_anchor_](const std::array<double, 16>& local) {
        const TilesOrigin g = OriginFromAnchor(anchor, local);
        char extra[128];
        std::snprintf(extra, sizeof(extra), ", the input's attitude (the cameras' mean up %.2f deg from "
                      "the vertical)", g.tilt);
        say(g, extra);
        return g;
      };
    }
    try {
      tiles_.emplace(o, out, json{{"job", JsonText(job)}, {"sequence", JsonText(seq_.name)}}, frame,
                     [this](const TileMesh& t, const fs::path& dir, const std::string& stem) {
                       WriteTile(t, dir, stem);
                     },
                     origin_for);
    } catch (const std::exception& e) {
      throw std::runtime_error(std::string("tiles: ") + e.what());
    }
  }
  fs::path spool;
  if (!job_.output.formats.empty()) {
    spool_dir_.emplace(out);
    spool = spool_dir_->path();
  }
  streamed_.emplace(engine_options_, spool, tiles_ ? &*tiles_ : nullptr);
  if (engine_options_.steiner_export == engine::SteinerExportRule::kOpenSteiner)
    Warn("engine.steiner_export open_steiner: this run writes its surface in parts (engine.forget, "
         "output.tiles), which keep all_steiner's triangles: a region's rim is known only once the "
         "surface is whole");
  if (refinement_) streamed_->SetPartFilter([this](engine::SurfacePart* part) { refinement_->Freeze(part); });
}

// One tile through the job's glb exporter: with the keyframes that may see it (their images for
// this export only), its vertex keys, origin and 3D Tiles' y-up rotation (SDK 1.2).
void SequenceRun::WriteTile(const TileMesh& t, const fs::path& dir, const std::string& stem) {
  watch_.SetPosition("writing tile " + std::to_string(t.index));
  // A level of detail L covers 2^L cells a side and takes every 2^L-th keyframe that may see it:
  // about as many views along it at every level (its texels are as coarse; the node at the top
  // of a 1,000-frame drive decoded ~95 images through the 128 MiB cache, the end's peak).
  ExportContext seeing = KeyframesSeeing(export_context_, t.box, engine_options_.max_ray_length);
  if (t.level > 0) seeing = EveryNthKeyframe(seeing, std::size_t{1} << std::min(t.level, 20));
  TileExportExtras extras;
  extras.vertex_keys = &t.keys;
  extras.origin = t.origin;
  extras.gltf_rotation = TileGltfRotation();
  // A level of detail is shown only from afar: a texel of its geometric error / 16 is about a
  // screen pixel where the viewer turns to its children (their geometric error is smaller), so
  // its atlas need not be as large as theirs together (it was: the images' resolution).
  if (t.level > 0) extras.texel_size = t.geometric_error / kLodTexelsPerError;
  try {
    const ExportImageStats s = ExportMesh(t.mesh, seeing, {"glb"}, exporters_, dir, stem, watch_,
                                          options_.stage_timeout, &extras);
    tile_images_.keyframes += s.keyframes;
    tile_images_.store.requests += s.store.requests;
    tile_images_.store.decodes += s.store.decodes;
    tile_images_.store.evictions += s.store.evictions;
    tile_images_.store.peak_bytes = std::max(tile_images_.store.peak_bytes, s.store.peak_bytes);
    tile_images_.store.decode_seconds += s.store.decode_seconds;
  } catch (const std::exception& e) {
    throw std::runtime_error("tile " + std::to_string(t.index) + " (" +
                             (result_->output_directory / "tiles" / (stem + ".glb")).string() +
                             "): " + e.what());
  }
}

// What runs after every keyframe, in this order (the trace writes the check's time).
void SequenceRun::AddObservers() {
  if (!options_.export_stream.empty() || !options_.export_colmap.empty()) {
    // The spool lies beside the first export: the same disk, a folder the run may write into.
    const fs::path first = ExpandExportPath(
        options_.export_stream.empty() ? options_.export_colmap : options_.export_stream, v_, seq_.name);
    const fs::path beside = first.has_parent_path() ? first.parent_path() : fs::path(".");
    auto o = std::make_unique<StreamRecording>(
        source_.get(), std::string("imr ") + Version() + ", job " + job_.Name() + ", sequence " +
                           seq_.name, beside);
    recording_ = o.get();
    observers_.push_back(std::move(o));
  }
  if (options_.check_invariants_every > 0) {
    auto o = std::make_unique<InvariantCheck>(*engine_, options_.check_invariants_every);
    checks_ = o.get();
    observers_.push_back(std::move(o));
  }
  if (!options_.trace.empty()) {
    auto o = std::make_unique<TraceWriter>(ExpandExportPath(options_.trace, v_, seq_.name), *engine_);
    trace_ = o.get();
    observers_.push_back(std::move(o));
  }
  if (job_.output.snapshot_every > 0) {
    std::function<void(engine::Mesh*)> refined;
    if (refinement_) refined = [this](engine::Mesh* m) { refinement_->ApplyRefined(m); };
    auto o = std::make_unique<Snapshots>(
        *engine_, job_.output.snapshot_every,
        Snapshots::Target{&export_context_, &job_.output.formats, &exporters_,
                          result_->output_directory, job_.output.stem, &watch_,
                          options_.stage_timeout, &result_->extra_files, refined});
    snapshots_ = o.get();
    observers_.push_back(std::move(o));
  }
  observers_.push_back(
      std::make_unique<Progress>(seq_.name, source_->KeyframeCount(), options_.progress));
}

// Input -> engine, keyframe by keyframe, each update in canonical order (run.h).
void SequenceRun::ProcessKeyframes() {
  engine::KeyframeUpdate update;
  io::KeyframeInfo kf;
  while (NextKeyframe(&update, &kf)) {
    if (plugin::CancelRequested()) throw std::runtime_error("cancelled (signal)");
    if (scale_mode_ == ScaleMode::kMetric && !probe_.Enough()) probe_.Add(update);
    in_front_.Add(update, *source_);
    canonical_.Apply(&update);
    watch_.SetPosition("keyframe " + std::to_string(kf.index) + ", frame " + std::to_string(kf.frame));
    const auto engine_start = std::chrono::steady_clock::now();
    const engine::Status st = [&] {
      const StageWatch::Call call = watch_.Enter(engine_stage_);
      return engine_->ApplyUpdate(update);
    }();
    KeyframeEvent event{update, kf};
    event.engine_seconds = SecondsSince(engine_start);
    engine_seconds_ += event.engine_seconds;
    if (!st.ok())
      throw std::runtime_error("keyframe " + std::to_string(kf.index) + " (frame " +
                               std::to_string(kf.frame) + "): " + st.message());
    if (policy_ && policy_->failed())
      throw std::runtime_error("keyframe " + std::to_string(kf.index) + ": weight policy " +
                               policy_->error());
    export_context_.Add(update, kf, front_end_);
    event.keyframes = ++keyframes_;
    if (!streamed_ && engine_->forgetting()) {  // engine.forget auto: the cameras travel
      LogInfo("[" + seq_.name + "] keyframe " + std::to_string(kf.index) + ": the engine forgets from here on "
              "(engine.forget auto: the cameras travel); the surface is written in parts");
      StartStreamedSurface();
    }
    // The refinement first: the parts handed out now carry its positions.
    if (refinement_) refinement_->OnKeyframe(*engine_, export_context_, watch_, keyframes_);
    if (streamed_) {
      watch_.SetPosition("keyframe " + std::to_string(kf.index) + ": the final parts of the surface");
      streamed_->Take(*engine_);
    }
    for (const auto& observer : observers_) observer->OnKeyframe(event);
  }
}

// The keyframes read to decide the scale first, then the rest.
bool SequenceRun::NextKeyframe(engine::KeyframeUpdate* update, io::KeyframeInfo* info) {
  if (early_.empty()) return Input().Next(update, info);
  *update = std::move(early_.front().first);
  *info = early_.front().second;
  early_.pop_front();
  return true;
}

// The last mesh, checked and with its warnings; then exports first (each whole or absent), the
// evaluation, the mesh and the report. With the overlap (2 cores or more) the evaluation, which
// only reads the mesh and the source, runs beside the mesh's export; its error still comes first.
// A streamed run's mesh stays on disk unless the evaluation needs it whole (a source that cannot
// measure it in blocks, the job's "evaluation"), an export does (colours, a texture, glTF/GLB),
// or forgetting is off (tiles only: the single mesh in canonical order, today's bytes).
void SequenceRun::Finish() {
  ReleaseFrontEnd();
  if (streamed_)
    FinishStreamedSurface();
  else
    mesh_ = CheckedMesh();
  if (refinement_ && !streamed_) {  // the mesh written and measured is the refined one
    refinement_->Finish(&*mesh_, export_context_, watch_);
    report_.mesh_check = engine::CheckMesh(*mesh_, /*closed=*/false);
  }
  if (!streamed_) {  // after the refinement, as a streamed run does per released piece
    // A pass that leaves the mesh no manifold (a case its own rules missed) is undone with a
    // warning: the surface before it is written.
    engine::MeshPassesStats passes;
    engine::RunMeshPasses(engine::MeshPasses(engine_options_, &passes), &*mesh_, &passes,
                          &report_.mesh_check, [this](const std::string& w) { Warn(w); });
    report_.planes = passes.planes;
    report_.flips = passes.flips;
    report_.normal_filter = passes.normal_filter;
    report_.pieces_undone = passes.undone;
    report_.undone_why = passes.undone_why;
    if (engine_options_.drop_back_faces) DropBackFaces();
  }
  WarnAbout();
  WriteStreamExports();
  // A source that measures the mesh triangle by triangle reads it in blocks too.
  std::unique_ptr<io::BlockEvaluation> blocks;
  const bool forgot = Forgot();
  if (streamed_ && forgot && v_.evaluation.is_null() && !job_.output.formats.empty())
    blocks = source_->EvaluateInBlocks();
  if (streamed_ && (!forgot || (source_->CanEvaluate() && !blocks) ||
                    !v_.evaluation.is_null()))
    WholeMesh();
  // The back-facing share of the mesh in memory, else of the spooled one read in blocks (the
  // same faces in the same order as read whole).
  if (mesh_ && !mesh_->faces.empty())
    report_.back_facing = BackFacingInKeyframes(*mesh_, export_context_);
  else if (streamed_ && forgot && !job_.output.formats.empty() && streamed_->face_count() > 0)
    report_.back_facing = BackFacingInKeyframes(*streamed_, export_context_);
  std::function<void()> evaluate;
  if (mesh_) {
    evaluate = [this] { EvaluateMesh(*mesh_); };
  } else if (blocks) {
    evaluate = [this, &blocks] {
      streamed_->ForEachTriangleBlock(
          [&](const std::vector<double>& v, const std::vector<uint32_t>& f) { blocks->AddTriangles(v, f); });
      report_.accuracy = blocks->Finish();
      blocks.reset();  // its truth samples (1.5 M on a 5,000-frame imr-synth street) go now
    };
  }
  std::future<void> evaluation;
  if (evaluate && overlap_ && front_end_ != nullptr)  // as with the front end's prefetch
    evaluation = std::async(std::launch::async, evaluate);
  else if (evaluate)
    evaluate();
  WriteMeshAndReport(&evaluation);
}

// The input read to its end: the front end's threads stop and its plugins go (the tracker's image
// pyramids, the dense stage's frames: ~18 MB at the end of an imr-synth drive), each on the lane
// that made it, before the end's refine call and exports decode keyframe images. The front end
// itself stays (its figures, the evaluation against its ground truth) and calls no plugin again.
void SequenceRun::ReleaseFrontEnd() {
  if (front_end_ == nullptr) return;
  prefetch_.reset();
  if (refiner_lane_)
    refiner_lane_->Run([&] {
      dense_.reset();
      refiner_.reset();
    });
  else {
    dense_.reset();
    refiner_.reset();
  }
  if (features_lane_) features_lane_->Run([&] { features_.reset(); });
  else features_.reset();
}

const engine::Mesh& SequenceRun::WholeMesh() {
  if (!mesh_) mesh_ = streamed_->ReadMesh(/*canonical=*/!Forgot());
  return *mesh_;
}

// The mesh after the last keyframe; throws when dO or the mesh is not what it must be.
engine::Mesh SequenceRun::CheckedMesh() {
  engine::Mesh mesh = engine_->ExtractMesh(&report_.small_components_dropped);
  report_.engine_memory = engine_->Memory();
  report_.boundary_check = engine_->CheckInvariants();
  report_.mesh_check = engine::CheckMesh(mesh, /*closed=*/false);
  if (!report_.boundary_check.ok)
    throw std::runtime_error("invariant check failed after the last keyframe (" +
                             std::to_string(keyframes_) + "): " + report_.boundary_check.message);
  if (!report_.mesh_check.ok)
    throw std::runtime_error("exported mesh check failed: " + report_.mesh_check.message);
  return mesh;
}

// The streamed surface's end: what is left of the engine's surface (its last part, and the mesh
// the refinement's final call takes), dO checked and the engine's figures taken; then the engine
// goes (its memory with it) before the final refine call, the last part, the last tiles and the
// exports, which decode keyframe images (the end of a 5,000-frame drive peaked with both). The
// single mesh was checked as it was spooled, one vertex at a time.
void SequenceRun::FinishStreamedSurface() {
  watch_.SetPosition("the last part of the surface and its tiles");
  std::optional<engine::Mesh> live;
  double extract_seconds = 0.0;
  if (refinement_) {
    const auto start = std::chrono::steady_clock::now();
    live = engine_->ExtractMesh();
    extract_seconds = SecondsSince(start);
  }
  engine::SurfacePart last = engine_->FinishSurface();
  report_.boundary_check = engine_->CheckInvariants();
  if (!report_.boundary_check.ok)
    throw std::runtime_error("invariant check failed after the last keyframe (" +
                             std::to_string(keyframes_) + "): " + report_.boundary_check.message);
  engine_stats_ = engine_->Stats();
  engine_forgot_ = engine_->forgetting();
  report_.engine_memory = engine_->Memory();
  engine_.reset();
  if (refinement_) refinement_->FinishLive(std::move(*live), extract_seconds, export_context_, watch_);
  live.reset();
  streamed_->Finish(std::move(last));
  if (tiles_)
    for (const fs::path& f : tiles_->files()) result_->extra_files.push_back(f);
  if (!job_.output.formats.empty()) {
    report_.mesh_check = streamed_->mesh_check();
    if (!report_.mesh_check.ok)
      throw std::runtime_error("exported mesh check failed: " + report_.mesh_check.message);
  }
}

// The share of what the keyframes see that faces away from them (report.json mesh.back_facing):
// at most `max_views` (60) keyframes spread over the run, each drawn at a quarter of its size.
// None for inputs without intrinsics.
std::vector<render::Camera> BackFacingCameras(const ExportContext& context, std::size_t max_views) {
  std::vector<const imr_camera*> usable;
  for (const imr_camera& c : context.keyframes)
    if (c.K[0] > 0.0 && c.K[4] > 0.0 && c.width > 0 && c.height > 0) usable.push_back(&c);
  std::vector<render::Camera> cameras;
  for (std::size_t i = 0; i < std::min(max_views, usable.size()); ++i) {
    const imr_camera& c = *usable[i * usable.size() / std::min(max_views, usable.size())];
    render::Camera r;
    r.width = c.width, r.height = c.height;
    r.fx = c.K[0], r.fy = c.K[4], r.cx = c.K[2], r.cy = c.K[5];
    for (int a = 0; a < 3; ++a) {
      for (int b = 0; b < 3; ++b) r.rotation[a][b] = c.R[3 * a + b];
      r.translation[a] = c.t[a];
    }
    if (r.Check().empty()) cameras.push_back(r);
  }
  return cameras;
}

// engine.drop_back_faces: the faces the keyframes see from behind more than from the front go (up
// to 300 keyframes spread over the run, each drawn at a quarter of its size), then those the
// dropped ones hid and that are now so seen, up to three times; pieces left under
// min_component_area go too. A mesh all of whose faces are so seen is kept, with a warning.
void SequenceRun::DropBackFaces() {
  std::vector<render::Camera> cameras = BackFacingCameras(export_context_, 300);
  if (cameras.empty() || mesh_->faces.empty()) return;
  for (int pass = 0; pass < 3; ++pass) {
    const std::vector<uint8_t> behind = render::FacesSeenFromBehind(
        render::MeshRefOf(mesh_->vertices, mesh_->faces), cameras, kBackFacingScale);
    if (std::find(behind.begin(), behind.end(), 0) == behind.end()) {
      Warn("engine.drop_back_faces: the keyframes see every face of the surface from behind "
           "more than from the front (its orientation?): it is written as it is");
      break;
    }
    const int64_t dropped = engine::DropFaces(&*mesh_, behind, engine_options_.MinComponentArea(),
                                              &report_.small_components_dropped);
    if (dropped == 0) break;
    report_.back_faces_dropped += dropped;
  }
  report_.mesh_check = engine::CheckMesh(*mesh_, /*closed=*/false);
  if (!report_.mesh_check.ok)
    throw std::runtime_error("engine.drop_back_faces left no manifold: " + report_.mesh_check.message);
}

std::optional<render::BackFacing> BackFacingInKeyframes(const engine::Mesh& mesh, const ExportContext& context) {
  const std::vector<render::Camera> cameras = BackFacingCameras(context);
  if (cameras.empty()) return std::nullopt;
  return render::MeasureBackFacing(render::MeshRefOf(mesh.vertices, mesh.faces), cameras, kBackFacingScale);
}

std::optional<render::BackFacing> BackFacingInKeyframes(const StreamedSurface& mesh, const ExportContext& context) {
  const std::vector<render::Camera> cameras = BackFacingCameras(context);
  if (cameras.empty()) return std::nullopt;
  render::BackFacingInBlocks blocks(cameras, kBackFacingScale);
  mesh.ForEachTriangleBlock([&](const std::vector<double>& v, const std::vector<uint32_t>& f) {
    blocks.AddTriangles(render::MeshRefOf(v, f));
  });
  return blocks.Result();
}

// Warnings: on stderr and in report.json (the summary lists them).
void SequenceRun::Warn(const std::string& warning) {
  LogWarning("[" + JsonText(seq_.name) + "] " + warning);
  result_->warnings.push_back(warning);
}

// A line worth reading at the default verbosity (RunOptions::note).
void SequenceRun::Note(const std::string& line) {
  const std::string shown = "[" + JsonText(seq_.name) + "] " + line;
  if (options_.note) options_.note(shown);
  else LogInfo(shown);
}

// What looks wrong though a mesh was made; no surface at all fails the sequence.
void SequenceRun::WarnAbout() {
  // A model with a share collapsed to one spot: left out by the reader (sfm_source.cc).
  if (const json s = source_ ? source_->Summary() : json(); s.is_object() && s.contains("collapsed")) {
    const json& c = s["collapsed"];
    std::string what;
    for (const char* k : {"views", "points"})
      if (c.contains(k))
        what += (what.empty() ? "" : " and ") + c[k]["left_out"].dump() + " of " + c[k]["of"].dump() +
                (std::string(k) == "views" ? " camera centres" : " points");
    const json& at = c.contains("points") ? c["points"]["at"] : c["views"]["at"];
    char spot[160];
    std::snprintf(spot, sizeof spot, "(%.6g, %.6g, %.6g), within %.3g", at[0].get<double>(),
                  at[1].get<double>(), at[2].get<double>(), c["within"].get<double>());
    Warn(what + " sit at one spot " + spot + ": a share of the model collapsed (a failed merge "
         "in the SfM run, cameras with no baseline); they were left out");
  }
  // A short sequence never reached the 100 observations of InFrontCheck; a few behind is noise,
  // more than 5 % is worth a word.
  if (2 * in_front_.behind() > in_front_.checked() && in_front_.checked() > 0)
    throw std::runtime_error(in_front_.Message());
  if (20 * in_front_.behind() > in_front_.checked()) Warn(in_front_.Message());
  // Pieces of a streamed surface that the planes, flips and normal filter passes would have broken.
  if (streamed_ && streamed_->stats().pieces_undone > 0)
    Warn("engine.retriangulate_planes, flip_edges and filter_normals undone on " +
         std::to_string(streamed_->stats().pieces_undone) +
         " released piece(s): they changed the piece's fans where other pieces meet it (" +
         streamed_->stats().undone_why + ")");
  // Rays longer than max_ray_length are not cast: most of them skipped usually means the
  // scene is not in metres (or is much larger or smaller than the defaults assume).
  const engine::EngineStats& stats = EngineStats();
  std::string scale_hint;
  if (stats.rays_skipped_too_long > stats.rays_cast) {
    scale_hint = std::to_string(stats.rays_skipped_too_long) + " of " +
                 std::to_string(stats.rays_skipped_too_long + stats.rays_cast) +
                 " rays were longer than engine.max_ray_length (" +
                 std::to_string(engine_options_.max_ray_length) +
                 "): set max_ray_length and steiner_spacing to the scene's scale";
    Warn(scale_hint);
  }
  // A metric job on a scene of another size: say so, with the values auto would choose.
  if (scale_mode_ == ScaleMode::kMetric) {
    const ScaleEstimate e = probe_.Estimate();
    if (e.rays > 0 && (e.factor < 0.25 || e.factor > 4.0)) {
      const engine::EngineOptions proposed = ScaledOptions(engine_options_, e, explicit_keys_);
      std::string hint = ScaleLogLine(e, proposed, explicit_keys_);
      hint.replace(0, std::string("engine.scale auto: ").size(), "");
      scale_hint = std::string("the scene is ") + (e.factor < 1.0 ? "far smaller" : "far larger") +
                   " than the engine's metric defaults assume: " + hint +
                   " would fit; set engine.scale \"auto\" (or these options) in the job";
      Warn(scale_hint);
    }
  }
  if (const std::string w = ForgettingWarning(stats, engine_options_); !w.empty()) Warn(w);
  if (const std::string w = SteinerGridWarning(stats, engine_options_); !w.empty()) Warn(w);
  if (MostPointsRefused(stats))
    if (const std::string w = RefusedPointsWarning(stats, mesh_ ? *mesh_ : WholeMesh()); !w.empty())
      Warn(w);
  const int64_t triangles = streamed_ ? streamed_->stats().stream.triangles_released
                                      : static_cast<int64_t>(mesh_->faces.size() / 3);
  if (triangles == 0) {
    // What would change it: more keyframes for a short image set, the scale for a scene of
    // another size.
    std::string hint;
    if (front_end_ != nullptr && keyframes_ < kMinKeyframes)
      hint = "; few keyframes: --set input.options.keyframe_every=1 makes every frame one";
    throw std::runtime_error("no surface was reconstructed (0 triangles after " +
                             std::to_string(keyframes_) + " keyframes): nothing to export" + hint +
                             (scale_hint.empty() ? "" : "; " + scale_hint));
  }
  if (recording_ != nullptr && recording_->recorder().unrepresentable() > 0)
    Warn(std::to_string(recording_->recorder().unrepresentable()) +
         " points entered the engine with no camera: the exported stream cannot hold them, so "
         "its replay will differ");
}

// Runs `write` (files into the staging folder `staging`); a failure names the file where it was
// to go in `destination`, not its staged copy.
template <class F>
void WriteStaged(const fs::path& staging, const fs::path& destination, F write) {
  try {
    write();
  } catch (const std::runtime_error& e) {
    std::string what = e.what();
    const std::string staged = staging.string() + "/";
    if (what.rfind(staged, 0) == 0)
      what = (destination.empty() ? fs::path(".") : destination).string() + "/" + what.substr(staged.size());
    throw std::runtime_error(what);
  }
}

// --export-stream and --export-colmap, from the recorded updates.
void SequenceRun::WriteStreamExports() {
  if (!options_.export_stream.empty()) {
    const fs::path p = ExpandExportPath(options_.export_stream, v_, seq_.name);
    CheckWriteTarget(p);  // before the file is written: a refusal costs no time
    // Written streamed into a staging folder beside it, then renamed into place.
    StagingDirectory out(p.has_parent_path() ? p.parent_path() : fs::path("."));
    WriteStaged(out.path(), p.parent_path(), [&] { recording_->recorder().WriteSlamJson(out.path() / p.filename()); });
    out.Commit();
    report_.exports["stream"] = fs::absolute(p).string();
    result_->extra_files.push_back(p);
  }
  if (!options_.export_colmap.empty()) {
    const fs::path p = ExpandExportPath(options_.export_colmap, v_, seq_.name);
    StagingDirectory colmap(p);
    WriteStaged(colmap.path(), p, [&] { recording_->recorder().WriteColmap(colmap.path()); });
    for (auto& f : colmap.Commit()) result_->extra_files.push_back(std::move(f));
    report_.exports["colmap"] = fs::absolute(p).string();
  }
}

// The source's own figures (a known synthetic scene) and, with the job's "evaluation", the
// figures against its ground truth, which win the "accuracy" key (the summary's column).
void SequenceRun::EvaluateMesh(const engine::Mesh& mesh) {
  if (mesh.faces.empty()) return;  // tiles only: no mesh in memory to measure
  report_.accuracy = source_->Evaluate(mesh);
  if (v_.evaluation.is_null()) return;
  const auto start = std::chrono::steady_clock::now();
  report_.accuracy_known_scene = std::move(report_.accuracy);
  report_.accuracy = EvaluateAgainstTruth(v_.evaluation, mesh, front_end_);
  report_.evaluation_seconds = SecondsSince(start);
}

// The mesh in every format and report.json, staged together and moved into the output folder,
// the glTF and report.json last: when the report cannot be written (a full disk) no mesh of the
// failed run is left under a final name either.
void SequenceRun::WriteMeshAndReport(std::future<void>* evaluation) {
  const auto export_start = std::chrono::steady_clock::now();
  StagingDirectory staging(result_->output_directory);
  watch_.SetPosition("writing the mesh after the last keyframe");
  try {
    // A mesh on disk in blocks to each exporter that takes them; whole to the others.
    std::vector<std::string> whole = job_.output.formats;
    if (!mesh_ && !whole.empty()) {
      whole.clear();
      report_.export_images = ExportStreamedMesh(*streamed_, export_context_, job_.output.formats,
                                                 exporters_, staging.path(), job_.output.stem,
                                                 watch_, options_.stage_timeout, &whole);
      report_.formats_streamed = job_.output.formats.size() - whole.size();
    }
    if (!whole.empty())
      report_.export_images = ExportMesh(WholeMesh(), export_context_, whole, exporters_,
                                         staging.path(), job_.output.stem, watch_,
                                         options_.stage_timeout);
  } catch (...) {
    if (evaluation->valid()) evaluation->get();  // its error first, as without the overlap
    throw;
  }
  report_.export_seconds = SecondsSince(export_start);
  if (evaluation->valid()) evaluation->get();
  spool_dir_.reset();  // the evaluation may read it in blocks until here
  const std::vector<std::string> commit_last = {job_.output.stem + ".gltf", "report.json"};

  report_.job = &v_;
  report_.sequence = &seq_;
  report_.format = format_;
  report_.source = source_.get();
  report_.front_end = front_end_;
  report_.engine_options = engine_options_;
  report_.scale_mode = scale_mode_;
  report_.scale = scale_;
  report_.explicit_keys = explicit_keys_;
  report_.stats = &EngineStats();
  if (streamed_) report_.streamed = &streamed_->stats();
  if (refinement_) report_.refinement = &refinement_->stats();
  if (tiles_) {
    report_.tiles = &tiles_->stats();
    report_.tile_images = tile_images_;
  }
  report_.peak_rss_bytes = PeakResidentBytes();
  report_.final_rss_bytes = ResidentBytes();
  report_.final_heap = CurrentHeapBytes();
  if (recording_ != nullptr) {
    const io::StreamRecorder& r = recording_->recorder();
    const io::StreamRecorder::Stats st = r.stats();
    report_.export_recorder = {{"held_bytes", r.HeldBytes()},        {"views", st.views},
                               {"observations", st.observations},   {"points_spooled", st.points_spooled},
                               {"points_recovered", st.points_recovered}, {"spool_scans", st.spool_scans},
                               {"evict_after_keyframes", st.evict_after_keyframes}};
  }
  report_.mesh = mesh_ ? &*mesh_ : nullptr;
  if (streamed_ && !job_.output.formats.empty()) report_.streamed_mesh = &*streamed_;
  report_.engine_seconds = engine_seconds_;
  report_.keyframe_images = !export_context_.image_paths.empty();
  report_.snapshots = snapshots_;
  report_.checks = checks_;
  if (trace_ != nullptr) {
    report_.trace = trace_->Finish();
    result_->extra_files.push_back(report_.trace);
  }
  report_.warnings = result_->warnings;
  for (const auto& f : staging.Staged(commit_last)) report_.files.push_back(f.filename().string());
  result_->seconds = SecondsSince(start_);
  report_.seconds = result_->seconds;
  json report = BuildReport(report_);
  WriteFileAtomically(staging.path() / "report.json", DumpJson(report, 2) + "\n");
  result_->files = staging.Commit(commit_last);
  result_->report = std::move(report);
  result_->ok = true;
}

}  // namespace

std::vector<std::string> CheckRunOptions(const RunOptions& o, const ValidatedJob& v) {
  std::vector<std::string> problems;
  if (const std::string e = CheckStageTimeout(o.stage_timeout); !e.empty())
    problems.push_back("--stage-timeout: " + e);
  if (o.check_invariants_every < 0)
    problems.push_back("--check-invariants-every " + std::to_string(o.check_invariants_every) +
                       ": expected a number of keyframes >= 1");
  // The range of imr run's --threads (batch/run_flags.cc); 0 leaves it to the job. Checked here
  // too for the callers that set it without the flag (the Python module's imr.run(threads=)).
  if (o.threads < 0 || o.threads > 1024)
    problems.push_back("threads " + std::to_string(o.threads) +
                       ": expected a number of threads in 1..1024 (0: the job's engine.threads)");
  const std::pair<const char*, const std::string*> flags[] = {
      {"--export-stream", &o.export_stream}, {"--export-colmap", &o.export_colmap},
      {"--trace", &o.trace}};
  for (const auto& [flag, value] : flags) {
    if (value->empty() || v.sequences.size() < 2) continue;
    if (value->find("{sequence}") == std::string::npos && value->find("{output}") == std::string::npos)
      problems.push_back(std::string(flag) + " " + *value + ": the job has " +
                         std::to_string(v.sequences.size()) +
                         " sequences; put {sequence} or {output} in the path so that each gets "
                         "its own (e.g. '{output}/stream.json')");
  }
  // An export must not be (or hold) an output folder: a stream file where a sequence's folder
  // goes breaks that sequence on every later run.
  auto folder = [](const fs::path& p) {
    fs::path n = fs::absolute(p).lexically_normal();
    return n.has_relative_path() && n.filename().empty() ? n.parent_path() : n;
  };
  std::map<fs::path, std::string> folders;  // output folders and their parents -> a sequence
  for (const SequenceRef& s : v.sequences)
    for (fs::path p = folder(v.job.OutputDirectory(s.name)); p.has_relative_path(); p = p.parent_path())
      folders.emplace(p, s.name);
  for (const auto& [flag, value] : flags) {
    if (value->empty()) continue;
    for (const SequenceRef& s : v.sequences) {
      const fs::path p = folder(ExpandExportPath(*value, v, s.name));
      const auto it = folders.find(p);
      if (it == folders.end()) continue;
      problems.push_back(std::string(flag) + " " + *value + ": " + p.string() +
                         (p == folder(v.job.OutputDirectory(it->second))
                              ? " is the output folder of sequence '"
                              : " holds the output folder of sequence '") +
                         JsonText(it->second) + "'; name a file (or folder) of its own, e.g. " +
                         "'{output}/stream.json'");
      break;
    }
  }
  for (const auto& [a, b] : {std::pair{&o.export_stream, &o.export_colmap},
                             std::pair{&o.export_stream, &o.trace},
                             std::pair{&o.export_colmap, &o.trace}})
    if (!a->empty() && *a == *b)
      problems.push_back("two of --export-stream, --export-colmap and --trace name the same "
                         "path (" + *a + ")");
  return problems;
}

fs::path ExpandExportPath(const std::string& tmpl, const ValidatedJob& v, const std::string& sequence) {
  return io::ExpandTemplate(tmpl, {{"{sequence}", sequence},
                                   {"{job}", v.job.Name()},
                                   {"{output}", v.job.OutputDirectory(sequence).string()}});
}

}  // namespace imr::pipeline
