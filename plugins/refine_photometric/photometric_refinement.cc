// Photometric mesh refinement: per-vertex ZNCC search along the normal, coarse to fine, with an
// umbrella regulariser and a guard that refuses any step folding or crossing the surface.
#include "photometric_refinement.hpp"

#include <opencv2/imgproc.hpp>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <exception>
#include <limits>
#include <mutex>
#include <stdexcept>
#include <thread>
#include <utility>

namespace imr::photometric {
namespace {

using Vec3 = Eigen::Vector3d;
using Mat34 = Eigen::Matrix<double, 3, 4>;
using Face = std::array<uint32_t, 3>;

constexpr double kMinDepth = 1e-3;          // metres in front of a camera to count as seen
constexpr double kMinPatchVariance = 0.25;  // gray levels^2 per sample: flatter patches say nothing
constexpr double kDepthRelTolerance = 0.02;  // z-buffer test: share of the depth
constexpr double kDepthEdgeSlack = 0.1;      // z-buffer test: absolute slack, in mean edge lengths
constexpr double kMaxFaceTurnCos = 0.5;      // a face may turn at most 60 degrees in one step
constexpr double kMinAreaRatio = 0.01;       // and keep 1 % of its area
constexpr int kMaxHalvings = 3;              // a refused step is halved this often, then dropped
constexpr int kMinPyramidSide = 16;          // no pyramid level smaller than this
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kPi = 3.14159265358979323846;

// ---------------------------------------------------------------------------------------------
// Threads: a chunked parallel for (threads joined before returning; an exception is rethrown).
template <class Body>
void ParallelFor(int64_t n, int threads, int64_t grain, const Body& body) {
  if (n <= 0) return;
  const int64_t chunks = (n + grain - 1) / grain;
  const int workers = static_cast<int>(std::min<int64_t>(threads, chunks));
  if (workers <= 1) {
    body(int64_t{0}, n);
    return;
  }
  std::atomic<int64_t> next{0};
  std::exception_ptr error;
  std::mutex error_mutex;
  auto work = [&] {
    try {
      for (;;) {
        const int64_t begin = next.fetch_add(grain);
        if (begin >= n) break;
        body(begin, std::min(n, begin + grain));
      }
    } catch (...) {
      std::lock_guard<std::mutex> lock(error_mutex);
      if (!error) error = std::current_exception();
      next = n;
    }
  };
  std::vector<std::thread> pool;
  pool.reserve(static_cast<std::size_t>(workers - 1));
  for (int i = 1; i < workers; ++i) pool.emplace_back(work);
  work();
  for (std::thread& t : pool) t.join();
  if (error) std::rethrow_exception(error);
}

// ---------------------------------------------------------------------------------------------
// Mesh topology: unique neighbours and incident faces per vertex (CSR), border flags.
struct Topology {
  std::vector<uint8_t> face_ok;  // false: a repeated index (degenerate by construction, ignored)
  std::vector<uint32_t> nb_begin, nb;
  std::vector<uint32_t> vf_begin, vf;
  std::vector<uint8_t> boundary;  // on an edge with one face (or a non-manifold edge)
};

Topology BuildTopology(std::size_t n, const std::vector<Face>& faces) {
  Topology t;
  t.face_ok.assign(faces.size(), 0);
  std::vector<uint64_t> edges;
  edges.reserve(faces.size() * 3);
  std::vector<uint32_t> face_count(n + 1, 0);
  for (std::size_t f = 0; f < faces.size(); ++f) {
    const Face& F = faces[f];
    if (F[0] == F[1] || F[1] == F[2] || F[2] == F[0]) continue;
    t.face_ok[f] = 1;
    for (int k = 0; k < 3; ++k) {
      const uint64_t a = F[k], b = F[(k + 1) % 3];
      edges.push_back(a < b ? (a << 32 | b) : (b << 32 | a));
      ++face_count[F[k] + 1];
    }
  }
  // Incident faces.
  t.vf_begin.assign(n + 1, 0);
  for (std::size_t v = 0; v < n; ++v) t.vf_begin[v + 1] = t.vf_begin[v] + face_count[v + 1];
  t.vf.resize(t.vf_begin[n]);
  std::vector<uint32_t> fill(t.vf_begin.begin(), t.vf_begin.end() - 1);
  for (std::size_t f = 0; f < faces.size(); ++f)
    if (t.face_ok[f])
      for (uint32_t v : faces[f]) t.vf[fill[v]++] = static_cast<uint32_t>(f);
  // Edges: an edge with other than two faces marks its ends as boundary.
  std::sort(edges.begin(), edges.end());
  t.boundary.assign(n, 0);
  std::vector<uint32_t> degree(n + 1, 0);
  std::vector<uint64_t> unique;
  unique.reserve(edges.size() / 2 + 1);
  for (std::size_t i = 0; i < edges.size();) {
    std::size_t j = i;
    while (j < edges.size() && edges[j] == edges[i]) ++j;
    const uint32_t a = static_cast<uint32_t>(edges[i] >> 32), b = static_cast<uint32_t>(edges[i]);
    if (j - i != 2) t.boundary[a] = t.boundary[b] = 1;
    unique.push_back(edges[i]);
    ++degree[a + 1];
    ++degree[b + 1];
    i = j;
  }
  t.nb_begin.assign(n + 1, 0);
  for (std::size_t v = 0; v < n; ++v) t.nb_begin[v + 1] = t.nb_begin[v] + degree[v + 1];
  t.nb.resize(t.nb_begin[n]);
  std::copy(t.nb_begin.begin(), t.nb_begin.end() - 1, fill.begin());
  for (uint64_t e : unique) {
    const uint32_t a = static_cast<uint32_t>(e >> 32), b = static_cast<uint32_t>(e);
    t.nb[fill[a]++] = b;
    t.nb[fill[b]++] = a;
  }
  return t;
}

Vec3 FaceCross(const std::vector<Vec3>& p, const Face& f) {
  return (p[f[1]] - p[f[0]]).cross(p[f[2]] - p[f[0]]);
}

// Area-weighted vertex normals (a face's edge cross product is twice its area along its normal).
// A vertex whose fan normals cancel (or has no face) gets none: ok[v] = 0.
void VertexNormals(const std::vector<Vec3>& p, const std::vector<Face>& faces, const Topology& t,
                   std::vector<Vec3>* normals, std::vector<uint8_t>* ok) {
  std::vector<Vec3> fn(faces.size(), Vec3::Zero());
  for (std::size_t f = 0; f < faces.size(); ++f)
    if (t.face_ok[f]) fn[f] = FaceCross(p, faces[f]);
  normals->assign(p.size(), Vec3::Zero());
  ok->assign(p.size(), 0);
  for (std::size_t v = 0; v < p.size(); ++v) {
    Vec3 sum = Vec3::Zero();
    double total = 0;
    for (uint32_t i = t.vf_begin[v]; i < t.vf_begin[v + 1]; ++i) {
      sum += fn[t.vf[i]];
      total += fn[t.vf[i]].norm();
    }
    const double len = sum.norm();
    if (total > 0 && len > 1e-3 * total) {
      (*normals)[v] = sum / len;
      (*ok)[v] = 1;
    }
  }
}

// ---------------------------------------------------------------------------------------------
// Views: projection matrices per pyramid level and the float pyramid.
struct ViewData {
  Mat34 P;      // world -> full-resolution pixels (homogeneous; third row gives camera z)
  Vec3 centre;  // camera centre in the world
  int width = 0, height = 0;
  double focal = 0;              // sqrt(fx fy), full resolution
  std::vector<cv::Mat> pyramid;  // level 0: the CV_8UC1 image (shared, not copied); level l >= 1:
                                 // CV_32F at 1/2^l (a float copy of level 0 would be 4x the image)
  std::vector<Mat34> P_level;    // world -> level-l pixels
};

// cv::pyrDown's output pixel i is the 5-tap Gaussian centred on input pixel 2i, so a level-l
// pixel coordinate is x / 2^l (pixel centres at integer coordinates).
Mat34 ScaleProjection(const Mat34& P, double s) {
  Mat34 out = P;
  out.row(0) = P.row(0) / s;
  out.row(1) = P.row(1) / s;
  return out;
}

// ---------------------------------------------------------------------------------------------
// Occlusion: a z-buffer of the mesh per view at reduced resolution.
struct DepthMap {
  int width = 0, height = 0;
  double scale = 1;          // full-resolution pixels per depth-map pixel
  Mat34 P;                   // world -> depth-map pixels
  std::vector<float> depth;  // camera z, +inf where the mesh is not seen
};

// Depth interpolated as 1/z linearly in the image (perspective correct); pixel centres at
// integer coordinates.
void RasterTriangle(const double (&x)[3], const double (&y)[3], const double (&z)[3], DepthMap* m) {
  const double xmin = std::min({x[0], x[1], x[2]}), xmax = std::max({x[0], x[1], x[2]});
  const double ymin = std::min({y[0], y[1], y[2]}), ymax = std::max({y[0], y[1], y[2]});
  if (!(xmax >= 0 && ymax >= 0 && xmin <= m->width - 1 && ymin <= m->height - 1)) return;
  const int x0 = std::max(0, static_cast<int>(std::ceil(xmin)));
  const int x1 = std::min(m->width - 1, static_cast<int>(std::floor(xmax)));
  const int y0 = std::max(0, static_cast<int>(std::ceil(ymin)));
  const int y1 = std::min(m->height - 1, static_cast<int>(std::floor(ymax)));
  if (x0 > x1 || y0 > y1) return;
  const double area = (x[1] - x[0]) * (y[2] - y[0]) - (x[2] - x[0]) * (y[1] - y[0]);
  if (std::abs(area) < 1e-12) return;
  const double inv_area = 1.0 / area;
  const double iz[3] = {1.0 / z[0], 1.0 / z[1], 1.0 / z[2]};
  constexpr double kEps = -1e-9;
  for (int py = y0; py <= y1; ++py) {
    float* row = m->depth.data() + static_cast<std::size_t>(py) * m->width;
    for (int px = x0; px <= x1; ++px) {
      const double w0 = ((x[1] - px) * (y[2] - py) - (x[2] - px) * (y[1] - py)) * inv_area;
      const double w1 = ((x[2] - px) * (y[0] - py) - (x[0] - px) * (y[2] - py)) * inv_area;
      const double w2 = 1.0 - w0 - w1;
      if (w0 < kEps || w1 < kEps || w2 < kEps) continue;
      const double inv = w0 * iz[0] + w1 * iz[1] + w2 * iz[2];
      if (inv <= 0) continue;
      const float d = static_cast<float>(1.0 / inv);
      if (d < row[px]) row[px] = d;
    }
  }
}

// Faces crossing the near plane are clipped (a road mesh passes under the camera).
void BuildDepthMap(const View& view, const ViewData& vd, int scale, const std::vector<Vec3>& p,
                   const std::vector<Face>& faces, const Topology& topo, DepthMap* m,
                   std::vector<Vec3>* cam_scratch, std::vector<uint8_t>* codes) {
  m->scale = scale;
  m->width = (vd.width + scale - 1) / scale;
  m->height = (vd.height + scale - 1) / scale;
  m->depth.assign(static_cast<std::size_t>(m->width) * m->height,
                  std::numeric_limits<float>::infinity());
  // Depth-map pixel x' = (x + 0.5) / scale - 0.5: each covers scale x scale image pixels.
  Eigen::Matrix3d Kd = view.K / view.K(2, 2);
  Kd.row(0) = Kd.row(0) / scale + (0.5 / scale - 0.5) * Kd.row(2);
  Kd.row(1) = Kd.row(1) / scale + (0.5 / scale - 0.5) * Kd.row(2);
  m->P.leftCols<3>() = Kd * view.R;
  m->P.col(3) = Kd * view.t;
  // Each vertex once per view: camera coordinates, pixel position and an outcode (which side of
  // the image it is off, or behind the near plane), so most faces are rejected by one AND.
  std::vector<Vec3>& cam = *cam_scratch;
  cam.resize(p.size());
  codes->resize(p.size());
  const double w = m->width, h = m->height;
  for (std::size_t v = 0; v < p.size(); ++v) {
    cam[v] = view.R * p[v] + view.t;
    uint8_t code = 0;
    if (cam[v](2) <= kMinDepth) {
      code = 16;
    } else {
      const double x = (Kd.row(0).dot(cam[v])) / cam[v](2), y = (Kd.row(1).dot(cam[v])) / cam[v](2);
      code = static_cast<uint8_t>((x < 0 ? 1 : 0) | (x > w - 1 ? 2 : 0) | (y < 0 ? 4 : 0) |
                                  (y > h - 1 ? 8 : 0));
    }
    (*codes)[v] = code;
  }
  for (std::size_t f = 0; f < faces.size(); ++f) {
    if (!topo.face_ok[f]) continue;
    const Face& F = faces[f];
    const uint8_t c0 = (*codes)[F[0]], c1 = (*codes)[F[1]], c2 = (*codes)[F[2]];
    if (c0 & c1 & c2) continue;  // all off the same side, or all behind
    const Vec3* c[3] = {&cam[F[0]], &cam[F[1]], &cam[F[2]]};
    int in_front = 0;
    for (const Vec3* q : c) in_front += (*q)(2) > kMinDepth ? 1 : 0;
    // Clip the polygon against z = kMinDepth (Sutherland-Hodgman on one plane).
    Vec3 poly[4];
    int count = 0;
    if (in_front == 3) {
      for (int k = 0; k < 3; ++k) poly[count++] = *c[k];
    } else {
      for (int k = 0; k < 3; ++k) {
        const Vec3& a = *c[k];
        const Vec3& b = *c[(k + 1) % 3];
        const bool ain = a(2) > kMinDepth, bin = b(2) > kMinDepth;
        if (ain) poly[count++] = a;
        if (ain != bin) {
          const double s = (kMinDepth - a(2)) / (b(2) - a(2));
          poly[count++] = a + s * (b - a);
        }
      }
    }
    double px[4], py[4], pz[4];
    bool left = true, right = true, top = true, bottom = true;
    for (int k = 0; k < count; ++k) {
      const Vec3 q = Kd * poly[k];
      pz[k] = std::max(poly[k](2), kMinDepth);
      px[k] = q(0) / q(2);
      py[k] = q(1) / q(2);
      left = left && px[k] < 0;
      right = right && px[k] > w - 1;
      top = top && py[k] < 0;
      bottom = bottom && py[k] > h - 1;
    }
    if (left || right || top || bottom) continue;
    for (int k = 1; k + 1 < count; ++k) {
      const double tx[3] = {px[0], px[k], px[k + 1]};
      const double ty[3] = {py[0], py[k], py[k + 1]};
      const double tz[3] = {pz[0], pz[k], pz[k + 1]};
      RasterTriangle(tx, ty, tz, m);
    }
  }
}

// ---------------------------------------------------------------------------------------------
// View choice: the max_views most frontal views that see a vertex unoccluded.
struct ViewChoice {
  int max_views = 0;
  std::vector<int> ids;        // max_views per vertex, best (reference) first
  std::vector<uint8_t> count;  // how many of them are set
};

struct VisibilityParams {
  double cos_max_angle = 0;
  double margin_pixels = 0;  // full-resolution pixels kept free at the image border
  double slack = 0;          // absolute depth slack
};

void ChooseViews(const std::vector<ViewData>& vd, const std::vector<DepthMap>& maps,
                 const std::vector<Vec3>& p, const std::vector<Vec3>& p_maps,
                 const std::vector<Vec3>& normals, const std::vector<uint8_t>& normal_ok,
                 const std::vector<uint8_t>& wanted, const VisibilityParams& vis, int threads,
                 ViewChoice* choice) {
  const std::size_t n = p.size();
  const int k_max = choice->max_views;
  choice->ids.assign(n * static_cast<std::size_t>(k_max), -1);
  choice->count.assign(n, 0);
  ParallelFor(static_cast<int64_t>(n), threads, 1024, [&](int64_t begin, int64_t end) {
    std::vector<double> best_cos(static_cast<std::size_t>(k_max));
    for (int64_t v = begin; v < end; ++v) {
      if (!wanted[v] || !normal_ok[v]) continue;
      const Vec3& X = p[v];
      const Vec3& nrm = normals[v];
      // The depth maps were drawn before this level's moves: allow for them.
      const double stale = (X - p_maps[v]).norm();
      int* ids = &choice->ids[static_cast<std::size_t>(v) * k_max];
      int count = 0;
      for (std::size_t j = 0; j < vd.size(); ++j) {
        const Vec3 ray = vd[j].centre - X;
        const double dist = ray.norm();
        if (dist <= 0) continue;
        const double c = nrm.dot(ray) / dist;
        if (c < vis.cos_max_angle) continue;
        if (count == k_max && c <= best_cos[k_max - 1]) continue;
        const Vec3 h = vd[j].P.leftCols<3>() * X + vd[j].P.col(3);
        const double z = h(2);
        if (z <= kMinDepth) continue;
        const double x = h(0) / z, y = h(1) / z;
        const double m = vis.margin_pixels;
        if (!(x >= m && y >= m && x <= vd[j].width - 1 - m && y <= vd[j].height - 1 - m)) continue;
        const DepthMap& dm = maps[j];
        const double s = dm.scale;
        const int ix =
            std::clamp(static_cast<int>(std::lround((x + 0.5) / s - 0.5)), 0, dm.width - 1);
        const int iy =
            std::clamp(static_cast<int>(std::lround((y + 0.5) / s - 0.5)), 0, dm.height - 1);
        const double zb = dm.depth[static_cast<std::size_t>(iy) * dm.width + ix];
        // The nearest depth-map pixel is up to ~0.7 of its width away on a surface seen at an
        // angle: its depth differs by that footprint times the slope.
        const double tan_angle =
            std::min(std::sqrt(std::max(0.0, 1 - c * c)) / std::max(c, 1e-3), 6.0);
        const double tol =
            kDepthRelTolerance * z + vis.slack + stale + z * 0.75 * s / vd[j].focal * tan_angle;
        if (z > zb + tol) continue;
        // Insert by frontality.
        int k = std::min(count, k_max - 1);
        while (k > 0 && best_cos[k - 1] < c) {
          best_cos[k] = best_cos[k - 1];
          ids[k] = ids[k - 1];
          --k;
        }
        best_cos[k] = c;
        ids[k] = static_cast<int>(j);
        count = std::min(count + 1, k_max);
      }
      choice->count[v] = static_cast<uint8_t>(std::min(count, 255));
    }
  });
}

// ---------------------------------------------------------------------------------------------
// Photo-consistency: ZNCC of tangent-plane patches.
struct PatchGeometry {
  int half = 3;  // patch_size / 2
  double patch_pixels = 1.5;
};

// Samples the projected patch: sample (a, b) is base + a*au + b*aw in homogeneous level pixels.
// False when a corner is behind the camera or outside the image (the projection of the planar
// grid is convex, so the corners bound every sample). Single precision inside: homogeneous
// coordinates of ~1e5 keep ~1e-4 pixel.
template <typename Pixel>
bool SamplePatchT(const cv::Mat& img, const Vec3& base, const Vec3& au, const Vec3& aw, int r,
                  float* out) {
  const double xmax = img.cols - 1 - 1e-3, ymax = img.rows - 1 - 1e-3;
  for (int sb = -1; sb <= 1; sb += 2)
    for (int sa = -1; sa <= 1; sa += 2) {
      const Vec3 h = base + (sa * r) * au + (sb * r) * aw;
      if (h(2) <= kMinDepth) return false;
      const double x = h(0) / h(2), y = h(1) / h(2);
      if (!(x >= 0 && y >= 0 && x <= xmax && y <= ymax)) return false;
    }
  const Pixel* data = img.ptr<Pixel>();
  const std::size_t stride = img.step1();
  const float ux = static_cast<float>(au(0)), uy = static_cast<float>(au(1)),
              uz = static_cast<float>(au(2));
  int k = 0;
  for (int b = -r; b <= r; ++b) {
    const Vec3 row = base + b * aw;
    const float rx = static_cast<float>(row(0)), ry = static_cast<float>(row(1)),
                rz = static_cast<float>(row(2));
    for (int a = -r; a <= r; ++a) {
      const float iz = 1.0f / (rz + a * uz);
      const float x = (rx + a * ux) * iz, y = (ry + a * uy) * iz;
      const int x0 = std::min(static_cast<int>(x), img.cols - 2),
                y0 = std::min(static_cast<int>(y), img.rows - 2);
      const float fx = x - x0, fy = y - y0;
      const Pixel* q = data + static_cast<std::size_t>(y0) * stride + x0;
      const float p00 = q[0], p01 = q[1], p10 = q[stride], p11 = q[stride + 1];
      const float top = p00 + fx * (p01 - p00);
      const float bottom = p10 + fx * (p11 - p10);
      out[k++] = top + fy * (bottom - top);
    }
  }
  return true;
}

bool SamplePatch(const cv::Mat& img, const Vec3& base, const Vec3& au, const Vec3& aw, int r,
                 float* out) {
  return img.depth() == CV_8U ? SamplePatchT<uint8_t>(img, base, au, aw, r, out)
                              : SamplePatchT<float>(img, base, au, aw, r, out);
}

// score[i] = mean ZNCC over the non-reference views that scored, of the patch on the plane
// through v + offsets[i] * n with normal n; NaN where none scored.
void ScoreOffsets(const std::vector<ViewData>& vd, const int* ids, int nviews, int level,
                  const Vec3& v, const Vec3& n, const PatchGeometry& g, const double* offsets,
                  int noffsets, std::vector<float>* scratch, double* score) {
  const int side = 2 * g.half + 1;
  const int samples = side * side;
  scratch->resize(static_cast<std::size_t>(3 * samples));
  float* ref = scratch->data();
  float* other = ref + samples;
  float* ref_norm = other + samples;  // the reference patch, zero mean and unit norm
  // Tangent basis, spaced for patch_pixels pixels per sample in the reference view.
  const Vec3 axis =
      std::abs(n(0)) < 0.6 ? Vec3::UnitX() : (std::abs(n(1)) < 0.6 ? Vec3::UnitY() : Vec3::UnitZ());
  const Vec3 u = n.cross(axis).normalized();
  const Vec3 w = n.cross(u);
  const ViewData& rv = vd[ids[0]];
  const double z_ref = rv.P.row(2).head<3>().dot(v) + rv.P(2, 3);
  const double spacing = g.patch_pixels * z_ref * std::ldexp(1.0, level) / rv.focal;
  struct Proj {
    Vec3 a0, an, au, aw;
  };
  Proj proj[256];
  nviews = std::min(nviews, 256);
  for (int k = 0; k < nviews; ++k) {
    const Mat34& P = vd[ids[k]].P_level[level];
    proj[k].a0 = P.leftCols<3>() * v + P.col(3);
    proj[k].an = P.leftCols<3>() * n;
    proj[k].au = P.leftCols<3>() * (spacing * u);
    proj[k].aw = P.leftCols<3>() * (spacing * w);
  }
  for (int i = 0; i < noffsets; ++i) {
    score[i] = kNaN;
    const double d = offsets[i];
    if (!SamplePatch(vd[ids[0]].pyramid[level], proj[0].a0 + d * proj[0].an, proj[0].au, proj[0].aw,
                     g.half, ref))
      continue;
    double mean = 0;
    for (int s = 0; s < samples; ++s) mean += ref[s];
    mean /= samples;
    double ss = 0;
    for (int s = 0; s < samples; ++s) ss += (ref[s] - mean) * (ref[s] - mean);
    if (ss < samples * kMinPatchVariance) continue;
    const double inv = 1.0 / std::sqrt(ss);
    for (int s = 0; s < samples; ++s) ref_norm[s] = static_cast<float>((ref[s] - mean) * inv);
    double total = 0;
    int scored = 0;
    for (int k = 1; k < nviews; ++k) {
      if (!SamplePatch(vd[ids[k]].pyramid[level], proj[k].a0 + d * proj[k].an, proj[k].au,
                       proj[k].aw, g.half, other))
        continue;
      double s1 = 0, s2 = 0, sr = 0;
      for (int s = 0; s < samples; ++s) {
        const double o = other[s];
        s1 += o;
        s2 += o * o;
        sr += ref_norm[s] * o;  // the reference is zero-mean, so this is the covariance
      }
      const double var = s2 - s1 * s1 / samples;
      if (var < samples * kMinPatchVariance) continue;
      total += sr / std::sqrt(var);
      ++scored;
    }
    if (scored > 0) score[i] = total / scored;
  }
}

// ---------------------------------------------------------------------------------------------
// Geometry guard: no fold-over, no self-intersection, no tunnelling.
struct Box {
  Vec3 lo, hi;
};

Box TriangleBox(const Vec3& a, const Vec3& b, const Vec3& c) {
  return {a.cwiseMin(b).cwiseMin(c), a.cwiseMax(b).cwiseMax(c)};
}

bool BoxesOverlap(const Box& a, const Box& b, double tol) {
  return (a.lo.array() <= b.hi.array() + tol).all() && (b.lo.array() <= a.hi.array() + tol).all();
}

// Is X inside triangle ABC (X in its plane)? Barycentric, inclusive: scale-invariant, so a sliver
// (the triangle a tiny step sweeps) does not take in points along its long edge's extension.
bool InsideTriangle(const Vec3& X, const Vec3& A, const Vec3& B, const Vec3& C) {
  const Vec3 N = (B - A).cross(C - A);
  const double nn = N.squaredNorm();
  if (!(nn > 0)) return false;
  const double la = N.dot((B - X).cross(C - X)) / nn;
  const double lb = N.dot((C - X).cross(A - X)) / nn;
  constexpr double kEps = -1e-9;
  return la >= kEps && lb >= kEps && 1.0 - la - lb >= kEps;
}

// Segment PQ (signed distances dP, dQ to the plane of ABC) against triangle ABC.
bool SegmentHitsTriangle(const Vec3& P, const Vec3& Q, double dP, double dQ, const Vec3& A,
                         const Vec3& B, const Vec3& C, double tol) {
  if ((dP > tol && dQ > tol) || (dP < -tol && dQ < -tol)) return false;
  if (std::abs(dP) <= tol && std::abs(dQ) <= tol) return false;  // in the plane: other edges tell
  const double t = std::clamp(dP / (dP - dQ), 0.0, 1.0);
  return InsideTriangle(P + t * (Q - P), A, B, C);
}

double Orient2(const Eigen::Vector2d& a, const Eigen::Vector2d& b, const Eigen::Vector2d& c) {
  return (b(0) - a(0)) * (c(1) - a(1)) - (b(1) - a(1)) * (c(0) - a(0));
}

bool Segments2Intersect(const Eigen::Vector2d& p, const Eigen::Vector2d& q,
                        const Eigen::Vector2d& a, const Eigen::Vector2d& b, double tol) {
  const double lpq = (q - p).norm(), lab = (b - a).norm();
  if (lpq <= 0 || lab <= 0) return false;
  const double d1 = Orient2(p, q, a) / lpq, d2 = Orient2(p, q, b) / lpq;
  const double d3 = Orient2(a, b, p) / lab, d4 = Orient2(a, b, q) / lab;
  if ((d1 > tol && d2 > tol) || (d1 < -tol && d2 < -tol)) return false;
  if ((d3 > tol && d4 > tol) || (d3 < -tol && d4 < -tol)) return false;
  if (std::abs(d1) <= tol && std::abs(d2) <= tol) {  // collinear: do the intervals overlap?
    const Eigen::Vector2d dir = (q - p) / lpq;
    const double s0 = dir.dot(a - p), s1 = dir.dot(b - p);
    return std::max(s0, s1) >= -tol && std::min(s0, s1) <= lpq + tol;
  }
  return true;
}

bool Inside2(const Eigen::Vector2d& x, const Eigen::Vector2d (&t)[3]) {
  const double area = Orient2(t[0], t[1], t[2]);
  if (area == 0) return false;
  const double l0 = Orient2(x, t[1], t[2]) / area, l1 = Orient2(t[0], x, t[2]) / area;
  constexpr double kEps = -1e-9;
  return l0 >= kEps && l1 >= kEps && 1.0 - l0 - l1 >= kEps;
}

// Triangle-triangle intersection, touching included. Degenerate triangles never intersect
// (the area check keeps mesh faces from becoming degenerate).
bool TrianglesIntersect(const Vec3 (&a)[3], const Box& ba, const Vec3 (&b)[3], const Box& bb) {
  const double extent = (ba.hi.cwiseMax(bb.hi) - ba.lo.cwiseMin(bb.lo)).maxCoeff();
  const double tol = 1e-9 * extent;
  if (!BoxesOverlap(ba, bb, tol)) return false;
  Vec3 na = (a[1] - a[0]).cross(a[2] - a[0]);
  Vec3 nb = (b[1] - b[0]).cross(b[2] - b[0]);
  const double la = na.norm(), lb = nb.norm();
  const double tiny = 1e-14 * extent * extent;
  if (la <= tiny || lb <= tiny) return false;
  na /= la;
  nb /= lb;
  double db[3], da[3];
  for (int k = 0; k < 3; ++k) {
    db[k] = na.dot(b[k] - a[0]);
    da[k] = nb.dot(a[k] - b[0]);
  }
  auto one_side = [tol](const double(&d)[3]) {
    return (d[0] > tol && d[1] > tol && d[2] > tol) || (d[0] < -tol && d[1] < -tol && d[2] < -tol);
  };
  if (one_side(db) || one_side(da)) return false;
  const bool coplanar = std::abs(db[0]) <= tol && std::abs(db[1]) <= tol &&
                        std::abs(db[2]) <= tol && std::abs(da[0]) <= tol &&
                        std::abs(da[1]) <= tol && std::abs(da[2]) <= tol;
  if (coplanar) {
    int drop = 0;
    na.cwiseAbs().maxCoeff(&drop);
    const int i0 = (drop + 1) % 3, i1 = (drop + 2) % 3;
    Eigen::Vector2d a2[3], b2[3];
    for (int k = 0; k < 3; ++k) {
      a2[k] = Eigen::Vector2d(a[k](i0), a[k](i1));
      b2[k] = Eigen::Vector2d(b[k](i0), b[k](i1));
    }
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j)
        if (Segments2Intersect(a2[i], a2[(i + 1) % 3], b2[j], b2[(j + 1) % 3], tol)) return true;
    return Inside2(a2[0], b2) || Inside2(b2[0], a2);
  }
  for (int k = 0; k < 3; ++k) {
    const int l = (k + 1) % 3;
    if (SegmentHitsTriangle(a[k], a[l], da[k], da[l], b[0], b[1], b[2], tol)) return true;
    if (SegmentHitsTriangle(b[k], b[l], db[k], db[l], a[0], a[1], a[2], tol)) return true;
  }
  return false;
}

// Is x strictly inside the tetrahedron p0..p3 (not flat)?
bool InsideTetrahedron(const Vec3& x, const Vec3& p0, const Vec3& p1, const Vec3& p2,
                       const Vec3& p3) {
  auto volume = [](const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& d) {
    return (b - a).dot((c - a).cross(d - a));
  };
  const double total = volume(p0, p1, p2, p3);
  const double extent =
      (p0.cwiseMax(p1).cwiseMax(p2).cwiseMax(p3) - p0.cwiseMin(p1).cwiseMin(p2).cwiseMin(p3))
          .maxCoeff();
  if (std::abs(total) <= 1e-12 * extent * extent * extent) return false;
  const double l0 = volume(x, p1, p2, p3) / total, l1 = volume(p0, x, p2, p3) / total;
  const double l2 = volume(p0, p1, x, p3) / total, l3 = volume(p0, p1, p2, x) / total;
  constexpr double kIn = 1e-12;
  return l0 > kIn && l1 > kIn && l2 > kIn && l3 > kIn;
}

class MoveGuard {
 public:
  MoveGuard(const std::vector<Face>& faces, const Topology& topo,
            const std::vector<Vec3>& input_face_normals, std::vector<Vec3>* p)
      : faces_(faces),
        topo_(topo),
        input_normals_(input_face_normals),
        p_(*p),
        stamp_(faces.size(), 0) {}

