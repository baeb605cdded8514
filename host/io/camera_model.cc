#include "host/io/camera_model.h"

#include <charconv>
#include <cmath>
#include <limits>
#include <sstream>

namespace imr::io {

Mat3 Identity3() { return {{{1, 0, 0}, {0, 1, 0}, {0, 0, 1}}}; }

Mat3 Transpose(const Mat3& m) {
  Mat3 t;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) t[i][j] = m[j][i];
  return t;
}

Vec3 Mul(const Mat3& m, const Vec3& v) {
  return {m[0][0] * v[0] + m[0][1] * v[1] + m[0][2] * v[2],
          m[1][0] * v[0] + m[1][1] * v[1] + m[1][2] * v[2],
          m[2][0] * v[0] + m[2][1] * v[1] + m[2][2] * v[2]};
}

Mat3 MatMul(const Mat3& a, const Mat3& b) {
  Mat3 c{};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      for (int k = 0; k < 3; ++k) c[i][j] += a[i][k] * b[k][j];
  return c;
}

Rigid Compose(const Rigid& a, const Rigid& b) { return {MatMul(a.r, b.r), Add(Mul(a.r, b.t), a.t)}; }

Rigid Inverse(const Rigid& a) {
  const Mat3 rt = Transpose(a.r);
  const Vec3 t = Mul(rt, a.t);
  return {rt, {-t[0], -t[1], -t[2]}};
}

double Determinant(const Mat3& m) {
  return m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) -
         m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) +
         m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
}

std::string RotationProblem(const Mat3& r, double tolerance) {
  for (const auto& row : r)
    for (double x : row)
      if (!std::isfinite(x)) return "has a non-finite entry";
  double worst = 0.0;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      double d = 0.0;
      for (int k = 0; k < 3; ++k) d += r[i][k] * r[j][k];
      worst = std::max(worst, std::abs(d - (i == j ? 1.0 : 0.0)));
    }
  std::ostringstream m;
  if (worst > tolerance) {
    m << "is not a rotation: not orthonormal (largest |R R^T - I| entry " << worst
      << ", more than the " << tolerance << " imr re-orthonormalises)";
    return m.str();
  }
  const double det = Determinant(r);
  if (det < 0.0) {
    m << "is not a rotation: determinant " << det << " (a reflection)";
    return m.str();
  }
  return {};
}

Mat3 Orthonormalized(const Mat3& r) {
  // Newton's iteration for the polar factor, R <- (R + R^-T) / 2: quadratic, so a few steps take
  // 1e-4 to rounding. R^-T is the cofactor matrix over the determinant; its rows are cross
  // products of R's rows.
  Mat3 q = r;
  for (int step = 0; step < 6; ++step) {
    const auto cross = [&q](int a, int b) -> std::array<double, 3> {
      return {q[a][1] * q[b][2] - q[a][2] * q[b][1], q[a][2] * q[b][0] - q[a][0] * q[b][2],
              q[a][0] * q[b][1] - q[a][1] * q[b][0]};
    };
    const double det = Determinant(q);
    if (!(std::abs(det) > 1e-12)) return q;
    const Mat3 cofactor = {cross(1, 2), cross(2, 0), cross(0, 1)};
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) q[i][j] = 0.5 * (q[i][j] + cofactor[i][j] / det);
  }
  return q;
}

std::string CheckRotation(Mat3* r) {
  std::string problem = RotationProblem(*r);
  // Orthonormal to rounding already (a file imr wrote, replayed): kept bit for bit, so that a
  // replay gives the engine exactly the rotations of the run it records.
  if (problem.empty() && !RotationProblem(*r, 1e-13).empty()) *r = Orthonormalized(*r);
  return problem;
}

std::string CoordinateProblem(double x) {
  if (std::abs(x) <= kMaxCoordinate) return {};
  std::ostringstream m;
  m << "expected a coordinate within +-1e12 (scene units), got " << x;
  return m.str();
}

std::string IntrinsicsProblem(double fx, double fy, double cx, double cy) {
  std::ostringstream m;
  if (!(std::isfinite(fx) && fx > 0.0 && std::isfinite(fy) && fy > 0.0)) {
    m << "expected focal lengths fx, fy finite and > 0 (pixels), got fx " << fx << ", fy " << fy;
    return m.str();
  }
  if (!(std::isfinite(cx) && std::isfinite(cy))) {
    m << "expected a finite principal point cx, cy (pixels), got cx " << cx << ", cy " << cy;
    return m.str();
  }
  return {};
}

