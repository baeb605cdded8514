#include "host/pipeline/mesh_export.h"

#include "host/pipeline/streamed_surface.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <functional>
#include <optional>

namespace imr::pipeline {

void ExportContext::Add(const engine::KeyframeUpdate& update, const io::KeyframeInfo& kf,
                        const ImageFrontEndSource* front_end) {
  auto camera_of = [&](const engine::Camera& c) {
    if (const io::CameraGeometry* g = source->Camera(c.id); g != nullptr)
      return ToPluginCamera(*g, g->intrinsics.width, g->intrinsics.height);
    io::CameraGeometry g;  // only the centre and rotation the engine got
    g.id = c.id;
    for (int r = 0; r < 3; ++r)
      for (int k = 0; k < 3; ++k) g.rotation[r][k] = c.rotation[3 * r + k];
    io::SetFromCenter(g.rotation, c.center, &g);
    return ToPluginCamera(g, 0, 0);
  };
  if (front_end != nullptr) {
    for (const engine::Camera& c : update.cameras) {
      if (c.id != static_cast<uint64_t>(kf.frame)) continue;
      keyframes.push_back(camera_of(c));
      image_paths.push_back(front_end->sequence().frames.at(c.id).image_path);
    }
    return;
  }
  for (const engine::Camera& c : update.cameras)
    if (seen_.insert(c.id).second) keyframes.push_back(camera_of(c));
}

std::array<double, 3> ExportOrigin(const engine::Mesh& mesh) {
  constexpr double kOriginFreeRange = 1e4;
  std::array<double, 3> lo{}, hi{}, origin{};
  bool small = true;
  for (std::size_t i = 0; i + 2 < mesh.vertices.size(); i += 3)
    for (std::size_t k = 0; k < 3; ++k) {
      const double x = mesh.vertices[i + k];
      small = small && std::fabs(x) <= kOriginFreeRange;
      lo[k] = i == 0 ? x : std::min(lo[k], x);
      hi[k] = i == 0 ? x : std::max(hi[k], x);
    }
  if (small) return origin;
  for (std::size_t k = 0; k < 3; ++k) origin[k] = std::round((lo[k] + hi[k]) / 2.0 / 1000.0) * 1000.0;
  return origin;
}

std::array<double, 3> ExportOrigin(const std::array<double, 6>& bounds) {
  engine::Mesh corners;
  corners.vertices.assign(bounds.begin(), bounds.end());
  return ExportOrigin(corners);
}

namespace {

// Every format through the first exporter stage that lists it, with the request all formats
// share; `call` hands it to the stage's instance and says whether it was taken (false: the
// format goes to `left`).
using ExportCall = std::function<bool(const plugin::LoadedInstance&, imr_export_request*)>;
ExportImageStats ExportFormats(const ExportContext& context, const std::vector<std::string>& formats,
                               const Exporters& exporters, const std::filesystem::path& directory,
                               const std::string& stem, StageWatch& watch, double stage_timeout,
                               const TileExportExtras* tile, const ExportCall& call,
                               std::vector<std::string>* left) {
  std::optional<plugin::KeyframeImageStore> images;
  if (!context.image_paths.empty()) images.emplace(context.image_paths);
  const plugin::ScopedKeyframeImages scope(images ? &*images : nullptr);
  std::set<std::string> written;
  const std::string dir = directory.string();
  for (const std::string& mesh_format : formats) {
    for (const auto& [stage, inst] : exporters) {
      const std::string list = std::string(",") + inst.instance.descriptor()->exporter->formats + ",";
      if (list.find("," + mesh_format + ",") == std::string::npos || written.count(mesh_format))
        continue;
      imr_export_request req{};
      req.directory = dir.c_str();
      req.stem = stem.c_str();
      req.format = mesh_format.c_str();
      req.keyframes = context.keyframes.empty() ? nullptr : context.keyframes.data();
      req.keyframe_count = context.keyframes.size();
      req.keyframe_images = images ? 1 : 0;
      if (tile != nullptr) {
        req.origin = tile->origin.data();
        req.gltf_rotation = tile->gltf_rotation.data();
        req.texel_size = tile->texel_size;
      }
      const WatchedStage watched = WatchedStageOf(*stage, stage_timeout);
      bool taken = false;
      {
        const StageWatch::Call watched_call = watch.Enter(watched);
        taken = call(inst, &req);
      }
      written.insert(mesh_format);
      if (!taken && left != nullptr) left->push_back(mesh_format);
      // Holds end with the call (plugin.h); the decoded images go too: the default job's 128 MiB
      // of them stayed through its other formats' writing, the end's peak (issue 46).
      if (images) {
        images->ReleaseAll();
        images->DropDecoded();
      }
    }
  }
  ExportImageStats stats;
  stats.keyframes = static_cast<int>(context.keyframes.size());
  if (images) stats.store = images->stats();
  return stats;
}

// The streamed mesh behind imr_mesh_stream's calls.
imr_status Guarded(imr_error* error, const std::function<void()>& body) {
  try {
    body();
    return IMR_OK;
  } catch (const std::exception& e) {
    std::snprintf(error->message, sizeof(error->message), "%s", e.what());
    return IMR_ERROR;
  }
}
imr_status ReadStreamVertices(void* context, uint64_t first, uint64_t count, double* xyz,
                              int64_t* point_ids, double* normal_sums, imr_error* error) {
  return Guarded(error, [&] {
    static_cast<const StreamedSurface*>(context)->ReadVertices(first, count, xyz, point_ids, normal_sums);
  });
}
imr_status ReadStreamFaces(void* context, uint64_t first, uint64_t count, uint32_t* faces,
                           imr_error* error) {
  return Guarded(error, [&] { static_cast<const StreamedSurface*>(context)->ReadFaces(first, count, faces); });
}

// Whether the source gives a colour to some vertex's point (the whole-mesh export carries them).
bool AnyPointColor(const StreamedSurface& mesh, const io::KeyframeSource& source) {
  constexpr uint64_t kBlock = 1 << 16;
  std::vector<int64_t> ids(kBlock);
  std::array<uint8_t, 3> rgb{};
  for (uint64_t i = 0; i < mesh.vertex_count(); i += kBlock) {
    const uint64_t n = std::min(kBlock, mesh.vertex_count() - i);
    mesh.ReadVertices(i, n, nullptr, ids.data(), nullptr);
    for (uint64_t k = 0; k < n; ++k)
      if (ids[k] >= 0 && source.PointColor(static_cast<uint64_t>(ids[k]), &rgb)) return true;
  }
  return false;
}

}  // namespace

ExportImageStats ExportMesh(const engine::Mesh& mesh, const ExportContext& context,
                            const std::vector<std::string>& formats, const Exporters& exporters,
                            const std::filesystem::path& directory, const std::string& stem,
                            StageWatch& watch, double stage_timeout, const TileExportExtras* tile) {
  imr_mesh_view view{};
  view.struct_size = sizeof(view);
  if (tile != nullptr && tile->vertex_keys != nullptr) view.vertex_keys = tile->vertex_keys->data();
  view.vertices = mesh.vertices.data();
  view.vertex_count = mesh.vertices.size() / 3;
  view.faces = mesh.faces.data();
  view.face_count = mesh.faces.size() / 3;
  view.point_ids = mesh.point_ids.data();
  // The points' own colours, when the input gives any (grey where it gives none).
  std::vector<uint8_t> colors;
  if (context.source != nullptr && context.image_paths.empty()) {
    bool any = false;
    colors.assign(mesh.vertices.size(), 128);
    std::array<uint8_t, 3> rgb{};
    for (std::size_t i = 0; i < mesh.point_ids.size(); ++i)
      if (mesh.point_ids[i] >= 0 &&
          context.source->PointColor(static_cast<uint64_t>(mesh.point_ids[i]), &rgb)) {
        std::copy(rgb.begin(), rgb.end(), colors.begin() + static_cast<std::ptrdiff_t>(3 * i));
        any = true;
      }
    if (!any) colors.clear();
  }
  view.vertex_colors = colors.empty() ? nullptr : colors.data();
  return ExportFormats(context, formats, exporters, directory, stem, watch, stage_timeout, tile,
                       [&](const plugin::LoadedInstance& inst, imr_export_request* req) {
                         req->mesh = &view;
                         inst.instance.ExportMesh(req);
                         return true;
                       },
                       nullptr);
}

ExportImageStats ExportStreamedMesh(const StreamedSurface& mesh, const ExportContext& context,
                                    const std::vector<std::string>& formats,
                                    const Exporters& exporters, const std::filesystem::path& directory,
                                    const std::string& stem, StageWatch& watch, double stage_timeout,
                                    std::vector<std::string>* left) {
  // Colours from the input's points ride in the whole mesh's view only.
  if (context.source != nullptr && context.image_paths.empty() && AnyPointColor(mesh, *context.source)) {
    *left = formats;
    return {};
  }
  imr_mesh_stream stream{};
  stream.struct_size = sizeof(stream);
  stream.vertex_count = mesh.vertex_count();
  stream.face_count = mesh.face_count();
  std::copy(mesh.bounds().begin(), mesh.bounds().end(), stream.bounds);
  stream.context = const_cast<StreamedSurface*>(&mesh);
  stream.read_vertices = &ReadStreamVertices;
  stream.read_faces = &ReadStreamFaces;
  // Once a format needs the mesh whole it is read back, and the formats after it go with it:
  // in blocks they would save no memory, and a PLY coloured block by block takes longer than the
  // colours the exporter makes once for every format of the whole mesh.
  return ExportFormats(context, formats, exporters, directory, stem, watch, stage_timeout, nullptr,
                       [&](const plugin::LoadedInstance& inst, imr_export_request* req) {
                         return left->empty() && inst.instance.ExportMeshStream(req, &stream);
                       },
                       left);
}

}  // namespace imr::pipeline