  // A uniform grid of the faces' bounding boxes, each grown by its vertices' planned moves this
  // pass: every position a face takes during the pass stays inside its grown box.
  void Prepare(const std::vector<double>& planned) {
    cells_.clear();
    big_.clear();
    boxes_.assign(faces_.size(), Box{Vec3::Zero(), Vec3::Zero()});
    double sum = 0;
    int64_t count = 0;
    for (std::size_t f = 0; f < faces_.size(); ++f) {
      if (!topo_.face_ok[f]) continue;
      const Face& F = faces_[f];
      Box b = TriangleBox(p_[F[0]], p_[F[1]], p_[F[2]]);
      const double grow = std::max({planned[F[0]], planned[F[1]], planned[F[2]]});
      b.lo.array() -= grow;
      b.hi.array() += grow;
      boxes_[f] = b;
      sum += (b.hi - b.lo).maxCoeff();
      ++count;
    }
    if (count == 0) return;
    cell_ = std::max(sum / count, 1e-9);
    for (std::size_t f = 0; f < faces_.size(); ++f) {
      if (!topo_.face_ok[f]) continue;
      const Eigen::Array3i lo = CellOf(boxes_[f].lo), hi = CellOf(boxes_[f].hi);
      const Eigen::Array3i span = hi - lo + 1;
      if (static_cast<int64_t>(span(0)) * span(1) * span(2) > 64) {
        big_.push_back(static_cast<uint32_t>(f));
        continue;
      }
      for (int x = lo(0); x <= hi(0); ++x)
        for (int y = lo(1); y <= hi(1); ++y)
          for (int z = lo(2); z <= hi(2); ++z)
            cells_.emplace_back(Key(x, y, z), static_cast<uint32_t>(f));
    }
    std::sort(cells_.begin(), cells_.end());
  }

