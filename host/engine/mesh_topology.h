// Mesh topology without CGAL: making a surface cut from a closed 2-manifold a 2-manifold with
// boundary again. CheckMesh, the matching test, is declared in engine.h.
#pragma once

#include "host/engine/engine.h"

#include <cstddef>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace imr::engine {

// Half the length of (b - a) x (c - a): the one area both DropSmallComponents and SurfaceStream
// sum, so the whole mesh and the stream weigh a piece alike.
double TriangleArea(const double* a, const double* b, const double* c);

// After dropping triangles from a closed 2-manifold, a vertex may keep several separate fans;
// give each extra fan its own copy of the vertex so the result is a 2-manifold with boundary.
void SplitPinchedVertices(Mesh* m);

// CheckMesh as first written (node-based maps, ~0.2 kB per face): what CheckMesh falls back on
// for a mesh its lean pass finds wrong, so the first message stays the same; for tests.
ManifoldCheckResult CheckMeshReference(const Mesh& mesh, bool closed);

// The link of one vertex: per triangle at it, in triangle order, the opposite edge (b, c) of
// the triangle (v, b, c). One fan is one cycle (an interior vertex) or one path (on the boundary)
// of consistently oriented edges. `by_first` and `seconds` are scratch space.
enum class LinkShape { kCycle, kPath, kNotOneFan };
LinkShape CheckLink(const std::pair<uint32_t, uint32_t>* link, std::size_t n,
                    std::vector<std::pair<uint32_t, uint32_t>>* by_first,
                    std::vector<uint32_t>* seconds);

// The faces at each vertex of `faces` (3 indices each, below `vertex_count`), in face order:
// those at v are fan[start[v]] .. fan[start[v + 1] - 1] (compressed rows).
void VertexFans(const std::vector<uint32_t>& faces, std::size_t vertex_count, std::vector<uint32_t>* start,
                std::vector<uint32_t>* fan);

// Per vertex, 1 when its faces (VertexFans' rows) make one closed cycle of consistently
// oriented faces around it (an inner vertex of a manifold: it may move), else 0.
std::vector<uint8_t> ClosedFans(const std::vector<uint32_t>& faces, const std::vector<uint32_t>& start,
                                const std::vector<uint32_t>& fan);

// Whether the faces `after` may stand in for `before` (triangles over the same `vertex_count`
// vertices, e.g. a part of a streamed surface that a pass changed in place) wherever they meet
// faces not given: every vertex's link the same open paths (their ends, the part's open edges at
// the vertex) and as many closed cycles, no neighbour twice. Empty when so, else the first vertex
// that differs and how.
std::string SameVertexLinks(const std::vector<uint32_t>& before, const std::vector<uint32_t>& after,
                            std::size_t vertex_count);

}  // namespace imr::engine
