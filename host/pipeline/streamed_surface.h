// The surface as the engine hands it out in parts (DESIGN.md section 10), for the run of one
// sequence when the engine forgets (engine.forget) or the job asks for tiles (output.tiles):
// after every update the engine's final parts go through the surface stream (pinched vertices
// split, small holes filled: host/engine/surface_stream.h), and what the stream releases goes to
// the tiles (tiles.h) and, when the job names mesh files, to a spool file on disk. At the end the
// rest of the surface (Engine::FinishSurface) goes the same way, and the single mesh is read back
// from the spool: after the engine is gone, so the mesh never sits in memory beside it.
#pragma once

#include "host/engine/engine.h"
#include "host/engine/surface_stream.h"
#include "host/pipeline/tiles.h"

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>

namespace imr::pipeline {

struct StreamedSurfaceStats {
  engine::SurfaceStreamStats stream;
  int64_t engine_parts = 0;        // parts the engine handed out (its last included)
  int64_t spool_bytes = 0;         // 0: no spool (tiles only)
  double seconds = 0.0;            // in Take and Finish: the stream, the spool, the tiles
  double max_update_seconds = 0.0; // the longest Take (one keyframe's parts)
};

class StreamedSurface {
 public:
  // `spool` empty: no single mesh (tiles only); else the spool file to write (its folder
  // exists; the caller removes it). `tiles` may be null (no tiles).
  StreamedSurface(const engine::EngineOptions& options, std::filesystem::path spool, TileWriter* tiles);
  // After each ApplyUpdate: the parts that became final. Throws when a part does not fit.
  void Take(engine::Engine& engine);
  // After the last update: the rest of the surface, the open tiles and the final tileset.
  void Finish(engine::Engine& engine);
  // The mesh the spool holds, vertices merged by key; in canonical order when `canonical` (the
  // order ExtractMesh gives: with one part, the same bytes), else in the order released.
  // Throws naming the spool when it cannot be read.
  engine::Mesh ReadMesh(bool canonical);

  const StreamedSurfaceStats& stats() const { return stats_; }

 private:
  void Feed(const engine::SurfacePart& part);

  engine::SurfaceStream stream_;
  std::filesystem::path spool_path_;
  std::ofstream spool_;
  TileWriter* tiles_;
  StreamedSurfaceStats stats_;
};

}  // namespace imr::pipeline
