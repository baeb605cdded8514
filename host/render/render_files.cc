#include "host/render/render_files.h"

#include "host/eval/mesh_io.h"
#include "host/io/image_io.h"
#include "host/io/image_sequence.h"
#include "host/io/colmap_model.h"
#include "host/io/openmvg_reader.h"
#include "host/io/slam_json.h"
#include "host/render/rasterizer.h"
#include "host/util/write_rule.h"

#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <sstream>
#include <string>
#include <vector>

namespace imr::render {
namespace {

namespace fs = std::filesystem;

Camera CameraOf(const io::CameraGeometry& g) {
  Camera c;
  const io::Intrinsics& k = g.intrinsics;
  c.width = k.width;
  c.height = k.height;
  c.fx = k.fx;
  c.fy = k.fy;
  c.cx = k.cx;
  c.cy = k.cy;
  c.rotation = g.rotation;
  c.translation = g.translation;
  return c;
}

// Writes the PNG under a temporary name beside `path` and renames it into place.
void WritePngAtomically(const fs::path& path, const io::Image& image) {
  const fs::path dir = path.has_parent_path() ? path.parent_path() : fs::path(".");
  const fs::path tmp = dir / ("." + path.stem().string() + ".partial-" + std::to_string(::getpid()) +
                              path.extension().string());
  CheckWriteTarget(path);
  try {
    io::WriteImage(tmp.string(), image);
    RecordWrittenFile(tmp, path);
    fs::rename(tmp, path);
  } catch (...) {
    std::error_code ec;
    fs::remove(tmp, ec);
    throw;
  }
}

std::string Percent(double share) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.1f%%", 100.0 * share);
  return buf;
}

// The cameras of a SLAM JSON stream as an image sequence without images: one frame per view, in
// the stream's order (every view its own keyframe, so each view's camera reaches the engine).
io::ImageSequence SlamJsonCameras(const std::string& file) {
  io::SlamJsonOptions o;
  o.min_views = 1;
  o.views_per_keyframe = 1;
  const std::unique_ptr<io::KeyframeSource> source = io::OpenSlamJson(file, o);
  io::ImageSequence seq;
  engine::KeyframeUpdate u;
  io::KeyframeInfo info;
  while (source->Next(&u, &info))
    for (const engine::Camera& c : u.cameras) {
      const io::CameraGeometry* g = source->Camera(c.id);
      if (g == nullptr || !g->has_intrinsics)
        throw std::runtime_error(file + ": view " + std::to_string(c.id) +
                                 " has no intrinsics: it cannot be drawn into");
      io::ImageFrame f;
      f.index = f.source_index = static_cast<int>(seq.frames.size());
      f.camera = *g;
      seq.frames.push_back(std::move(f));
    }
  return seq;
}

// The posed views of an SfM model (COLMAP, OpenMVG) as an image sequence without images: one
// frame per view, by view id (COLMAP's image ids, OpenMVG's view ids).
io::ImageSequence SfmCameras(const io::SfmModel& model) {
  io::ImageSequence seq;
  for (const io::CameraGeometry& g : model.views) {
    if (!g.has_intrinsics)
      throw std::runtime_error(model.file + ": view " + std::to_string(g.id) +
                               " has no intrinsics: it cannot be drawn into");
    io::ImageFrame f;
    f.index = f.source_index = static_cast<int>(seq.frames.size());
    f.camera = g;
    seq.frames.push_back(std::move(f));
  }
  return seq;
}

}  // namespace