Mat3 QuaternionToRotation(const std::array<double, 4>& q0) {
  const double n = std::sqrt(q0[0] * q0[0] + q0[1] * q0[1] + q0[2] * q0[2] + q0[3] * q0[3]);
  const double w = q0[0] / n, x = q0[1] / n, y = q0[2] / n, z = q0[3] / n;
  return {{{1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)},
           {2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)},
           {2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)}}};
}

std::array<double, 4> RotationToQuaternion(const Mat3& r) {
  // Shepperd's method: pivot on the largest of w, x, y, z for accuracy.
  const double tr = r[0][0] + r[1][1] + r[2][2];
  std::array<double, 4> q;
  if (tr > r[0][0] && tr > r[1][1] && tr > r[2][2]) {
    const double s = 2.0 * std::sqrt(1.0 + tr);
    q = {0.25 * s, (r[2][1] - r[1][2]) / s, (r[0][2] - r[2][0]) / s, (r[1][0] - r[0][1]) / s};
  } else if (r[0][0] > r[1][1] && r[0][0] > r[2][2]) {
    const double s = 2.0 * std::sqrt(1.0 + r[0][0] - r[1][1] - r[2][2]);
    q = {(r[2][1] - r[1][2]) / s, 0.25 * s, (r[0][1] + r[1][0]) / s, (r[0][2] + r[2][0]) / s};
  } else if (r[1][1] > r[2][2]) {
    const double s = 2.0 * std::sqrt(1.0 + r[1][1] - r[0][0] - r[2][2]);
    q = {(r[0][2] - r[2][0]) / s, (r[0][1] + r[1][0]) / s, 0.25 * s, (r[1][2] + r[2][1]) / s};
  } else {
    const double s = 2.0 * std::sqrt(1.0 + r[2][2] - r[0][0] - r[1][1]);
    q = {(r[1][0] - r[0][1]) / s, (r[0][2] + r[2][0]) / s, (r[1][2] + r[2][1]) / s, 0.25 * s};
  }
  if (q[0] < 0.0)
    for (double& x : q) x = -x;  // COLMAP's habit: w >= 0
  return q;
}

void SetFromCenter(const Mat3& r, const Vec3& c, CameraGeometry* g) {
  g->rotation = r;
  g->center = c;
  const Vec3 rc = Mul(r, c);
  g->translation = {-rc[0], -rc[1], -rc[2]};
}

void SetFromTranslation(const Mat3& r, const Vec3& t, CameraGeometry* g) {
  g->rotation = r;
  g->translation = t;
  const Vec3 c = Mul(Transpose(r), t);
  g->center = {-c[0], -c[1], -c[2]};
}

namespace {

// (a, b) = (x/z, y/z) through the lens mapping and the distortion (camera_model.h).
void Distort(const Intrinsics& k, double a, double b, double* ad, double* bd) {
  if (k.lens == Lens::kFisheye) {
    const double r = std::sqrt(a * a + b * b);
    if (r > std::numeric_limits<double>::epsilon()) {
      const double s = std::atan(r) / r;
      a *= s, b *= s;
    }
  } else if (k.lens == Lens::kFov) {
    // COLMAP's FOVCameraModel::Distortion, with its series where omega or r is near 0.
    const double r2 = a * a + b * b, w2 = k.omega * k.omega;
    double factor;
    if (w2 < 1e-4) {
      factor = w2 * r2 / 3.0 - w2 / 12.0 + 1.0;
    } else if (r2 < 1e-4) {
      const double t = std::tan(k.omega / 2.0);
      factor = -2.0 * t * (4.0 * r2 * t * t - 3.0) / (3.0 * k.omega);
    } else {
      const double r = std::sqrt(r2);
      factor = std::atan(2.0 * r * std::tan(k.omega / 2.0)) / (r * k.omega);
    }
    *ad = a * factor, *bd = b * factor;
    return;
  }
  const double r2 = a * a + b * b;
  const double radial = (1.0 + r2 * (k.k1 + r2 * (k.k2 + r2 * (k.k3 + r2 * k.k4)))) /
                        (1.0 + r2 * (k.q1 + r2 * (k.q2 + r2 * k.q3)));
  *ad = a * radial + 2.0 * k.p1 * a * b + k.p2 * (r2 + 2.0 * a * a) + k.s1 * r2;
  *bd = b * radial + 2.0 * k.p2 * a * b + k.p1 * (r2 + 2.0 * b * b) + k.s2 * r2;
}

}  // namespace

