#include "host/render/rasterizer.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <stdexcept>

namespace imr::render {
namespace {

constexpr float kNoDepth = std::numeric_limits<float>::infinity();

Vec3 Normalized(const Vec3& a) {
  const double n = Norm(a);
  return n > 0 ? Scale(a, 1.0 / n) : Vec3{0, 0, 0};
}
Vec3 Mul(const Mat3& m, const Vec3& v) { return {Dot(m[0], v), Dot(m[1], v), Dot(m[2], v)}; }

Vec3 VertexOf(const MeshRef& mesh, uint32_t i) {
  const double* p = mesh.xyz + 3 * static_cast<std::size_t>(i);
  return {p[0], p[1], p[2]};
}

void CheckMesh(const MeshRef& mesh) {
  if ((mesh.vertex_count > 0 && mesh.xyz == nullptr) || (mesh.face_count > 0 && mesh.faces == nullptr))
    throw std::invalid_argument("mesh: null vertex or face array");
  for (std::size_t i = 0; i < 3 * mesh.face_count; ++i) {
    if (mesh.faces[i] >= mesh.vertex_count)
      throw std::invalid_argument("mesh: face " + std::to_string(i / 3) + " has vertex index " +
                                  std::to_string(mesh.faces[i]) + " (" +
                                  std::to_string(mesh.vertex_count) + " vertices)");
    const Vec3 x = VertexOf(mesh, mesh.faces[i]);
    if (!std::isfinite(x[0]) || !std::isfinite(x[1]) || !std::isfinite(x[2]))
      throw std::invalid_argument("mesh: vertex " + std::to_string(mesh.faces[i]) +
                                  " (of face " + std::to_string(i / 3) + ") is not finite");
  }
}

std::string CheckColorRange(const char* name, double v, double lo, double hi) {
  if (!(v >= lo && v <= hi))
    return std::string(name) + " = " + std::to_string(v) + ": must be in [" + std::to_string(lo) +
           ", " + std::to_string(hi) + "]";
  return "";
}

// A vertex after projection: pixel position and a quantity linear in screen space from which
// the depth follows (perspective: 1/z; orthographic: the depth itself).
struct ScreenVertex {
  double x, y, q;
};

// The frame buffers being drawn into.
class Target {
 public:
  Target(int width, int height, bool perspective)
      : width_(width), height_(height), perspective_(perspective),
        depth_(static_cast<std::size_t>(width) * static_cast<std::size_t>(height), kNoDepth),
        face_(depth_.size(), -1),
        edge_distance_(depth_.size(), std::numeric_limits<float>::infinity()) {}

