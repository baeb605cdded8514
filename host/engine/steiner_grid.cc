// The Steiner grid (engine_parts.h, SteinerGrid): the grid's nodes along the rays, and the
// keyframe's step that inserts the ones its rays newly reach (Engine::Impl::PlaceSteinerPoints).
// Steiner points sit off their grid nodes by a deterministic jitter (steiner_jitter, 1e-3 of the
// spacing): on an exact grid many cells are cospherical and CGAL's predicates fall back to exact
// arithmetic.
#include "host/engine/engine_parts.h"

#include <CGAL/property_map.h>
#include <CGAL/spatial_sort.h>
#include <CGAL/Spatial_sort_traits_adapter_3.h>

namespace imr::engine {
namespace detail {
namespace {

// A deterministic number in [-1, 1] from a key and an axis (splitmix64).
double Jitter(uint64_t key, int axis) {
  uint64_t z = key * 3 + static_cast<uint64_t>(axis) + 0x9E3779B97F4A7C15ull;
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  z ^= z >> 31;
  return static_cast<double>(z >> 11) / static_cast<double>(1ull << 52) - 1.0;
}

}  // namespace

// The grid follows the rays (issue 47): a cube of +-(max_ray_length + margin) around each camera
// put most nodes behind, beside and above the cameras where no ray goes (a forward COLMAP model:
// 670,824 Steiner points for 4,217 points). The carving needs cells no larger than a grid step
// along the rays and a margin around them (a ray's cells, their neighbours and theirs are
// weighted); beyond that the cells are matter whatever their size.
Point SteinerGrid::NodePoint(const Node& n) const {
  const double s = opt_.steiner_spacing;
  return Point((static_cast<double>(n.i) + opt_.steiner_origin[0]) * s,
               (static_cast<double>(n.j) + opt_.steiner_origin[1]) * s,
               (static_cast<double>(n.k) + opt_.steiner_origin[2]) * s);
}

int64_t SteinerGrid::Visit(const Node& voxel, std::vector<Node>* fresh) {
  if (!voxels_.insert(voxel).second) return 1;
  const int64_t m = std::max<int64_t>(
      1, static_cast<int64_t>(std::ceil(opt_.steiner_margin / opt_.steiner_spacing - 1e-9)));
  for (int64_t i = voxel.i - m; i <= voxel.i + 1 + m; ++i)
    for (int64_t j = voxel.j - m; j <= voxel.j + 1 + m; ++j)
      for (int64_t k = voxel.k - m; k <= voxel.k + 1 + m; ++k)
        if (nodes_.insert({i, j, k}).second) fresh->push_back({i, j, k});
  return (2 * m + 2) * (2 * m + 2) * (2 * m + 2);
}

std::vector<Point> SteinerGrid::NewPoints(const std::vector<Segment>& segments,
                                          const std::function<bool()>& stop) {
  const double s = opt_.steiner_spacing;
  std::vector<Node> fresh;
  // The nodes looked at so far, and when to poll `stop` next.
  int64_t walked = 0, next_poll = 0x10000;
  auto visit = [&](const int64_t v[3]) {
    walked += Visit({v[0], v[1], v[2]}, &fresh);
    if (walked >= next_poll) {
      next_poll = walked + 0x10000;
      if (stop && stop())
        throw Stopped("stopped on request while placing the Steiner grid's nodes");
    }
  };
  for (const Segment& seg : segments) {
    // In node units; the voxel v holds [v, v + 1) on each axis.
    double ua[3] = {seg.a.x() / s - opt_.steiner_origin[0], seg.a.y() / s - opt_.steiner_origin[1],
                    seg.a.z() / s - opt_.steiner_origin[2]};
    double ub[3] = {seg.b.x() / s - opt_.steiner_origin[0], seg.b.y() / s - opt_.steiner_origin[1],
                    seg.b.z() / s - opt_.steiner_origin[2]};
    int64_t v[3], end[3], step[3];
    double t_max[3], t_delta[3];
    int64_t steps = 0;
    for (int d = 0; d < 3; ++d) {
      const double fa = std::floor(ua[d]), fb = std::floor(ub[d]);
      // Node numbers (with the margin) are exact integers in a double up to 2^53.
      if (!(std::abs(fa) < 0x1p52 && std::abs(fb) < 0x1p52))
        throw std::runtime_error("a ray to " + std::to_string(seg.b[d]) + " on axis " +
                                 std::to_string(d) +
                                 " is beyond the Steiner grid's node numbers (2^52 steps of "
                                 "steiner_spacing " + std::to_string(s) +
                                 "): raise steiner_spacing");
      v[d] = static_cast<int64_t>(fa);
      end[d] = static_cast<int64_t>(fb);
      steps += std::abs(end[d] - v[d]);
      const double du = ub[d] - ua[d];
      step[d] = end[d] > v[d] ? 1 : end[d] < v[d] ? -1 : 0;
      t_delta[d] = step[d] != 0 ? 1.0 / std::abs(du) : HUGE_VAL;
      t_max[d] = step[d] > 0   ? (fa + 1.0 - ua[d]) / du
                 : step[d] < 0 ? (fa - ua[d]) / du
                               : HUGE_VAL;
    }
    // Every voxel the segment crosses, in order (Amanatides & Woo), ending in the last one's even
    // when rounding would stop the walk short: steps bounds it.
    visit(v);
    for (int64_t n = 0; n < steps; ++n) {
      int d = t_max[0] <= t_max[1] ? (t_max[0] <= t_max[2] ? 0 : 2)
                                   : (t_max[1] <= t_max[2] ? 1 : 2);
      if (v[d] == end[d]) {  // rounding: step on an axis that still has steps to go
        for (int e = 0; e < 3; ++e)
          if (v[e] != end[e]) d = e;
      }
      v[d] += step[d];
      t_max[d] += t_delta[d];
      visit(v);
    }
  }
  // Named in the grid's order, whatever order the rays came in.
  std::sort(fresh.begin(), fresh.end());
  std::vector<Point> out;
  out.reserve(fresh.size());
  for (const Node& n : fresh) {
    // Off the exact grid by a deterministic jitter (steiner_jitter): on a regular grid eight
    // points share every circumsphere and CGAL's predicates fall back to exact arithmetic. The
    // jitter's seed packs the node in 63 bits (it only needs to vary).
    const uint64_t key = (static_cast<uint64_t>(n.i & 0x1FFFFF) << 42) |
                         (static_cast<uint64_t>(n.j & 0x1FFFFF) << 21) |
                         static_cast<uint64_t>(n.k & 0x1FFFFF);
    const double jit = opt_.steiner_jitter * s;
    const Point p = NodePoint(n);
    out.emplace_back(p.x() + jit * Jitter(key, 0), p.y() + jit * Jitter(key, 1),
                     p.z() + jit * Jitter(key, 2));
  }
  return out;
}

void SteinerGrid::Forget(const std::function<bool(const Point&)>& gone) {
  for (auto* set : {&nodes_, &voxels_})
    for (auto it = set->begin(); it != set->end();)
      it = gone(NodePoint(*it)) ? set->erase(it) : std::next(it);
}

}  // namespace detail

using detail::PointRecord;
using detail::ToPoint;

// The Steiner points the update's rays newly reach (a point refused - a duplicate, or its
// conflict zone could not leave O - is counted and not tried again): the segments camera -> point
// of its new points and of its moved points' new positions (as they are cast: a ray longer than
// max_ray_length only near the camera, or not at all), and each new camera's path from the one
// before when within max_ray_length (camera_path opens it). The grid's order names them (their
// vertex ids, which the canonical orders of growing and peeling read); they are inserted along a
// Hilbert curve (CGAL's spatial sort), each located from the last and near it: the street
// stream's 22 k Steiner points took 0.76 s in the grid's order, 0.30-0.37 s along the curve (the
// same triangulation and mesh bytes).
void Engine::Impl::PlaceSteinerPoints(const KeyframeUpdate& update, size_t first_new_camera) {
  using Segment = detail::SteinerGrid::Segment;
  std::vector<Segment> segments;
  const double max_len = s.opt.max_ray_length;
  auto ray = [&](const Point& c, const Point& p) {
    const double len2 = CGAL::squared_distance(c, p);
    if (len2 <= max_len * max_len) {
      segments.push_back({c, p});
    } else if (s.opt.long_rays == LongRays::kNearCamera) {
      const double f = max_len / std::sqrt(len2);
      segments.push_back({c, c + f * (p - c)});
    }
  };
  // A camera's path from the one before, when it is a step (not a jump to another place).
  for (size_t c = first_new_camera; c < s.cameras.size(); ++c) {
    const bool step = c > 0 && s.opt.camera_path > 0 &&
                      CGAL::squared_distance(s.cameras[c - 1], s.cameras[c]) <= max_len * max_len;
    segments.push_back({step ? s.cameras[c - 1] : s.cameras[c], s.cameras[c]});
  }
  for (const NewPoint& p : update.new_points) {
    const Point end = ToPoint(p.position);
    for (uint64_t cam : p.camera_ids) ray(s.cameras[s.camera_index.at(cam)], end);
  }
  // A moved point's rays from its last `window` cameras are cast again to its new position
  // (older ones keep their end), and those from its new cameras. Its window's rays are followed
  // again once it is a quarter step from where they were last followed: a ray within a quarter
  // step of one followed has nodes at least the margin less a quarter step around it (following
  // them at every move of every point took imr-bench speed's Steiner phase from 0.6 to 1.3 s;
  // this takes 0.1 s and places the same nodes there).
  const double again = 0.25 * s.opt.steiner_spacing;
  for (const MovedPoint& m : update.moved_points) {
    PointRecord& rec = s.points[s.point_index.at(m.id)];
    if (rec.removed) continue;
    const Point end = ToPoint(m.position);
    for (uint64_t cam : m.camera_ids) ray(s.cameras[s.camera_index.at(cam)], end);
    if (CGAL::squared_distance(ToPoint(rec.grid_end), end) <= again * again) continue;
    rec.grid_end = m.position;
    for (uint32_t cam : s.Window(rec)) ray(s.cameras[cam], end);
  }
  std::vector<std::pair<Point, int64_t>> points;
  for (const Point& p : steiner.NewPoints(segments, stop_requested))
    points.emplace_back(p, -(++steiner_nodes_));
  using PointOf = CGAL::First_of_pair_property_map<std::pair<Point, int64_t>>;
  CGAL::spatial_sort(points.begin(), points.end(),
                     CGAL::Spatial_sort_traits_adapter_3<detail::K, PointOf>());
  size_t placed = 0;
  for (const auto& [p, id] : points) {
    if ((++placed & 0x3FF) == 0 && stop_requested && stop_requested())
      throw detail::Stopped("stopped on request while inserting the Steiner grid's points");
    bool dup = false;
    std::vector<RayEntry> u;
    Vertex_handle v = InsertPoint(p, id, s.opt.transfer_on_insert, &dup, &u);
    if (v == Vertex_handle()) {
      ++s.stats.steiner_dropped;
      continue;
    }
    ++s.stats.steiner_points;
    if (s.opt.visibility_mode == VisibilityMode::kRays) caster.RecastRays(std::move(u), -1);
  }
}

}  // namespace imr::engine