  // May v move to q? Checks its fan (turn, area, orientation against the input), then the moved
  // fan and the volume it sweeps against the faces nearby that share no vertex with the tested
  // face. A face sharing a vertex with it is left to the fan checks.
  bool Allows(uint32_t v, const Vec3& q) {
    const Vec3 old = p_[v];
    const uint32_t fb = topo_.vf_begin[v], fe = topo_.vf_begin[v + 1];
    for (uint32_t i = fb; i < fe; ++i) {
      const uint32_t f = topo_.vf[i];
      const Vec3 before = FaceCross(p_, faces_[f]);
      p_[v] = q;
      const Vec3 after = FaceCross(p_, faces_[f]);
      p_[v] = old;
      const double a0 = before.norm(), a1 = after.norm();
      if (a0 > 0) {
        if (a1 < kMinAreaRatio * a0) return false;
        if (before.dot(after) < kMaxFaceTurnCos * a0 * a1) return false;
      }
      if (input_normals_[f].squaredNorm() > 0 && input_normals_[f].dot(after) <= 0) return false;
    }
    // The query box: the fan before and after the move.
    Box query{old.cwiseMin(q), old.cwiseMax(q)};
    for (uint32_t i = topo_.nb_begin[v]; i < topo_.nb_begin[v + 1]; ++i) {
      const Vec3& r = p_[topo_.nb[i]];
      query.lo = query.lo.cwiseMin(r);
      query.hi = query.hi.cwiseMax(r);
    }
    if (++epoch_ == 0) {
      std::fill(stamp_.begin(), stamp_.end(), 0);
      epoch_ = 1;
    }
    for (uint32_t i = fb; i < fe; ++i) stamp_[topo_.vf[i]] = epoch_;  // the fan itself
    BuildFan(v, old, q);
    const bool moved = (q - old).squaredNorm() > 0;
    bool ok = true;
    auto visit = [&](uint32_t g) {
      if (!ok || stamp_[g] == epoch_) return;
      stamp_[g] = epoch_;
      if (!BoxesOverlap(boxes_[g], query, 0)) return;
      ok = !Crosses(old, q, moved, g);
    };
    const Eigen::Array3i lo = CellOf(query.lo), hi = CellOf(query.hi);
    const Eigen::Array3i span = hi - lo + 1;
    if (static_cast<int64_t>(span(0)) * span(1) * span(2) > static_cast<int64_t>(faces_.size())) {
      for (std::size_t g = 0; g < faces_.size() && ok; ++g)
        if (topo_.face_ok[g]) visit(static_cast<uint32_t>(g));
      return ok;
    }
    for (int x = lo(0); x <= hi(0) && ok; ++x)
      for (int y = lo(1); y <= hi(1) && ok; ++y)
        for (int z = lo(2); z <= hi(2) && ok; ++z) {
          const uint64_t key = Key(x, y, z);
          auto it =
              std::lower_bound(cells_.begin(), cells_.end(), std::make_pair(key, uint32_t{0}));
          for (; it != cells_.end() && it->first == key && ok; ++it) visit(it->second);
        }
    for (uint32_t g : big_) visit(g);
    return ok;
  }

