// WGS84 geodesy: known points of the ellipsoid, the ENU axes where they are obvious, round trips
// over the heights output.tiles.origin accepts.
#include "host/util/geodesy.h"

#include <gtest/gtest.h>

#include <cmath>

namespace imr::geo {
namespace {

void ExpectNear(const std::array<double, 3>& got, const std::array<double, 3>& want, double tol) {
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(got[k], want[k], tol) << "component " << k;
}

TEST(Geodesy, KnownPointsOfTheEllipsoid) {
  ExpectNear(EcefFromGeodetic({0, 0, 0}), {6378137.0, 0, 0}, 1e-6);
  ExpectNear(EcefFromGeodetic({0, 90, 0}), {0, 6378137.0, 0}, 1e-6);
  ExpectNear(EcefFromGeodetic({0, 180, 100}), {-6378237.0, 0, 0}, 1e-6);
  // The pole: the semi-minor axis b = a (1 - f) = 6356752.314245 m.
  ExpectNear(EcefFromGeodetic({90, 0, 0}), {0, 0, 6356752.314245}, 1e-5);
  ExpectNear(EcefFromGeodetic({-90, 0, 10}), {0, 0, -6356762.314245}, 1e-5);
}

TEST(Geodesy, EnuAxesAtKnownPlaces) {
  // At (0, 0): east is +y, north +z, up +x.
  const std::array<double, 9> a = EnuAxes(0, 0);
  const std::array<double, 9> want = {0, 1, 0, 0, 0, 1, 1, 0, 0};
  for (int k = 0; k < 9; ++k) EXPECT_NEAR(a[k], want[k], 1e-15) << k;
  // At 45 N, 90 E: east is -x, north (0, -1, 1)/sqrt2, up (0, 1, 1)/sqrt2.
  const double h = std::sqrt(0.5);
  const std::array<double, 9> b = EnuAxes(45, 90);
  const std::array<double, 9> want_b = {-1, 0, 0, 0, -h, h, 0, h, h};
  for (int k = 0; k < 9; ++k) EXPECT_NEAR(b[k], want_b[k], 1e-15) << k;
  // The ENU transform: its columns are those axes and the origin's ECEF position.
  const std::array<double, 16> m = EcefFromEnu({45, 90, 20});
  const std::array<double, 3> o = EcefFromGeodetic({45, 90, 20});
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) EXPECT_EQ(m[4 * c + r], b[3 * c + r]);
    EXPECT_EQ(m[12 + r], o[r]);
    EXPECT_EQ(m[4 * r + 3], 0.0);
  }
  EXPECT_EQ(m[15], 1.0);
  // Up at the origin is the ellipsoid's normal: 1 m up raises the height by 1 m.
  const std::array<double, 3> up1 = {o[0] + b[6], o[1] + b[7], o[2] + b[8]};
  EXPECT_NEAR(GeodeticFromEcef(up1).height, 21.0, 1e-6);
}

TEST(Geodesy, RoundTripsOverTheAcceptedHeights) {
  for (double lat : {-89.9999, -60.0, -1e-7, 0.0, 12.5, 49.0113, 89.9999})
    for (double lon : {-180.0, -73.98, 0.0, 8.39, 179.99})
      for (double height : {-11000.0, 0.0, 115.3, 100000.0}) {
        const Geodetic g = GeodeticFromEcef(EcefFromGeodetic({lat, lon, height}));
        EXPECT_NEAR(g.latitude, lat, 1e-10) << lat << " " << lon << " " << height;
        EXPECT_NEAR(std::remainder(g.longitude - lon, 360.0), 0.0, 1e-9);
        EXPECT_NEAR(g.height, height, 1e-6) << lat << " " << lon;
      }
}

}  // namespace
}  // namespace imr::geo
