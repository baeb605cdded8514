// WGS84 geodesy for geo-referenced output (issue 46: 3D Tiles in ECEF): geodetic <-> ECEF and the
// east-north-up (ENU) frame at a point, as 3D Tiles viewers (CesiumJS) place a local frame on
// the Earth.
#pragma once

#include <array>
#include <string>

namespace imr::geo {

// WGS84: semi-major axis (m) and flattening.
inline constexpr double kWgs84A = 6378137.0;
inline constexpr double kWgs84F = 1.0 / 298.257223563;

struct Geodetic {
  double latitude = 0.0;   // degrees, north positive
  double longitude = 0.0;  // degrees, east positive
  double height = 0.0;     // metres above the WGS84 ellipsoid
};

std::array<double, 3> EcefFromGeodetic(const Geodetic& g);
// Exact to well under a millimetre for heights in [-11 km, 100 km] (a few fixed-point steps).
Geodetic GeodeticFromEcef(const std::array<double, 3>& ecef);

// The ENU axes at (latitude, longitude) in ECEF, row-major: rows east, north, up (ENU <- ECEF).
std::array<double, 9> EnuAxes(double latitude, double longitude);

// ECEF <- ENU at `g`: column-major 4x4 (3D Tiles' `transform` order).
std::array<double, 16> EcefFromEnu(const Geodetic& g);

// Where a sequence's frame stands on the Earth, when its input says so (KITTI raw's GNSS/IMU):
// the WGS84 position of the frame's origin and the rotation from its axes to ENU there.
struct GeoAnchor {
  Geodetic origin;
  std::array<double, 9> enu_from_world{};  // row-major
  std::string source;                      // for messages: which file said so
};

}  // namespace imr::geo
