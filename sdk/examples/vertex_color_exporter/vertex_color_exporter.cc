// Example imr plugin of ABI 1.1: an exporter that uses the keyframe cameras and images.
//
// It writes the mesh as an ASCII PLY with a colour per vertex (format "colored_ply", file
// <stem>_colored.ply). A vertex takes the colour of the pixel it projects to in the nearest
// keyframe whose image it falls in (no visibility test: the real exporter, org.imr.exporter.assimp,
// z-buffers the mesh; this one keeps to what the SDK offers). Without images (an engine-only input)
// it writes the colours the input gave the points, or grey.
//
// It shows what ABI 1.1 adds for exporters:
//  - ExportMesh(const ExportRequest&) instead of Export(...): the request carries the keyframe
//    cameras (imr_camera: K, R, t world -> camera, image size) and says whether images exist;
//  - Host::GetKeyframeImage(i): the host decodes keyframe i's image once and lends it (gray or
//    BGR rows) until the returned object goes out of scope: fetch one keyframe at a time and let
//    it go, so the host's memory stays bounded;
//  - MeshView::vertex_colors: the input's own point colours (COLMAP), when there are any.
#include <imr/sdk/plugin.hpp>

#include <cmath>
#include <cstdio>
#include <limits>
#include <vector>

namespace {

class VertexColorExporter : public imr::sdk::Exporter {
 public:
  static constexpr const char* kId = "org.imr.example.exporter.vertex_color";
  static constexpr const char* kVersion = "1.0.0";
  static constexpr const char* kDescription =
      "Example: ASCII PLY coloured from the nearest keyframe image (sdk/examples/vertex_color_exporter)";
  static constexpr const char* kFormats = "colored_ply";
  static constexpr const char* kParamsSchema = R"({})";

  VertexColorExporter(const imr::sdk::Params&, const imr::sdk::Host& host) : host_(host) {}

  void ExportMesh(const imr::sdk::ExportRequest& r) override {
    const imr::sdk::MeshView& mesh = r.mesh;
    const std::size_t nv = mesh.vertex_count();
    std::vector<uint8_t> rgb(3 * nv, 128);
    if (mesh.vertex_colors.size() == 3 * nv) rgb.assign(mesh.vertex_colors.begin(), mesh.vertex_colors.end());

    if (r.keyframe_images && host_.HasKeyframeImages()) {
      // Each vertex's nearest keyframe that sees it in front, inside its image.
      std::vector<double> best(nv, std::numeric_limits<double>::infinity());
      std::vector<int64_t> view(nv, -1);
      std::vector<double> pixel(2 * nv);
      for (std::size_t k = 0; k < r.keyframes.size(); ++k) {
        const imr_camera& c = r.keyframes[k];
        if (!(c.K[0] > 0 && c.width > 0)) continue;  // no intrinsics
        for (std::size_t i = 0; i < nv; ++i) {
          const double* X = &mesh.vertices[3 * i];
          double x[3];
          for (int row = 0; row < 3; ++row)
            x[row] = c.R[3 * row] * X[0] + c.R[3 * row + 1] * X[1] + c.R[3 * row + 2] * X[2] + c.t[row];
          if (!(x[2] > 0) || !(x[2] < best[i])) continue;
          const double u = c.K[0] * x[0] / x[2] + c.K[1] * x[1] / x[2] + c.K[2];
          const double v = c.K[4] * x[1] / x[2] + c.K[5];
          if (u < 0 || v < 0 || u > c.width - 1 || v > c.height - 1) continue;
          best[i] = x[2];
          view[i] = static_cast<int64_t>(k);
          pixel[2 * i] = u, pixel[2 * i + 1] = v;
        }
      }
      // One image at a time: fetched, used, released (when `image` goes out of scope).
      for (std::size_t k = 0; k < r.keyframes.size(); ++k) {
        host_.CheckCancelled();
        bool needed = false;
        for (std::size_t i = 0; i < nv && !needed; ++i) needed = view[i] == static_cast<int64_t>(k);
        if (!needed) continue;
        const imr::sdk::KeyframeImage image = host_.GetKeyframeImage(k);
        for (std::size_t i = 0; i < nv; ++i) {
          if (view[i] != static_cast<int64_t>(k)) continue;
          const auto x = static_cast<int>(std::lround(pixel[2 * i]));
          const auto y = static_cast<int>(std::lround(pixel[2 * i + 1]));
          const uint8_t* p = image.Row(y) + static_cast<std::ptrdiff_t>(x) * image.channels();
          for (int ch = 0; ch < 3; ++ch) rgb[3 * i + ch] = image.channels() == 1 ? p[0] : p[2 - ch];  // BGR
        }
      }
    }

    const std::string path = r.directory + "/" + r.stem + "_colored.ply";
    std::FILE* f = std::fopen(path.c_str(), "w");
    if (f == nullptr) throw std::runtime_error(path + ": cannot write");
    std::fprintf(f, "ply\nformat ascii 1.0\nelement vertex %zu\nproperty double x\nproperty double y\n"
                    "property double z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n"
                    "element face %zu\nproperty list uchar int vertex_indices\nend_header\n",
                 nv, mesh.face_count());
    for (std::size_t i = 0; i < nv; ++i)
      std::fprintf(f, "%.17g %.17g %.17g %u %u %u\n", mesh.vertices[3 * i], mesh.vertices[3 * i + 1],
                   mesh.vertices[3 * i + 2], rgb[3 * i], rgb[3 * i + 1], rgb[3 * i + 2]);
    for (std::size_t t = 0; t < mesh.face_count(); ++t)
      std::fprintf(f, "3 %u %u %u\n", mesh.faces[3 * t], mesh.faces[3 * t + 1], mesh.faces[3 * t + 2]);
    if (std::fclose(f) != 0) throw std::runtime_error(path + ": write failed");
    host_.Debug("wrote " + path);
  }

 private:
  imr::sdk::Host host_;
};

}  // namespace

// The one exported symbol: lists this library's plugin classes.
IMR_PLUGIN_EXPORT(VertexColorExporter)
