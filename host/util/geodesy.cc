#include "host/util/geodesy.h"

#include <cmath>
#include <numbers>

namespace imr::geo {
namespace {

constexpr double kE2 = kWgs84F * (2.0 - kWgs84F);  // first eccentricity squared
constexpr double kDeg = std::numbers::pi / 180.0;

}  // namespace

std::array<double, 3> EcefFromGeodetic(const Geodetic& g) {
  const double phi = g.latitude * kDeg, lambda = g.longitude * kDeg;
  const double s = std::sin(phi), c = std::cos(phi);
  const double n = kWgs84A / std::sqrt(1.0 - kE2 * s * s);  // prime vertical radius
  return {(n + g.height) * c * std::cos(lambda), (n + g.height) * c * std::sin(lambda),
          (n * (1.0 - kE2) + g.height) * s};
}

Geodetic GeodeticFromEcef(const std::array<double, 3>& x) {
  const double p = std::hypot(x[0], x[1]);
  Geodetic g;
  g.longitude = std::atan2(x[1], x[0]) / kDeg;
  // Fixed point on the latitude: converges to double precision in a handful of steps near the
  // surface (each step gains about e^2 = 0.0067 in relative error).
  double phi = std::atan2(x[2], p * (1.0 - kE2));
  double n = kWgs84A;
  for (int i = 0; i < 10; ++i) {
    const double s = std::sin(phi);
    n = kWgs84A / std::sqrt(1.0 - kE2 * s * s);
    phi = std::atan2(x[2] + kE2 * n * s, p);
  }
  const double s = std::sin(phi), c = std::cos(phi);
  n = kWgs84A / std::sqrt(1.0 - kE2 * s * s);
  // Near the poles p / cos(phi) loses precision: the height from z there.
  g.height = std::fabs(c) > 0.1 ? p / c - n : x[2] / s - n * (1.0 - kE2);
  g.latitude = phi / kDeg;
  return g;
}

std::array<double, 9> EnuAxes(double latitude, double longitude) {
  const double phi = latitude * kDeg, lambda = longitude * kDeg;
  const double sp = std::sin(phi), cp = std::cos(phi), sl = std::sin(lambda), cl = std::cos(lambda);
  return {-sl, cl, 0.0,                 // east
          -sp * cl, -sp * sl, cp,       // north
          cp * cl, cp * sl, sp};        // up
}

std::array<double, 16> EcefFromEnu(const Geodetic& g) {
  const std::array<double, 9> r = EnuAxes(g.latitude, g.longitude);
  const std::array<double, 3> t = EcefFromGeodetic(g);
  // Column k is the ENU axis k in ECEF (row k of r), then the origin.
  return {r[0], r[1], r[2], 0.0, r[3], r[4], r[5], 0.0, r[6], r[7], r[8], 0.0, t[0], t[1], t[2], 1.0};
}

}  // namespace imr::geo
