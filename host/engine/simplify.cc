// CGAL's edge collapse behind simplify.h: the only translation unit that compiles it.
#include "host/engine/simplify.h"

#include "host/engine/mesh_topology.h"

#include <CGAL/AABB_triangle_primitive.h>
#include <CGAL/AABB_traits.h>
#include <CGAL/AABB_tree.h>
#include <CGAL/Simple_cartesian.h>
#include <CGAL/Surface_mesh.h>
#include <CGAL/Surface_mesh_simplification/Edge_collapse_visitor_base.h>
#include <CGAL/Surface_mesh_simplification/Policies/Edge_collapse/Bounded_distance_placement.h>
#include <CGAL/Surface_mesh_simplification/Policies/Edge_collapse/Bounded_normal_change_filter.h>
#include <CGAL/Surface_mesh_simplification/Policies/Edge_collapse/Count_stop_predicate.h>
#include <CGAL/Surface_mesh_simplification/Policies/Edge_collapse/LindstromTurk_cost.h>
#include <CGAL/Surface_mesh_simplification/Policies/Edge_collapse/LindstromTurk_placement.h>
#include <CGAL/Surface_mesh_simplification/edge_collapse.h>

#include <algorithm>
#include <cmath>
#include <limits>

namespace imr::engine {
namespace {

using Kernel = CGAL::Simple_cartesian<double>;
using Point = Kernel::Point_3;
using SM = CGAL::Surface_mesh<Point>;
using VD = SM::Vertex_index;
namespace SMS = CGAL::Surface_mesh_simplification;

// Lindstrom-Turk's placement, but a collapse keeps a locked vertex where it is, an edge between
// two locked vertices stays, and no collapse joins two locked vertices that were not joined: two
// meshes sharing a seam of locked vertices would otherwise each bridge the same two seam
// vertices, and merged they would hold that edge four times.
struct LockedPlacement {
  const SM::Property_map<VD, bool>* locked;
  SMS::LindstromTurk_placement<SM> base;
  template <typename Profile>
  boost::optional<typename Profile::Point> operator()(const Profile& p) const {
    const bool l0 = (*locked)[p.v0()], l1 = (*locked)[p.v1()];
    if (l0 && l1) return boost::none;
    if (!l0 && !l1) return base(p);
    // The free vertex goes onto the locked one: its other locked neighbours must be the locked
    // one's already.
    const VD keep = l0 ? p.v0() : p.v1(), gone = l0 ? p.v1() : p.v0();
    const SM& sm = p.surface_mesh();
    for (VD r : CGAL::vertices_around_target(sm.halfedge(gone), sm))
      if (r != keep && (*locked)[r] && !sm.halfedge(keep, r).is_valid()) return boost::none;
    return l0 ? p.p0() : p.p1();
  }
};

// The kept vertex handle takes the identity (input vertex, lock) of the one whose place it takes.
struct KeepIdentity : SMS::Edge_collapse_visitor_base<SM> {
  SM::Property_map<VD, uint32_t>* source;
  SM::Property_map<VD, bool>* locked;
  uint32_t pending_source = 0;
  bool pending_locked = false, pending = false;
  template <typename Profile>
  void OnCollapsing(const Profile& p, const boost::optional<Point>&) {
    pending = (*locked)[p.v0()] || (*locked)[p.v1()];
    if (pending) {
      const VD v = (*locked)[p.v0()] ? p.v0() : p.v1();
      pending_source = (*source)[v];
      pending_locked = true;
    }
  }
  template <typename Profile>
  void OnCollapsed(const Profile&, const VD& kept) {
    if (!pending) return;
    (*source)[kept] = pending_source;
    (*locked)[kept] = pending_locked;
  }
};

}  // namespace

SimplifiedMesh SimplifyMesh(const Mesh& input, const std::vector<char>& locked_in, int64_t target_triangles,
                            double max_distance) {
  SimplifiedMesh out;
  // Pinched vertices: one copy per fan (point_ids carry the input index through the split), each
  // locked: the fans meet there.
  Mesh m = input;
  const std::size_t n_in = input.vertices.size() / 3;
  for (std::size_t v = 0; v < n_in; ++v) m.point_ids[v] = static_cast<int64_t>(v);
  SplitPinchedVertices(&m);
  const std::size_t n = m.vertices.size() / 3;
  std::vector<char> lock(n, 0);
  for (std::size_t v = 0; v < n; ++v) {
    const auto s = static_cast<std::size_t>(m.point_ids[v]);
    lock[v] = (s < locked_in.size() && locked_in[s]) || v >= n_in;
    if (v >= n_in) lock[s] = 1;
  }
  // And their neighbours: the fans of a pinched vertex keep their links, so that no collapse
  // gives two of its fans the same edge (one vertex again, they would repeat it).
  std::vector<char> pinched(n, 0);
  for (std::size_t v = n_in; v < n; ++v) pinched[v] = pinched[static_cast<std::size_t>(m.point_ids[v])] = 1;
  for (std::size_t f = 0; f + 2 < m.faces.size(); f += 3)
    if (pinched[m.faces[f]] || pinched[m.faces[f + 1]] || pinched[m.faces[f + 2]])
      for (int k = 0; k < 3; ++k) lock[m.faces[f + k]] = 1;
  const auto as_is = [&] {
    SimplifiedMesh same;
    same.mesh = input;
    same.source.resize(n_in);
    for (std::size_t v = 0; v < n_in; ++v) same.source[v] = static_cast<uint32_t>(v);
    return same;
  };
  SM sm;
  auto [source, s_ok] = sm.add_property_map<VD, uint32_t>("v:source", 0);
  auto [locked, l_ok] = sm.add_property_map<VD, bool>("v:locked", false);
  std::vector<VD> vd(n);
  for (std::size_t v = 0; v < n; ++v) {
    vd[v] = sm.add_vertex(Point(m.vertices[3 * v], m.vertices[3 * v + 1], m.vertices[3 * v + 2]));
    source[vd[v]] = static_cast<uint32_t>(m.point_ids[v]);
    locked[vd[v]] = lock[v] != 0;
  }
  for (std::size_t f = 0; f + 2 < m.faces.size(); f += 3)
    if (sm.add_face(vd[m.faces[f]], vd[m.faces[f + 1]], vd[m.faces[f + 2]]) == SM::null_face())
      return as_is();  // not a 2-manifold with boundary
  const int64_t faces = static_cast<int64_t>(m.faces.size() / 3);
  if (target_triangles < faces) {
    // Edges ~ 3/2 faces on a surface.
    SMS::Count_stop_predicate<SM> stop(static_cast<std::size_t>(std::max<int64_t>(3, target_triangles * 3 / 2)));
    KeepIdentity visitor;
    visitor.source = &source;
    visitor.locked = &locked;
    LockedPlacement placement{&locked, {}};
    const auto params = CGAL::parameters::get_cost(SMS::LindstromTurk_cost<SM>())
                            .filter(SMS::Bounded_normal_change_filter<>())
                            .visitor(visitor);
    if (max_distance > 0.0)
      SMS::edge_collapse(sm, stop,
                         params.get_placement(SMS::Bounded_distance_placement<LockedPlacement, Kernel>(max_distance, placement)));
    else
      SMS::edge_collapse(sm, stop, params.get_placement(placement));
    sm.collect_garbage();
  }
  // Back to an engine::Mesh; the split copies of one input vertex are one vertex again.
  std::vector<int64_t> index_of(n_in, -1);
  std::vector<uint32_t> new_index(sm.number_of_vertices() + sm.number_of_removed_vertices() + 1, 0);
  for (VD v : sm.vertices()) {
    const uint32_t s = source[v];
    if (index_of[s] < 0) {
      index_of[s] = static_cast<int64_t>(out.source.size());
      out.source.push_back(s);
      const Point& p = sm.point(v);
      out.mesh.vertices.insert(out.mesh.vertices.end(), {p.x(), p.y(), p.z()});
      out.mesh.point_ids.push_back(input.point_ids[s]);
    }
    new_index[static_cast<std::size_t>(v)] = static_cast<uint32_t>(index_of[s]);
  }
  for (auto f : sm.faces())
    for (VD v : CGAL::vertices_around_face(sm.halfedge(f), sm))
      out.mesh.faces.push_back(new_index[static_cast<std::size_t>(v)]);
  out.error = MaxDistanceToMesh(input.vertices, out.mesh);
  return out;
}

double MaxDistanceToMesh(const std::vector<double>& points, const Mesh& mesh) {
  if (points.empty()) return 0.0;
  if (mesh.faces.empty()) return std::numeric_limits<double>::infinity();
  using Triangle = Kernel::Triangle_3;
  using Iterator = std::vector<Triangle>::const_iterator;
  using Primitive = CGAL::AABB_triangle_primitive<Kernel, Iterator>;
  using Tree = CGAL::AABB_tree<CGAL::AABB_traits<Kernel, Primitive>>;
  std::vector<Triangle> triangles;
  triangles.reserve(mesh.faces.size() / 3);
  const auto at = [&](uint32_t v) {
    return Point(mesh.vertices[3 * v], mesh.vertices[3 * v + 1], mesh.vertices[3 * v + 2]);
  };
  for (std::size_t f = 0; f + 2 < mesh.faces.size(); f += 3)
    triangles.emplace_back(at(mesh.faces[f]), at(mesh.faces[f + 1]), at(mesh.faces[f + 2]));
  Tree tree(triangles.begin(), triangles.end());
  tree.accelerate_distance_queries();
  double worst = 0.0;
  for (std::size_t i = 0; i + 2 < points.size(); i += 3)
    worst = std::max(worst, std::sqrt(tree.squared_distance(Point(points[i], points[i + 1], points[i + 2]))));
  return worst;
}

}  // namespace imr::engine
