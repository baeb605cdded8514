// Weight-transfer policies of Romanoni & Matteucci, section 3.2 ("The efficient approach").
//
// When the Delaunay triangulation replaces a set R of removed tetrahedra by a set A of new ones
// (a vertex removed, or a point inserted), the new tetrahedra need weights without re-casting the
// viewing rays. Each policy maps (centroids and weights of R, centroids of A) to weights of A.
//
// Pure functions on plain arrays: no SDK, no CGAL. The policy plugins wrap them, and the engine's
// tests and benchmark use them directly so that one implementation serves everywhere.
#pragma once

#include <cmath>
#include <cstddef>
#include <limits>

namespace imr::policies {

// Centroids are packed xyz triples: centroid i is (c[3i], c[3i+1], c[3i+2]).
struct RemovedCells {
  const double* centroids = nullptr;
  const double* weights = nullptr;
  std::size_t count = 0;
};

struct AddedCells {
  const double* centroids = nullptr;
  std::size_t count = 0;
};

inline double SquaredDistance(const double* a, const double* b) {
  const double dx = a[0] - b[0], dy = a[1] - b[1], dz = a[2] - b[2];
  return dx * dx + dy * dy + dz * dz;
}

// "Mean value": every new cell gets the mean weight of the removed cells. (The paper's formula
// divides by n_A, a typo: the mean over R is what it describes.) With no removed cell: 0.
inline void TransferMean(const RemovedCells& removed, const AddedCells& added, double* out) {
  double sum = 0.0;
  for (std::size_t k = 0; k < removed.count; ++k) sum += removed.weights[k];
  const double mean = removed.count > 0 ? sum / static_cast<double>(removed.count) : 0.0;
  for (std::size_t i = 0; i < added.count; ++i) out[i] = mean;
}

// "Weighted mean": inverse-distance weighting of the removed weights by centroid distance. (The
// paper's formula lost the w_k in the numerator.) A removed centroid that coincides with the new
// one (distance below 1e-12) takes all the weight, which is the limit of the formula.
inline void TransferWeightedMean(const RemovedCells& removed, const AddedCells& added,
                                 double* out) {
  for (std::size_t i = 0; i < added.count; ++i) {
    const double* a = added.centroids + 3 * i;
    double num = 0.0, den = 0.0;
    bool coincident = false;
    for (std::size_t k = 0; k < removed.count; ++k) {
      const double d2 = SquaredDistance(a, removed.centroids + 3 * k);
      if (d2 < 1e-24) {
        out[i] = removed.weights[k];
        coincident = true;
        break;
      }
      const double inv = 1.0 / std::sqrt(d2);
      num += inv * removed.weights[k];
      den += inv;
    }
    if (!coincident) out[i] = den > 0.0 ? num / den : 0.0;
  }
}

// "Minimum distance" (the paper's recommended policy): the weight of the removed cell whose
// centroid is nearest. Keeps the matter/free-space discontinuity sharp. Ties go to the lowest
// index so results are deterministic.
inline void TransferNearest(const RemovedCells& removed, const AddedCells& added, double* out) {
  for (std::size_t i = 0; i < added.count; ++i) {
    const double* a = added.centroids + 3 * i;
    double best = std::numeric_limits<double>::infinity();
    double w = 0.0;
    for (std::size_t k = 0; k < removed.count; ++k) {
      const double d2 = SquaredDistance(a, removed.centroids + 3 * k);
      if (d2 < best) {
        best = d2;
        w = removed.weights[k];
      }
    }
    out[i] = w;
  }
}

}  // namespace imr::policies