std::string RenderFiles(const RenderFilesRequest& q) {
  const fs::path out_dir = fs::absolute(q.out).parent_path();
  if (!fs::is_directory(out_dir)) throw std::runtime_error(out_dir.string() + ": no such folder (for --out)");
  io::ImageSequence seq;
  if (!q.sequence.empty()) {
    if (q.format == "middlebury") {
      seq = io::ReadMiddlebury(q.sequence, q.sequence_options);
    } else if (q.format == "slam_json") {
      seq = SlamJsonCameras(q.sequence);
    } else if (q.format == "colmap") {
      seq = SfmCameras(io::ColmapToSfm(io::ReadColmapModel(q.sequence), q.sequence));
    } else if (q.format == "openmvg") {
      seq = SfmCameras(io::ReadOpenMvg(q.sequence));
    } else {
      seq = q.format == "kitti_odometry" ? io::ReadKittiOdometry(q.sequence, q.sequence_options)
                                         : io::ReadKittiRaw(q.sequence, q.sequence_options);
    }
  }
  const eval::TriangleMesh read = eval::ReadMesh(q.mesh);
  std::vector<double> xyz;
  std::vector<uint32_t> faces;
  xyz.reserve(3 * read.vertices.size());
  for (const auto& v : read.vertices) xyz.insert(xyz.end(), v.begin(), v.end());
  faces.reserve(3 * read.triangles.size());
  for (const auto& t : read.triangles) faces.insert(faces.end(), t.begin(), t.end());
  const MeshRef mesh = MeshRefOf(xyz, faces);
  std::ostringstream said;

  if (q.top_down) {
    CameraPath path;
    for (const io::ImageFrame& f : seq.frames) {
      path.cameras.push_back(CameraOf(f.camera));
      path.keyframe.push_back(q.keyframe_every > 0 && f.index % q.keyframe_every == 0);
    }
    const TopDownRendering r = RenderTopDown(mesh, path, q.top_down_options);
    WritePngAtomically(q.out, r.rendering.image);
    said << q.out.string() << ": top-down " << r.rendering.image.width << "x"
         << r.rendering.image.height << ", " << r.rendering.faces_drawn << " of "
         << faces.size() / 3 << " triangles visible, " << path.cameras.size() << " cameras, "
         << r.view.scale << " px per unit, up (" << r.view.up[0] << ", " << r.view.up[1] << ", "
         << r.view.up[2] << ")"
         << (q.top_down_options.up ? " (--up)"
             : path.cameras.empty() ? " (+z: no cameras)"
                                    : " (the cameras' mean up)");
    return said.str();
  }
  const int n = q.frame;
  if (n < 0 || n >= static_cast<int>(seq.frames.size()))
    throw FrameOutOfRange("--frame " + std::to_string(n) + ": the sequence has " +
                          std::to_string(seq.frames.size()) + " frames (0.." +
                          std::to_string(static_cast<int>(seq.frames.size()) - 1) + ")");
  const io::ImageFrame& frame = seq.frames[static_cast<std::size_t>(n)];
  io::Image image;
  const bool no_image =
      q.no_image || q.format == "slam_json" || q.format == "colmap" || q.format == "openmvg";
  if (!no_image) image = io::ReadImage(frame.image_path, seq.image_limits);
  const Camera camera = CameraOf(frame.camera);
  if (!no_image && (image.width != camera.width || image.height != camera.height))
    throw std::runtime_error(frame.image_path + ": image is " + std::to_string(image.width) + "x" +
                             std::to_string(image.height) + ", its camera " +
                             std::to_string(camera.width) + "x" + std::to_string(camera.height));
  const Rendering r = RenderIntoCamera(mesh, camera, no_image ? nullptr : &image, q.render);
  WritePngAtomically(q.out, r.image);
  // A SLAM JSON view has no image: it is named by its id and file name.
  const std::string what =
      !frame.image_path.empty() ? frame.image_path
                                : "view " + std::to_string(frame.camera.id) +
                                      (frame.camera.name.empty() ? "" : ", " + frame.camera.name);
  said << q.out.string() << ": frame " << n << " (" << what << "), " << r.image.width
       << "x" << r.image.height << ", " << r.faces_drawn << " of " << faces.size() / 3
       << " triangles visible, " << Percent(r.Coverage()) << " of the pixels covered";
  return said.str();
}

}  // namespace imr::render
