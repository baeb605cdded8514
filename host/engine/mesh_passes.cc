#include "host/engine/mesh_passes.h"

#include <algorithm>
#include <memory>
#include <string>
#include <utility>

namespace imr::engine {

namespace {

// The figures of a later round of a pass on the same mesh: its counts add; the angles are the
// mesh's before the first round that ran and after this one (the same edges: a pass keeps the
// vertices and the boundary, so a triangulation of them has as many edges).
template <class Stats>
void AddAngles(Stats* total, const Stats& round) {
  if (total->edges == 0) {
    *total = round;
    return;
  }
  const double before = total->degrees_sum_before;
  *total += round;
  total->edges = round.edges;
  total->degrees_sum_before = before;
  total->degrees_sum_after = round.degrees_sum_after;
}

}  // namespace

void AddRound(PlaneRetriangulationStats* total, const PlaneRetriangulationStats& round) { *total += round; }
void AddRound(EdgeFlipStats* total, const EdgeFlipStats& round) { AddAngles(total, round); }
void AddRound(NormalFilterStats* total, const NormalFilterStats& round) { AddAngles(total, round); }

namespace {

// A pass whose figures go to stats->*field: added over the rounds (AddRound), as they were
// before it when it is undone. `changed` says from its figures whether it changed the mesh.
template <class Stats, class Run, class Changed>
MeshPass Pass(std::string name, bool moves_vertices, bool changes_faces, MeshPassesStats* stats,
              Stats MeshPassesStats::*field, Run run, Changed changed) {
  auto kept = std::make_shared<Stats>();
  return {std::move(name), moves_vertices, changes_faces,
          [stats, field, kept, run, changed](Mesh* m) {
            *kept = stats->*field;
            const Stats s = run(m);
            AddRound(&(stats->*field), s);
            return changed(s);
          },
          [stats, field, kept] { stats->*field = *kept; }};
}

}  // namespace

std::vector<MeshPass> MeshPasses(const EngineOptions& options, MeshPassesStats* stats) {
  std::vector<MeshPass> passes;
  const auto planes = PlaneRetriangulationOptions::FromEngine(options);
  const auto flips = EdgeFlipOptions::FromEngine(options);
  const auto normals = NormalFilterOptions::FromEngine(options);
  for (int round = 1; round <= std::max(1, options.mesh_pass_rounds); ++round) {
    const std::string suffix = round == 1 ? "" : " (round " + std::to_string(round) + ")";
    if (planes.enabled())
      passes.push_back(Pass(
          "engine.retriangulate_planes" + suffix, true, true, stats, &MeshPassesStats::planes,
          [planes](Mesh* m) { return RetriangulatePlanes(m, planes); },
          [](const PlaneRetriangulationStats& s) { return s.regions > 0; }));
    if (flips.enabled)
      passes.push_back(Pass(
          "engine.flip_edges" + suffix, false, true, stats, &MeshPassesStats::flips,
          [flips](Mesh* m) { return FlipEdges(m, flips); }, [](const EdgeFlipStats& s) { return s.flips > 0; }));
    if (normals.enabled())
      passes.push_back(Pass(
          "engine.filter_normals" + suffix, true, false, stats, &MeshPassesStats::normal_filter,
          [normals](Mesh* m) { return FilterNormals(m, normals); },
          [](const NormalFilterStats& s) { return s.vertices_moved > 0; }));
  }
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