 private:
  // v's fan moved to q: per fan face, the moved face, the triangle its edge v-a sweeps, and the
  // boxes of those and of the tetrahedron the face sweeps (for cheap rejection).
  struct FanPiece {
    uint32_t a, b;
    Vec3 face[3], swept[3];
    Box face_box, swept_box, tet_box;
  };

  void BuildFan(uint32_t v, const Vec3& old, const Vec3& q) {
    fan_.clear();
    for (uint32_t i = topo_.vf_begin[v]; i < topo_.vf_begin[v + 1]; ++i) {
      const Face& F = faces_[topo_.vf[i]];
      // Rotated so that v comes first (keeps the orientation).
      const int k = F[0] == v ? 0 : (F[1] == v ? 1 : 2);
      FanPiece piece;
      piece.a = F[(k + 1) % 3];
      piece.b = F[(k + 2) % 3];
      const Vec3& pa = p_[piece.a];
      const Vec3& pb = p_[piece.b];
      piece.face[0] = q;
      piece.face[1] = pa;
      piece.face[2] = pb;
      piece.swept[0] = old;
      piece.swept[1] = q;
      piece.swept[2] = pa;
      piece.face_box = TriangleBox(q, pa, pb);
      piece.swept_box = TriangleBox(old, q, pa);
      piece.tet_box = {piece.face_box.lo.cwiseMin(old), piece.face_box.hi.cwiseMax(old)};
      fan_.push_back(piece);
    }
  }

