// Canonical order for meshes the engine returns (no CGAL here). CGAL's cell storage order differs
// between processes, so without this two runs of the same job write the same surface in a
// different order and their files differ byte for byte.
#include <algorithm>
#include <array>
#include <numeric>
#include <tuple>

#include "host/engine/engine.h"

namespace imr::engine {
namespace {

// A vertex's identity independent of storage: its point id, then its position.
using VertexKey = std::tuple<int64_t, double, double, double>;

VertexKey KeyOf(const Mesh& m, uint32_t v) {
  return {m.point_ids.empty() ? 0 : m.point_ids[v], m.vertices[3 * v], m.vertices[3 * v + 1],
          m.vertices[3 * v + 2]};
}

}  // namespace

void CanonicalizeMesh(Mesh* m, std::vector<uint32_t>* new_index) {
  const size_t nf = m->faces.size() / 3;
  const size_t nv = m->vertices.size() / 3;
  // Rotate each face so its smallest vertex comes first (orientation kept).
  std::vector<std::array<uint32_t, 3>> faces(nf);
  for (size_t f = 0; f < nf; ++f) {
    std::array<uint32_t, 3> t = {m->faces[3 * f], m->faces[3 * f + 1], m->faces[3 * f + 2]};
    int first = 0;
    for (int k = 1; k < 3; ++k)
      if (KeyOf(*m, t[k]) < KeyOf(*m, t[first])) first = k;
    std::rotate(t.begin(), t.begin() + first, t.end());
    faces[f] = t;
  }
  // Order faces by their vertices' keys. Split copies of a pinched vertex share a key, but two
  // faces of a manifold never share all three keys, so the order is total.
  std::vector<size_t> order(nf);
  std::iota(order.begin(), order.end(), 0);
  auto face_key = [&](size_t f) {
    return std::array<VertexKey, 3>{KeyOf(*m, faces[f][0]), KeyOf(*m, faces[f][1]),
                                    KeyOf(*m, faces[f][2])};
  };
  std::vector<std::array<VertexKey, 3>> keys(nf);
  for (size_t f = 0; f < nf; ++f) keys[f] = face_key(f);
  std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) { return keys[a] < keys[b]; });
  // Number vertices by first use in that face order; unused vertices (none expected) last.
  constexpr uint32_t kUnset = ~0u;
  std::vector<uint32_t> remap(nv, kUnset);
  uint32_t next = 0;
  Mesh out;
  out.faces.reserve(m->faces.size());
  for (size_t f : order)
    for (uint32_t v : faces[f]) {
      if (remap[v] == kUnset) remap[v] = next++;
      out.faces.push_back(remap[v]);
    }
  for (uint32_t v = 0; v < nv; ++v)
    if (remap[v] == kUnset) remap[v] = next++;
  out.vertices.resize(m->vertices.size());
  out.point_ids.resize(m->point_ids.size());
  for (uint32_t v = 0; v < nv; ++v) {
    std::copy_n(&m->vertices[3 * v], 3, &out.vertices[3 * remap[v]]);
    if (!m->point_ids.empty()) out.point_ids[remap[v]] = m->point_ids[v];
  }
  *m = std::move(out);
  if (new_index != nullptr) *new_index = std::move(remap);
}

}  // namespace imr::engine
