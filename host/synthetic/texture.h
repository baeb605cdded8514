// Procedural appearance of a known Scene, for rendering images of it (tools/synth): facades are
// rows of buildings (windows with dark frames, bricks or plaster, string courses, shop fronts),
// the ground is asphalt with lane markings, zebra crossings, kerbs and paved pavements, boxes are
// cars (body colour, glass, wheels, lights, plates). Every surface gives Canny edges and texture
// for KLT at all distances.
//
// Band-limited: Albedo() returns the texture averaged over the pixel's footprint on the surface (a
// box filter; exact for the rectangular patterns, whose coverage is integrated analytically, and
// octave fading for the noise), so a moving camera sees no shimmer and no moire. Deterministic by
// seed; const and thread-safe after construction.
#pragma once

#include <cstdint>
#include <vector>

#include "host/synthetic/scene.h"

namespace imr::synthetic {

// Linear colour, components in [0, 1].
struct Rgb {
  float r = 0.0f, g = 0.0f, b = 0.0f;
};

class SceneTexture {
 public:
  // `scene` must outlive this object (its rects are read at every call).
  SceneTexture(const Scene& scene, uint64_t seed);

  // Albedo of rect `rect` (index into scene.rects()) at the point p on it, averaged over the
  // parallelogram p + a * dpdx + b * dpdy, |a|, |b| <= 1/2: the footprint of one pixel (the hit
  // point's derivatives along the image axes). Zero vectors give the unfiltered point value.
  Rgb Albedo(int rect, const Vec3& p, const Vec3& dpdx, const Vec3& dpdy) const;

  const Scene& scene() const { return scene_; }

  // Luminance (OpenCV's gray weights 0.299, 0.587, 0.114).
  static float Luminance(const Rgb& c) { return 0.299f * c.r + 0.587f * c.g + 0.114f * c.b; }

 private:
  // Texture coordinates of a rect: s = (p - origin) . axis_s, t = (p - origin) . axis_t, metres.
  struct Frame {
    Vec3 origin{};
    Vec3 axis_s{};
    Vec3 axis_t{};
    double half_s = 0.0;  // Box faces and tops: half extent along s.
    double half_t = 0.0;  // Box tops: half extent along t.
    double height = 0.0;  // Box faces: height of the box; facades: facade height.
    bool front = false;   // Box ends: the +y end (headlights) rather than the -y end.
  };
  // One building of a facade: the span [s0, s1) along the street and how it looks.
  struct Building {
    double s0 = 0.0, s1 = 0.0;
    uint64_t key = 0;    // Seeds its per-element variation (bricks, windows).
    bool brick = false;  // Brick wall, else plaster.
    bool shop = false;   // Ground floor: shop windows, else small windows.
    Rgb wall, trim, frame, glass;
    double ground_floor = 3.5;            // Height of the ground floor.
    double storey = 3.0;                  // Height of the upper storeys.
    double bay = 3.0;                     // Window spacing along the street.
    double bay_offset = 0.0;              // s of the left frame edge of the first window.
    double bays_lo = 0.0, bays_hi = 0.0;  // s range holding windows.
    double win_w = 1.2, win_h = 1.5, sill = 0.9, frame_w = 0.1;
  };
  // One parked car (a box of the street scene).
  struct Car {
    Rgb body, accent, glass;
    bool stripe = false;
  };

  Rgb Ground(double x, double y, double wx, double wy) const;
  Rgb Facade(int side, double s, double t, double ws, double wt, double height) const;
  Rgb BuildingColor(const Building& b, double s, double t, double ws, double wt,
                    double height) const;
  Rgb CarSide(const Car& car, double s, double t, double ws, double wt, double half_len,
              double height) const;
  Rgb CarEnd(const Car& car, double s, double t, double ws, double wt, double half_width,
             double height, bool front) const;
  Rgb CarTop(const Car& car, double s, double t, double ws, double wt, double half_s,
             double half_t) const;
  Rgb Plain(double s, double t, double ws, double wt) const;
  const Car& CarOf(int group) const;

  const Scene& scene_;
  uint64_t seed_;
  std::vector<Frame> frames_;
  std::vector<Building> buildings_[2];  // Per facade side, sorted by s.
  std::vector<Car> cars_;               // Indexed by box group.
  std::vector<double> crossings_;       // y of the zebra crossings (their near edge).
  double road_half_width_ = 0.0;        // Half width of the ground rect (kerbs lie inside it).
};

}  // namespace imr::synthetic
