// The surface as the engine hands it out (no CGAL here): what ExtractMesh does after the Steiner
// filter, and the union of a run's SurfaceParts (DESIGN.md section 10: parts share their seam
// vertices by key).
#include <string>
#include <unordered_map>

#include "host/engine/engine.h"
#include "host/engine/mesh_topology.h"

namespace imr::engine {

void FinishExportedMesh(Mesh* m, const EngineOptions& o, DroppedComponents* dropped) {
  if (o.steiner_export == SteinerExportRule::kOpenSteiner)
    DropOpenSteinerRegions(m, o.open_steiner_crease);
  if (o.steiner_export != SteinerExportRule::kNone) SplitPinchedVertices(m);
  CanonicalizeMesh(m);
  if (o.fill_holes_perimeter > 0.0 || o.smoothing_iterations > 0) {
    FillSmallHoles(m, o.fill_holes_perimeter);
    SmoothTaubin(m, o.smoothing_iterations);
    CanonicalizeMesh(m);
  }
  // Last, on the finished pieces (a filled hole adds to its piece's area), as SurfaceStream
  // weighs them; dropping whole components keeps the canonical order of the rest.
  DropSmallComponents(m, o.MinComponentArea(), dropped);
}

std::string MergeSurfaceParts(const std::vector<SurfacePart>& parts, Mesh* merged) {
  *merged = Mesh();
  std::unordered_map<int64_t, uint32_t> index;  // key -> vertex of `merged`
  for (size_t p = 0; p < parts.size(); ++p) {
    const SurfacePart& part = parts[p];
    const size_t nv = part.keys.size();
    if (part.vertices.size() != 3 * nv || part.point_ids.size() != nv)
      return "part " + std::to_string(p) + ": vertices, keys and point ids differ in number";
    std::vector<uint32_t> local(nv);
    for (size_t i = 0; i < nv; ++i) {
      const auto [it, inserted] =
          index.emplace(part.keys[i], static_cast<uint32_t>(merged->point_ids.size()));
      if (inserted) {
        merged->vertices.insert(merged->vertices.end(), &part.vertices[3 * i],
                                &part.vertices[3 * i] + 3);
        merged->point_ids.push_back(part.point_ids[i]);
      } else {
        const double* a = &merged->vertices[3 * size_t{it->second}];
        const double* b = &part.vertices[3 * i];
        if (a[0] != b[0] || a[1] != b[1] || a[2] != b[2] ||
            merged->point_ids[it->second] != part.point_ids[i])
          return "part " + std::to_string(p) + ": vertex key " + std::to_string(part.keys[i]) +
                 " is not where an earlier part put it";
      }
      local[i] = it->second;
    }
    for (uint32_t f : part.faces) {
      if (f >= nv) return "part " + std::to_string(p) + ": a face index is out of range";
      merged->faces.push_back(local[f]);
    }
  }
  return "";
}

}  // namespace imr::engine
