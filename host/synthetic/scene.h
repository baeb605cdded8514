// Known synthetic scenes for tests and benchmarks: a street canyon (facades, ground, parked boxes),
// a closed room, a plane. Geometry: distance to the true surface and ray intersection; each rect
// also says what it is (Material) so that texture.h can give it an appearance. The observation
// stream (stream.h) and the image renderer (tools/synth) are built on top of it.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "host/util/geometry.h"

namespace imr::synthetic {

using ::imr::Vec3;

// What a rect is, for its appearance only (texture.h); geometry ignores it.
enum class Material : uint8_t {
  kPlain,    // No role (rooms, planes, hand-made scenes): a neutral tiled pattern.
  kGround,   // Street surface: asphalt, lane markings, kerbs and pavements.
  kFacade,   // A row of buildings: windows, bricks or plaster.
  kBoxSide,  // Long vertical side of a box (a parked car).
  kBoxEnd,   // Short vertical side of a box (front or back of a car).
  kBoxTop,   // Top of a box (a car roof).
};
std::string ToString(Material material);

// An oriented rectangle: center + s*u + t*v with |s| <= half_u, |t| <= half_v (u, v orthonormal).
struct Rect {
  Vec3 center{};
  Vec3 u{};
  Vec3 v{};
  double half_u = 0.0;
  double half_v = 0.0;
  Material material = Material::kPlain;
  int group = -1;  // The object it belongs to (box number, facade side 0 = -x / 1 = +x); -1: none.
};

class Scene {
 public:
  // Street canyon along +y from y = 0 to y = length: ground z = 0, facades at x = +-half_width
  // (height facade_height), boxes (parked cars) along both kerbs, placed at random by seed.
  static Scene StreetCanyon(double length, uint64_t seed, double half_width = 8.0,
                            double facade_height = 12.0);
  // The six inner faces of the box [min, max] (a closed room, cameras inside).
  static Scene ClosedRoom(const Vec3& min, const Vec3& max);
  // One horizontal square plane z = height, side 2 * half_size, centred on the origin.
  static Scene Plane(double half_size, double height = 0.0);

  void AddRect(const Rect& r);
  // Axis-aligned box; with_bottom = false leaves out the face at min z (a box standing on a floor).
  void AddBox(const Vec3& min, const Vec3& max, bool with_bottom);

  // Unsigned distance from p to the nearest surface of the scene.
  double Distance(const Vec3& p) const;
  // First intersection of the ray origin + t * dir (dir unit), 0 < t <= t_max. Returns false if none.
  bool Intersect(const Vec3& origin, const Vec3& dir, double t_max, double* t_hit) const;
  // True when nothing in the scene lies on the segment from `from` to `to` (up to `eps` before it).
  bool Visible(const Vec3& from, const Vec3& to, double eps = 1e-3) const;
  // Indices (ascending, each once) of the rects whose xy bounding box may meet the box
  // [x0, x1] x [y0, y1]: a superset, found through the bin index, so its cost follows the box's
  // size, not the scene's.
  std::vector<int> RectsNear(double x0, double y0, double x1, double y1) const;

  const std::vector<Rect>& rects() const { return rects_; }
  const std::string& name() const { return name_; }

 private:
  void Index() const;
  // Calls visit(i) for every rect that may meet the xy box (large rects first, then the bins'
  // rects; a rect spanning several bins may come more than once): no allocation, no sorting.
  template <typename Visit>
  void ForEachCandidate(double x0, double y0, double x1, double y1, Visit&& visit) const;
  // Nearest hit of the ray within (0, t_max]; with `any`, the first hit found.
  bool Cast(const Vec3& origin, const Vec3& dir, double t_max, bool any, double* t_hit) const;

  std::string name_;
  std::vector<Rect> rects_;
  // Uniform xy bins over rect bounding boxes, built lazily (scenes are immutable once built). A
  // rect spanning more than kLargeBins bins (a street's ground and facades, as long as the
  // street) is kept out of the bins, in large_, and tried by every query: otherwise every bin
  // holds it and a query sorts out the copies.
  mutable bool indexed_ = false;
  mutable std::vector<int> large_;
  mutable double bin_ = 10.0;
  mutable double min_x_ = 0.0, min_y_ = 0.0;
  mutable int nx_ = 0, ny_ = 0;
  mutable std::vector<std::vector<int>> bins_;
};

// The vector helpers (host/util/geometry.h), also as synthetic::Add etc. for the benchmarks.
using ::imr::Add;
using ::imr::Cross;
using ::imr::Dot;
using ::imr::Norm;
using ::imr::Scale;
using ::imr::Sub;
// a / |a|, or a itself when it has no length.
Vec3 Normalized(const Vec3& a);

}  // namespace imr::synthetic
