// Handing a mesh to the job's exporter plugins: every output format through the first exporter
// stage that writes it, with what SDK 1.1 carries beside the mesh (the keyframes so far, their
// images on demand, the points' colours).
#pragma once

#include "host/engine/engine.h"
#include "host/io/keyframe_source.h"
#include "host/pipeline/front_end.h"
#include "host/pipeline/stage_watch.h"
#include "host/plugin/keyframe_images.h"
#include "host/plugin/host_services.h"

#include <imr/sdk/plugin.h>

#include <array>
#include <cstdint>
#include <filesystem>
#include <set>
#include <string>
#include <utility>
#include <vector>

namespace imr::pipeline {

// The job's exporter stages, in job order, with their instances.
using Exporters = std::vector<std::pair<const io::StageSpec*, plugin::LoadedInstance>>;

// What an export carries beside the mesh (SDK 1.1): the keyframes so far, their image files
// (inputs with images) and the source, which may know the points' colours.
struct ExportContext {
  std::vector<imr_camera> keyframes;
  std::vector<std::string> image_paths;  // one per keyframe, or empty: no images
  const io::KeyframeSource* source = nullptr;

  // Records the cameras of a keyframe update: the keyframe's own camera for image inputs (the
  // update also carries the frames between keyframes), every new camera for the others.
  void Add(const engine::KeyframeUpdate& update, const io::KeyframeInfo& kf,
           const ImageFrontEndSource* front_end);

 private:
  std::set<uint64_t> seen_;
};

// How the keyframe images were served to one export (all formats of one mesh).
struct ExportImageStats {
  plugin::KeyframeImageStoreStats store;
  int keyframes = 0;
};

// The local origin org.imr.exporter.assimp writes PLY and glTF/GLB vertices relative to (float32
// loses centimetres on geo-referenced coordinates): 0 when every coordinate is within 1e4, else
// the bounding box's centre rounded to a whole kilometre. The same rule as the plugin's
// ExportOrigin (plugins/exporter_assimp/point_id_channel.hpp); report.json records it.
std::array<double, 3> ExportOrigin(const engine::Mesh& mesh);
// The same from the vertices' bounds (min xyz, max xyz).
std::array<double, 3> ExportOrigin(const std::array<double, 6>& bounds);

// What a 3D Tiles tile's export carries beyond the mesh (SDK 1.2; host/pipeline/tiles.h).
struct TileExportExtras {
  const std::vector<int64_t>* vertex_keys = nullptr;  // per vertex
  std::array<double, 3> origin{};                     // vertices written relative to it
  std::array<double, 9> gltf_rotation{};              // the glTF root's, row-major
  double texel_size = 0.0;  // a level of detail's texel (ABI 1.6); 0: the images' resolution
};

// Writes `mesh` into `directory` as stem.<format> for every format, each through the first
// exporter stage that writes it, with the keyframes of `context` (their images decoded on demand
// for this export only, within a bounded cache). Every call is watched against its stage's
// timeout (stage_timeout when the stage sets none). `tile`: the request of a tile.
ExportImageStats ExportMesh(const engine::Mesh& mesh, const ExportContext& context,
                            const std::vector<std::string>& formats, const Exporters& exporters,
                            const std::filesystem::path& directory, const std::string& stem,
                            StageWatch& watch, double stage_timeout,
                            const TileExportExtras* tile = nullptr);

class StreamedSurface;  // streamed_surface.h

// ExportMesh for the single mesh of a streamed run, which stays on disk: each format through
// its first exporter stage as an SDK 1.3 mesh stream, read in blocks. The formats whose stage
// cannot take a stream (no such call, or a request it writes from the whole mesh only: glTF, a
// texture) go to `left`, nothing of theirs written, and so do the formats after the first such
// (the mesh is read whole for it anyway): ExportMesh with the whole mesh writes them.
ExportImageStats ExportStreamedMesh(const StreamedSurface& mesh, const ExportContext& context,
                                    const std::vector<std::string>& formats,
                                    const Exporters& exporters, const std::filesystem::path& directory,
                                    const std::string& stem, StageWatch& watch, double stage_timeout,
                                    std::vector<std::string>* left);

// The keyframes of `context` (with their images) that may see the box (min xyz, max xyz): a
// corner or the centre in front of the camera within its image, within `max_distance` of the
// camera centre; cameras without intrinsics by distance alone.
ExportContext KeyframesSeeing(const ExportContext& context, const std::array<double, 6>& box,
                              double max_distance);

// Every n-th keyframe of `context` (with its image), the first and the last among them.
ExportContext EveryNthKeyframe(const ExportContext& context, std::size_t n);

}  // namespace imr::pipeline
