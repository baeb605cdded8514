// Test support: a closed dO (Engine::ExtractBoundary) cut into SurfaceParts with exactly the
// engine's semantics (engine.h, SurfacePart): every triangle of dO is handed out once, in chunks;
// a part holds its chunk's triangles that pass the Steiner rule; a vertex is completed by the
// part whose chunk holds the last triangle of the closed dO around it (filtered or not), when
// some part named it.
#pragma once

#include <algorithm>
#include <cstdint>
#include <numeric>
#include <random>
#include <unordered_map>
#include <vector>

#include "host/engine/engine.h"

namespace imr::engine::testing {

enum class CutOrder {
  kAlongY,     // triangles sorted by their centroid's y (the synthetic street's drive)
  kAlongX,
  kBackward,   // along y, from the far end
  kShuffled,   // no order at all: every part touches the whole surface
};

inline bool KeptBySteinerRule(const Mesh& m, std::size_t f, SteinerExportRule rule) {
  int steiner = 0;
  for (int k = 0; k < 3; ++k) steiner += m.point_ids[m.faces[3 * f + k]] < 0 ? 1 : 0;
  if (rule == SteinerExportRule::kAllSteiner || rule == SteinerExportRule::kOpenSteiner)
    return steiner < 3;
  if (rule == SteinerExportRule::kAnySteiner) return steiner == 0;
  return true;
}

// `boundary` closed; keys are its vertex indices.
inline std::vector<SurfacePart> SliceIntoParts(const Mesh& boundary, SteinerExportRule rule,
                                               int parts, CutOrder order, uint32_t seed = 1) {
  const std::size_t nf = boundary.faces.size() / 3, nv = boundary.point_ids.size();
  std::vector<std::size_t> faces(nf);
  std::iota(faces.begin(), faces.end(), 0);
  auto centroid = [&](std::size_t f, int axis) {
    double s = 0.0;
    for (int k = 0; k < 3; ++k) s += boundary.vertices[3 * boundary.faces[3 * f + k] + axis];
    return s;
  };
  if (order == CutOrder::kShuffled) {
    std::mt19937 rng(seed);
    std::shuffle(faces.begin(), faces.end(), rng);
  } else {
    const int axis = order == CutOrder::kAlongX ? 0 : 1;
    const double sign = order == CutOrder::kBackward ? -1.0 : 1.0;
    std::stable_sort(faces.begin(), faces.end(), [&](std::size_t a, std::size_t b) {
      return sign * centroid(a, axis) < sign * centroid(b, axis);
    });
  }
  auto chunk_of = [&](std::size_t rank) { return static_cast<int>(rank * parts / nf); };
  std::vector<int> last(nv, -1);
  for (std::size_t r = 0; r < nf; ++r)
    for (int k = 0; k < 3; ++k) {
      int& l = last[boundary.faces[3 * faces[r] + k]];
      l = std::max(l, chunk_of(r));
    }
  std::vector<SurfacePart> out(static_cast<std::size_t>(parts));
  std::vector<char> named(nv, 0);
  std::vector<std::vector<uint32_t>> completes_at(static_cast<std::size_t>(parts));
  for (uint32_t v = 0; v < nv; ++v)
    if (last[v] >= 0) completes_at[static_cast<std::size_t>(last[v])].push_back(v);
  std::size_t r = 0;
  for (int c = 0; c < parts; ++c) {
    SurfacePart& p = out[static_cast<std::size_t>(c)];
    p.update = c;
    std::unordered_map<uint32_t, uint32_t> local;
    for (; r < nf && chunk_of(r) == c; ++r) {
      const std::size_t f = faces[r];
      if (!KeptBySteinerRule(boundary, f, rule)) continue;
      for (int k = 0; k < 3; ++k) {
        const uint32_t v = boundary.faces[3 * f + k];
        const auto [it, fresh] = local.emplace(v, static_cast<uint32_t>(p.keys.size()));
        if (fresh) {
          p.keys.push_back(v);
          p.point_ids.push_back(boundary.point_ids[v]);
          p.vertices.insert(p.vertices.end(), &boundary.vertices[3 * v], &boundary.vertices[3 * v] + 3);
          named[v] = 1;
        }
        p.faces.push_back(it->second);
      }
    }
    for (uint32_t v : completes_at[static_cast<std::size_t>(c)])
      if (named[v]) p.completed.push_back(v);
  }
  return out;
}

}  // namespace imr::engine::testing