  // Does face g cross the moved fan, or the volume it swept?
  bool Crosses(const Vec3& old, const Vec3& q, bool moved, uint32_t g) const {
    const Face& G = faces_[g];
    const Vec3 tg[3] = {p_[G[0]], p_[G[1]], p_[G[2]]};
    const Box box_g = TriangleBox(tg[0], tg[1], tg[2]);
    auto in_g = [&G](uint32_t x) { return G[0] == x || G[1] == x || G[2] == x; };
    for (const FanPiece& piece : fan_) {
      const bool shares_a = in_g(piece.a), shares_b = in_g(piece.b);
      if (!shares_a && !shares_b) {
        if (TrianglesIntersect(piece.face, piece.face_box, tg, box_g)) return true;
        if (moved && BoxesOverlap(piece.tet_box, box_g, 0))
          for (const Vec3& x : tg)
            if (InsideTetrahedron(x, old, q, piece.face[1], piece.face[2])) return true;
      }
      if (moved && !shares_a && TrianglesIntersect(piece.swept, piece.swept_box, tg, box_g))
        return true;
    }
    return false;
  }

  Eigen::Array3i CellOf(const Vec3& x) const { return (x.array() / cell_).floor().cast<int>(); }
  static uint64_t Key(int x, int y, int z) {
    constexpr uint64_t kMask = (uint64_t{1} << 21) - 1;
    return (static_cast<uint64_t>(static_cast<uint32_t>(x)) & kMask) << 42 |
           (static_cast<uint64_t>(static_cast<uint32_t>(y)) & kMask) << 21 |
           (static_cast<uint64_t>(static_cast<uint32_t>(z)) & kMask);
  }

  const std::vector<Face>& faces_;
  const Topology& topo_;
  const std::vector<Vec3>& input_normals_;
  std::vector<Vec3>& p_;
  std::vector<Box> boxes_;
  std::vector<std::pair<uint64_t, uint32_t>> cells_;  // sorted (cell key, face)
  std::vector<uint32_t> big_;                         // faces too big for the grid
  std::vector<uint32_t> stamp_;
  uint32_t epoch_ = 0;
  std::vector<FanPiece> fan_;
  double cell_ = 1;
};

// ---------------------------------------------------------------------------------------------
void Validate(const std::vector<View>& views, const std::vector<Face>& faces,
              const std::vector<uint8_t>& active, const RefineOptions& options,
              const std::vector<Eigen::Vector3d>* vertices) {
  std::string error;
  if (!options.Check(&error)) throw std::invalid_argument("RefineOptions: " + error);
  if (vertices == nullptr) throw std::invalid_argument("vertices: null");
  const std::size_t n = vertices->size();
  if (n > std::numeric_limits<uint32_t>::max()) throw std::invalid_argument("vertices: too many");
  for (std::size_t v = 0; v < n; ++v)
    if (!(*vertices)[v].allFinite())
      throw std::invalid_argument("vertex " + std::to_string(v) + " is not finite");
  for (std::size_t f = 0; f < faces.size(); ++f)
    for (uint32_t i : faces[f])
      if (i >= n)
        throw std::invalid_argument("face " + std::to_string(f) + " indexes vertex " +
                                    std::to_string(i) + " of " + std::to_string(n));
  if (!active.empty() && active.size() != n)
    throw std::invalid_argument("active has " + std::to_string(active.size()) + " entries for " +
                                std::to_string(n) + " vertices");
  for (std::size_t j = 0; j < views.size(); ++j) {
    const View& w = views[j];
    const std::string name = "view " + std::to_string(j) + ": ";
    if (w.gray.empty()) throw std::invalid_argument(name + "empty image");
    if (w.gray.type() != CV_8UC1) throw std::invalid_argument(name + "image is not CV_8UC1");
    if (!w.K.allFinite()) throw std::invalid_argument(name + "K is not finite");
    if (!(w.K(2, 2) > 0) || w.K(2, 0) != 0 || w.K(2, 1) != 0 || !(w.K(0, 0) > 0) ||
        !(w.K(1, 1) > 0))
      throw std::invalid_argument(name + "K is not a pinhole (positive fx, fy; last row 0 0 k)");
    if (!w.R.allFinite() || !w.t.allFinite())
      throw std::invalid_argument(name + "R or t is not finite");
  }
}

double MeanEdge(const std::vector<Vec3>& p, const std::vector<Face>& faces, const Topology& t) {
  double sum = 0;
  int64_t count = 0;
  for (std::size_t f = 0; f < faces.size(); ++f) {
    if (!t.face_ok[f]) continue;
    for (int k = 0; k < 3; ++k) sum += (p[faces[f][k]] - p[faces[f][(k + 1) % 3]]).norm();
    count += 3;
  }
  return count > 0 ? sum / count : 0.0;
}

}  // namespace

