// A sequence's report.json (host/pipeline/REPORT.md lists its keys), built from what the run
// gathered; and the pieces of it computed from the inputs (checksums, accuracy, warnings).
#pragma once

#include "host/engine/engine.h"
#include "host/io/input_formats.h"
#include "host/pipeline/front_end.h"
#include "host/pipeline/job_validation.h"
#include "host/pipeline/keyframe_observers.h"
#include "host/pipeline/mesh_export.h"
#include "host/pipeline/scale.h"
#include "host/pipeline/streamed_surface.h"
#include "host/pipeline/surface_refinement.h"
#include "host/pipeline/tiles.h"
#include "host/util/process_memory.h"
#include "host/plugin/registry.h"
#include "host/render/rasterizer.h"

#include <nlohmann/json.hpp>

#include <filesystem>
#include <optional>
#include <set>
#include <string>
#include <vector>

namespace imr::pipeline {

// One stage of the job as the report names it: id, version, kind, abi, file, params.
nlohmann::json PluginJson(const plugin::PluginInfo& info, const nlohmann::json& params);

// Accuracy against the ground truth the job names (its "evaluation" section, with defaults), as
// the report's "accuracy": the paper's mean distance from ground truth to the mesh, completeness
// and precision at the job's tau, and host/eval's full report under "evaluation". Velodyne
// ground truth needs an image sequence (`front_end`), whose cameras also crop the truth.
nlohmann::json EvaluateAgainstTruth(const nlohmann::json& evaluation, const engine::Mesh& mesh,
                                    const ImageFrontEndSource* front_end);

// When most points never entered the triangulation (all at one position, at a camera, or cut
// off by the reconstructed volume), the mesh rests on a few points and is mostly the Steiner
// grid's: "ok" alone would hide it. Empty when a half or less was refused (points refused at
// first and entered later, as they moved, count as entered).
std::string RefusedPointsWarning(const engine::EngineStats& stats, const engine::Mesh& mesh);
// Whether RefusedPointsWarning has something to say (it needs the mesh whole; this does not).
bool MostPointsRefused(const engine::EngineStats& stats);

// Forgetting (engine.forget) keeps what it handed out as it was: a change that would reshape it
// is refused, an update of a point it forgot is ignored. Either makes a mesh other than the run
// without forgetting would: said with the counts and what would keep more. Empty when nothing
// was refused or ignored (or forgetting is off).
std::string ForgettingWarning(const engine::EngineStats& stats, const engine::EngineOptions& options);

// The Steiner grid follows the rays (a margin around each), so it grows with the points and
// their rays; a grid step far below the scene's scale still makes it outgrow them, and with it
// the run's time and memory (about 1.1 kB a Steiner point). Said, with the options to change, when
// it holds more than kSteinerWarnRatio Steiner points a data point and at least
// kSteinerWarnFloor of them (a small scene's grid costs little whatever the ratio). Empty
// otherwise.
inline constexpr double kSteinerWarnRatio = 20.0;
inline constexpr int64_t kSteinerWarnFloor = 100000;
std::string SteinerGridWarning(const engine::EngineStats& stats, const engine::EngineOptions& options);

// What the report is made of, gathered by the run (host/pipeline/run.cc) as it goes.
struct ReportInputs {
  const ValidatedJob* job = nullptr;
  const SequenceRef* sequence = nullptr;
  const io::InputFormat* format = nullptr;
  const io::KeyframeSource* source = nullptr;
  const ImageFrontEndSource* front_end = nullptr;  // image inputs only
  nlohmann::json plugins;                          // PluginJson per stage, in job order
  // The engine's options as used, and how its scale was decided (scale.h).
  engine::EngineOptions engine_options;
  ScaleMode scale_mode = ScaleMode::kMetric;
  ScaleEstimate scale;
  std::set<std::string> explicit_keys;
  const engine::EngineStats* stats = nullptr;
  engine::EngineMemory engine_memory;  // at the end of the run
  uint64_t peak_rss_bytes = 0, final_rss_bytes = 0;  // the process's (one sequence per process in a batch)
  HeapBytes final_heap;  // the allocator's figures at the end, beside final_rss_bytes
  nlohmann::json export_recorder;  // --export-stream/--export-colmap's recorder (null: not asked)
  const engine::Mesh* mesh = nullptr;  // null: tiles only, or the single mesh written in blocks
  const StreamedSurface* streamed_mesh = nullptr;  // the single mesh on disk (streamed runs)
  std::size_t formats_streamed = 0;    // of the job's formats, written in blocks
  engine::ManifoldCheckResult boundary_check, mesh_check;
  engine::DroppedComponents small_components_dropped;  // by ExtractMesh (a streamed run: its stats)
  engine::PlaneRetriangulationStats planes;  // engine.retriangulate_planes (a streamed run: its stats)
  engine::EdgeFlipStats flips;               // engine.flip_edges (a streamed run: its stats)
  engine::NormalFilterStats normal_filter;   // engine.filter_normals (a streamed run: its stats)
  int64_t back_faces_dropped = 0;            // engine.drop_back_faces (a whole mesh only)
  // The mesh (or, streamed, the pieces) written without a pass that broke it; the first why.
  int64_t pieces_undone = 0;
  std::string undone_why;
  nlohmann::json accuracy, accuracy_known_scene;  // null: none
  double engine_seconds = 0.0, export_seconds = 0.0, evaluation_seconds = 0.0;
  ExportImageStats export_images;
  bool keyframe_images = false;               // the exporters were offered keyframe images
  const Snapshots* snapshots = nullptr;       // null: no snapshots asked
  const StreamedSurfaceStats* streamed = nullptr;  // null: the surface was taken whole
  const TilesStats* tiles = nullptr;          // null: no tiles asked
  ExportImageStats tile_images;               // the tiles' exports, summed
  const SurfaceRefinementStats* refinement = nullptr;  // null: no mesh_refiner stage
  std::optional<render::BackFacing> back_facing;       // of the final mesh in the keyframes
  const InvariantCheck* checks = nullptr;     // null: no check during the loop
  std::filesystem::path trace;                // empty: no trace
  nlohmann::json exports = nlohmann::json::object();  // stream, colmap: absolute paths
  std::vector<std::string> warnings;
  std::vector<std::string> files;             // names in the output folder, report.json last
  double seconds = 0.0;                       // the sequence's wall time
};

nlohmann::json BuildReport(const ReportInputs& in);

// The report's "engine" object: every counter of the engine's stats (REPORT.md lists them).
nlohmann::json EngineStatsJson(const engine::EngineStats& stats);

}  // namespace imr::pipeline
