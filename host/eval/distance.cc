// The one CGAL translation unit of host/eval.
#include "host/eval/distance.h"

#include "host/eval/parallel.h"

#include <CGAL/AABB_traits.h>
#include <CGAL/AABB_tree.h>
#include <CGAL/AABB_triangle_primitive.h>
#include <CGAL/Orthogonal_k_neighbor_search.h>
#include <CGAL/Search_traits_3.h>
#include <CGAL/Simple_cartesian.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <utility>

namespace imr::eval {
namespace {

using K = CGAL::Simple_cartesian<double>;
using Point = K::Point_3;
using Triangle = K::Triangle_3;
using TriangleIterator = std::vector<Triangle>::const_iterator;
using Primitive = CGAL::AABB_triangle_primitive<K, TriangleIterator>;
using Tree = CGAL::AABB_tree<CGAL::AABB_traits<K, Primitive>>;

using SearchTraits = CGAL::Search_traits_3<K>;
using NeighborSearch = CGAL::Orthogonal_k_neighbor_search<SearchTraits>;
using KdTree = NeighborSearch::Tree;

Point ToPoint(const Vec3& v) { return Point(v[0], v[1], v[2]); }

// Spreads the low 21 bits of v to every third bit.
uint64_t Spread(uint64_t v) {
  v &= 0x1fffff;
  v = (v | v << 32) & 0x1f00000000ffffull;
  v = (v | v << 16) & 0x1f0000ff0000ffull;
  v = (v | v << 8) & 0x100f00f00f00f00full;
  v = (v | v << 4) & 0x10c30c30c30c30c3ull;
  v = (v | v << 2) & 0x1249249249249249ull;
  return v;
}

// Indices of `points` sorted along a Morton (Z-order) curve over their bounding box: neighbours
// in the order are mostly neighbours in space.
std::vector<uint32_t> MortonOrder(const std::vector<Vec3>& points) {
  Vec3 lo = {INFINITY, INFINITY, INFINITY}, hi = {-INFINITY, -INFINITY, -INFINITY};
  for (const Vec3& p : points)
    for (int k = 0; k < 3; ++k) {
      lo[k] = std::min(lo[k], p[k]);
      hi[k] = std::max(hi[k], p[k]);
    }
  double extent = 0.0;
  for (int k = 0; k < 3; ++k) extent = std::max(extent, hi[k] - lo[k]);
  const double scale = extent > 0.0 ? (double(1 << 21) - 1.0) / extent : 0.0;
  std::vector<std::pair<uint64_t, uint32_t>> keyed(points.size());
  for (std::size_t i = 0; i < points.size(); ++i) {
    uint64_t code = 0;
    for (int k = 0; k < 3; ++k)
      code |= Spread(static_cast<uint64_t>((points[i][k] - lo[k]) * scale)) << k;
    keyed[i] = {code, static_cast<uint32_t>(i)};
  }
  std::sort(keyed.begin(), keyed.end());
  std::vector<uint32_t> order(points.size());
  for (std::size_t i = 0; i < points.size(); ++i) order[i] = keyed[i].second;
  return order;
}

}  // namespace

struct MeshDistance::Impl {
  std::vector<Triangle> triangles;  // the tree refers to them: kept alive and unmoved
  std::size_t degenerate = 0;
  Tree tree;
};

MeshDistance::MeshDistance(const TriangleMesh& mesh) : impl_(std::make_unique<Impl>()) {
  impl_->triangles.reserve(mesh.triangles.size());
  for (const auto& t : mesh.triangles) {
    const Triangle tri(ToPoint(mesh.vertices[t[0]]), ToPoint(mesh.vertices[t[1]]),
                       ToPoint(mesh.vertices[t[2]]));
    if (tri.is_degenerate()) {
      ++impl_->degenerate;
      continue;
    }
    impl_->triangles.push_back(tri);
  }
  if (impl_->triangles.empty())
    throw std::invalid_argument("the mesh has no triangle of non-zero area");
  impl_->tree.insert(impl_->triangles.begin(), impl_->triangles.end());
  // Build now, not lazily inside the first (threaded) query. No kd-tree of hints: Distances()
  // takes its hints from the previous query.
  impl_->tree.do_not_accelerate_distance_queries();
  impl_->tree.build();
}

MeshDistance::~MeshDistance() = default;

std::size_t MeshDistance::triangles() const { return impl_->triangles.size(); }
std::size_t MeshDistance::degenerate() const { return impl_->degenerate; }

template <class Out>
void MeshDistance::Query(const std::vector<Vec3>& points, int threads, const Out& out) const {
  const Tree& tree = impl_->tree;
  // Queries in Morton order, each starting from the previous one's closest point: a near hint
  // shrinks the search at once and costs nothing (the tree's own hints need a kd-tree search).
  // Any hint gives the exact closest point; only the time changes.
  const std::vector<uint32_t> order = MortonOrder(points);
  ParallelFor(points.size(), threads, [&](std::size_t begin, std::size_t end) {
    Tree::Point_and_primitive_id hint;
    for (std::size_t k = begin; k < end; ++k) {
      const uint32_t i = order[k];
      const Point q = ToPoint(points[i]);
      hint = k == begin ? tree.closest_point_and_primitive(q) : tree.closest_point_and_primitive(q, hint);
      out(i, q, hint.first);
    }
  });
}

std::vector<double> MeshDistance::Distances(const std::vector<Vec3>& points, int threads) const {
  std::vector<double> out(points.size());
  Query(points, threads, [&out](uint32_t i, const Point& q, const Point& nearest) {
    out[i] = std::sqrt(CGAL::squared_distance(q, nearest));
  });
  return out;
}

std::vector<Vec3> MeshDistance::ClosestPoints(const std::vector<Vec3>& points, int threads) const {
  std::vector<Vec3> out(points.size());
  Query(points, threads, [&out](uint32_t i, const Point&, const Point& nearest) {
    out[i] = Vec3{nearest.x(), nearest.y(), nearest.z()};
  });
  return out;
}

struct PointSetDistance::Impl {
  KdTree tree;
};

PointSetDistance::PointSetDistance(const std::vector<Vec3>& points) : impl_(std::make_unique<Impl>()) {
  if (points.empty()) throw std::invalid_argument("the point set is empty");
  std::vector<Point> p;
  p.reserve(points.size());
  for (const Vec3& v : points) p.push_back(ToPoint(v));
  impl_->tree.insert(p.begin(), p.end());
  impl_->tree.build();  // now, not lazily inside the first (threaded) query
}

PointSetDistance::~PointSetDistance() = default;

std::vector<double> PointSetDistance::Distances(const std::vector<Vec3>& queries, int threads) const {
  std::vector<double> out(queries.size());
  const KdTree& tree = impl_->tree;
  const std::vector<uint32_t> order = MortonOrder(queries);  // cache-friendly tree walks
  ParallelFor(queries.size(), threads, [&](std::size_t begin, std::size_t end) {
    for (std::size_t k = begin; k < end; ++k) {
      const uint32_t i = order[k];
      const NeighborSearch search(tree, ToPoint(queries[i]), 1);
      out[i] = std::sqrt(search.begin()->second);  // squared Euclidean distance
    }
  });
  return out;
}

}  // namespace imr::eval