  // Rasterises one triangle; real_edge[k] says whether edge (v_k, v_{k+1}) is an edge of the
  // mesh (false for the edges near-plane clipping made).
  void Triangle(const ScreenVertex (&v)[3], int32_t face, const bool (&real_edge)[3]) {
    const double area = Edge(v[0], v[1], v[2].x, v[2].y);
    if (!(std::abs(area) > 0.0)) return;  // no pixel centre can be strictly inside
    // Edge k runs from v[k] to v[k+1]; its function is positive inside for area > 0.
    const double sign = area > 0 ? 1.0 : -1.0;
    double len[3];
    bool top_left[3];
    for (int k = 0; k < 3; ++k) {
      const ScreenVertex& a = v[k];
      const ScreenVertex& b = v[(k + 1) % 3];
      len[k] = std::hypot(b.x - a.x, b.y - a.y);
      // Top-left rule (y down; edges oriented so that the inside is where the edge function is
      // positive): a top edge is horizontal with the inside below it (dx > 0), a left edge has
      // the inside to its right (dy < 0). Pixel centres exactly on an edge belong to the
      // triangle only on such edges, so neighbours never both take them.
      const double dx = (b.x - a.x) * sign, dy = (b.y - a.y) * sign;
      top_left[k] = (dy == 0.0 && dx > 0.0) || dy < 0.0;
    }
    const double min_x = std::min({v[0].x, v[1].x, v[2].x});
    const double max_x = std::max({v[0].x, v[1].x, v[2].x});
    const double min_y = std::min({v[0].y, v[1].y, v[2].y});
    const double max_y = std::max({v[0].y, v[1].y, v[2].y});
    const int x0 = std::max(0, static_cast<int>(std::ceil(std::max(min_x, -1.0))));
    const int x1 = std::min(width_ - 1, static_cast<int>(std::floor(std::min(max_x, double(width_)))));
    const int y0 = std::max(0, static_cast<int>(std::ceil(std::max(min_y, -1.0))));
    const int y1 = std::min(height_ - 1, static_cast<int>(std::floor(std::min(max_y, double(height_)))));
    for (int y = y0; y <= y1; ++y) {
      for (int x = x0; x <= x1; ++x) {
        double e[3];
        bool inside = true;
        for (int k = 0; k < 3 && inside; ++k) {
          e[k] = Edge(v[k], v[(k + 1) % 3], x, y) * sign;
          inside = e[k] > 0.0 || (e[k] == 0.0 && top_left[k]);
        }
        if (!inside) continue;
        // Barycentric weight of v[k] is the edge opposite it: edge (k+1, k+2).
        const double abs_area = std::abs(area);
        const double w0 = e[1] / abs_area, w1 = e[2] / abs_area, w2 = e[0] / abs_area;
        const double q = w0 * v[0].q + w1 * v[1].q + w2 * v[2].q;
        const double depth = perspective_ ? 1.0 / q : q;
        const std::size_t i = static_cast<std::size_t>(y) * static_cast<std::size_t>(width_) +
                              static_cast<std::size_t>(x);
        if (!(depth < depth_[i])) continue;
        depth_[i] = static_cast<float>(depth);
        face_[i] = face;
        float d = std::numeric_limits<float>::infinity();
        for (int k = 0; k < 3; ++k)
          if (real_edge[k] && len[k] > 0.0) d = std::min(d, static_cast<float>(e[k] / len[k]));
        edge_distance_[i] = d;
      }
    }
  }

  int width() const { return width_; }
  int height() const { return height_; }
  std::vector<float>& depth() { return depth_; }
  std::vector<int32_t>& face() { return face_; }
  const std::vector<int32_t>& face() const { return face_; }
  const std::vector<float>& edge_distance() const { return edge_distance_; }

 private:
  static double Edge(const ScreenVertex& a, const ScreenVertex& b, double x, double y) {
    return (b.x - a.x) * (y - a.y) - (b.y - a.y) * (x - a.x);
  }