bool RefineOptions::Check(std::string* error) const {
  auto fail = [error](const std::string& message) {
    if (error) *error = message;
    return false;
  };
  if (levels < 1) return fail("levels must be >= 1");
  if (iterations_per_level < 1) return fail("iterations_per_level must be >= 1");
  if (!(search_range > 0) || !std::isfinite(search_range)) return fail("search_range must be > 0");
  if (search_steps < 1) return fail("search_steps must be >= 1");
  if (patch_size < 3 || patch_size % 2 == 0 || patch_size > 31)
    return fail("patch_size must be odd, 3..31");
  if (!(patch_pixels > 0) || !std::isfinite(patch_pixels)) return fail("patch_pixels must be > 0");
  if (image_scale_levels < 1) return fail("image_scale_levels must be >= 1");
  if (!(min_zncc >= 0 && min_zncc <= 1)) return fail("min_zncc must be in [0, 1]");
  if (!(min_gain >= 0 && min_gain <= 2)) return fail("min_gain must be in [0, 2]");
  if (normal_smoothing < 0 || normal_smoothing > 100) return fail("normal_smoothing must be in [0, 100]");
  if (!(flatten_spikes >= 0) || !std::isfinite(flatten_spikes)) return fail("flatten_spikes must be >= 0");
  if (max_views < 2) return fail("max_views must be >= 2");
  if (!(max_view_angle_deg > 0 && max_view_angle_deg <= 90))
    return fail("max_view_angle_deg must be in (0, 90]");
  if (!(step > 0 && step <= 1)) return fail("step must be in (0, 1]");
  if (!(smoothness >= 0 && smoothness <= 1)) return fail("smoothness must be in [0, 1]");
  if (!(max_move > 0) || !std::isfinite(max_move)) return fail("max_move must be > 0");
  if (planarize < 0 || planarize > 100) return fail("planarize must be in [0, 100]");
  if (!(planarize_tolerance > 0) || !std::isfinite(planarize_tolerance))
    return fail("planarize_tolerance must be > 0");
  if (!(planarize_min_share > 0 && planarize_min_share <= 1)) return fail("planarize_min_share must be in (0, 1]");
  if (depth_map_scale < 1) return fail("depth_map_scale must be >= 1");
  if (threads < 1) return fail("threads must be >= 1");
  if (error) error->clear();
  return true;
}

namespace {

// How many pyramid levels every view can have: coarse levels stop at kMinPyramidSide pixels.
int ImageLevels(const std::vector<View>& views, int wanted) {
  int image_levels = wanted;
  for (const View& w : views) {
    int possible = 1;
    for (int c = w.gray.cols, r = w.gray.rows; possible < image_levels; ++possible) {
      c = (c + 1) / 2;
      r = (r + 1) / 2;
      if (std::min(c, r) < kMinPyramidSide) break;
    }
    image_levels = std::min(image_levels, possible);
  }
  return image_levels;
}

// Views: projections and float pyramids.
std::vector<ViewData> PrepareViews(const std::vector<View>& views, int image_levels, int threads) {
  std::vector<ViewData> vd(views.size());
  ParallelFor(static_cast<int64_t>(views.size()), threads, 1, [&](int64_t begin, int64_t end) {
    for (int64_t j = begin; j < end; ++j) {
      const View& w = views[j];
      ViewData& d = vd[j];
      const Eigen::Matrix3d K = w.K / w.K(2, 2);
      d.P.leftCols<3>() = K * w.R;
      d.P.col(3) = K * w.t;
      d.centre = -w.R.transpose() * w.t;
      d.width = w.gray.cols;
      d.height = w.gray.rows;
      d.focal = std::sqrt(K(0, 0) * K(1, 1));
      d.pyramid.resize(static_cast<std::size_t>(image_levels));
      d.pyramid[0] = w.gray;
      d.P_level.push_back(d.P);
      if (image_levels > 1) {
        cv::Mat full;
        w.gray.convertTo(full, CV_32F);
        for (int l = 1; l < image_levels; ++l) {
          cv::pyrDown(l == 1 ? full : d.pyramid[l - 1], d.pyramid[l]);
          d.P_level.push_back(ScaleProjection(d.P, std::ldexp(1.0, l)));
        }
      }
    }
  });
  return vd;
}

std::vector<Vec3> InputFaceNormals(const std::vector<Vec3>& p, const std::vector<Face>& faces,
                                   const Topology& topo) {
  std::vector<Vec3> normals(faces.size(), Vec3::Zero());
  for (std::size_t f = 0; f < faces.size(); ++f)
    if (topo.face_ok[f]) normals[f] = FaceCross(p, faces[f]);
  return normals;
}

// One call of Refine: the mesh, its views, and what the passes share.
class Refinement {
 public:
  Refinement(const std::vector<View>& views, const std::vector<Face>& faces,
             std::vector<uint8_t> active, const RefineOptions& options, std::vector<Vec3>* p)
      : views_(views), faces_(faces), options_(options), p_(*p), n_(p->size()), input_(*p),
        active_(std::move(active)), threads_(options.threads), topo_(BuildTopology(n_, faces)),
        input_face_normals_(InputFaceNormals(p_, faces, topo_)), mean_edge_(MeanEdge(p_, faces, topo_)),
        image_levels_(ImageLevels(views, options.image_scale_levels)),
        vd_(PrepareViews(views, image_levels_, threads_)),
        patch_{options.patch_size / 2, options.patch_pixels}, maps_(views.size()),
        offsets_(static_cast<std::size_t>(2 * options.search_steps + 1)), match_(n_, 0.0),
        matched_(n_, 0), ever_matched_(n_, 0), target_(n_), planned_(n_, 0.0) {
    choice_.max_views = std::max(
        2,
        std::min<int>(options.max_views, static_cast<int>(std::max<std::size_t>(views.size(), 2))));
    choice_.max_views = std::min(choice_.max_views, 255);
    vis_.cos_max_angle = std::cos(options.max_view_angle_deg * kPi / 180.0);
    vis_.slack = kDepthEdgeSlack * mean_edge_;
  }

  const std::vector<Vec3>& input() const { return input_; }
  const std::vector<uint8_t>& ever_matched() const { return ever_matched_; }

  // Mean ZNCC at the current positions (offset 0, full resolution) over active vertices two
  // views see; `seen` counts those vertices.
  double Evaluate(int64_t* seen) {
    if (p_maps_ != p_) BuildMaps();
    VertexNormals(p_, faces_, topo_, &normals_, &normal_ok_);
    vis_.margin_pixels = MarginFor(0);
    ChooseViews(vd_, maps_, p_, p_maps_, normals_, normal_ok_, active_, vis_, threads_, &choice_);
    std::vector<double> score(n_, kNaN);
    ParallelFor(static_cast<int64_t>(n_), threads_, 256, [&](int64_t begin, int64_t end) {
      std::vector<float> scratch;
      const double zero = 0;
      for (int64_t v = begin; v < end; ++v)
        if (choice_.count[v] >= 2)
          ScoreOffsets(vd_, &choice_.ids[v * choice_.max_views], choice_.count[v], 0, p_[v], normals_[v],
                       patch_, &zero, 1, &scratch, &score[v]);
    });
    double sum = 0;
    int64_t scored = 0, count = 0;
    for (std::size_t v = 0; v < n_; ++v) {
      count += choice_.count[v] >= 2 ? 1 : 0;
      if (!std::isnan(score[v])) {
        sum += score[v];
        ++scored;
      }
    }
    if (seen) *seen = count;
    return scored > 0 ? sum / scored : 0.0;
  }

