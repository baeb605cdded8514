// The surface: dO as a mesh (ExtractMesh, ExtractBoundary) or handed out in parts (SurfacePart:
// forget's steps, then FinishSurface), its triangles through the Steiner filter in a canonical
// order.
#include "host/engine/engine_parts.h"

namespace imr::engine {
namespace detail {

// dO: facets between a cell of O and a cell outside O, oriented toward the O cell (free space).
std::vector<Triangle> Boundary(const EngineState& s, bool live) {
  std::vector<Triangle> out;
  for (auto c = s.dt.finite_cells_begin(); c != s.dt.finite_cells_end(); ++c) {
    if (!c->info().in_o) continue;
    for (int i = 0; i < 4; ++i) {
      if (c->neighbor(i)->info().in_o) continue;
      if (live && c->info().final && c->neighbor(i)->info().final) continue;
      // vertex_triple_index(i, .) orders facet i so that its normal points toward vertex i,
      // i.e. into this cell of O.
      out.push_back({{c->vertex(Dt::vertex_triple_index(i, 0)),
                      c->vertex(Dt::vertex_triple_index(i, 1)),
                      c->vertex(Dt::vertex_triple_index(i, 2))}});
    }
  }
  return out;
}

// Whether triangle t of dO stays under `rule`'s per-triangle filter (open_steiner's regions go
// later, in FinishExportedMesh).
static bool PassesSteinerRule(const Triangle& t, SteinerExportRule rule) {
  int steiner_vertices = 0;
  for (Vertex_handle v : t.v) steiner_vertices += v->info().id < 0 ? 1 : 0;
  switch (rule) {
    case SteinerExportRule::kNone: return true;
    case SteinerExportRule::kAllSteiner:
    case SteinerExportRule::kOpenSteiner: return steiner_vertices < 3;
    case SteinerExportRule::kAnySteiner: return steiner_vertices == 0;
  }
  return true;
}

}  // namespace detail

using detail::Boundary;
using detail::PassesSteinerRule;
using detail::Clock;
using detail::Triangle;

Mesh Engine::Impl::ToMesh(const std::vector<Triangle>& tris, SteinerExportRule rule) const {
  Mesh m;
  std::unordered_map<Vertex_handle, uint32_t> index;
  for (const Triangle& t : tris) {
    if (!PassesSteinerRule(t, rule)) continue;
    for (Vertex_handle v : t.v) {
      auto [it, inserted] = index.emplace(v, static_cast<uint32_t>(index.size()));
      if (inserted) {
        const Point& p = v->point();
        m.vertices.insert(m.vertices.end(), {p.x(), p.y(), p.z()});
        const int64_t id = v->info().id;
        m.point_ids.push_back(id >= 0 ? static_cast<int64_t>(s.points[id].id) : -1);
      }
      m.faces.push_back(it->second);
    }
  }
  CanonicalizeMesh(&m);
  return m;
}

// The triangles as a SurfacePart: through the Steiner filter, in a canonical order (the vertices'
// internal ids, which do not depend on CGAL's storage: the same part for any number of threads),
// each vertex with its key (given here when the vertex is named for the first time).
SurfacePart Engine::Impl::MakePart(std::vector<Triangle> tris) {
  const SteinerExportRule rule = s.opt.steiner_export;
  using Ids = std::array<int64_t, 3>;
  std::vector<std::pair<Ids, Triangle>> kept;
  kept.reserve(tris.size());
  for (const Triangle& t : tris) {
    if (!PassesSteinerRule(t, rule)) continue;
    // Rotated to start at its smallest id, orientation kept.
    int first = 0;
    for (int k = 1; k < 3; ++k)
      if (t.v[k]->info().id < t.v[first]->info().id) first = k;
    Triangle r;
    for (int k = 0; k < 3; ++k) r.v[k] = t.v[(first + k) % 3];
    kept.push_back({{r.v[0]->info().id, r.v[1]->info().id, r.v[2]->info().id}, r});
  }
  std::sort(kept.begin(), kept.end(),
            [](const auto& a, const auto& b) { return a.first < b.first; });
  SurfacePart part;
  part.update = s.stats.updates;
  std::unordered_map<Vertex_handle, uint32_t> index;
  for (const auto& [ids, t] : kept)
    for (Vertex_handle v : t.v) {
      auto [it, inserted] = index.emplace(v, static_cast<uint32_t>(index.size()));
      if (inserted) {
        const Point& p = v->point();
        part.vertices.insert(part.vertices.end(), {p.x(), p.y(), p.z()});
        if (v->info().key < 0) v->info().key = next_key_++;
        part.keys.push_back(v->info().key);
        const int64_t id = v->info().id;
        part.point_ids.push_back(id >= 0 ? static_cast<int64_t>(s.points[id].id) : -1);
      }
      part.faces.push_back(it->second);
    }
  return part;
}

// A facet of dO between two final cells was handed out when the second became final (or, next
// to a forgotten cell, lies where forgotten vertices were: never a surface).
std::vector<Triangle> Engine::Impl::LiveBoundary() const { return Boundary(s, /*live=*/true); }

std::vector<SurfacePart> Engine::TakeFinalParts() {
  std::vector<SurfacePart> out;
  out.swap(impl_->final_parts_);
  return out;
}

SurfacePart Engine::FinishSurface() {
  Impl& m = *impl_;
  SurfacePart part = m.MakePart(m.LiveBoundary());
  // Every vertex named so far and not completed by a step is complete now, this part's too.
  for (auto v = m.s.dt.finite_vertices_begin(); v != m.s.dt.finite_vertices_end(); ++v)
    if (v->info().key >= 0 && !v->info().deep) part.completed.push_back(v->info().key);
  std::sort(part.completed.begin(), part.completed.end());
  ++m.s.stats.parts;
  m.s.stats.part_triangles += static_cast<int64_t>(part.faces.size() / 3);
  return part;
}

SurfacePart Engine::LiveSurface() { return impl_->MakePart(impl_->LiveBoundary()); }

Mesh Engine::ExtractMesh(DroppedComponents* dropped) const {
  const auto t0 = Clock::now();
  Mesh m = impl_->ToMesh(impl_->LiveBoundary(), impl_->s.opt.steiner_export);
  FinishExportedMesh(&m, impl_->s.opt, dropped);
  impl_->s.stats.time.extract += SecondsSince(t0);
  return m;
}

Mesh Engine::ExtractBoundary() const {
  return impl_->ToMesh(Boundary(impl_->s), SteinerExportRule::kNone);
}

}  // namespace imr::engine