bool Project(const CameraGeometry& g, const Vec3& x, double* u, double* v) {
  if (!g.has_intrinsics || !g.intrinsics.projectable) return false;
  const Vec3 rx = Mul(g.rotation, x);
  const Vec3 p = {rx[0] + g.translation[0], rx[1] + g.translation[1], rx[2] + g.translation[2]};
  if (!(p[2] > 0.0)) return false;
  const Intrinsics& k = g.intrinsics;
  double xd, yd;
  Distort(k, p[0] / p[2], p[1] / p[2], &xd, &yd);
  *u = k.fx * xd + k.cx;
  *v = k.fy * yd + k.cy;
  return true;
}

namespace {

struct ColmapModel {
  int id;
  const char* name;
  int params;
};
// COLMAP's camera models (src/colmap/sensor/models.h), id, name, parameter count: 0-10 since
// 2.x, 11 since 3.11, 12-15 since 4.0, 16-17 since 4.1 (cameras.bin's layout is unchanged).
const ColmapModel kColmapModels[] = {
    {0, "SIMPLE_PINHOLE", 3}, {1, "PINHOLE", 4},         {2, "SIMPLE_RADIAL", 4},
    {3, "RADIAL", 5},         {4, "OPENCV", 8},          {5, "OPENCV_FISHEYE", 8},
    {6, "FULL_OPENCV", 12},   {7, "FOV", 5},             {8, "SIMPLE_RADIAL_FISHEYE", 4},
    {9, "RADIAL_FISHEYE", 5}, {10, "THIN_PRISM_FISHEYE", 12},
    {11, "RAD_TAN_THIN_PRISM_FISHEYE", 16}, {12, "SIMPLE_DIVISION", 4}, {13, "DIVISION", 5},
    {14, "SIMPLE_FISHEYE", 3}, {15, "FISHEYE", 4}, {16, "EUCM", 6}, {17, "EQUIRECTANGULAR", 2}};

}  // namespace

int ColmapModelId(const std::string& name) {
  for (const auto& m : kColmapModels)
    if (name == m.name) return m.id;
  return -1;
}

std::string ColmapModelName(int id) {
  for (const auto& m : kColmapModels)
    if (id == m.id) return m.name;
  return {};
}

int ColmapModelParamCount(const std::string& name) {
  for (const auto& m : kColmapModels)
    if (name == m.name) return m.params;
  return -1;
}

bool IntrinsicsFromColmap(const std::string& model, const std::vector<double>& p, int width,
                          int height, Intrinsics* out, std::string* error) {
  *out = Intrinsics{};
  out->source_model = model;
  out->source_params = p;
  out->width = width;
  out->height = height;
  const int n = ColmapModelParamCount(model);
  if (n >= 0 && static_cast<int>(p.size()) != n) {
    *error = "camera model " + model + " takes " + std::to_string(n) + " parameters, got " +
             std::to_string(p.size());
    return false;
  }
  // Parameter lists of COLMAP's sensor/models.h: a single focal length f (fx = fy) or fx, fy;
  // then cx, cy; then the model's distortion in its own order.
  const bool one_focal = model == "SIMPLE_PINHOLE" || model == "SIMPLE_RADIAL" ||
                         model == "RADIAL" || model == "SIMPLE_RADIAL_FISHEYE" ||
                         model == "RADIAL_FISHEYE" || model == "SIMPLE_FISHEYE";
  const bool known = one_focal || model == "PINHOLE" || model == "OPENCV" ||
                     model == "OPENCV_FISHEYE" || model == "FULL_OPENCV" || model == "FOV" ||
                     model == "THIN_PRISM_FISHEYE" || model == "FISHEYE";
  if (!known) return true;  // kept as written, not projectable; the engine needs no intrinsics
  out->projectable = true;
  std::size_t i = 0;
  out->fx = p[i++];
  out->fy = one_focal ? out->fx : p[i++];
  out->cx = p[i++];
  out->cy = p[i++];
  if (std::string e = IntrinsicsProblem(out->fx, out->fy, out->cx, out->cy); !e.empty()) {
    *error = std::move(e);
    return false;
  }
  const double* d = p.data() + i;  // the distortion parameters
  if (model == "SIMPLE_RADIAL") {
    out->k1 = d[0];
  } else if (model == "RADIAL") {
    out->k1 = d[0], out->k2 = d[1];
  } else if (model == "OPENCV") {
    out->k1 = d[0], out->k2 = d[1], out->p1 = d[2], out->p2 = d[3];
  } else if (model == "FULL_OPENCV") {
    out->k1 = d[0], out->k2 = d[1], out->p1 = d[2], out->p2 = d[3], out->k3 = d[4];
    out->q1 = d[5], out->q2 = d[6], out->q3 = d[7];
  } else if (model == "FOV") {
    out->lens = Lens::kFov, out->omega = d[0];
  } else if (model == "SIMPLE_FISHEYE" || model == "FISHEYE") {
    out->lens = Lens::kFisheye;  // equidistant, no distortion
  } else if (model == "SIMPLE_RADIAL_FISHEYE") {
    out->lens = Lens::kFisheye, out->k1 = d[0];
  } else if (model == "RADIAL_FISHEYE") {
    out->lens = Lens::kFisheye, out->k1 = d[0], out->k2 = d[1];
  } else if (model == "OPENCV_FISHEYE") {
    out->lens = Lens::kFisheye, out->k1 = d[0], out->k2 = d[1], out->k3 = d[2], out->k4 = d[3];
  } else if (model == "THIN_PRISM_FISHEYE") {
    out->lens = Lens::kFisheye;
    out->k1 = d[0], out->k2 = d[1], out->p1 = d[2], out->p2 = d[3], out->k3 = d[4], out->k4 = d[5];
    out->s1 = d[6], out->s2 = d[7];
  }
  return true;
}

