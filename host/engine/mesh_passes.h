// The passes over an exported surface (engine.retriangulate_planes, flip_edges, filter_normals),
// in that order, mesh_pass_rounds times, on a whole mesh, each undone when the mesh is no manifold
// after it (no CGAL here). A streamed run applies the same passes per released piece (host/pipeline/
// streamed_surface.cc), where a piece that no longer meets its neighbours is written as it came.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "host/engine/edge_flips.h"
#include "host/engine/engine.h"
#include "host/engine/normal_filter.h"
#include "host/engine/plane_retriangulation.h"

namespace imr::engine {

// One pass: changes the mesh in place; true when it changed anything.
struct MeshPass {
  std::string name;  // the engine option that asks for it, for warnings and the report
  bool moves_vertices = true, changes_faces = true;  // what is kept aside to undo it
  std::function<bool(Mesh*)> run;
  std::function<void()> undone;  // its figures forgotten (may be empty)
};

struct MeshPassesStats {
  PlaneRetriangulationStats planes;
  EdgeFlipStats flips;
  NormalFilterStats normal_filter;
  int64_t undone = 0;       // passes undone: the mesh was no manifold after them
  std::string undone_why;   // the first one's name and the check's message
};

// The figures of one more round of a pass on the same mesh or piece (EngineOptions::
// mesh_pass_rounds): counts add; the angles are the mesh's before the first round and after this.
void AddRound(PlaneRetriangulationStats* total, const PlaneRetriangulationStats& round);
void AddRound(EdgeFlipStats* total, const EdgeFlipStats& round);
void AddRound(NormalFilterStats* total, const NormalFilterStats& round);

// The passes the engine options ask for, mesh_pass_rounds times in turn, their figures into
// `stats` (a pass undone: as they were before it).
std::vector<MeshPass> MeshPasses(const EngineOptions& options, MeshPassesStats* stats);

// Runs `passes` on `mesh` in order. A pass that changed the mesh and left it no manifold (a case
// its own rules missed) is undone, the mesh as before it, and `warn` (may be empty) told why;
// the next passes run on that. `check` is CheckMesh's result (open allowed) on the mesh as it
// stands: given for the mesh before the passes, measured again after each pass that changed it.
void RunMeshPasses(const std::vector<MeshPass>& passes, Mesh* mesh, MeshPassesStats* stats,
                   ManifoldCheckResult* check,
                   const std::function<void(const std::string&)>& warn = {});

}  // namespace imr::engine
