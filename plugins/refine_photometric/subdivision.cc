#include "subdivision.hpp"

#include <unordered_map>

namespace imr::photometric {

namespace {

uint64_t EdgeKey(uint32_t a, uint32_t b) {
  if (a > b) std::swap(a, b);
  return (static_cast<uint64_t>(a) << 32) | b;
}

}  // namespace

SubdivisionStats SubdivideLongEdges(double max_edge, int rounds, std::vector<Eigen::Vector3d>* vertices,
                                    std::vector<std::array<uint32_t, 3>>* faces,
                                    std::vector<uint8_t>* eligible) {
  SubdivisionStats stats;
  stats.faces_before = static_cast<int64_t>(faces->size());
  std::vector<Eigen::Vector3d>& p = *vertices;
  if (eligible->empty()) eligible->assign(p.size(), 1);
  const double max2 = max_edge * max_edge;
  for (int round = 0; round < rounds; ++round) {
    // The midpoint of every long edge, once per edge.
    std::unordered_map<uint64_t, uint32_t> mid;
    for (const auto& f : *faces)
      for (int k = 0; k < 3; ++k) {
        const uint32_t a = f[k], b = f[(k + 1) % 3];
        if (!(*eligible)[a] || !(*eligible)[b] || (p[a] - p[b]).squaredNorm() <= max2) continue;
        if (mid.emplace(EdgeKey(a, b), static_cast<uint32_t>(p.size())).second) {
          p.push_back(0.5 * (p[a] + p[b]));
          eligible->push_back(1);
        }
      }
    if (mid.empty()) break;
    stats.edges_split += static_cast<int64_t>(mid.size());
    std::vector<std::array<uint32_t, 3>> out;
    out.reserve(faces->size() * 2);
    for (const auto& f : *faces) {
      uint32_t m[3];  // midpoint of edge k (f[k], f[k+1]), or UINT32_MAX
      int split = 0;
      for (int k = 0; k < 3; ++k) {
        auto it = mid.find(EdgeKey(f[k], f[(k + 1) % 3]));
        m[k] = it == mid.end() ? UINT32_MAX : it->second;
        split += it == mid.end() ? 0 : 1;
      }
      if (split == 0) {
        out.push_back(f);
      } else if (split == 3) {
        out.push_back({f[0], m[0], m[2]});
        out.push_back({m[0], f[1], m[1]});
        out.push_back({m[2], m[1], f[2]});
        out.push_back({m[0], m[1], m[2]});
      } else if (split == 1) {
        const int k = m[0] != UINT32_MAX ? 0 : m[1] != UINT32_MAX ? 1 : 2;
        const uint32_t a = f[k], b = f[(k + 1) % 3], c = f[(k + 2) % 3];
        out.push_back({a, m[k], c});
        out.push_back({m[k], b, c});
      } else {
        // Two split edges: the unsplit one is (f[k], f[k+1]); cut the quad along the shorter
        // diagonal.
        const int k = m[0] == UINT32_MAX ? 0 : m[1] == UINT32_MAX ? 1 : 2;
        const uint32_t a = f[k], b = f[(k + 1) % 3], c = f[(k + 2) % 3];
        const uint32_t mbc = m[(k + 1) % 3], mca = m[(k + 2) % 3];
        out.push_back({mca, mbc, c});
        // Quad a, b, mbc, mca.
        if ((p[a] - p[mbc]).squaredNorm() <= (p[b] - p[mca]).squaredNorm()) {
          out.push_back({a, b, mbc});
          out.push_back({a, mbc, mca});
        } else {
          out.push_back({a, b, mca});
          out.push_back({b, mbc, mca});
        }
      }
    }
    faces->swap(out);
  }
  stats.faces_after = static_cast<int64_t>(faces->size());
  return stats;
}

}  // namespace imr::photometric
