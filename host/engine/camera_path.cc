// The camera path (EngineOptions::camera_path): the space the cameras moved through is free, so
// its cells join O even where no ray crossed them (Carving::OpenPath, with the fewest free cells
// around that keep dO manifold), before grow and again after; a camera whose cell is still
// outside O has O peeled around it and grown again from its cell. With forget, the cell where the
// cameras come back to forgotten space starts a component of O (CameraCell).
#include "host/engine/engine_parts.h"

namespace imr::engine {
namespace detail {

bool Carving::AddWithRepair(Cell_handle c, std::vector<Cell_handle>* added) {
  const size_t start = added->size();
  auto add = [&](Cell_handle x) {
    SetInO(x, true);
    added->push_back(x);
  };
  auto addable = [&](Cell_handle x) {
    return !s_.dt.is_infinite(x) && !x->info().in_o && !x->info().final && !s_.HullAdjacent(x);
  };
  if (!addable(c)) return false;
  add(c);
  std::vector<Vertex_handle> verts;
  std::vector<Cell_handle> star;
  for (int round = 0;; ++round) {
    verts.clear();
    for (size_t k = start; k < added->size(); ++k)
      for (int i = 0; i < 4; ++i) verts.push_back((*added)[k]->vertex(i));
    // By id, not address: which irregular vertex is repaired first decides what joins O.
    std::sort(verts.begin(), verts.end(), EngineState::ById);
    verts.erase(std::unique(verts.begin(), verts.end()), verts.end());
    Vertex_handle bad;
    for (Vertex_handle v : verts)
      if (!VertexRegular(v, Cell_handle())) {
        bad = v;
        break;
      }
    if (bad == Vertex_handle()) break;
    // The free cells around the irregular vertex join O; none left, or out of rounds: undo.
    star.clear();
    s_.dt.incident_cells(bad, std::back_inserter(star));
    size_t joined = 0;
    for (Cell_handle x : star)
      if (addable(x) && s_.IsFree(x)) add(x), ++joined;
    if (joined == 0) {
      // Only cells that no ray crossed are left around it: when they are few, a pocket of matter
      // in free space that no ray happened to cross, they join and the vertex is inside O.
      size_t rest = 0, blocked = 0;
      for (Cell_handle x : star)
        if (!x->info().in_o) ++rest, blocked += addable(x) ? 0 : 1;
      if (blocked == 0 && rest * 8 <= star.size())
        for (Cell_handle x : star)
          if (!x->info().in_o) add(x), ++joined;
    }
    if (joined == 0 || round >= s_.opt.camera_path_repair) {
      for (size_t k = added->size(); k-- > start;) SetInO((*added)[k], false);
      added->resize(start);
      return false;
    }
  }
  return true;
}

bool Carving::ForceCell(Cell_handle c) {
  std::vector<Cell_handle> added;
  bool ok = false;
  if (s_.TouchesO(c)) {
    ok = AddWithRepair(c, &added);
  } else if (ToggleKeepsManifold(c)) {  // a component of O of its own until grow joins it
    SetInO(c, true);
    added.push_back(c);
    ok = true;
  }
  SeedAround(added);
  return ok;
}

void Carving::SeedAround(const std::vector<Cell_handle>& added) {
  for (Cell_handle x : added) {
    s_.MarkDirty(x);
    for (int i = 0; i < 4; ++i) s_.MarkDirty(x->neighbor(i));
  }
}

int64_t Carving::OpenPath(const std::vector<Cell_handle>& path) {
  std::vector<Cell_handle> added;
  // Outward from the cells of the path that touch O: a pass adds those it can; again while any did.
  for (bool progress = true; progress;) {
    progress = false;
    for (Cell_handle c : path)
      if (!c->info().in_o && s_.TouchesO(c) && AddWithRepair(c, &added)) progress = true;
  }
  SeedAround(added);
  s_.stats.cells_opened += static_cast<int64_t>(added.size());
  return static_cast<int64_t>(added.size());
}

}  // namespace detail

using detail::Dt;

// The cell holding the newest camera when the cameras are back where they were long ago
// (Forgetting::Returned) and no cell of O lies within two grid steps of it: the O that was there
// is forgotten, and O must start there again.
Engine::Impl::Cell_handle Engine::Impl::CameraCell() {
  if (s.cameras.empty() || s.dt.dimension() != 3 || s.cells_in_o == 0 || !forgetting.Returned())
    return Cell_handle();
  const Point& camera = s.cameras.back();
  Dt::Locate_type lt;
  int li, lj;
  const Cell_handle c = s.dt.locate(camera, lt, li, lj, s.WalkHint());
  if (lt != Dt::CELL || s.dt.is_infinite(c) || c->info().in_o) return Cell_handle();
  const double r = 2.0 * s.opt.steiner_spacing;
  const uint64_t seen = ++s.stamp;  // stamps are only compared for equality
  std::vector<Cell_handle> todo = {c};
  c->info().stamp = seen;
  for (size_t i = 0; i < todo.size(); ++i) {
    for (int k = 0; k < 4; ++k) {
      const Cell_handle n = todo[i]->neighbor(k);
      if (n->info().stamp == seen || s.dt.is_infinite(n)) continue;
      n->info().stamp = seen;
      if (n->info().in_o) return Cell_handle();
      if (CGAL::squared_distance(s.Centroid(n), camera) <= r * r) todo.push_back(n);
    }
  }
  return c;
}

std::vector<Engine::Impl::Cell_handle> Engine::Impl::CameraPathCells() {
  std::vector<Cell_handle> path;
  const size_t n = s.cameras.size();
  const size_t k = std::min(n, static_cast<size_t>(s.opt.camera_path));
  const uint64_t seen = ++s.stamp;  // stamps are only compared for equality
  Cell_handle hint = s.WalkHint();
  auto visit = [&](const Point& p) {
    const Cell_handle c = s.dt.locate(p, hint);
    if (s.dt.is_infinite(c)) return;
    hint = c;
    if (c->info().stamp == seen) return;
    c->info().stamp = seen;
    path.push_back(c);
  };
  // Samples a tenth of the Steiner spacing apart (cells along the path are larger: the Steiner
  // grid keeps points around the cameras that far apart), at most 256 per segment.
  const double step = s.opt.steiner_spacing > 0.0 ? s.opt.steiner_spacing / 10.0 : 0.5;
  for (size_t i = n - k; i < n; ++i) {
    const Point& b = s.cameras[i];
    if (i > n - k) {
      const Point& a = s.cameras[i - 1];
      const double len = std::sqrt(CGAL::squared_distance(a, b));
      const int samples = static_cast<int>(std::min(256.0, std::ceil(len / step)));
      for (int j = 1; j < samples; ++j) {
        const double t = static_cast<double>(j) / samples;
        visit(Point(a.x() + t * (b.x() - a.x()), a.y() + t * (b.y() - a.y()),
                    a.z() + t * (b.z() - a.z())));
      }
    }
    visit(b);
  }
  return path;
}

void Engine::Impl::OpenCameraPath(const std::vector<Cell_handle>& path) {
  if (carving.OpenPath(path) > 0) carving.Grow();
  if (s.opt.camera_path_radius <= 0.0) return;
  const size_t n = s.cameras.size();
  const size_t k = std::min(n, static_cast<size_t>(s.opt.camera_path));
  std::vector<Vertex_handle> around;
  for (size_t i = n - k; i < n; ++i) {
    const Cell_handle c = s.dt.locate(s.cameras[i], s.WalkHint());
    if (s.dt.is_infinite(c) || c->info().in_o || c->info().final || s.HullAdjacent(c)) continue;
    // Its cell could not join O as O is around it: O leaves the cells near it, its cell joins
    // first (touching O, with the free cells that keep dO manifold; else on its own) and O grows
    // again into the rest in weight order.
    // By id: PeelAround's region depends on the order of its centres, and a cell's vertex order
    // on the cell's history (CGAL's moves and the planned ones make the same cell differently).
    around.clear();
    for (int j = 0; j < 4; ++j) around.push_back(c->vertex(j));
    std::sort(around.begin(), around.end(), detail::EngineState::ById);
    carving.PeelAround(around, s.opt.camera_path_radius);
    carving.ForceCell(c);
    carving.Grow();  // labels only change: c is still a cell
    ++s.stats.camera_regrowths;
    if (c->info().in_o) ++s.stats.camera_cells_regrown;
  }
}

}  // namespace imr::engine