  int width_, height_;
  bool perspective_;
  std::vector<float> depth_;
  std::vector<int32_t> face_;
  std::vector<float> edge_distance_;
};

uint8_t Channel(double v) { return static_cast<uint8_t>(std::clamp(std::lround(v), 0L, 255L)); }

// A face's shaded colour (RGB) given the directions toward the viewer and toward the light.
Rgb ShadeFace(const Vec3& normal, const Vec3& to_viewer, const Vec3& light,
              const RenderOptions& o) {
  const Rgb& base = Dot(normal, to_viewer) >= 0.0 ? o.front_color : o.back_color;
  const double intensity = o.ambient + (1.0 - o.ambient) * std::abs(Dot(normal, light));
  return {Channel(base[0] * intensity), Channel(base[1] * intensity), Channel(base[2] * intensity)};
}

// The height ramp of the top-down view: t in [0, 1] -> RGB.
Rgb HeightColor(double t) {
  static constexpr double kStops[5][3] = {
      {175, 175, 165}, {110, 160, 225}, {80, 185, 115}, {240, 200, 60}, {215, 70, 40}};
  t = std::clamp(t, 0.0, 1.0) * 4.0;
  const int i = std::min(3, static_cast<int>(t));
  const double s = t - i;
  Rgb c{};
  for (std::size_t k = 0; k < 3; ++k)
    c[k] = Channel(kStops[i][k] * (1.0 - s) + kStops[i + 1][k] * s);
  return c;
}

Vec3 FaceNormal(const MeshRef& mesh, std::size_t f) {
  const Vec3 a = VertexOf(mesh, mesh.faces[3 * f]);
  const Vec3 b = VertexOf(mesh, mesh.faces[3 * f + 1]);
  const Vec3 c = VertexOf(mesh, mesh.faces[3 * f + 2]);
  return Normalized(Cross(Sub(b, a), Sub(c, a)));
}

Vec3 FaceCentroid(const MeshRef& mesh, std::size_t f) {
  Vec3 s{};
  for (int k = 0; k < 3; ++k) s = Add(s, VertexOf(mesh, mesh.faces[3 * f + static_cast<std::size_t>(k)]));
  return Scale(s, 1.0 / 3.0);
}

// Composites the buffers into `out` (BGR, already holding the background).
void Composite(const Target& target, const std::vector<Rgb>& face_color, const RenderOptions& o,
               double opacity, io::Image* out) {
  const std::vector<int32_t>& face = target.face();
  const std::vector<float>& edge = target.edge_distance();
  const float half_wire = static_cast<float>(o.wire_width / 2.0);
  for (std::size_t i = 0; i < face.size(); ++i) {
    if (face[i] < 0) continue;
    uint8_t* px = &out->pixels[3 * i];
    if (o.wireframe && edge[i] <= half_wire) {
      px[0] = o.wire_color[2];
      px[1] = o.wire_color[1];
      px[2] = o.wire_color[0];
      continue;
    }
    if (!o.shaded) continue;
    const Rgb& c = face_color[static_cast<std::size_t>(face[i])];
    for (int k = 0; k < 3; ++k)
      px[k] = Channel(opacity * c[static_cast<std::size_t>(2 - k)] + (1.0 - opacity) * px[k]);
  }
}

io::Image BlankImage(int width, int height, const Rgb& color) {
  io::Image img;
  img.width = width;
  img.height = height;
  img.channels = 3;
  img.stride_bytes = static_cast<int64_t>(width) * 3;
  img.pixels.resize(static_cast<std::size_t>(width) * static_cast<std::size_t>(height) * 3);
  for (std::size_t i = 0; i < img.pixels.size(); i += 3) {
    img.pixels[i] = color[2];
    img.pixels[i + 1] = color[1];
    img.pixels[i + 2] = color[0];
  }
  return img;
}

// Counts the faces that own at least one pixel.
int64_t FacesDrawn(const std::vector<int32_t>& face, std::size_t face_count) {
  std::vector<char> seen(face_count, 0);
  int64_t n = 0;
  for (int32_t f : face)
    if (f >= 0 && !seen[static_cast<std::size_t>(f)]) {
      seen[static_cast<std::size_t>(f)] = 1;
      ++n;
    }
  return n;
}

// Pixel-space helpers for the path overlay.
void SetPixel(io::Image* img, int x, int y, const Rgb& c) {
  if (x < 0 || y < 0 || x >= img->width || y >= img->height) return;
  uint8_t* px = &img->pixels[3 * (static_cast<std::size_t>(y) * static_cast<std::size_t>(img->width) +
                                  static_cast<std::size_t>(x))];
  px[0] = c[2];
  px[1] = c[1];
  px[2] = c[0];
}

// Pixels whose centre is within `width` / 2 of segment ab.
void DrawSegment(io::Image* img, std::array<double, 2> a, std::array<double, 2> b, double width,
                 const Rgb& c) {
  const double r = std::max(width / 2.0, 0.5);
  const int x0 = static_cast<int>(std::floor(std::min(a[0], b[0]) - r));
  const int x1 = static_cast<int>(std::ceil(std::max(a[0], b[0]) + r));
  const int y0 = static_cast<int>(std::floor(std::min(a[1], b[1]) - r));
  const int y1 = static_cast<int>(std::ceil(std::max(a[1], b[1]) + r));
  const double dx = b[0] - a[0], dy = b[1] - a[1];
  const double len2 = dx * dx + dy * dy;
  for (int y = std::max(y0, 0); y <= std::min(y1, img->height - 1); ++y) {
    for (int x = std::max(x0, 0); x <= std::min(x1, img->width - 1); ++x) {
      double s = len2 > 0 ? ((x - a[0]) * dx + (y - a[1]) * dy) / len2 : 0.0;
      s = std::clamp(s, 0.0, 1.0);
      const double ex = a[0] + s * dx - x, ey = a[1] + s * dy - y;
      if (ex * ex + ey * ey <= r * r) SetPixel(img, x, y, c);
    }
  }
}

// A disc (ring when inner > 0) centred at p.
void DrawDisc(io::Image* img, std::array<double, 2> p, double radius, double inner, const Rgb& c) {
  for (int y = static_cast<int>(std::floor(p[1] - radius)); y <= static_cast<int>(std::ceil(p[1] + radius)); ++y)
    for (int x = static_cast<int>(std::floor(p[0] - radius)); x <= static_cast<int>(std::ceil(p[0] + radius)); ++x) {
      const double d2 = (x - p[0]) * (x - p[0]) + (y - p[1]) * (y - p[1]);
      if (d2 <= radius * radius && d2 >= inner * inner) SetPixel(img, x, y, c);
    }
}

}  // namespace

MeshRef MeshRefOf(const std::vector<double>& xyz, const std::vector<uint32_t>& faces) {
  return {xyz.data(), xyz.size() / 3, faces.data(), faces.size() / 3};
}

Vec3 Camera::Center() const {
  // C = -R^T t
  Vec3 c{};
  for (std::size_t i = 0; i < 3; ++i)
    for (std::size_t k = 0; k < 3; ++k) c[i] -= rotation[k][i] * translation[k];
  return c;
}

std::string Camera::Check() const {
  if (width <= 0 || height <= 0)
    return "image size " + std::to_string(width) + "x" + std::to_string(height) + " is not positive";
  if (!(fx > 0.0) || !(fy > 0.0)) return "focal lengths fx, fy must be positive";
  if (!std::isfinite(cx) || !std::isfinite(cy)) return "principal point is not finite";
  double worst = 0.0;
  for (std::size_t i = 0; i < 3; ++i)
    for (std::size_t j = 0; j < 3; ++j)
      worst = std::max(worst, std::abs(Dot(rotation[i], rotation[j]) - (i == j ? 1.0 : 0.0)));
  if (!(worst < 1e-4)) return "rotation is not orthonormal (|R R^T - I| = " + std::to_string(worst) + ")";
  if (Dot(Cross(rotation[0], rotation[1]), rotation[2]) < 0) return "rotation has determinant -1 (a reflection)";
  for (double v : translation)
    if (!std::isfinite(v)) return "translation is not finite";
  return "";
}

std::string RenderOptions::Check() const {
  if (!shaded && !wireframe) return "shaded and wireframe both off: nothing to draw";
  if (auto p = CheckColorRange("opacity", opacity, 0.0, 1.0); !p.empty()) return p;
  if (auto p = CheckColorRange("ambient", ambient, 0.0, 1.0); !p.empty()) return p;
  if (!(wire_width > 0.0 && wire_width < 1e4))
    return "wire_width = " + std::to_string(wire_width) + ": must be positive (pixels)";
  if (!(near > 0.0 && std::isfinite(near)))
    return "near = " + std::to_string(near) + ": must be a positive distance";
  return "";
}

std::string TopDownOptions::Check() const {
  if (auto p = render.Check(); !p.empty()) return "render: " + p;
  if (size < 16 || size > 32768) return "size = " + std::to_string(size) + ": must be in [16, 32768] pixels";
  if (margin < 0 || 2 * margin >= size) return "margin = " + std::to_string(margin) + ": must be >= 0 and < size / 2";
  if (up && !(Norm(*up) > 0.0 && std::isfinite(Norm(*up)))) return "up must be a non-zero finite vector";
  if (!(path_width > 0.0)) return "path_width must be positive";
  if (!(keyframe_radius >= 0.0)) return "keyframe_radius must be >= 0";
  return "";
}

namespace {

void DrawFaces(const MeshRef& mesh, const Camera& camera, const RenderOptions& options,
               int32_t first_face, Target* target, std::vector<Rgb>* face_color, int64_t* behind,
               int64_t* clipped);

// A camera drawn at `scale` of its size: fx, fy, cx, cy and the image scaled, pixel centres kept.
Camera ScaledCamera(const Camera& full, double scale) {
  Camera c = full;
  c.width = std::max(1, static_cast<int>(std::lround(full.width * scale)));
  c.height = std::max(1, static_cast<int>(std::lround(full.height * scale)));
  c.fx = full.fx * scale, c.fy = full.fy * scale;
  c.cx = (full.cx + 0.5) * scale - 0.5, c.cy = (full.cy + 0.5) * scale - 0.5;
  return c;
}

// Whether face f faces away from `center` (the right-hand rule over its vertex order).
bool SeenFromBehind(const MeshRef& mesh, std::size_t f, const Vec3& center) {
  return Dot(FaceNormal(mesh, f), Sub(center, FaceCentroid(mesh, f))) < 0.0;
}

void CheckScale(double scale) {
  if (!(scale > 0.0 && scale <= 1.0)) throw std::invalid_argument("back-facing share: scale must be in (0, 1]");
}

// Each camera drawn at `scale` of its size: every pixel showing a face, as (face, seen from behind).
void ForEachPixelSide(const MeshRef& mesh, const std::vector<Camera>& cameras, double scale,
                      const std::function<void(int32_t face, bool back)>& pixel) {
  CheckScale(scale);
  RenderOptions o;
  o.opacity = 1.0;
  for (const Camera& full : cameras) {
    const Camera c = ScaledCamera(full, scale);
    const Rendering r = RenderIntoCamera(mesh, c, nullptr, o);
    const Vec3 center = c.Center();
    std::vector<int8_t> side(mesh.face_count, -1);  // per face: unknown, front 0, back 1
    for (int32_t f : r.face) {
      if (f < 0) continue;
      if (side[f] < 0) side[f] = SeenFromBehind(mesh, static_cast<std::size_t>(f), center) ? 1 : 0;
      pixel(f, side[f] == 1);
    }
  }
}

}  // namespace

BackFacing MeasureBackFacing(const MeshRef& mesh, const std::vector<Camera>& cameras, double scale) {
  BackFacing out;
  ForEachPixelSide(mesh, cameras, scale, [&](int32_t, bool back) {
    ++out.pixels;
    out.back_pixels += back ? 1 : 0;
  });
  out.views = static_cast<int64_t>(cameras.size());
  return out;
}

std::vector<uint8_t> FacesSeenFromBehind(const MeshRef& mesh, const std::vector<Camera>& cameras, double scale) {
  std::vector<int64_t> front(mesh.face_count, 0), back(mesh.face_count, 0);
  ForEachPixelSide(mesh, cameras, scale, [&](int32_t f, bool behind) { ++(behind ? back : front)[f]; });
  std::vector<uint8_t> behind(mesh.face_count, 0);
  for (std::size_t f = 0; f < behind.size(); ++f) behind[f] = back[f] > front[f] ? 1 : 0;
  return behind;
}

// One camera's frame buffer over the blocks, and per pixel whether its face is seen from behind
// (decided while the face's block is there).
struct BackFacingInBlocks::View {
  Camera camera;
  Target target;
  std::vector<int8_t> back;
};

BackFacingInBlocks::BackFacingInBlocks(const std::vector<Camera>& cameras, double scale) {
  CheckScale(scale);
  for (const Camera& full : cameras) {
    const Camera c = ScaledCamera(full, scale);
    if (const std::string p = c.Check(); !p.empty()) throw std::invalid_argument("camera: " + p);
    views_.push_back(std::make_unique<View>(View{c, Target(c.width, c.height, /*perspective=*/true),
                                                 std::vector<int8_t>(static_cast<std::size_t>(c.width) * static_cast<std::size_t>(c.height), 0)}));
  }
}

BackFacingInBlocks::~BackFacingInBlocks() = default;

void BackFacingInBlocks::AddTriangles(const MeshRef& block) {
  CheckMesh(block);
  if (faces_ + static_cast<int64_t>(block.face_count) > std::numeric_limits<int32_t>::max())
    throw std::invalid_argument("back-facing share: more than 2^31 - 1 faces");
  const auto first = static_cast<int32_t>(faces_);
  RenderOptions o;
  o.opacity = 1.0;
  for (const auto& view : views_) {
    int64_t behind = 0, clipped = 0;
    DrawFaces(block, view->camera, o, first, &view->target, nullptr, &behind, &clipped);
    // The pixels this block's faces won: their side now, while the block's vertices are here.
    const Vec3 center = view->camera.Center();
    std::vector<int8_t> side(block.face_count, -1);
    const std::vector<int32_t>& face = view->target.face();
    for (std::size_t i = 0; i < face.size(); ++i) {
      if (face[i] < first) continue;
      const auto f = static_cast<std::size_t>(face[i] - first);
      if (side[f] < 0) side[f] = SeenFromBehind(block, f, center) ? 1 : 0;
      view->back[i] = side[f];
    }
  }
  faces_ += static_cast<int64_t>(block.face_count);
}

BackFacing BackFacingInBlocks::Result() const {
  BackFacing out;
  for (const auto& view : views_) {
    const std::vector<int32_t>& face = view->target.face();
    for (std::size_t i = 0; i < face.size(); ++i) {
      if (face[i] < 0) continue;
      ++out.pixels;
      out.back_pixels += view->back[i];
    }
    ++out.views;
  }
  return out;
}

double Rendering::Coverage() const {
  if (face.empty()) return 0.0;
  std::size_t n = 0;
  for (int32_t f : face) n += f >= 0 ? 1 : 0;
  return static_cast<double>(n) / static_cast<double>(face.size());
}

namespace {

// Draws every face of `mesh` into `target` as face first_face + f, in face order (a later face
// wins only a pixel it is strictly nearer at); face_color (optional) gets their shading.
void DrawFaces(const MeshRef& mesh, const Camera& camera, const RenderOptions& options,
               int32_t first_face, Target* target, std::vector<Rgb>* face_color, int64_t* behind,
               int64_t* clipped) {
  const Vec3 center = camera.Center();
  for (std::size_t f = 0; f < mesh.face_count; ++f) {
    Vec3 cam[3];
    for (int k = 0; k < 3; ++k)
      cam[k] = Add(Mul(camera.rotation, VertexOf(mesh, mesh.faces[3 * f + static_cast<std::size_t>(k)])),
                   camera.translation);
    const int in_front = (cam[0][2] >= options.near) + (cam[1][2] >= options.near) + (cam[2][2] >= options.near);
    if (in_front == 0) {
      ++*behind;
      continue;
    }
    if (face_color != nullptr) {  // headlight: the light comes from the camera
      const Vec3 to_viewer = Normalized(Sub(center, FaceCentroid(mesh, f)));
      (*face_color)[f] = ShadeFace(FaceNormal(mesh, f), to_viewer, to_viewer, options);
    }
    // Clip the polygon to z >= near (Sutherland-Hodgman); remember which vertices are new.
    Vec3 poly[4];
    bool made[4];
    int n = 0;
    for (int k = 0; k < 3; ++k) {
      const Vec3& a = cam[k];
      const Vec3& b = cam[(k + 1) % 3];
      const bool a_in = a[2] >= options.near, b_in = b[2] >= options.near;
      if (a_in) {
        poly[n] = a;
        made[n++] = false;
      }
      if (a_in != b_in) {
        const double s = (options.near - a[2]) / (b[2] - a[2]);
        poly[n] = Add(a, Scale(Sub(b, a), s));
        poly[n][2] = options.near;
        made[n++] = true;
      }
    }
    if (in_front < 3) ++*clipped;
    ScreenVertex sv[4];
    for (int k = 0; k < n; ++k)
      sv[k] = {camera.fx * poly[k][0] / poly[k][2] + camera.cx,
               camera.fy * poly[k][1] / poly[k][2] + camera.cy, 1.0 / poly[k][2]};
    // Fan triangulation; an edge of the polygon is a mesh edge unless clipping made both ends.
    for (int k = 1; k + 1 < n; ++k) {
      const ScreenVertex tri[3] = {sv[0], sv[k], sv[k + 1]};
      const bool real[3] = {k == 1 && !(made[0] && made[1]), !(made[k] && made[k + 1]),
                            k + 2 == n && !(made[k + 1] && made[0])};
      target->Triangle(tri, first_face + static_cast<int32_t>(f), real);
    }
  }
}

}  // namespace

Rendering RenderIntoCamera(const MeshRef& mesh, const Camera& camera, const io::Image* background,
                           const RenderOptions& options) {
  if (const std::string p = camera.Check(); !p.empty()) throw std::invalid_argument("camera: " + p);
  if (const std::string p = options.Check(); !p.empty()) throw std::invalid_argument("render options: " + p);
  CheckMesh(mesh);
  Rendering out;
  if (background != nullptr) {
    if (background->width != camera.width || background->height != camera.height)
      throw std::invalid_argument("background image is " + std::to_string(background->width) + "x" +
                                  std::to_string(background->height) + ", the camera " +
                                  std::to_string(camera.width) + "x" + std::to_string(camera.height));
    if (background->channels != 1 && background->channels != 3)
      throw std::invalid_argument("background image has " + std::to_string(background->channels) +
                                  " channels (1 or 3 expected)");
    out.image = BlankImage(camera.width, camera.height, {0, 0, 0});
    for (int y = 0; y < camera.height; ++y) {
      const uint8_t* row = background->pixels.data() + static_cast<std::ptrdiff_t>(y) * background->stride_bytes;
      uint8_t* dst = out.image.pixels.data() + static_cast<std::size_t>(y) * static_cast<std::size_t>(out.image.stride_bytes);
      for (int x = 0; x < camera.width; ++x)
        for (int k = 0; k < 3; ++k)
          dst[3 * x + k] = background->channels == 1 ? row[x] : row[3 * x + k];
    }
  } else {
    out.image = BlankImage(camera.width, camera.height, options.background);
  }

  Target target(camera.width, camera.height, /*perspective=*/true);
  std::vector<Rgb> face_color(mesh.face_count);
  DrawFaces(mesh, camera, options, 0, &target, &face_color, &out.faces_behind, &out.faces_clipped);
  Composite(target, face_color, options, options.opacity, &out.image);
  out.faces_drawn = FacesDrawn(target.face(), mesh.face_count);
  out.depth = std::move(target.depth());
  out.face = std::move(target.face());
  return out;
}

std::array<double, 2> TopDownView::ToPixel(const Vec3& x) const {
  return {margin + (Dot(x, right) - origin_right) * scale, margin + (Dot(x, down) - origin_down) * scale};
}

TopDownRendering RenderTopDown(const MeshRef& mesh, const CameraPath& path,
                               const TopDownOptions& options) {
  if (const std::string p = options.Check(); !p.empty()) throw std::invalid_argument("top-down options: " + p);
  if (!path.keyframe.empty() && path.keyframe.size() != path.cameras.size())
    throw std::invalid_argument("camera path: " + std::to_string(path.keyframe.size()) +
                                " keyframe flags for " + std::to_string(path.cameras.size()) + " cameras");
  CheckMesh(mesh);
  std::vector<Vec3> centers;
  for (const Camera& c : path.cameras) centers.push_back(c.Center());

  // Axes: up (given, or the cameras' mean up), right = the direction of travel, down = right x up
  // (so that right, down, -up is a right-handed image frame looking down).
  TopDownView view;
  Vec3 up = options.up ? *options.up : Vec3{0, 0, 0};
  if (!options.up) {
    for (const Camera& c : path.cameras) up = Sub(up, c.rotation[1]);
    if (!(Norm(up) > 1e-9)) up = {0, 0, 1};
  }
  up = Normalized(up);
  auto flatten = [&](const Vec3& v) { return Sub(v, Scale(up, Dot(v, up))); };
  Vec3 right{};
  double extent = 0.0;
  for (std::size_t i = 1; i < centers.size(); ++i) extent = std::max(extent, Norm(flatten(Sub(centers[i], centers[0]))));
  if (centers.size() >= 2) {
    const Vec3 travel = flatten(Sub(centers.back(), centers.front()));
    if (Norm(travel) > 0.25 * extent && Norm(travel) > 0) right = Normalized(travel);
  }
  if (Norm(right) == 0.0 && !path.cameras.empty()) {
    const Camera& c = path.cameras.front();
    right = Normalized(flatten(c.rotation[2]));
  }
  if (Norm(right) == 0.0) {
    // Any direction perpendicular to up.
    const Vec3 axis = std::abs(up[0]) < 0.9 ? Vec3{1, 0, 0} : Vec3{0, 1, 0};
    right = Normalized(flatten(axis));
  }
  view.up = up;
  view.right = right;
  view.down = Cross(right, up);
  view.margin = options.margin;

  // Extent of what is drawn: the used vertices and the camera centres.
  double lo_r = std::numeric_limits<double>::infinity(), hi_r = -lo_r, lo_d = lo_r, hi_d = -lo_r;
  double top = -std::numeric_limits<double>::infinity();
  auto include = [&](const Vec3& x) {
    const double r = Dot(x, view.right), d = Dot(x, view.down);
    lo_r = std::min(lo_r, r);
    hi_r = std::max(hi_r, r);
    lo_d = std::min(lo_d, d);
    hi_d = std::max(hi_d, d);
  };
  for (std::size_t i = 0; i < 3 * mesh.face_count; ++i) {
    const Vec3 x = VertexOf(mesh, mesh.faces[i]);
    include(x);
    top = std::max(top, Dot(x, up));
  }
  if (options.draw_path)
    for (const Vec3& c : centers) include(c);
  if (!std::isfinite(lo_r)) lo_r = hi_r = lo_d = hi_d = 0.0;  // nothing at all
  if (!std::isfinite(top)) top = 0.0;
  const double span = std::max(hi_r - lo_r, hi_d - lo_d);
  const int inner = options.size - 2 * options.margin;
  view.scale = span > 0 ? inner / span : 1.0;
  view.origin_right = lo_r;
  view.origin_down = lo_d;
  view.top = top;
  const int width = std::clamp(static_cast<int>(std::ceil((hi_r - lo_r) * view.scale)) + 2 * options.margin + 1, 1, options.size + 1);
  const int height = std::clamp(static_cast<int>(std::ceil((hi_d - lo_d) * view.scale)) + 2 * options.margin + 1, 1, options.size + 1);

  TopDownRendering result;
  result.view = view;
  Rendering& out = result.rendering;
  out.image = BlankImage(width, height, options.render.background);
  Target target(width, height, /*perspective=*/false);
  // Light from above, a little from the upper left of the picture, so slopes show.
  const Vec3 light = Normalized(Add(Scale(up, 2.0), Sub(Scale(view.down, -0.6), Scale(view.right, 0.6))));
  double bottom = top;
  for (std::size_t i = 0; i < 3 * mesh.face_count; ++i) bottom = std::min(bottom, Dot(VertexOf(mesh, mesh.faces[i]), up));
  std::vector<Rgb> face_color(mesh.face_count);
  for (std::size_t f = 0; f < mesh.face_count; ++f) {
    RenderOptions shade = options.render;
    if (options.color_by_height) {
      const double t = top > bottom ? (Dot(FaceCentroid(mesh, f), up) - bottom) / (top - bottom) : 0.0;
      shade.front_color = shade.back_color = HeightColor(t);
    }
    face_color[f] = ShadeFace(FaceNormal(mesh, f), up, light, shade);
    ScreenVertex sv[3];
    for (int k = 0; k < 3; ++k) {
      const Vec3 x = VertexOf(mesh, mesh.faces[3 * f + static_cast<std::size_t>(k)]);
      const auto p = view.ToPixel(x);
      sv[k] = {p[0], p[1], top - Dot(x, up)};
    }
    const bool real[3] = {true, true, true};
    target.Triangle(sv, static_cast<int32_t>(f), real);
  }
  Composite(target, face_color, options.render, 1.0, &out.image);
  out.faces_drawn = FacesDrawn(target.face(), mesh.face_count);
  out.depth = std::move(target.depth());
  out.face = std::move(target.face());

  if (options.draw_path && !centers.empty()) {
    for (std::size_t i = 1; i < centers.size(); ++i)
      DrawSegment(&out.image, view.ToPixel(centers[i - 1]), view.ToPixel(centers[i]),
                  options.path_width, options.path_color);
    if (options.keyframe_radius > 0)
      for (std::size_t i = 0; i < path.keyframe.size(); ++i)
        if (path.keyframe[i]) DrawDisc(&out.image, view.ToPixel(centers[i]), options.keyframe_radius, 0.0, options.keyframe_color);
    const double ring = std::max(options.keyframe_radius, options.path_width) + 3.0;
    DrawDisc(&out.image, view.ToPixel(centers.front()), ring, ring - 2.0, options.start_color);
  }
  return result;
}

}  // namespace imr::render
