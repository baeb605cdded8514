#include "host/pipeline/mesh_export.h"

#include <algorithm>
#include <array>
#include <cmath>
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

ExportImageStats ExportMesh(const engine::Mesh& mesh, const ExportContext& context,
                            const std::vector<std::string>& formats, const Exporters& exporters,
                            const std::filesystem::path& directory, const std::string& stem,
                            StageWatch& watch, double stage_timeout) {
  imr_mesh_view view{};
  view.struct_size = sizeof(view);
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
      req.mesh = &view;
      req.directory = dir.c_str();
      req.stem = stem.c_str();
      req.format = mesh_format.c_str();
      req.keyframes = context.keyframes.empty() ? nullptr : context.keyframes.data();
      req.keyframe_count = context.keyframes.size();
      req.keyframe_images = images ? 1 : 0;
      const WatchedStage watched = WatchedStageOf(*stage, stage_timeout);
      const StageWatch::Call call = watch.Enter(watched);
      inst.instance.ExportMesh(&req);
      written.insert(mesh_format);
      if (images) images->ReleaseAll();  // holds end with the call (plugin.h)
    }
  }
  ExportImageStats stats;
  stats.keyframes = static_cast<int>(context.keyframes.size());
  if (images) stats.store = images->stats();
  return stats;
}

}  // namespace imr::pipeline
