// Edge-length subdivision for the photometric refinement: a triangle spanning metres between
// sparse points cannot bend to the surface the images show, its new vertices can. Every edge
// longer than a bound is split at its midpoint (the same new vertex for both its faces), and each
// face is re-triangulated by how many of its edges were split (1: two triangles, 2: three, 3:
// four), so a 2-manifold stays one, with the same boundary loops and orientation.
#pragma once

#include <Eigen/Core>

#include <array>
#include <cstdint>
#include <vector>

namespace imr::photometric {

struct SubdivisionStats {
  int64_t edges_split = 0;
  int64_t faces_before = 0;
  int64_t faces_after = 0;
};

// Splits every edge longer than `max_edge` whose two ends are both `eligible` (an empty
// `eligible`: all), repeating `rounds` times (each round halves the long edges again). New
// vertices are appended to `vertices` (each the midpoint of its edge) and to `eligible` (as
// eligible); `faces` is replaced. A face's corners keep their order (orientation kept).
SubdivisionStats SubdivideLongEdges(double max_edge, int rounds, std::vector<Eigen::Vector3d>* vertices,
                                    std::vector<std::array<uint32_t, 3>>* faces,
                                    std::vector<uint8_t>* eligible);

}  // namespace imr::photometric
