// Colour and texture for the exported surface, from the keyframe images (issue 17).
//
// Vertex colours: every keyframe that sees a vertex (z-buffer visibility against the mesh itself,
// the vertex in front of its own surface) contributes its bilinear image sample with weight
// (cos(angle between the vertex normal and the viewing ray) / depth)^2, i.e. by the surface
// resolution it gives, when it stands within the colour reach of the vertex (40 steps of the
// camera path: ColourFrame; a vertex no keyframe within the reach sees takes those beyond it);
// vertices nobody sees take their neighbours' colours.
//
// Texture atlas (after Waechter, Moehrle and Goesele, "Let there be color!", ECCV 2014): each
// triangle gets one view, a label, minimising a data term plus a Potts smoothness term over the
// face adjacency graph:
//   E(l) = sum_f (1 - q(f, l_f) / q_max(f)) + seam_penalty * #{adjacent f, g : l_f != l_g},
//   q(f, v) = the triangle's projected area in view v in pixels (resolution and viewing angle)
//             when v sees it whole (its corners and centroid pass the depth test, most of its
//             pixels are its own, it lies inside the image and faces the camera), else no label.
// The labelling starts from each face's best view and runs alpha-expansion moves (each an exact
// minimum cut: every face that sees view alpha whole may switch to it at once) until a cycle
// over the views changes nothing; greedy per-face moves (ICM) stall where two regions meet,
// expansion moves shift whole region boundaries. Faces with one label that are connected form patches; each patch's
// pixel rectangle (plus padding) is copied from its view's image into atlas pages of
// atlas_size^2 pixels (shelf packing, tallest first; a patch never exceeds a page), at the
// image's own resolution. Faces that no view sees whole keep no texture (their vertex colours).
//
// Images come through a callback (the host's keyframe-image service): each selected view is
// asked for once for visibility and colours, then once per atlas page that holds one of its
// patches (the pages are filled one at a time), and held only while it is used.
#pragma once

#include <imr/sdk/plugin.hpp>

#include <array>
#include <cstdint>
#include <functional>
#include <span>
#include <string>
#include <vector>

namespace imr::exporter_assimp {

struct TexturingOptions {
  bool texture = true;        // build the atlas; false: vertex colours only
  int atlas_size = 4096;      // pixels on a side of an atlas page (64 .. 16384)
  int keyframe_step = 1;      // use keyframes 0, n, 2n, ... (and the last one)
  double seam_penalty = 1.0;  // Potts weight per pair of adjacent faces with different views
  int padding = 2;            // texels kept around each patch (bilinear filtering, mipmaps)
  // The world length of one texel the content needs (the request's, ABI 1.6: a level of detail
  // seen from afar); 0: the images' own resolution. Where a view sees pixels smaller than this,
  // a patch takes one texel per n x n pixels (their mean), n the largest whole number of pixels
  // within it at the patch's first face's farthest corner; its other faces allow n to 2n - 1.
  double texel_size = 0.0;

