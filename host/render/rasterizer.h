// Looking at a mesh without a 3D viewer (issue 6, the paper's Figure 3): a depth-tested triangle
// rasteriser that draws a mesh into a camera over that camera's image, and a top-down
// orthographic view of the whole mesh with the camera path. No OpenCV, no CGAL: plain arrays in,
// an io::Image (8-bit BGR, the struct of image_io.h) plus its depth and triangle-id buffers out.
//
// Camera convention: the one of host/io/camera_model.h and image_sequence.h —
//   x_cam = R X + t, camera looking down +z, x right, y down;
//   pixel (u, v) = (fx x/z + cx, fy y/z + cy), the CENTRE of the top-left pixel at (0, 0).
// A pixel is covered by a triangle when its centre is inside the projected triangle (top-left
// fill rule on the edges, so two triangles sharing an edge never both cover a pixel). Triangles
// crossing the near plane (z = near) are clipped to it; distortion is not modelled (the image
// sequences imr reads are rectified).
//
// Shading: flat, by face normal (right-hand rule over the face's vertex order; the engine orients
// normals toward free space, i.e. toward the cameras): colour = base * (ambient + (1 - ambient) *
// |cos(normal, light)|), base = front_color where the normal faces the viewer and back_color
// where it faces away (a back face seen from a camera is worth noticing). Wireframe: a pixel is on
// an edge when its centre, inside the visible triangle, lies within wire_width / 2 pixels of
// one of that triangle's edges; only visible parts of edges are drawn (hidden-line removal by
// the z-buffer, exactly: the test uses the visible triangle's own pixels).
#pragma once

