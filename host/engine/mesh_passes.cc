#include "host/engine/mesh_passes.h"

#include <utility>

namespace imr::engine {

std::vector<MeshPass> MeshPasses(const EngineOptions& options, MeshPassesStats* stats) {
  std::vector<MeshPass> passes;
  const auto planes = PlaneRetriangulationOptions::FromEngine(options);
  if (planes.enabled())
    passes.push_back({"engine.retriangulate_planes", true, true,
                      [planes, stats](Mesh* m) {
                        stats->planes = RetriangulatePlanes(m, planes);
                        return stats->planes.regions > 0;
                      },
                      [stats] { stats->planes = {}; }});
  const auto flips = EdgeFlipOptions::FromEngine(options);
  if (flips.enabled)
    passes.push_back({"engine.flip_edges", false, true,
                      [flips, stats](Mesh* m) {
                        stats->flips = FlipEdges(m, flips);
                        return stats->flips.flips > 0;
                      },
                      [stats] { stats->flips = {}; }});
  const auto normals = NormalFilterOptions::FromEngine(options);
  if (normals.enabled())
    passes.push_back({"engine.filter_normals", true, false,
                      [normals, stats](Mesh* m) {
                        stats->normal_filter = FilterNormals(m, normals);
                        return stats->normal_filter.vertices_moved > 0;
                      },
                      [stats] { stats->normal_filter = {}; }});
  return passes;
}

void RunMeshPasses(const std::vector<MeshPass>& passes, Mesh* mesh, MeshPassesStats* stats,
                   ManifoldCheckResult* check,
                   const std::function<void(const std::string&)>& warn) {
  for (const MeshPass& pass : passes) {
    std::vector<double> xyz;
    std::vector<uint32_t> faces;
    if (pass.moves_vertices) xyz = mesh->vertices;
    if (pass.changes_faces) faces = mesh->faces;
    if (!pass.run(mesh)) continue;
    ManifoldCheckResult after = CheckMesh(*mesh, /*closed=*/false);
    if (after.ok) {
      *check = std::move(after);
      continue;
    }
    if (warn) warn(pass.name + " undone: the mesh was no manifold after it (" + after.message + ")");
    if (stats->undone++ == 0) stats->undone_why = pass.name + ": " + after.message;
    if (pass.undone) pass.undone();
    if (pass.moves_vertices) mesh->vertices.swap(xyz);
    if (pass.changes_faces) mesh->faces.swap(faces);
  }
}

}  // namespace imr::engine
