// Renders the textured street scene (host/synthetic/texture.h) by per-pixel ray casting, and
// scans it with a simulated Velodyne HDL-64E. Deterministic: a frame's pixels depend only on the
// scene, the camera centre, the options and (for the image noise) seed and frame number.
#pragma once

#include <cstdint>
#include <opencv2/core.hpp>
#include <vector>

#include "host/synthetic/texture.h"
#include "tools/synth/raycaster.h"
#include "tools/synth/rig.h"

namespace imr::synth {

struct RenderOptions {
  bool color = false;      // BGR 8-bit image, else gray 8-bit.
  double noise = 2.0;      // Gaussian image noise, standard deviation in grey levels.
  uint64_t seed = 1;       // Seeds the image noise (with the frame number).
  int supersample = 8;     // Rays averaged over a pixel on a geometric edge (n-rooks pattern).
  bool id_colors = false;  // Debug/test: colour = rect index + 1 (24-bit BGR; gray: low byte),
                           // sky 0; no shading, no noise, no anti-aliasing.
};

class Renderer {
 public:
  Renderer(const synthetic::Scene& scene, const synthetic::SceneTexture& texture,
           const RayCaster& caster, const Intrinsics& camera, const RenderOptions& options);

  // The image seen by a camera centred at `center` (scene frame), oriented like every camera of
  // the rig (rig.h). `frame` only seeds the noise.
  cv::Mat Render(const Vec3& center, int frame) const;

  // The scene's own colour at scene point p as the camera centred at `center` sees it: what
  // Render gives the pixel whose centre ray passes through p, before noise and quantisation and
  // without edge supersampling (the texture filtered over that pixel's footprint, lit, hazed).
  // With `rect` >= 0: the colour of that rect at p (p on it), whatever lies in front of it; with
  // -1: of whatever the ray meets first. The rect shaded through *hit (-1: nothing, the sky).
  // For tests that compare a texture made from the images with the truth (the exporter's atlas).
  synthetic::Rgb ColorToward(const Vec3& center, const Vec3& p, int rect, int* hit) const;

 private:
  // Shaded colour (linear, 0..1) of the ray center + t * dir, its pixel footprint spanned by the
  // direction derivatives ddx, ddy. Returns the rect hit (-1: sky) through *rect.
  // Only the small rects in small[0..n) are tested (with every large one).
  synthetic::Rgb Shade(const Vec3& o, const Vec3& dir, const Vec3& ddx, const Vec3& ddy,
                       const uint32_t* small, size_t n, int* rect) const;
  // The colour of rect `rect` hit at o + t * dir (Shade after its ray cast).
  synthetic::Rgb ShadeHit(const Vec3& o, const Vec3& dir, const Vec3& ddx, const Vec3& ddy,
                          int rect, double t) const;

  // The small rects (RayCaster) whose projection, grown by one pixel, meets each kTile x kTile
  // pixel tile of the view from `center`: every ray through a pixel of the tile needs only those.
  struct TileBins {
    int tiles_x = 0;
    std::vector<uint32_t> begin;  // Per tile, offsets into items (one more entry at the end).
    std::vector<uint32_t> items;
  };
  static constexpr int kTile = 16;
  TileBins Bin(const Vec3& center) const;

  const synthetic::Scene& scene_;
  const synthetic::SceneTexture& texture_;
  const RayCaster& caster_;
  Intrinsics camera_;
  RenderOptions options_;
  std::vector<float> gauss_;  // Standard normal quantiles, indexed by a hash (the noise).
  std::vector<uint32_t> all_small_;  // Every small rect (ColorToward tests them all).
};

struct LidarOptions {
  double horizontal_step_deg = 0.2;  // Azimuth step.
  int beams = 64;                    // Elevations evenly from +2 to -24.9 degrees.
  double max_elevation_deg = 2.0;
  double min_elevation_deg = -24.9;
  double max_range = 120.0;
};

// One scan in the velodyne frame, KITTI layout: x, y, z, reflectance (albedo) per point, beam by
// beam from the top beam down, each beam sweeping clockwise seen from above from straight behind;
// rays that hit nothing within max_range give no point.
std::vector<float> ScanVelodyne(const RayCaster& caster, const synthetic::SceneTexture& texture,
                                const Rig& rig, const Vec3& camera_center,
                                const LidarOptions& options);

}  // namespace imr::synth