#include "host/io/image_io.h"
#include "host/util/geometry.h"

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace imr::render {

using ::imr::Vec3;
using Mat3 = std::array<std::array<double, 3>, 3>;  // row-major
using Rgb = std::array<uint8_t, 3>;                  // red, green, blue

// A triangle mesh as packed arrays (engine::Mesh's layout): xyz per vertex, 3 indices per face.
struct MeshRef {
  const double* xyz = nullptr;
  std::size_t vertex_count = 0;
  const uint32_t* faces = nullptr;
  std::size_t face_count = 0;
};
// A view of packed vectors; the vectors must outlive it.
MeshRef MeshRefOf(const std::vector<double>& xyz, const std::vector<uint32_t>& faces);

// A pinhole camera in imr's convention (above).
struct Camera {
  int width = 0;   // image size, pixels
  int height = 0;
  double fx = 0.0, fy = 0.0, cx = 0.0, cy = 0.0;
  Mat3 rotation{{{1, 0, 0}, {0, 1, 0}, {0, 0, 1}}};  // R: world -> camera
  Vec3 translation{};                                // t: x_cam = R X + t

  Vec3 Center() const;  // C = -R^T t
  // Empty when usable, else what is wrong (size, focal lengths, R not a rotation).
  std::string Check() const;
};

struct RenderOptions {
  bool shaded = true;        // fill the triangles (flat shading); false: wireframe only
  bool wireframe = false;    // draw the visible edges
  // Into a camera over its image: shaded pixels = opacity * mesh + (1 - opacity) * image; edges
  // are drawn opaque. 1: the mesh hides the image. (The top-down view draws the mesh opaque.)
  double opacity = 0.6;
  Rgb front_color{235, 165, 70};   // faces whose normal points toward the viewer
  Rgb back_color{80, 135, 235};    // faces seen from behind
  Rgb wire_color{0, 210, 0};
  double wire_width = 2.0;         // pixels (see the header comment)
  double ambient = 0.3;            // share of the colour that does not depend on the light
  double near = 1e-3;              // near clipping distance, scene units (camera view)
  Rgb background{0, 0, 0};         // where there is no image below (no background given)

  // Empty when usable, else which field and why.
  std::string Check() const;
};

// What was drawn: the picture and, per pixel (row-major, width * height), the visible surface.
struct Rendering {
  io::Image image;              // 8-bit BGR (channels = 3), like io::ReadImage's colour images
  std::vector<float> depth;     // camera: z of the visible surface (along the optical axis);
                                // top-down: distance below the view's top plane; +inf: none
  std::vector<int32_t> face;    // index of the visible triangle; -1: none
  int64_t faces_drawn = 0;      // triangles that won at least one pixel
  int64_t faces_clipped = 0;    // crossing the near plane (drawn clipped)
  int64_t faces_behind = 0;     // wholly behind the near plane (not drawn)

  // Share of pixels showing a triangle.
  double Coverage() const;
};

// Draws `mesh` into `camera`. `background`: the camera's image (gray or BGR, same size as the
// camera; nullptr: options.background). Throws std::invalid_argument when the camera or the
// options are unusable (their Check()), a face index is out of range or a face's vertex is not
// finite, or the background's size differs from the camera's.
Rendering RenderIntoCamera(const MeshRef& mesh, const Camera& camera, const io::Image* background,
                           const RenderOptions& options);

// How much of what the cameras see is seen from behind (issue 34): the cameras are in free space,
// so every surface they see should face them. Over every camera (drawn at `scale` of its size:
// fx, fy, cx, cy and the image scaled, pixel centres kept), the pixels showing a face whose
// normal (right-hand rule over its vertex order) points away from the camera centre.
struct BackFacing {
  int64_t views = 0;        // cameras drawn
  int64_t pixels = 0;       // pixels showing the mesh, summed over them
  int64_t back_pixels = 0;  // of those, showing a face from behind
  double Share() const { return pixels > 0 ? static_cast<double>(back_pixels) / static_cast<double>(pixels) : 0.0; }
};
// Throws as RenderIntoCamera does; `scale` in (0, 1].
BackFacing MeasureBackFacing(const MeshRef& mesh, const std::vector<Camera>& cameras, double scale);

// Per face, 1 when the cameras (each drawn at `scale` of its size) show it from behind more than
// from the front: of the pixels it wins, more in cameras it faces away from; else 0 (a face seen
// from behind through a hole by one camera and from the front by others stays). Throws as
// MeasureBackFacing does.
std::vector<uint8_t> FacesSeenFromBehind(const MeshRef& mesh, const std::vector<Camera>& cameras, double scale);

// MeasureBackFacing over a mesh given in blocks of triangles (a long drive's single mesh, read
// back from disk), each camera's frame buffer kept across the blocks: the same figures as the
// whole mesh when the blocks come in its face order. Holds per camera ~13 bytes a pixel.
class BackFacingInBlocks {
 public:
  // Throws std::invalid_argument for an unusable camera or scale.
  BackFacingInBlocks(const std::vector<Camera>& cameras, double scale);
  ~BackFacingInBlocks();
  BackFacingInBlocks(const BackFacingInBlocks&) = delete;
  BackFacingInBlocks& operator=(const BackFacingInBlocks&) = delete;
  // The next faces (indices into the block's own vertices); throws as RenderIntoCamera does.
  void AddTriangles(const MeshRef& block);
  BackFacing Result() const;

 private:
  struct View;
  std::vector<std::unique_ptr<View>> views_;
  int64_t faces_ = 0;
};

// The camera path of the top-down view: one entry per frame, in order.
struct CameraPath {
  std::vector<Camera> cameras;  // only rotation and translation are used
  std::vector<bool> keyframe;   // same size (or empty: no keyframe marked)
};

struct TopDownOptions {
  RenderOptions render{.opacity = 1.0, .background = {255, 255, 255}};
  int size = 1600;    // pixels along the longer side of the image
  int margin = 24;    // pixels of background around the mesh and the path
  // World "up" (looked down along). Unset: the mean of the cameras' up directions (their -y
  // axes, the image's up); +z when there are no cameras.
  std::optional<Vec3> up;
  Rgb path_color{215, 25, 25};       // camera centres, joined in frame order
  double path_width = 2.0;           // pixels
  Rgb keyframe_color{25, 25, 200};   // a disc at each keyframe's centre
  double keyframe_radius = 4.0;      // pixels
  Rgb start_color{0, 160, 0};        // a ring around the first camera
  bool draw_path = true;
  // Colour faces by the height of their centre (grey at the lowest, through blue, green and
  // yellow to red at the highest), shaded; false: front_color / back_color as in a camera.
  bool color_by_height = true;

  std::string Check() const;
};

// How the top-down view maps the world to pixels: pixel = margin + (dot(X, axis) - origin) *
// scale per axis (right: image x, down: image y); looking along -up.
struct TopDownView {
  Vec3 right{}, down{}, up{};
  double origin_right = 0.0, origin_down = 0.0, top = 0.0;  // top: the highest height drawn
  double scale = 1.0;   // pixels per scene unit
  int margin = 0;
  std::array<double, 2> ToPixel(const Vec3& x) const;
};

struct TopDownRendering {
  Rendering rendering;
  TopDownView view;
};

// The whole mesh seen from above (orthographic), the direction of travel (first to last camera;
// the first camera's viewing direction when the path returns to its start) pointing right, with
// the camera path drawn over it. Throws std::invalid_argument like RenderIntoCamera.
TopDownRendering RenderTopDown(const MeshRef& mesh, const CameraPath& path,
                               const TopDownOptions& options);

}  // namespace imr::render
