#include "host/io/camera_model.h"

#include <charconv>
#include <cmath>
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

bool Project(const CameraGeometry& g, const Vec3& x, double* u, double* v) {
  if (!g.has_intrinsics || !g.intrinsics.projectable) return false;
  const Vec3 rx = Mul(g.rotation, x);
  const Vec3 p = {rx[0] + g.translation[0], rx[1] + g.translation[1], rx[2] + g.translation[2]};
  if (!(p[2] > 0.0)) return false;
  const Intrinsics& k = g.intrinsics;
  const double xn = p[0] / p[2], yn = p[1] / p[2];
  const double r2 = xn * xn + yn * yn;
  const double radial = 1.0 + r2 * (k.k1 + r2 * (k.k2 + r2 * k.k3));
  const double xd = xn * radial + 2.0 * k.p1 * xn * yn + k.p2 * (r2 + 2.0 * xn * xn);
  const double yd = yn * radial + k.p1 * (r2 + 2.0 * yn * yn) + 2.0 * k.p2 * xn * yn;
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
// COLMAP's camera models (src/colmap/sensor/models.h), id, name, parameter count.
const ColmapModel kColmapModels[] = {
    {0, "SIMPLE_PINHOLE", 3}, {1, "PINHOLE", 4},         {2, "SIMPLE_RADIAL", 4},
    {3, "RADIAL", 5},         {4, "OPENCV", 8},          {5, "OPENCV_FISHEYE", 8},
    {6, "FULL_OPENCV", 12},   {7, "FOV", 5},             {8, "SIMPLE_RADIAL_FISHEYE", 4},
    {9, "RADIAL_FISHEYE", 5}, {10, "THIN_PRISM_FISHEYE", 12},
    {11, "RAD_TAN_THIN_PRISM_FISHEYE", 16}};

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
  out->projectable = true;
  if (model == "SIMPLE_PINHOLE") {
    out->fx = out->fy = p[0], out->cx = p[1], out->cy = p[2];
  } else if (model == "PINHOLE") {
    out->fx = p[0], out->fy = p[1], out->cx = p[2], out->cy = p[3];
  } else if (model == "SIMPLE_RADIAL") {
    out->fx = out->fy = p[0], out->cx = p[1], out->cy = p[2], out->k1 = p[3];
  } else if (model == "RADIAL") {
    out->fx = out->fy = p[0], out->cx = p[1], out->cy = p[2], out->k1 = p[3], out->k2 = p[4];
  } else if (model == "OPENCV") {
    out->fx = p[0], out->fy = p[1], out->cx = p[2], out->cy = p[3];
    out->k1 = p[4], out->k2 = p[5], out->p1 = p[6], out->p2 = p[7];
  } else if (model == "FULL_OPENCV" && p[9] == 0.0 && p[10] == 0.0 && p[11] == 0.0) {
    out->fx = p[0], out->fy = p[1], out->cx = p[2], out->cy = p[3];
    out->k1 = p[4], out->k2 = p[5], out->p1 = p[6], out->p2 = p[7], out->k3 = p[8];
  } else {
    out->projectable = false;  // kept as written; the engine needs no intrinsics
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
  if (in.k3 != 0.0) {
    *model = "FULL_OPENCV";
    *params = {in.fx, in.fy, in.cx, in.cy, in.k1, in.k2, in.p1, in.p2, in.k3, 0.0, 0.0, 0.0};
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