namespace imr::pipeline {

ExportContext KeyframesSeeing(const ExportContext& context, const std::array<double, 6>& box,
                              double max_distance) {
  ExportContext out;
  out.source = context.source;
  for (std::size_t i = 0; i < context.keyframes.size(); ++i) {
    const imr_camera& c = context.keyframes[i];
    double centre[3];  // C = -R^T t
    for (int k = 0; k < 3; ++k) centre[k] = -(c.R[k] * c.t[0] + c.R[3 + k] * c.t[1] + c.R[6 + k] * c.t[2]);
    double d2 = 0.0;  // from the camera to the box
    for (int k = 0; k < 3; ++k) {
      const double d = std::max({box[k] - centre[k], 0.0, centre[k] - box[3 + k]});
      d2 += d * d;
    }
    if (d2 > max_distance * max_distance) continue;
    // The box's corners projected: seen when their rectangle meets the image (a box that
    // straddles the camera's plane, or no intrinsics to project with: by distance alone).
    bool sees = d2 == 0.0 || c.K[0] == 0.0 || c.width <= 0 || c.height <= 0;
    int in_front = 0;
    double lo[2] = {1e300, 1e300}, hi[2] = {-1e300, -1e300};
    for (int corner = 0; corner < 8 && !sees; ++corner) {
      double p[3], x[3];
      for (int k = 0; k < 3; ++k) p[k] = ((corner >> k) & 1) ? box[3 + k] : box[k];
      for (int r = 0; r < 3; ++r) x[r] = c.R[3 * r] * p[0] + c.R[3 * r + 1] * p[1] + c.R[3 * r + 2] * p[2] + c.t[r];
      if (x[2] <= 1e-6) continue;
      ++in_front;
      const double uv[2] = {c.K[0] * x[0] / x[2] + c.K[1] * x[1] / x[2] + c.K[2], c.K[4] * x[1] / x[2] + c.K[5]};
      for (int k = 0; k < 2; ++k) {
        lo[k] = std::min(lo[k], uv[k]);
        hi[k] = std::max(hi[k], uv[k]);
      }
    }
    if (!sees && in_front > 0)
      sees = in_front < 8 || (hi[0] >= 0 && hi[1] >= 0 && lo[0] < c.width && lo[1] < c.height);
    if (!sees) continue;
    out.keyframes.push_back(c);
    if (!context.image_paths.empty()) out.image_paths.push_back(context.image_paths[i]);
  }
  return out;
}

ExportContext EveryNthKeyframe(const ExportContext& context, std::size_t n) {
  ExportContext out;
  out.source = context.source;
  const std::size_t count = context.keyframes.size();
  for (std::size_t i = 0; i < count; ++i) {
    if (n > 1 && i % n != 0 && i + 1 != count) continue;
    out.keyframes.push_back(context.keyframes[i]);
    if (!context.image_paths.empty()) out.image_paths.push_back(context.image_paths[i]);
  }
  return out;
}

}  // namespace imr::pipeline