  // Coarse to fine; false when cancelled. Counts the moves the guard refused in `undone`.
  bool CoarseToFine(const std::function<bool()>& cancelled, int64_t* undone) {
    const int S = options_.search_steps;
    for (int round = 0; round < options_.levels; ++round) {
      // The first round searches search_range on the coarsest images; each round halves the
      // range, and the last one uses full resolution.
      const int level = std::min(options_.levels - 1 - round, image_levels_ - 1);
      const double range = options_.search_range / std::ldexp(1.0, round);
      for (int k = -S; k <= S; ++k) offsets_[k + S] = range * k / S;
      if (views_.size() >= 2 && p_maps_ != p_) BuildMaps();
      for (int it = 0; it < options_.iterations_per_level; ++it) {
        if (cancelled && cancelled()) return false;
        VertexNormals(p_, faces_, topo_, &normals_, &normal_ok_);
        SmoothNormals();
        Search(level, range);
        for (std::size_t v = 0; v < n_; ++v) ever_matched_[v] |= matched_[v];
        PlanTargets();
        ApplyTargets(undone);
      }
    }
    return true;
  }

  // Mean angle (degrees) between the normals of the two faces of each interior edge that has a
  // face with an active vertex: what planarizing lowers (imr-bench's roughness).
  double Roughness() const {
    double sum = 0;
    int64_t edges = 0;
    for (std::size_t f = 0; f < faces_.size(); ++f) {
      if (!topo_.face_ok[f] || !TouchesActive(f)) continue;
      const Face& F = faces_[f];
      for (int k = 0; k < 3; ++k) {
        const uint32_t g = OtherFace(f, F[k], F[(k + 1) % 3]);
        // Each edge once: from its lower face, or from this face when the other has no active vertex.
        if (g == kNoFace || (g < f && TouchesActive(g))) continue;
        const Vec3 a = FaceCross(p_, F), b = FaceCross(p_, faces_[g]);
        if (a.norm() <= 0 || b.norm() <= 0) continue;
        sum += std::acos(std::clamp(a.normalized().dot(b.normalized()), -1.0, 1.0)) * 180.0 / kPi;
        ++edges;
      }
    }
    return edges > 0 ? sum / static_cast<double>(edges) : 0.0;
  }

  // Planarizing (after the photometric passes): each vertex whose neighbourhood (its 2-ring)
  // lies on one plane, robustly fitted (a spike or a point of another surface does not tilt it),
  // goes onto that plane; a vertex at a corner (no plane holds enough of its neighbours) stays.
  // Jacobi rounds, each step through the same guard as the photometric moves. `moved` counts
  // the vertices it moved.
  void Planarize(int64_t* undone, int64_t* moved, int64_t* on_plane) {
    if (options_.planarize <= 0) return;
    const double tol = options_.planarize_tolerance;
    std::vector<uint32_t> stamp(n_, 0), ring;
    uint32_t epoch = 0;
    std::vector<uint8_t> touched(n_, 0);
    for (int round = 0; round < options_.planarize; ++round) {
      for (std::size_t v = 0; v < n_; ++v) {
        target_[v] = p_[v];
        planned_[v] = 0;
        if (!active_[v] || (!options_.planarize_matched && ever_matched_[v])) continue;
        ++epoch;
        stamp[v] = epoch;
        ring.clear();
        for (uint32_t i = topo_.nb_begin[v]; i < topo_.nb_begin[v + 1]; ++i) {
          const uint32_t a = topo_.nb[i];
          if (stamp[a] != epoch) stamp[a] = epoch, ring.push_back(a);
        }
        const std::size_t first = ring.size();
        for (std::size_t k = 0; k < first; ++k)
          for (uint32_t i = topo_.nb_begin[ring[k]]; i < topo_.nb_begin[ring[k] + 1]; ++i) {
            const uint32_t b = topo_.nb[i];
            if (stamp[b] != epoch) stamp[b] = epoch, ring.push_back(b);
          }
        Vec3 centre, normal;
        if (!FitPlane(ring, tol, &centre, &normal)) continue;
        if (round == 0) ++*on_plane;
        PlanMove(v, p_[v] - normal.dot(p_[v] - centre) * normal);
      }
      const std::vector<Vec3> before = p_;
      ApplyTargets(undone);
      for (std::size_t v = 0; v < n_; ++v) touched[v] |= p_[v] != before[v];
    }
    for (uint8_t t : touched) *moved += t;
  }

 private:
  static constexpr uint32_t kNoFace = std::numeric_limits<uint32_t>::max();

  // A plane through the points `ids` that holds at least planarize_min_share of them within
  // `tol`: a least-squares fit, then reweighted (Tukey, cut at 3 tol) so that outliers stop
  // tilting it. False when there are too few points or no such plane (a corner, a crease).
  bool FitPlane(const std::vector<uint32_t>& ids, double tol, Vec3* centre, Vec3* normal) const {
    if (ids.size() < 6) return false;
    std::vector<double> w(ids.size(), 1.0);
    const double cut = 3.0 * tol;
    for (int it = 0; it < 4; ++it) {
      Vec3 c = Vec3::Zero();
      double total = 0;
      for (std::size_t k = 0; k < ids.size(); ++k) c += w[k] * p_[ids[k]], total += w[k];
      if (total <= 0) return false;
      c /= total;
      Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
      for (std::size_t k = 0; k < ids.size(); ++k) {
        const Vec3 d = p_[ids[k]] - c;
        cov += w[k] * d * d.transpose();
      }
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);
      *centre = c;
      *normal = eig.eigenvectors().col(0);
      for (std::size_t k = 0; k < ids.size(); ++k) {
        const double r = std::fabs(normal->dot(p_[ids[k]] - c)) / cut;
        w[k] = r < 1 ? (1 - r * r) * (1 - r * r) : 0.0;
      }
    }
    std::size_t inliers = 0;
    for (uint32_t id : ids) inliers += std::fabs(normal->dot(p_[id] - *centre)) <= tol ? 1 : 0;
    return inliers >= options_.planarize_min_share * static_cast<double>(ids.size());
  }

  bool TouchesActive(std::size_t f) const {
    const Face& F = faces_[f];
    return active_[F[0]] || active_[F[1]] || active_[F[2]];
  }

  // The face other than f on edge (a, b), or kNoFace (a boundary or non-manifold edge).
  uint32_t OtherFace(std::size_t f, uint32_t a, uint32_t b) const {
    uint32_t found = kNoFace;
    int count = 0;
    for (uint32_t i = topo_.vf_begin[a]; i < topo_.vf_begin[a + 1]; ++i) {
      const uint32_t g = topo_.vf[i];
      if (g == f) continue;
      const Face& G = faces_[g];
      if (G[0] == b || G[1] == b || G[2] == b) {
        found = g;
        ++count;
      }
    }
    return count == 1 ? found : kNoFace;
  }

  void BuildMaps() {
    ParallelFor(static_cast<int64_t>(views_.size()), threads_, 1, [&](int64_t begin, int64_t end) {
      std::vector<Vec3> cam;
      std::vector<uint8_t> codes;
      for (int64_t j = begin; j < end; ++j)
        BuildDepthMap(views_[j], vd_[j], options_.depth_map_scale, p_, faces_, topo_, &maps_[j], &cam,
                      &codes);
    });
    p_maps_ = p_;
  }

  double MarginFor(int level) const {
    return (patch_.half + 1) * options_.patch_pixels * std::ldexp(1.0, level) + 1.0;
  }

  // The patch planes from a smoothed normal field: a spike's own normal points anywhere.
  void SmoothNormals() {
    for (int s = 0; s < options_.normal_smoothing; ++s) {
      std::vector<Vec3> smoothed(n_);
      for (std::size_t v = 0; v < n_; ++v) {
        Vec3 sum = normal_ok_[v] ? normals_[v] : Vec3::Zero();
        for (uint32_t i = topo_.nb_begin[v]; i < topo_.nb_begin[v + 1]; ++i)
          if (normal_ok_[topo_.nb[i]]) sum += normals_[topo_.nb[i]];
        smoothed[v] = sum.norm() > 1e-12 ? Vec3(sum.normalized()) : normals_[v];
      }
      normals_.swap(smoothed);
    }
  }

  // Photometric search (parallel; each vertex writes only its own slots).
  void Search(int level, double range) {
    std::fill(matched_.begin(), matched_.end(), 0);
    search_.clear();
    if (views_.size() >= 2) {
      vis_.margin_pixels = MarginFor(level);
      ChooseViews(vd_, maps_, p_, p_maps_, normals_, normal_ok_, active_, vis_, threads_, &choice_);
      for (std::size_t v = 0; v < n_; ++v)
        if (choice_.count[v] >= 2) search_.push_back(static_cast<uint32_t>(v));
    }
    ParallelFor(
        static_cast<int64_t>(search_.size()), threads_, 64, [&](int64_t begin, int64_t end) {
          std::vector<float> scratch;
          std::vector<double> score(offsets_.size());
          for (int64_t i = begin; i < end; ++i) SearchVertex(search_[i], level, range, &scratch, &score);
        });
  }

