#include "tools/bench/common/surface_figures.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <stdexcept>
#include <string>
#include <utility>

#include "host/io/camera_model.h"

namespace imr::bench {

namespace {

std::vector<Vec3> FaceNormals(const std::vector<double>& xyz, const std::vector<uint32_t>& faces) {
  const std::size_t nf = faces.size() / 3;
  std::vector<Vec3> normal(nf);
  for (std::size_t f = 0; f < nf; ++f) {
    const double* a = &xyz[3 * faces[3 * f]];
    const double* b = &xyz[3 * faces[3 * f + 1]];
    const double* c = &xyz[3 * faces[3 * f + 2]];
    const Vec3 u = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
    const Vec3 v = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    Vec3 n = Cross(u, v);
    const double len = Norm(n);
    for (double& x : n) x = len > 0.0 ? x / len : 0.0;
    normal[f] = n;
  }
  return normal;
}

// Each undirected edge with the faces that use it.
std::map<std::pair<uint32_t, uint32_t>, std::vector<std::size_t>> EdgeFaces(
    const std::vector<uint32_t>& faces) {
  std::map<std::pair<uint32_t, uint32_t>, std::vector<std::size_t>> edges;
  for (std::size_t f = 0; f < faces.size() / 3; ++f)
    for (int k = 0; k < 3; ++k) {
      const uint32_t a = faces[3 * f + k], b = faces[3 * f + (k + 1) % 3];
      edges[{std::min(a, b), std::max(a, b)}].push_back(f);
    }
  return edges;
}

double AngleDegrees(const Vec3& n, const Vec3& m) {
  return std::acos(std::clamp(Dot(n, m), -1.0, 1.0)) * 180.0 / M_PI;
}

// Distance from p to the rect (center + s u + t v, |s| <= half_u, |t| <= half_v).
double RectDistance(const synthetic::Rect& r, const Vec3& p) {
  const Vec3 d = Sub(p, r.center);
  const double s = std::clamp(Dot(d, r.u), -r.half_u, r.half_u);
  const double t = std::clamp(Dot(d, r.v), -r.half_v, r.half_v);
  return Norm(Sub(d, Add(Scale(r.u, s), Scale(r.v, t))));
}

}  // namespace

double Roughness(const std::vector<double>& xyz, const std::vector<uint32_t>& faces) {
  const std::vector<Vec3> normal = FaceNormals(xyz, faces);
  double sum = 0.0;
  std::size_t count = 0;
  for (const auto& [edge, list] : EdgeFaces(faces)) {
    if (list.size() != 2) continue;
    sum += AngleDegrees(normal[list[0]], normal[list[1]]);
    ++count;
  }
  return count > 0 ? sum / static_cast<double>(count) : 0.0;
}

PlaneRoughness RoughnessOnPlanes(const std::vector<double>& xyz, const std::vector<uint32_t>& faces,
                                 const PlaneOf& plane_of) {
  PlaneRoughness r;
  const std::size_t nf = faces.size() / 3;
  if (nf == 0) return r;
  std::vector<int> vertex_plane(xyz.size() / 3, -2);  // -2: not asked yet
  auto plane = [&](uint32_t v) {
    if (vertex_plane[v] == -2) vertex_plane[v] = plane_of({xyz[3 * v], xyz[3 * v + 1], xyz[3 * v + 2]});
    return vertex_plane[v];
  };
  std::vector<int> face_plane(nf, -1);
  int64_t on_plane = 0;
  for (std::size_t f = 0; f < nf; ++f) {
    const int a = plane(faces[3 * f]);
    if (a >= 0 && plane(faces[3 * f + 1]) == a && plane(faces[3 * f + 2]) == a) face_plane[f] = a, ++on_plane;
  }
  r.face_share = static_cast<double>(on_plane) / static_cast<double>(nf);
  const std::vector<Vec3> normal = FaceNormals(xyz, faces);
  double sum = 0.0;
  for (const auto& [edge, list] : EdgeFaces(faces)) {
    if (list.size() != 2 || face_plane[list[0]] < 0 || face_plane[list[0]] != face_plane[list[1]])
      continue;
    sum += AngleDegrees(normal[list[0]], normal[list[1]]);
    ++r.edges;
  }
  r.degrees = r.edges > 0 ? sum / static_cast<double>(r.edges) : 0.0;
  return r;
}

PlaneOf SyntheticPlanes(const eval::SyntheticTruth& truth, double tolerance) {
  // Coplanar rects share an id: the plane's unit normal (sign fixed: first non-zero component
  // positive) to a thousandth and its offset to a centimetre.
  std::vector<int> plane_id(truth.scene.rects().size());
  std::map<std::array<long, 4>, int> ids;
  for (std::size_t i = 0; i < plane_id.size(); ++i) {
    const synthetic::Rect& r = truth.scene.rects()[i];
    Vec3 n = synthetic::Normalized(Cross(r.u, r.v));
    for (double c : n)
      if (std::abs(c) > 1e-9) {
        if (c < 0.0) n = Scale(n, -1.0);
        break;
      }
    const std::array<long, 4> key = {std::lround(n[0] * 1000), std::lround(n[1] * 1000),
                                     std::lround(n[2] * 1000), std::lround(Dot(n, r.center) * 100)};
    plane_id[i] = ids.emplace(key, static_cast<int>(ids.size())).first->second;
  }
  return [truth, plane_id, tolerance](const Vec3& world) {
    const Vec3 p = truth.ToScene(world);
    int found = -1;
    for (int i : truth.scene.RectsNear(p[0] - tolerance, p[1] - tolerance, p[0] + tolerance,
                                       p[1] + tolerance)) {
      if (RectDistance(truth.scene.rects()[static_cast<std::size_t>(i)], p) > tolerance) continue;
      const int id = plane_id[static_cast<std::size_t>(i)];
      if (found >= 0 && found != id) return -1;  // near two planes: an edge of the truth
      found = id;
    }
    return found;
  };
}

SmallComponents SmallComponentsOf(const eval::MeshStatistics& stats, double share) {
  if (!(share > 0.0 && share < 1.0))
    throw std::invalid_argument("SmallComponentsOf: share must be in (0, 1), got " + std::to_string(share));
  SmallComponents s;
  s.components = static_cast<int64_t>(stats.component_list.size());
  double total = 0.0;
  for (const eval::ComponentStatistics& c : stats.component_list) total += c.area;
  if (total <= 0.0) return s;
  double small_area = 0.0;
  for (const eval::ComponentStatistics& c : stats.component_list)
    if (c.area < share * total) ++s.small, small_area += c.area;
  s.area_share = small_area / total;
  return s;
}

std::vector<render::Camera> KeyframeViews(const io::ColmapModel& model, int keyframe_every, int every) {
  std::vector<const io::ColmapModel::Image*> images;
  for (const io::ColmapModel::Image& im : model.images) images.push_back(&im);
  std::sort(images.begin(), images.end(), [](const auto* a, const auto* b) { return a->id < b->id; });
  const std::size_t step = static_cast<std::size_t>(std::max(1, keyframe_every)) *
                           static_cast<std::size_t>(std::max(1, every));
  std::vector<render::Camera> cameras;
  for (std::size_t k = 0; k < images.size(); k += step) {
    const io::ColmapModel::Image& im = *images[k];
    const auto cam = std::find_if(model.cameras.begin(), model.cameras.end(),
                                  [&](const auto& c) { return c.id == im.camera_id; });
    if (cam == model.cameras.end())
      throw std::runtime_error("image " + im.name + ": no camera " + std::to_string(im.camera_id));
    render::Camera c;
    c.width = static_cast<int>(cam->width), c.height = static_cast<int>(cam->height);
    if (cam->model == "PINHOLE" && cam->params.size() == 4)
      c.fx = cam->params[0], c.fy = cam->params[1], c.cx = cam->params[2], c.cy = cam->params[3];
    else if (cam->model == "SIMPLE_PINHOLE" && cam->params.size() == 3)
      c.fx = c.fy = cam->params[0], c.cx = cam->params[1], c.cy = cam->params[2];
    else
      throw std::runtime_error("camera " + std::to_string(cam->id) + " is " + cam->model +
                               ": expected PINHOLE or SIMPLE_PINHOLE");
    c.rotation = io::QuaternionToRotation(im.qvec);
    c.translation = im.tvec;
    if (const std::string e = c.Check(); !e.empty())
      throw std::runtime_error("image " + im.name + ": " + e);
    cameras.push_back(c);
  }
  return cameras;
}

render::BackFacing SeenFromBehind(const std::vector<double>& xyz, const std::vector<uint32_t>& faces,
                                  const std::vector<render::Camera>& cameras, double scale) {
  return render::MeasureBackFacing(render::MeshRefOf(xyz, faces), cameras, scale);
}

}  // namespace imr::bench