  // Empty when usable, else which field and why.
  std::string Check() const;
};

struct AtlasPage {
  int width = 0;
  int height = 0;
  std::vector<uint8_t> rgb;  // width * height * 3, rows top to bottom
};

struct TexturingStats {
  int views = 0;                  // keyframes used (selected, with intrinsics and an image)
  int64_t faces = 0;
  int64_t faces_textured = 0;     // with a view (the rest: vertex colours)
  int64_t vertices_seen = 0;      // vertices some view saw (the rest: filled from neighbours)
  int64_t candidates = 0;         // (face, view) pairs that passed the visibility test
  int64_t seams_best_view = 0;    // adjacent face pairs with different views, each face's best view
  int64_t seams = 0;              // the same after the smoothness term (alpha-expansion)
  int64_t seams_forced = 0;       // adjacent textured faces no single view sees both whole
  int expansion_cycles = 0;       // cycles of alpha-expansion moves over the views
  int64_t patches = 0;
  int64_t atlas_pixels = 0;       // over all pages
  int64_t patch_pixels = 0;       // texels copied from images (patch rectangles)
  double seconds_visibility = 0.0;  // rasterising, visibility, vertex colours
  double seconds_labelling = 0.0;   // alpha-expansion, patches, packing
  double seconds_atlas = 0.0;       // copying pixels
  double seconds_total = 0.0;
};

struct TexturedMesh {
  // 3 per input vertex (RGB): from the images, neighbours' for vertices nobody saw, else the
  // fallback; empty when no view was usable.
  std::vector<uint8_t> vertex_rgb;
  // Per input vertex: 1 when some view within the colour reach saw it, 2 when only views beyond
  // it did, 0 when none (its colour filled from its neighbours').
  std::vector<uint8_t> vertex_seen;
  // Per face: its atlas page (-1: no texture), its view (keyframe index, -1: none), and 6
  // texture coordinates (u, v per corner, in [0, 1] of its page, origin at the top-left corner,
  // v down: glTF's convention).
  std::vector<int32_t> face_page;
  std::vector<int32_t> face_view;
  std::vector<float> face_uv;
  std::vector<int32_t> face_patch;  // patch number, -1: none (for tests and debugging)
  std::vector<AtlasPage> pages;
  TexturingStats stats;
};

// The image of keyframe i, held while the returned object lives.
using KeyframeImageFetch = std::function<imr::sdk::KeyframeImage(uint64_t keyframe)>;
// Called once per atlas page, in order, as soon as its pixels are whole; it may take them (move
// `page.rgb` out, or clear it: width and height must stay).
using AtlasPageSink = std::function<void(std::size_t index, AtlasPage& page)>;

// Colours (and, with options.texture, the atlas) for `mesh` from `keyframes`. `fetch` gives the
// images; `check_cancelled` is called between views (it may throw to stop); `page_done` sees each
// atlas page when it is whole (the pages are filled one after the other). Throws
// std::invalid_argument for bad options.
TexturedMesh ColorAndTexture(const imr::sdk::MeshView& mesh,
                             std::span<const imr_camera> keyframes, const KeyframeImageFetch& fetch,
                             const TexturingOptions& options,
                             const std::function<void()>& check_cancelled = {},
                             const AtlasPageSink& page_done = {});

// What colouring a piece of a larger mesh as the whole is coloured needs from the whole: the
// keyframes ColorAndTexture takes its views from (indices into `keyframes`: every
// keyframe_step-th and the last, usable ones), their centres, the near plane and the reach (a view
// adds to the colours of the vertices within this distance of it only: 40 times the median step
// between consecutive views; infinity when they do not move). `extent`: the largest absolute
// coordinate of a vertex of the whole.
struct ColourFrame {
  std::vector<int> views;
  std::vector<std::array<double, 3>> centres;  // per entry of `views`
  double near = 0.0;
  double reach = 0.0;
};
ColourFrame ColourFrameOf(std::span<const imr_camera> keyframes, const TexturingOptions& options,
                          double extent);

// The vertex colours of `mesh`, a piece of a larger one, from the keyframes `views` (indices into
// `keyframes`) with the whole's near plane and reach (ColourFrame): a vertex gets the colour
// ColorAndTexture gives it in the whole when the piece holds its faces and every face between it
// and those views that lie within the reach, those are all the views within the reach that see
// it, and one of them does. Vertices no view within the reach sees take the piece's views beyond
// it, then their neighbours' colours within the piece. 3 per vertex.
std::vector<uint8_t> ColourPiece(const imr::sdk::MeshView& mesh, std::span<const imr_camera> keyframes,
                                 std::span<const int> views, const KeyframeImageFetch& fetch,
                                 double near, double reach,
                                 const std::function<void()>& check_cancelled = {});

// A face that a view sees whole, with its quality there (projected area in pixels).
struct ViewCandidate {
  uint32_t face;
  int32_t view;   // 0 .. views - 1
  float quality;  // >= 0
};

// The view selection alone (ColorAndTexture's labelling, for tests): per face its view, -1 for a
// face without candidates; stats gets the seam counts (seams_best_view, seams_forced, seams,
// expansion_cycles). Throws std::invalid_argument for a candidate out of range.
std::vector<int32_t> SelectViews(const imr::sdk::MeshView& mesh, std::vector<ViewCandidate> candidates,
                                 int views, double seam_penalty, TexturingStats* stats);

// Area-weighted vertex normals of the counter-clockwise faces (unit; zero where undefined), packed
// xyz: the normals the exporter writes, and the ones visibility uses.
std::vector<double> VertexNormals(const imr::sdk::MeshView& mesh);

// The keyframes' display frame for glTF (+Y up, looking along -Z): rows = the glTF axes in world
// coordinates. Y = the world's up, the mean of the cameras' up directions (their -y axes, as
// `imr render --top-down`); -Z = their mean viewing direction flattened to the horizontal, so a
// viewer's default camera (on +Z, looking at -Z) looks the way the cameras did, the mesh's
// observed side toward it; X = Y x Z. False (rotation untouched) when there are no cameras or
// their up directions cancel out.
bool UprightRotation(std::span<const imr_camera> keyframes, double rotation[9]);

}  // namespace imr::exporter_assimp