  // The offset along the normal where vertex v's views agree best, when it beats where v is.
  void SearchVertex(uint32_t v, int level, double range, std::vector<float>* scratch,
                    std::vector<double>* score_out) {
    const int S = options_.search_steps;
    std::vector<double>& score = *score_out;
    ScoreOffsets(vd_, &choice_.ids[static_cast<std::size_t>(v) * choice_.max_views],
                 choice_.count[v], level, p_[v], normals_[v], patch_, offsets_.data(),
                 static_cast<int>(offsets_.size()), scratch, score.data());
    int best = -1;
    for (int k = 0; k < static_cast<int>(score.size()); ++k)
      if (!std::isnan(score[k]) && (best < 0 || score[k] > score[best])) best = k;
    if (best < 0 || score[best] < options_.min_zncc) return;
    // A vertex that already looks right stays: the match must beat where it is.
    const double here = score[static_cast<std::size_t>(S)];
    if (!std::isnan(here) && score[best] - here < options_.min_gain) return;
    double d = offsets_[best];
    // Sub-step refinement: the vertex of the parabola through the best and its neighbours.
    if (best > 0 && best + 1 < static_cast<int>(score.size()) &&
        !std::isnan(score[best - 1]) && !std::isnan(score[best + 1])) {
      const double denom = score[best - 1] - 2 * score[best] + score[best + 1];
      if (denom < 0) {
        const double shift =
            std::clamp(0.5 * (score[best - 1] - score[best + 1]) / denom, -0.5, 0.5);
        d += shift * (range / S);
      }
    }
    match_[v] = d;
    matched_[v] = 1;
  }

  // A spike: neighbours on a plane, the vertex well off it, and the images do not say where it
  // belongs. Its move onto its neighbours' plane; a corner (neighbours not on one plane) stays.
  Vec3 SpikeMove(std::size_t v, const Vec3& mean, uint32_t b, uint32_t e) const {
    Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
    for (uint32_t i = b; i < e; ++i) {
      const Vec3 d = p_[topo_.nb[i]] - mean;
      cov += d * d.transpose();
    }
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov / static_cast<double>(e - b));
    const Vec3 plane_normal = eig.eigenvectors().col(0);
    const double residual = std::sqrt(std::max(eig.eigenvalues()(0), 0.0));
    const double off = (p_[v] - mean).dot(plane_normal);
    if (std::fabs(off) > options_.flatten_spikes * std::max(residual, 1e-12)) return -off * plane_normal;
    return Vec3::Zero();
  }

  // Targets (Jacobi: all from the positions at the start of the pass): the match along the
  // normal, the umbrella's pull, a spike flattened; within max_move of the input.
  void PlanTargets() {
    for (std::size_t v = 0; v < n_; ++v) {
      target_[v] = p_[v];
      planned_[v] = 0;
      if (!active_[v]) continue;
      Vec3 move = Vec3::Zero();
      if (matched_[v]) move += options_.step * match_[v] * normals_[v];
      const uint32_t b = topo_.nb_begin[v], e = topo_.nb_begin[v + 1];
      if (!topo_.boundary[v] && e > b) {
        Vec3 mean = Vec3::Zero();
        for (uint32_t i = b; i < e; ++i) mean += p_[topo_.nb[i]];
        mean /= static_cast<double>(e - b);
        Vec3 umbrella = mean - p_[v];
        // Along the normal only: a spike is flattened without pulling the sheet sideways.
        if (options_.smooth_along_normal && normal_ok_[v]) umbrella = umbrella.dot(normals_[v]) * normals_[v];
        if (!options_.smooth_matched && matched_[v]) umbrella.setZero();
        move += options_.smoothness * umbrella;
        if (options_.flatten_spikes > 0 && !matched_[v] && e - b >= 4) move += SpikeMove(v, mean, b, e);
      }
      PlanMove(v, p_[v] + move);
    }
  }

  // Vertex v's target `t`, kept within max_move of its input position.
  void PlanMove(std::size_t v, Vec3 t) {
    const Vec3 off = t - input_[v];
    const double len = off.norm();
    if (len > options_.max_move) t = input_[v] + off * (options_.max_move / len);
    // Displacements at rounding level are noise, not moves.
    if ((t - p_[v]).norm() <= 1e-12 * std::max(mean_edge_, 1e-300)) return;
    target_[v] = t;
    planned_[v] = (t - p_[v]).norm();
  }

  // Apply vertex by vertex so every check sees the current neighbours; a refused step is
  // halved, then dropped.
  void ApplyTargets(int64_t* undone) {
    guard_.Prepare(planned_);
    for (std::size_t v = 0; v < n_; ++v) {
      if (planned_[v] == 0) continue;
      const Vec3 delta = target_[v] - p_[v];
      bool done = false;
      for (int h = 0; h <= kMaxHalvings && !done; ++h) {
        const Vec3 q = p_[v] + std::ldexp(1.0, -h) * delta;
        if (guard_.Allows(static_cast<uint32_t>(v), q)) {
          p_[v] = q;
          done = true;
        }
      }
      if (!done) ++*undone;
    }
  }

  const std::vector<View>& views_;
  const std::vector<Face>& faces_;
  const RefineOptions& options_;
  std::vector<Vec3>& p_;
  const std::size_t n_;
  const std::vector<Vec3> input_;
  const std::vector<uint8_t> active_;
  const int threads_;
  const Topology topo_;
  const std::vector<Vec3> input_face_normals_;
  const double mean_edge_;
  const int image_levels_;
  std::vector<ViewData> vd_;
  const PatchGeometry patch_;
  ViewChoice choice_;
  VisibilityParams vis_;
  std::vector<DepthMap> maps_;
  std::vector<Vec3> p_maps_;  // positions the depth maps were drawn from
  std::vector<Vec3> normals_;
  std::vector<uint8_t> normal_ok_;
  std::vector<double> offsets_;
  std::vector<double> match_;         // accepted offset along the normal
  std::vector<uint8_t> matched_;
  std::vector<uint8_t> ever_matched_;  // stats.vertices_matched
  std::vector<Vec3> target_;
  std::vector<double> planned_;
  std::vector<uint32_t> search_;
  MoveGuard guard_{faces_, topo_, input_face_normals_, &p_};
};

}  // namespace

bool Refine(const std::vector<View>& views, const std::vector<std::array<uint32_t, 3>>& faces,
            const std::vector<uint8_t>& active_in, const RefineOptions& options,
            std::vector<Eigen::Vector3d>* vertices, RefineStats* stats_out,
            const std::function<bool()>& cancelled) {
  const auto start = std::chrono::steady_clock::now();
  Validate(views, faces, active_in, options, vertices);
  RefineStats local_stats;
  RefineStats& stats = stats_out ? *stats_out : local_stats;
  stats = RefineStats{};
  const std::vector<Vec3>& p = *vertices;
  const std::size_t n = p.size();
  std::vector<uint8_t> active = active_in;
  if (active.empty()) active.assign(n, 1);
  for (uint8_t& a : active) a = a ? 1 : 0;
  stats.vertices = static_cast<int64_t>(n);
  for (uint8_t a : active) stats.vertices_active += a;

  Refinement refinement(views, faces, std::move(active), options, vertices);
  stats.mean_zncc_before = views.size() >= 2 ? refinement.Evaluate(&stats.vertices_seen) : 0.0;
  const bool planarize = options.planarize > 0;
  if (planarize) stats.roughness_before = refinement.Roughness();
  bool completed = refinement.CoarseToFine(cancelled, &stats.moves_undone);
  if (completed && planarize) {
    if (cancelled && cancelled()) {
      completed = false;
    } else {
      refinement.Planarize(&stats.moves_undone, &stats.vertices_planarized,
                           &stats.vertices_on_plane);
    }
  }
  if (planarize) stats.roughness_after = refinement.Roughness();
  stats.mean_zncc_after = views.size() >= 2 ? refinement.Evaluate(nullptr) : 0.0;

  const std::vector<Vec3>& input = refinement.input();
  double moved = 0;
  for (std::size_t v = 0; v < n; ++v)
    if (p[v] != input[v]) {
      ++stats.vertices_moved;
      moved += (p[v] - input[v]).norm();
    }
  stats.mean_move = stats.vertices_moved > 0 ? moved / stats.vertices_moved : 0.0;
  for (uint8_t m : refinement.ever_matched()) stats.vertices_matched += m;
  stats.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return completed;
}

}  // namespace imr::photometric