bool IntrinsicsToColmap(const Intrinsics& in, std::string* model, std::vector<double>* params) {
  if (ColmapModelId(in.source_model) >= 0) {
    *model = in.source_model;
    *params = in.source_params;
    return true;
  }
  if (!in.projectable) return false;
  const bool tangential = in.p1 != 0.0 || in.p2 != 0.0;
  const bool prism = in.s1 != 0.0 || in.s2 != 0.0;
  if (in.lens == Lens::kFov) {
    *model = "FOV";
    *params = {in.fx, in.fy, in.cx, in.cy, in.omega};
    return true;
  }
  if (in.lens == Lens::kFisheye) {  // e.g. OpenMVG's fisheye
    if (in.q1 != 0.0 || in.q2 != 0.0 || in.q3 != 0.0) return false;
    if (tangential || prism) {
      *model = "THIN_PRISM_FISHEYE";
      *params = {in.fx, in.fy, in.cx, in.cy, in.k1, in.k2, in.p1, in.p2, in.k3, in.k4, in.s1, in.s2};
    } else {
      *model = "OPENCV_FISHEYE";
      *params = {in.fx, in.fy, in.cx, in.cy, in.k1, in.k2, in.k3, in.k4};
    }
    return true;
  }
  if (in.k4 != 0.0 || prism) return false;  // no perspective COLMAP model has them
  if (in.k3 != 0.0 || in.q1 != 0.0 || in.q2 != 0.0 || in.q3 != 0.0) {
    *model = "FULL_OPENCV";
    *params = {in.fx, in.fy, in.cx, in.cy, in.k1, in.k2, in.p1, in.p2, in.k3, in.q1, in.q2, in.q3};
  } else if (tangential || in.fx != in.fy) {
    if (!tangential && in.k1 == 0.0 && in.k2 == 0.0) {
      *model = "PINHOLE";
      *params = {in.fx, in.fy, in.cx, in.cy};
    } else {
      *model = "OPENCV";
      *params = {in.fx, in.fy, in.cx, in.cy, in.k1, in.k2, in.p1, in.p2};
    }
  } else if (in.k2 != 0.0) {
    *model = "RADIAL";
    *params = {in.fx, in.cx, in.cy, in.k1, in.k2};
  } else if (in.k1 != 0.0) {
    *model = "SIMPLE_RADIAL";
    *params = {in.fx, in.cx, in.cy, in.k1};
  } else {
    *model = "SIMPLE_PINHOLE";
    *params = {in.fx, in.cx, in.cy};
  }
  return true;
}

std::string ExactNumber(double v) {
  char buf[64];
  auto r = std::to_chars(buf, buf + sizeof(buf), v);
  return std::string(buf, r.ptr);
}

}  // namespace imr::io
