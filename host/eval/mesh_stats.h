// Topology and size of a triangle mesh, for reports (issue 6: "mesh statistics (vertices, faces,
// connected components, Euler characteristic/genus, manifold check result)"). Plain arrays in,
// so the pipeline passes engine::Mesh and `imr evaluate` / `imr render` pass what they read.
//
// Definitions (what each count means, so two reports compare):
//   - Only faces with three distinct vertex indices count ("valid" faces); the others are counted
//     in `degenerate_faces` and ignored everywhere else. Zero-AREA faces with distinct indices
//     are valid (topology does not look at coordinates).
//   - V = vertices used by some valid face (`used_vertices`); unused vertices are counted in
//     `unused_vertices` and belong to no component. E = distinct undirected edges of the valid
//     faces. F = valid faces. Euler characteristic chi = V - E + F.
//   - Connected components: faces connected through SHARED VERTICES (two cones touching at their
//     tips are one component). V, E, F, chi are also given per component.
//   - Boundary edge: in exactly one face. Non-manifold edge: in three or more faces.
//   - Boundary loops: connected components of the graph of boundary edges (on a manifold mesh,
//     each is one closed loop; where boundaries touch at a vertex, the touching loops count once).
//   - Non-manifold vertex: on a non-manifold edge, or whose faces form two or more fans (sets
//     connected through edges at that vertex used by exactly two faces) — e.g. a bowtie's centre.
//   - Orientable: the faces of the component can be flipped so that every edge in two faces is
//     traversed once in each direction. Consistently oriented: that holds without flipping.
//   - Genus of a component: for a manifold (no non-manifold edge or vertex), orientable
//     component, g = (2 - chi - b) / 2 with b its boundary loops (0 when closed); -1 otherwise.
//     The mesh's genus is the sum over components when every component has one, else -1.
#pragma once

#include <nlohmann/json.hpp>

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace imr::eval {

struct ComponentStatistics {
  int64_t vertices = 0;        // used vertices in this component
  int64_t edges = 0;
  int64_t faces = 0;
  int64_t euler_characteristic = 0;  // vertices - edges + faces
  int64_t boundary_edges = 0;
  int64_t boundary_loops = 0;
  int64_t nonmanifold_edges = 0;
  int64_t nonmanifold_vertices = 0;
  bool manifold = false;               // no non-manifold edge or vertex
  bool closed = false;                 // no boundary edge
  bool orientable = false;
  bool consistently_oriented = false;  // orientable without flipping any face
  int64_t genus = -1;                  // -1 when not a manifold orientable surface
  double area = 0.0;
};

struct MeshStatistics {
  int64_t vertices = 0;            // as given
  int64_t used_vertices = 0;       // V: used by a valid face
  int64_t unused_vertices = 0;
  int64_t faces = 0;               // as given
  int64_t degenerate_faces = 0;    // a repeated vertex index; ignored below
  int64_t edges = 0;               // E
  int64_t euler_characteristic = 0;  // V - E + F (F = faces - degenerate_faces)
  int64_t components = 0;          // connected through shared vertices
  int64_t boundary_edges = 0;
  int64_t boundary_loops = 0;
  int64_t nonmanifold_edges = 0;
  int64_t nonmanifold_vertices = 0;
  bool manifold = false;               // every component manifold
  bool closed = false;                 // no boundary edge
  bool orientable = false;             // every component orientable
  bool consistently_oriented = false;  // every component, as given
  int64_t genus = -1;                  // sum over components; -1 when some has none
  double area = 0.0;
  // Axis-aligned bounding box of the used vertices; both zero when there are none.
  std::array<double, 3> bbox_min{};
  std::array<double, 3> bbox_max{};
  // Per component, largest first (by faces, then by smallest vertex index).
  std::vector<ComponentStatistics> component_list;

  // The report's "mesh_stats" object: every field above, and the `max_components` largest
  // components (with "components_listed"), so a mesh of 10^5 specks keeps a small report.
  nlohmann::json ToJson(std::size_t max_components = 10) const;
};

// Statistics of `vertex_count` vertices (packed xyz, 3 doubles each) and `face_count` triangles
// (3 indices each). Throws std::invalid_argument naming the face when an index is out of range.
// O((V + F) log F).
MeshStatistics ComputeMeshStatistics(const double* xyz, std::size_t vertex_count,
                                     const uint32_t* faces, std::size_t face_count);

// The same on packed vectors (engine::Mesh's layout). Throws std::invalid_argument when a size
// is not a multiple of 3.
MeshStatistics ComputeMeshStatistics(const std::vector<double>& xyz,
                                     const std::vector<uint32_t>& faces);

}  // namespace imr::eval
