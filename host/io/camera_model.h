// Camera geometry shared by the SfM/SLAM readers and writers (docs/interop.md), in ONE convention:
//
//   x_cam = R * X_world + t        R: world -> camera rotation (row-major 3x3), t: translation,
//   C = -R^T t                     C: the camera centre in world coordinates,
//
// camera looking down +z, x right, y down; pixels u = fx * x_d + cx, v = fy * y_d + cy, where
// (x_d, y_d) are the normalised coordinates (x/z, y/z) after the OpenCV distortion model
// (radial k1, k2, k3 and tangential p1, p2). Each reader converts to this on reading:
//   - OpenMVG: extrinsics store R (world -> camera) and C; t = -R C.
//   - COLMAP: images store qvec (qw, qx, qy, qz; scalar first) = R and tvec = t.
//   - SLAM JSON 0.3: extrinsic{rotation (world -> camera, as OpenMVG), center}.
// Pixel coordinates are kept as each file writes them (COLMAP puts the centre of the top-left
// pixel at (0.5, 0.5), OpenMVG at (0, 0)); the engine never uses pixels.
#pragma once

#include "host/engine/engine.h"

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace imr::io {

using engine::Vec3;
using Mat3 = std::array<std::array<double, 3>, 3>;  // row-major: m[row][col]

Mat3 Identity3();
Mat3 Transpose(const Mat3& m);
Vec3 Mul(const Mat3& m, const Vec3& v);
Mat3 MatMul(const Mat3& a, const Mat3& b);  // a b
double Determinant(const Mat3& m);

// A rigid transform x' = r x + t: a pose, or the calibration between two sensors.
struct Rigid {
  Mat3 r = Identity3();
  Vec3 t{};
};
// a after b: x -> a(b(x)).
Rigid Compose(const Rigid& a, const Rigid& b);
Rigid Inverse(const Rigid& a);

// The one tolerance of every reader on rotations, on the largest entry of |R R^T - I|. Files
// keep 6 to 9 significant digits (1e-9 .. 1e-6 off): within it a rotation is re-orthonormalised
// (the refiner and the engine expect orthonormal to rounding), beyond it refused.
inline constexpr double kRotationTolerance = 1e-4;
// The largest coordinate every reader accepts in a position (camera centre or translation,
// point): far beyond any scene (1e12 metres), far below where squared distances overflow.
inline constexpr double kMaxCoordinate = 1e12;

// Empty when `r` is a rotation (orthonormal rows within `tolerance`, determinant +1); otherwise
// what is wrong, e.g. "is not a rotation: not orthonormal (largest |R R^T - I| entry 0.3, more
// than the 0.0001 imr re-orthonormalises)" or "... determinant -1 (a reflection)".
std::string RotationProblem(const Mat3& r, double tolerance = kRotationTolerance);
// The rotation nearest to `r` (its polar factor), for `r` close to one.
Mat3 Orthonormalized(const Mat3& r);
// RotationProblem(*r); when there is none, *r is re-orthonormalised.
std::string CheckRotation(Mat3* r);
// Empty when |x| <= kMaxCoordinate, else "expected a coordinate within +-1e12 (scene units),
// got <x>".
std::string CoordinateProblem(double x);

// Empty when (fx, fy, cx, cy) are intrinsics: focal lengths finite and > 0, a finite principal
// point (pixels); else what is wrong ("expected focal lengths fx, fy finite and > 0 (pixels),
// got fx 0, fy 0"). The readers of OpenMVG, SLAM JSON and COLMAP check theirs with it.
std::string IntrinsicsProblem(double fx, double fy, double cx, double cy);

// Unit quaternion (w, x, y, z; scalar first, as COLMAP) <-> rotation matrix.
Mat3 QuaternionToRotation(const std::array<double, 4>& q);
std::array<double, 4> RotationToQuaternion(const Mat3& r);

// How a direction (x, y, z) in the camera frame becomes the normalised coordinates (a, b) that
// the distortion polynomial then bends (COLMAP's sensor/models.h, OpenCV's calib3d):
//   kPerspective: (a, b) = (x/z, y/z);
//   kFisheye: equidistant, (a, b) = (x/z, y/z) * theta / r with r = |(x/z, y/z)|, theta = atan(r)
//     (COLMAP's *FISHEYE models, OpenCV's and OpenMVG's fisheye);
//   kFov: (a, b) = (x/z, y/z) * atan(2 r tan(omega / 2)) / (omega r) (Devernay and Faugeras;
//     COLMAP's FOV), no polynomial.
enum class Lens { kPerspective, kFisheye, kFov };

// Intrinsics with the distortion of every model imr reads, plus the model as the source wrote it
// (so a COLMAP model written back keeps its camera model and parameters). After the lens
// mapping, with r2 = a^2 + b^2:
//   radial = (1 + k1 r2 + k2 r2^2 + k3 r2^3 + k4 r2^4) / (1 + q1 r2 + q2 r2^2 + q3 r2^3)
//   a_d = a radial + 2 p1 a b + p2 (r2 + 2 a^2) + s1 r2
//   b_d = b radial + 2 p2 a b + p1 (r2 + 2 b^2) + s2 r2
//   u = fx a_d + cx, v = fy b_d + cy.
struct Intrinsics {
  std::string source_model;          // e.g. "pinhole_radial_k3" (OpenMVG), "SIMPLE_RADIAL" (COLMAP)
  std::vector<double> source_params;  // as the source lists them
  int width = 0;
  int height = 0;
  double fx = 0.0, fy = 0.0, cx = 0.0, cy = 0.0;
  double k1 = 0.0, k2 = 0.0, k3 = 0.0, p1 = 0.0, p2 = 0.0;
  Lens lens = Lens::kPerspective;
  double k4 = 0.0;                  // r2^4 (COLMAP's OPENCV_FISHEYE, THIN_PRISM_FISHEYE)
  double q1 = 0.0, q2 = 0.0, q3 = 0.0;  // rational denominator (FULL_OPENCV's k4, k5, k6)
  double s1 = 0.0, s2 = 0.0;        // thin prism (THIN_PRISM_FISHEYE's sx1, sy1)
  double omega = 0.0;               // kFov's field of view parameter
  bool projectable = false;  // false: a model imr keeps but cannot project (e.g. spherical)
};

// Everything a reader knows of one camera (view / image / keyframe).
struct CameraGeometry {
  uint64_t id = 0;
  std::string name;   // image file name, when known
  Mat3 rotation = Identity3();  // R, world -> camera
  Vec3 translation{};           // t = -R C
  Vec3 center{};                // C
  bool has_intrinsics = false;
  Intrinsics intrinsics;
};

// Sets translation from rotation and center (t = -R C).
void SetFromCenter(const Mat3& r, const Vec3& c, CameraGeometry* g);
// Sets center from rotation and translation (C = -R^T t).
void SetFromTranslation(const Mat3& r, const Vec3& t, CameraGeometry* g);

// Pixel of world point X in camera g; false when X is not in front of the camera or the
// intrinsics are unknown or not projectable.
bool Project(const CameraGeometry& g, const Vec3& x, double* u, double* v);

// A COLMAP camera model, by COLMAP's model name and parameter order. Fills `out` from `params`;
// false (with *error) when the count is wrong. The models of COLMAP 2.x-3.12 but one
// (SIMPLE_PINHOLE ... THIN_PRISM_FISHEYE, ids 0-10) and COLMAP 4's SIMPLE_FISHEYE and FISHEYE
// are projectable; the others (RAD_TAN_THIN_PRISM_FISHEYE, the division models, EUCM,
// EQUIRECTANGULAR, unknown names in text files) are kept with projectable = false: the engine
// needs only the camera centres.
bool IntrinsicsFromColmap(const std::string& model, const std::vector<double>& params, int width,
                          int height, Intrinsics* out, std::string* error);
// The simplest COLMAP model that represents `in` exactly (its source model when it came from
// COLMAP); false when none does (e.g. an OpenMVG fisheye).
bool IntrinsicsToColmap(const Intrinsics& in, std::string* model, std::vector<double>* params);

// COLMAP's numeric model ids (binary files) <-> names; -1 / "" when unknown.
int ColmapModelId(const std::string& name);
std::string ColmapModelName(int id);
// Number of parameters of a COLMAP model, -1 when unknown.
int ColmapModelParamCount(const std::string& name);

// Shortest text that reads back to exactly `v` (std::to_chars): for files that must round-trip.
std::string ExactNumber(double v);

}  // namespace imr::io
