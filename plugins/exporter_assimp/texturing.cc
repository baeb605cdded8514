#include "texturing.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <unordered_map>

namespace imr::exporter_assimp {
namespace {

using Clock = std::chrono::steady_clock;
using Vec3 = std::array<double, 3>;

double Since(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

Vec3 Sub(const Vec3& a, const Vec3& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
Vec3 Cross(const Vec3& a, const Vec3& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
double Dot(const Vec3& a, const Vec3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
double Norm(const Vec3& a) { return std::sqrt(Dot(a, a)); }

// A face of at least this many pixels must own this share of them in the z-buffer (corners and
// centroid alone miss a thin occluder crossing its middle).
constexpr double kMinOwnPixelsArea = 16.0;
constexpr double kMinOwnPixelsShare = 0.5;
constexpr double kNearRelative = 1e-6;
// A keyframe adds to the colour of the vertices within this many steps of the keyframe path (the
// median distance between consecutive views): a drive's view 40 steps away weighs (1/40)^2 of a
// near one ((cos / depth)^2), which changes no byte one can see, and the bound lets a long
// drive's colours be made block by block (StreamedVertexColours) with the same result. An
// object ring's views stand a few steps from everything they see: no bound there.
constexpr double kColourReachSteps = 40.0;

// One keyframe as the rasteriser sees it: x_cam = R X + t, pixel = (fx x/z + cx, fy y/z + cy).
struct View {
  int index = 0;  // keyframe index
  int width = 0, height = 0;
  double fx = 0, fy = 0, cx = 0, cy = 0;
  double R[9]{}, t[3]{};
  Vec3 center{};

  static bool Usable(const imr_camera& c) {
    if (!(c.K[0] > 0 && c.K[4] > 0 && c.width > 0 && c.height > 0)) return false;
    for (double x : c.K) if (!std::isfinite(x)) return false;
    for (double x : c.R) if (!std::isfinite(x)) return false;
    for (double x : c.t) if (!std::isfinite(x)) return false;
    return true;
  }
  View(int i, const imr_camera& c) : index(i), width(c.width), height(c.height) {
    fx = c.K[0], fy = c.K[4], cx = c.K[2], cy = c.K[5];
    std::copy(c.R, c.R + 9, R);
    std::copy(c.t, c.t + 3, t);
    for (int k = 0; k < 3; ++k)  // C = -R^T t
      center[k] = -(R[k] * t[0] + R[3 + k] * t[1] + R[6 + k] * t[2]);
  }
  Vec3 ToCamera(const double* X) const {
    return {R[0] * X[0] + R[1] * X[1] + R[2] * X[2] + t[0],
            R[3] * X[0] + R[4] * X[1] + R[5] * X[2] + t[1],
            R[6] * X[0] + R[7] * X[1] + R[8] * X[2] + t[2]};
  }
};

// Inverse depth (0: nothing drawn) and the face drawn, per pixel.
struct ZBuffer {
  int width = 0, height = 0;
  std::vector<float> inv_depth;
  std::vector<int32_t> face;
  void Reset(int w, int h) {
    width = w, height = h;
    inv_depth.assign(static_cast<std::size_t>(w) * h, 0.0f);
    face.assign(static_cast<std::size_t>(w) * h, -1);
  }
};

struct ScreenVertex {
  double u, v, inv_z;
};

// Fills the pixels whose centres lie inside the triangle (either orientation), nearest wins.
void DrawTriangle(const ScreenVertex& a, const ScreenVertex& b, const ScreenVertex& c, int32_t id,
                  ZBuffer* zb) {
  const double area = (b.u - a.u) * (c.v - a.v) - (b.v - a.v) * (c.u - a.u);
  if (!(std::fabs(area) > 1e-12)) return;
  const int x0 = std::max(0, static_cast<int>(std::ceil(std::min({a.u, b.u, c.u}))));
  const int x1 = std::min(zb->width - 1, static_cast<int>(std::floor(std::max({a.u, b.u, c.u}))));
  const int y0 = std::max(0, static_cast<int>(std::ceil(std::min({a.v, b.v, c.v}))));
  const int y1 = std::min(zb->height - 1, static_cast<int>(std::floor(std::max({a.v, b.v, c.v}))));
  if (x0 > x1 || y0 > y1) return;
  const double inv_area = 1.0 / area;
  // Edge functions at (x0, y) and their steps along x: w_a = edge(b, c), etc.
  auto edge = [](const ScreenVertex& p, const ScreenVertex& q, double x, double y) {
    return (q.u - p.u) * (y - p.v) - (q.v - p.v) * (x - p.u);
  };
  const double da = -(c.v - b.v), db = -(a.v - c.v), dc = -(b.v - a.v);
  for (int y = y0; y <= y1; ++y) {
    double wa = edge(b, c, x0, y), wb = edge(c, a, x0, y), wc = edge(a, b, x0, y);
    float* depth = zb->inv_depth.data() + static_cast<std::size_t>(y) * zb->width;
    int32_t* face = zb->face.data() + static_cast<std::size_t>(y) * zb->width;
    for (int x = x0; x <= x1; ++x, wa += da, wb += db, wc += dc) {
      const double la = wa * inv_area, lb = wb * inv_area, lc = wc * inv_area;
      if (la < 0.0 || lb < 0.0 || lc < 0.0) continue;
      const auto iz = static_cast<float>(la * a.inv_z + lb * b.inv_z + lc * c.inv_z);
      if (iz > depth[x]) {
        depth[x] = iz;
        face[x] = id;
      }
    }
  }
}

// Draws every face into `zb` (camera coordinates `cam`, 3 per vertex), clipping at z = near.
void Rasterize(const std::vector<Vec3>& cam, const imr::sdk::MeshView& mesh, const View& view,
               double near, ZBuffer* zb) {
  zb->Reset(view.width, view.height);
  auto screen = [&](const Vec3& p) {
    return ScreenVertex{view.fx * p[0] / p[2] + view.cx, view.fy * p[1] / p[2] + view.cy, 1.0 / p[2]};
  };
  const std::size_t nf = mesh.face_count();
  for (std::size_t f = 0; f < nf; ++f) {
    const Vec3* p[3] = {&cam[mesh.faces[3 * f]], &cam[mesh.faces[3 * f + 1]], &cam[mesh.faces[3 * f + 2]]};
    const int in = ((*p[0])[2] >= near) + ((*p[1])[2] >= near) + ((*p[2])[2] >= near);
    if (in == 0) continue;
    const auto id = static_cast<int32_t>(f);
    if (in == 3) {
      DrawTriangle(screen(*p[0]), screen(*p[1]), screen(*p[2]), id, zb);
      continue;
    }
    // Sutherland-Hodgman against z >= near: 3 or 4 vertices, drawn as a fan.
    Vec3 poly[4];
    int n = 0;
    for (int k = 0; k < 3; ++k) {
      const Vec3& a = *p[k];
      const Vec3& b = *p[(k + 1) % 3];
      if (a[2] >= near) poly[n++] = a;
      if ((a[2] >= near) != (b[2] >= near)) {
        const double s = (near - a[2]) / (b[2] - a[2]);
        poly[n++] = {a[0] + s * (b[0] - a[0]), a[1] + s * (b[1] - a[1]), near};
      }
    }
    for (int k = 1; k + 1 < n; ++k) DrawTriangle(screen(poly[0]), screen(poly[k]), screen(poly[k + 1]), id, zb);
  }
}

// Visibility against the mesh itself, without a depth tolerance (a fixed one either hides the
// ground seen at a grazing angle, whose depth changes by metres per pixel far away, or lets a
// car's side hide nothing of the ground it stands on): a point of the surface is seen when,
// within a pixel of its projection, the z-buffer shows its own surface there — a face with the
// vertex (a vertex's test), or sharing a corner with the face (a centroid's test).
template <typename Own>
bool SeenWithin(const ZBuffer& zb, double u, double v, const Own& own) {
  const auto x = static_cast<int>(std::lround(u)), y = static_cast<int>(std::lround(v));
  for (int dy = -1; dy <= 1; ++dy)
    for (int dx = -1; dx <= 1; ++dx) {
      const int px = x + dx, py = y + dy;
      if (px < 0 || py < 0 || px >= zb.width || py >= zb.height) continue;
      const int32_t g = zb.face[static_cast<std::size_t>(py) * zb.width + px];
      if (g >= 0 && own(static_cast<uint32_t>(g))) return true;
    }
  return false;
}

bool VertexSeen(const ZBuffer& zb, const imr::sdk::MeshView& mesh, double u, double v, uint32_t vertex) {
  return SeenWithin(zb, u, v, [&](uint32_t g) {
    const uint32_t* t = &mesh.faces[3 * static_cast<std::size_t>(g)];
    return t[0] == vertex || t[1] == vertex || t[2] == vertex;
  });
}

bool FaceSeen(const ZBuffer& zb, const imr::sdk::MeshView& mesh, double u, double v, uint32_t face) {
  const uint32_t* f = &mesh.faces[3 * static_cast<std::size_t>(face)];
  return SeenWithin(zb, u, v, [&](uint32_t g) {
    const uint32_t* t = &mesh.faces[3 * static_cast<std::size_t>(g)];
    for (int i = 0; i < 3; ++i)
      if (t[i] == f[0] || t[i] == f[1] || t[i] == f[2]) return true;
    return false;
  });
}

// Bilinear RGB at (u, v) (pixel centres at integers); (u, v) within [0, w-1] x [0, h-1].
std::array<double, 3> Sample(const imr::sdk::KeyframeImage& image, double u, double v) {
  const int w = image.width(), h = image.height(), ch = image.channels();
  const int x0 = std::clamp(static_cast<int>(std::floor(u)), 0, w - 1);
  const int y0 = std::clamp(static_cast<int>(std::floor(v)), 0, h - 1);
  const int x1 = std::min(x0 + 1, w - 1), y1 = std::min(y0 + 1, h - 1);
  const double fx = std::clamp(u - x0, 0.0, 1.0), fy = std::clamp(v - y0, 0.0, 1.0);
  std::array<double, 3> rgb{};
  const int xs[2] = {x0, x1}, ys[2] = {y0, y1};
  const double wx[2] = {1 - fx, fx}, wy[2] = {1 - fy, fy};
  for (int j = 0; j < 2; ++j)
    for (int i = 0; i < 2; ++i) {
      const uint8_t* p = image.Row(ys[j]) + static_cast<std::ptrdiff_t>(xs[i]) * ch;
      const double wgt = wx[i] * wy[j];
      if (ch == 1) {
        for (double& c : rgb) c += wgt * p[0];
      } else {  // BGR
        rgb[0] += wgt * p[2];
        rgb[1] += wgt * p[1];
        rgb[2] += wgt * p[0];
      }
    }
  return rgb;
}

uint8_t Byte(double v) { return static_cast<uint8_t>(std::clamp(std::lround(v), 0L, 255L)); }

// Face adjacency over shared edges, as CSR (neighbours of face f: adj[begin[f] .. begin[f+1])).
struct Adjacency {
  std::vector<uint32_t> begin, adj;
};
Adjacency FaceAdjacency(const imr::sdk::MeshView& mesh) {
  const std::size_t nf = mesh.face_count();
  struct Edge {
    uint64_t key;
    uint32_t face;
  };
  std::vector<Edge> edges;
  edges.reserve(3 * nf);
  for (std::size_t f = 0; f < nf; ++f)
    for (int k = 0; k < 3; ++k) {
      const uint64_t a = mesh.faces[3 * f + k], b = mesh.faces[3 * f + (k + 1) % 3];
      edges.push_back({std::min(a, b) << 32 | std::max(a, b), static_cast<uint32_t>(f)});
    }
  std::sort(edges.begin(), edges.end(),
            [](const Edge& x, const Edge& y) { return x.key < y.key || (x.key == y.key && x.face < y.face); });
  std::vector<std::pair<uint32_t, uint32_t>> pairs;
  for (std::size_t i = 0; i < edges.size();) {
    std::size_t j = i;
    while (j < edges.size() && edges[j].key == edges[i].key) ++j;
    for (std::size_t a = i; a < j; ++a)
      for (std::size_t b = i; b < j; ++b)
        if (a != b && edges[a].face != edges[b].face) pairs.emplace_back(edges[a].face, edges[b].face);
    i = j;
  }
  std::sort(pairs.begin(), pairs.end());
  pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
  Adjacency a;
  a.begin.assign(nf + 1, 0);
  for (const auto& [f, g] : pairs) ++a.begin[f + 1];
  for (std::size_t f = 0; f < nf; ++f) a.begin[f + 1] += a.begin[f];
  a.adj.resize(pairs.size());
  for (std::size_t i = 0; i < pairs.size(); ++i) a.adj[i] = pairs[i].second;  // sorted by f
  return a;
}

int64_t CountSeams(const Adjacency& a, const std::vector<int32_t>& label) {
  int64_t seams = 0;
  for (std::size_t f = 0; f + 1 < a.begin.size(); ++f)
    for (uint32_t k = a.begin[f]; k < a.begin[f + 1]; ++k) {
      const uint32_t g = a.adj[k];
      if (g > f && label[f] >= 0 && label[g] >= 0 && label[f] != label[g]) ++seams;
    }
  return seams;
}

using Candidate = ViewCandidate;

struct Patch {
  int view = 0;             // position in the views list
  int x0 = 0, y0 = 0;       // image pixel of the rectangle's top-left corner
  int width = 0, height = 0;  // in image pixels
  int step = 1;             // image pixels per texel on each axis (TexturingOptions::texel_size)
  int page = 0, px = 0, py = 0;  // where it goes in the atlas
  int texels_x() const { return (width + step - 1) / step; }
  int texels_y() const { return (height + step - 1) / step; }
};

// Maximum flow (Dinic) on a small graph with real capacities: the min cut of one expansion move.
class MaxFlow {
 public:
  explicit MaxFlow(int nodes) : head_(static_cast<std::size_t>(nodes), -1) {}
  void Add(int from, int to, double cap, double reverse_cap = 0.0) {
    edges_.push_back({to, head_[static_cast<std::size_t>(from)], cap});
    head_[static_cast<std::size_t>(from)] = static_cast<int>(edges_.size()) - 1;
    edges_.push_back({from, head_[static_cast<std::size_t>(to)], reverse_cap});
    head_[static_cast<std::size_t>(to)] = static_cast<int>(edges_.size()) - 1;
  }
  double Run(int s, int t) {
    double flow = 0.0;
    while (Levels(s, t)) {
      next_ = head_;
      for (double f; (f = Push(s, t, std::numeric_limits<double>::infinity())) > kEps;) flow += f;
    }
    return flow;
  }
  // After Run: whether `node` is on the source side of the minimum cut.
  bool SourceSide(int node) const { return level_[static_cast<std::size_t>(node)] >= 0; }

 private:
  static constexpr double kEps = 1e-12;
  struct Edge {
    int to, next;
    double cap;
  };
  bool Levels(int s, int t) {
    level_.assign(head_.size(), -1);
    std::vector<int> queue = {s};
    level_[static_cast<std::size_t>(s)] = 0;
    for (std::size_t q = 0; q < queue.size(); ++q)
      for (int e = head_[static_cast<std::size_t>(queue[q])]; e >= 0; e = edges_[static_cast<std::size_t>(e)].next) {
        const Edge& x = edges_[static_cast<std::size_t>(e)];
        if (x.cap > kEps && level_[static_cast<std::size_t>(x.to)] < 0) {
          level_[static_cast<std::size_t>(x.to)] = level_[static_cast<std::size_t>(queue[q])] + 1;
          queue.push_back(x.to);
        }
      }
    return level_[static_cast<std::size_t>(t)] >= 0;
  }
  // One augmenting path in the level graph (iterative: paths can be long).
  double Push(int s, int t, double limit) {
    std::vector<int> path;  // edges
    int u = s;
    while (true) {
      if (u == t) {
        double f = limit;
        for (int e : path) f = std::min(f, edges_[static_cast<std::size_t>(e)].cap);
        for (int e : path) {
          edges_[static_cast<std::size_t>(e)].cap -= f;
          edges_[static_cast<std::size_t>(e ^ 1)].cap += f;
        }
        return f;
      }
      int& e = next_[static_cast<std::size_t>(u)];
      for (; e >= 0; e = edges_[static_cast<std::size_t>(e)].next) {
        const Edge& x = edges_[static_cast<std::size_t>(e)];
        if (x.cap > kEps && level_[static_cast<std::size_t>(x.to)] == level_[static_cast<std::size_t>(u)] + 1) break;
      }
      if (e >= 0) {
        path.push_back(e);
        u = edges_[static_cast<std::size_t>(e)].to;
        continue;
      }
      if (path.empty()) return 0.0;
      // Dead end: retreat and skip the edge that led here.
      level_[static_cast<std::size_t>(u)] = -2;
      const int back = path.back();
      path.pop_back();
      u = edges_[static_cast<std::size_t>(back ^ 1)].to;
      next_[static_cast<std::size_t>(u)] = edges_[static_cast<std::size_t>(next_[static_cast<std::size_t>(u)])].next;
    }
  }

  std::vector<int> head_, next_, level_;
  std::vector<Edge> edges_;
};

// Alpha-expansion (Boykov, Veksler and Zabih 2001) of the labelling energy: data 1 - q / q_max per
// face (its candidates only), Potts `lambda` per adjacent pair of labelled faces with different
// views. Each move lets every face that sees view alpha whole switch to it, optimally (a minimum
// cut); cycles over the views until a cycle changes nothing (at most 8). Returns the cycles run.
int AlphaExpansion(const std::vector<uint32_t>& cbegin, const std::vector<Candidate>& by_face,
                   const std::vector<float>& qmax, const Adjacency& adjacency, double lambda,
                   int views, std::vector<int32_t>* label_io) {
  std::vector<int32_t>& label = *label_io;
  const std::size_t nf = label.size();
  auto data = [&](std::size_t f, int32_t view) {
    for (uint32_t k = cbegin[f]; k < cbegin[f + 1]; ++k)
      if (by_face[k].view == view) return qmax[f] > 0.0f ? 1.0 - by_face[k].quality / qmax[f] : 0.0;
    return std::numeric_limits<double>::infinity();  // not a candidate
  };
  std::vector<std::vector<uint32_t>> seen_by(static_cast<std::size_t>(views));
  for (std::size_t f = 0; f < nf; ++f)
    for (uint32_t k = cbegin[f]; k < cbegin[f + 1]; ++k)
      seen_by[static_cast<std::size_t>(by_face[k].view)].push_back(static_cast<uint32_t>(f));
  std::vector<int32_t> node(nf, -1);
  int cycles = 0;
  for (bool changed = true; changed && cycles < 8; ++cycles) {
    changed = false;
    for (int32_t alpha = 0; alpha < views; ++alpha) {
      std::vector<uint32_t> faces;
      for (uint32_t f : seen_by[static_cast<std::size_t>(alpha)])
        if (label[f] != alpha) faces.push_back(f);
      if (faces.empty()) continue;
      for (std::size_t i = 0; i < faces.size(); ++i) node[faces[i]] = static_cast<int32_t>(i);
      const int n = static_cast<int>(faces.size()), s = n, t = n + 1;
      std::vector<double> keep(faces.size()), take(faces.size());  // x = 0 (keep), x = 1 (alpha)
      MaxFlow graph(n + 2);
      for (std::size_t i = 0; i < faces.size(); ++i) {
        const uint32_t f = faces[i];
        keep[i] += data(f, label[f]);
        take[i] += data(f, alpha);
        for (uint32_t a = adjacency.begin[f]; a < adjacency.begin[f + 1]; ++a) {
          const uint32_t g = adjacency.adj[a];
          if (label[g] < 0) continue;  // no texture there: no seam either way
          if (node[g] < 0) {           // fixed neighbour
            keep[i] += lambda * (label[f] != label[g]);
            take[i] += lambda * (alpha != label[g]);
          } else if (g > f) {  // both free, once per pair: E(0,0)=A, E(0,1)=E(1,0)=lambda, E(1,1)=0
            const double A = lambda * (label[f] != label[g]);
            const auto j = static_cast<std::size_t>(node[g]);
            take[i] += lambda - A;  // C - A
            take[j] -= lambda;      // D - C
            graph.Add(node[f], node[g], 2.0 * lambda - A);  // B + C - A - D, cut when f keeps, g takes
          }
        }
      }
      for (std::size_t i = 0; i < faces.size(); ++i) {
        const double m = std::min(keep[i], take[i]);
        graph.Add(s, static_cast<int>(i), take[i] - m);  // cut when i takes alpha
        graph.Add(static_cast<int>(i), t, keep[i] - m);  // cut when i keeps its label
      }
      graph.Run(s, t);
      for (std::size_t i = 0; i < faces.size(); ++i) {
        if (!graph.SourceSide(static_cast<int>(i))) {
          label[faces[i]] = alpha;
          changed = true;
        }
        node[faces[i]] = -1;
      }
    }
  }
  return cycles;
}

// The view selection over a face adjacency: each face's best view, then alpha-expansion; the
// seam counts into *stats.
std::vector<int32_t> SelectViewsOn(const Adjacency& adjacency, std::size_t nf,
                                   std::vector<ViewCandidate> candidates, int views,
                                   double seam_penalty, TexturingStats* stats) {
  std::vector<uint32_t> cbegin(nf + 1, 0);
  for (const Candidate& c : candidates) ++cbegin[c.face + 1];
  for (std::size_t f = 0; f < nf; ++f) cbegin[f + 1] += cbegin[f];
  std::vector<Candidate> by_face(candidates.size());
  {
    std::vector<uint32_t> at(cbegin.begin(), cbegin.end() - 1);
    for (const Candidate& c : candidates) by_face[at[c.face]++] = c;
    candidates = {};
  }
  std::vector<float> qmax(nf, 0.0f);
  std::vector<int32_t> label(nf, -1);
  for (std::size_t f = 0; f < nf; ++f)
    for (uint32_t k = cbegin[f]; k < cbegin[f + 1]; ++k)
      if (by_face[k].quality > qmax[f] || label[f] < 0) {
        qmax[f] = by_face[k].quality;
        label[f] = by_face[k].view;
      }
  stats->seams_best_view = CountSeams(adjacency, label);
  // Seams no labelling avoids: adjacent faces that no view sees both whole.
  stats->seams_forced = 0;
  for (std::size_t f = 0; f < nf; ++f)
    for (uint32_t a = adjacency.begin[f]; a < adjacency.begin[f + 1]; ++a) {
      const uint32_t g = adjacency.adj[a];
      if (g < f || cbegin[f] == cbegin[f + 1] || cbegin[g] == cbegin[g + 1]) continue;
      bool shared = false;
      for (uint32_t i = cbegin[f]; i < cbegin[f + 1] && !shared; ++i)
        for (uint32_t j = cbegin[g]; j < cbegin[g + 1] && !shared; ++j)
          shared = by_face[i].view == by_face[j].view;
      stats->seams_forced += !shared;
    }
  if (seam_penalty > 0.0)
    stats->expansion_cycles = AlphaExpansion(cbegin, by_face, qmax, adjacency, seam_penalty, views, &label);
  stats->seams = CountSeams(adjacency, label);
  return label;
}

}  // namespace

std::string TexturingOptions::Check() const {
  if (atlas_size < 64 || atlas_size > 16384) return "atlas_size: expected 64 .. 16384 pixels";
  if (keyframe_step < 1) return "keyframe_step: expected >= 1";
  if (!(seam_penalty >= 0.0 && std::isfinite(seam_penalty))) return "seam_penalty: expected >= 0";
  if (padding < 0 || 2 * padding + 8 > atlas_size) return "padding: expected 0 .. (atlas_size - 8) / 2";
  if (!(texel_size >= 0.0 && std::isfinite(texel_size))) return "texel_size: expected >= 0";
  return {};
}

std::vector<int32_t> SelectViews(const imr::sdk::MeshView& mesh, std::vector<ViewCandidate> candidates,
                                 int views, double seam_penalty, TexturingStats* stats) {
  for (const ViewCandidate& c : candidates)
    if (c.face >= mesh.face_count() || c.view < 0 || c.view >= views || !(c.quality >= 0.0f))
      throw std::invalid_argument("SelectViews: candidate (face " + std::to_string(c.face) + ", view " +
                                  std::to_string(c.view) + ") out of range");
  return SelectViewsOn(FaceAdjacency(mesh), mesh.face_count(), std::move(candidates), views,
                       seam_penalty, stats);
}

std::vector<double> VertexNormals(const imr::sdk::MeshView& mesh) {
  const std::size_t nv = mesh.vertex_count();
  std::vector<double> acc(3 * nv, 0.0);
  const double* v = mesh.vertices.data();
  for (std::size_t f = 0; f < mesh.face_count(); ++f) {
    const uint32_t a = mesh.faces[3 * f], b = mesh.faces[3 * f + 1], c = mesh.faces[3 * f + 2];
    const Vec3 n = Cross(Sub({v[3 * b], v[3 * b + 1], v[3 * b + 2]}, {v[3 * a], v[3 * a + 1], v[3 * a + 2]}),
                         Sub({v[3 * c], v[3 * c + 1], v[3 * c + 2]}, {v[3 * a], v[3 * a + 1], v[3 * a + 2]}));
    for (const uint32_t i : {a, b, c})
      for (int k = 0; k < 3; ++k) acc[3 * i + k] += n[k];  // |n| = 2 * area
  }
  for (std::size_t i = 0; i < nv; ++i) {
    double* n = &acc[3 * i];
    const double len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    for (int k = 0; k < 3; ++k) n[k] = len > 0 && std::isfinite(len) ? n[k] / len : 0.0;
  }
  return acc;
}

bool UprightRotation(std::span<const imr_camera> keyframes, double rotation[9]) {
  Vec3 up{}, forward{};
  for (const imr_camera& c : keyframes) {
    bool finite = true;
    for (double x : c.R) finite = finite && std::isfinite(x);
    if (!finite) continue;
    for (int k = 0; k < 3; ++k) {
      up[k] -= c.R[3 + k];       // row 1: the camera's y axis (image down) in world coordinates
      forward[k] += c.R[6 + k];  // row 2: its viewing direction
    }
  }
  const double n = Norm(up);
  if (!(n > 1e-9)) return false;
  for (double& x : up) x /= n;
  const double along = Dot(forward, up);
  for (int k = 0; k < 3; ++k) forward[k] -= along * up[k];
  if (!(Norm(forward) > 1e-9)) forward = std::fabs(up[0]) < 0.9 ? Cross(up, {1, 0, 0}) : Cross(up, {0, 1, 0});
  const double fn = Norm(forward);
  const Vec3 z = {-forward[0] / fn, -forward[1] / fn, -forward[2] / fn};
  const Vec3 x = Cross(up, z);
  for (int k = 0; k < 3; ++k) {
    rotation[k] = x[k];
    rotation[3 + k] = up[k];
    rotation[6 + k] = z[k];
  }
  return true;
}

namespace {

// The keyframes that are textured from: every keyframe_step-th and the last, when usable.
std::vector<View> TexturingViews(std::span<const imr_camera> keyframes, const TexturingOptions& options) {
  std::vector<View> views;
  const int nk = static_cast<int>(keyframes.size());
  for (int i = 0; i < nk; ++i)
    if ((i % options.keyframe_step == 0 || i + 1 == nk) && View::Usable(keyframes[i]))
      views.emplace_back(i, keyframes[i]);
  return views;
}

// The near plane (the clipping of faces through a camera), from the scene's extent: the largest
// absolute coordinate of a vertex (`extent`) or a view's centre.
double NearPlane(double extent, const std::vector<View>& views) {
  for (const View& v : views) extent = std::max({extent, std::fabs(v.center[0]), std::fabs(v.center[1]), std::fabs(v.center[2])});
  return std::max(extent, 1.0) * kNearRelative;
}
double NearPlane(const imr::sdk::MeshView& mesh, const std::vector<View>& views) {
  const double* X = mesh.vertices.data();
  double extent = 0.0;
  for (std::size_t i = 0; i < 3 * mesh.vertex_count(); ++i) extent = std::max(extent, std::fabs(X[i]));
  return NearPlane(extent, views);
}

// How far a view adds to a vertex's colour: kColourReachSteps times the median distance between
// consecutive views (infinite for fewer than two views or no step).
double ColourReachOf(const std::vector<View>& views) {
  std::vector<double> steps;
  for (std::size_t i = 1; i < views.size(); ++i) steps.push_back(Norm(Sub(views[i].center, views[i - 1].center)));
  if (steps.empty()) return std::numeric_limits<double>::infinity();
  std::nth_element(steps.begin(), steps.begin() + static_cast<std::ptrdiff_t>(steps.size() / 2), steps.end());
  const double step = steps[steps.size() / 2];
  return step > 0.0 && std::isfinite(step) ? kColourReachSteps * step : std::numeric_limits<double>::infinity();
}

void Project(const View& view, const Vec3& p, double* u, double* v) {
  *u = view.fx * p[0] / p[2] + view.cx;
  *v = view.fy * p[1] / p[2] + view.cy;
}

// Pass 1: per view, the z-buffer, the vertex colour samples and the faces it sees whole.
class VisibilityPass {
 public:
  VisibilityPass(const imr::sdk::MeshView& mesh, double near, double reach, bool texture)
      : mesh_(mesh), X_(mesh.vertices.data()), nv_(mesh.vertex_count()), nf_(mesh.face_count()),
        near_(near), reach_(reach), texture_(texture), normals_(VertexNormals(mesh)), face_normal_(nf_),
        centroid_(nf_), color_sum_(3 * nv_, 0.0), weight_sum_(nv_, 0.0), far_color_sum_(3 * nv_, 0.0),
        far_weight_sum_(nv_, 0.0), cam_(nv_), own_pixels_(nf_) {
    for (std::size_t f = 0; f < nf_; ++f) {
      const double* a = X_ + 3 * mesh.faces[3 * f];
      const double* b = X_ + 3 * mesh.faces[3 * f + 1];
      const double* c = X_ + 3 * mesh.faces[3 * f + 2];
      face_normal_[f] = Cross(Sub({b[0], b[1], b[2]}, {a[0], a[1], a[2]}), Sub({c[0], c[1], c[2]}, {a[0], a[1], a[2]}));
      centroid_[f] = {(a[0] + b[0] + c[0]) / 3, (a[1] + b[1] + c[1]) / 3, (a[2] + b[2] + c[2]) / 3};
    }
  }

  // View vi (views[vi]) with its image.
  void See(std::size_t vi, const View& view, const imr::sdk::KeyframeImage& image) {
    if (image.width() != view.width || image.height() != view.height)
      throw std::runtime_error("keyframe " + std::to_string(view.index) + ": its image is " +
                               std::to_string(image.width()) + "x" + std::to_string(image.height()) +
                               ", its camera says " + std::to_string(view.width) + "x" +
                               std::to_string(view.height));
    for (std::size_t i = 0; i < nv_; ++i) cam_[i] = view.ToCamera(X_ + 3 * i);
    Rasterize(cam_, mesh_, view, near_, &zb_);
    std::fill(own_pixels_.begin(), own_pixels_.end(), 0u);
    for (const int32_t f : zb_.face)
      if (f >= 0) ++own_pixels_[static_cast<std::size_t>(f)];
    SampleVertexColours(view, image);
    if (texture_) AddFaceCandidates(vi, view);
  }

  // Within the reach, and beyond it (what a vertex no view within the reach sees takes).
  const std::vector<double>& color_sum(bool far) const { return far ? far_color_sum_ : color_sum_; }
  const std::vector<double>& weight_sum(bool far) const { return far ? far_weight_sum_ : weight_sum_; }
  std::vector<Candidate>& candidates() { return candidates_; }

 private:
  // Every vertex this view sees, on the side its normal points to.
  void SampleVertexColours(const View& view, const imr::sdk::KeyframeImage& image) {
    const double umax = view.width - 1.0, vmax = view.height - 1.0;
    for (std::size_t i = 0; i < nv_; ++i) {
      const Vec3& p = cam_[i];
      if (!(p[2] > near_)) continue;
      const Vec3 ray = Sub(view.center, {X_[3 * i], X_[3 * i + 1], X_[3 * i + 2]});
      const bool far = Norm(ray) > reach_;
      double u, v;
      Project(view, p, &u, &v);
      if (!(u >= 0 && v >= 0 && u <= umax && v <= vmax) ||
          !VertexSeen(zb_, mesh_, u, v, static_cast<uint32_t>(i)))
        continue;
      const Vec3 n = {normals_[3 * i], normals_[3 * i + 1], normals_[3 * i + 2]};
      double cosine = 1.0;
      if (Dot(n, n) > 0.0) {
        cosine = Dot(n, ray) / Norm(ray);
        if (!(cosine > 0.0)) continue;
      }
      const double w = (cosine / p[2]) * (cosine / p[2]);
      const std::array<double, 3> rgb = Sample(image, u, v);
      for (int k = 0; k < 3; ++k) (far ? far_color_sum_ : color_sum_)[3 * i + k] += w * rgb[k];
      (far ? far_weight_sum_ : weight_sum_)[i] += w;
    }
  }

  // Faces seen whole: candidates for the texture, with their projected area as quality.
  void AddFaceCandidates(std::size_t vi, const View& view) {
    const double umax = view.width - 1.0, vmax = view.height - 1.0;
    for (std::size_t f = 0; f < nf_; ++f) {
      if (!(Dot(face_normal_[f], Sub(view.center, centroid_[f])) > 0.0)) continue;  // back face
      double u[3], v[3];
      bool ok = true;
      for (int k = 0; k < 3 && ok; ++k) {
        const Vec3& p = cam_[mesh_.faces[3 * f + k]];
        ok = p[2] > near_;
        if (!ok) break;
        Project(view, p, &u[k], &v[k]);
        ok = u[k] >= 0.5 && v[k] >= 0.5 && u[k] <= umax - 0.5 && v[k] <= vmax - 0.5 &&
             VertexSeen(zb_, mesh_, u[k], v[k], mesh_.faces[3 * f + k]);
      }
      if (!ok) continue;
      const Vec3 c = view.ToCamera(centroid_[f].data());
      double cu, cv;
      Project(view, c, &cu, &cv);
      if (!FaceSeen(zb_, mesh_, cu, cv, static_cast<uint32_t>(f))) continue;
      const double area = 0.5 * std::fabs((u[1] - u[0]) * (v[2] - v[0]) - (v[1] - v[0]) * (u[2] - u[0]));
      if (area >= kMinOwnPixelsArea && own_pixels_[f] < kMinOwnPixelsShare * area) continue;
      candidates_.push_back({static_cast<uint32_t>(f), static_cast<int32_t>(vi), static_cast<float>(area)});
    }
  }

  const imr::sdk::MeshView& mesh_;
  const double* X_;
  std::size_t nv_, nf_;
  double near_;
  double reach_;  // a view adds to the colours of the vertices within this distance only
  bool texture_;
  std::vector<double> normals_;
  std::vector<Vec3> face_normal_, centroid_;
  std::vector<double> color_sum_, weight_sum_, far_color_sum_, far_weight_sum_;
  std::vector<Candidate> candidates_;
  std::vector<Vec3> cam_;  // the vertices in the current view's camera frame
  std::vector<uint32_t> own_pixels_;
  ZBuffer zb_;
};

// Vertex colours: the weighted means, then vertices nobody saw from their neighbours.
void VertexColours(const imr::sdk::MeshView& mesh, const VisibilityPass& pass, TexturedMesh& out) {
  const std::size_t nv = mesh.vertex_count(), nf = mesh.face_count();
  const std::vector<double>& color_sum = pass.color_sum(false);
  const std::vector<double>& weight_sum = pass.weight_sum(false);
  const std::vector<double>& far_color_sum = pass.color_sum(true);
  const std::vector<double>& far_weight_sum = pass.weight_sum(true);
  out.vertex_rgb.assign(3 * nv, 128);
  out.vertex_seen.assign(nv, 0);
  std::vector<uint8_t> known(nv, 0);
  for (std::size_t i = 0; i < nv; ++i) {
    // The views within the reach; a vertex none of them sees takes those beyond it (a camera
    // creeping along, or standing, far from what it looks at).
    const bool near = weight_sum[i] > 0.0;
    const std::vector<double>& c = near ? color_sum : far_color_sum;
    const double w = near ? weight_sum[i] : far_weight_sum[i];
    if (!(w > 0.0)) continue;
    for (int k = 0; k < 3; ++k) out.vertex_rgb[3 * i + k] = Byte(c[3 * i + k] / w);
    known[i] = 1;
    out.vertex_seen[i] = near ? 1 : 2;
    ++out.stats.vertices_seen;
  }
  // Rings of neighbours: each round colours the unknown vertices next to known ones.
  std::vector<std::vector<uint32_t>> ring(nv);
  for (std::size_t f = 0; f < nf; ++f)
    for (int k = 0; k < 3; ++k) {
      const uint32_t a = mesh.faces[3 * f + k], b = mesh.faces[3 * f + (k + 1) % 3];
      ring[a].push_back(b);
      ring[b].push_back(a);
    }
  for (bool progress = true; progress;) {
    std::vector<uint32_t> now;
    for (std::size_t i = 0; i < nv; ++i) {
      if (known[i]) continue;
      double sum[3] = {0, 0, 0};
      int count = 0;
      for (uint32_t j : ring[i])
        if (known[j] == 1) {
          for (int k = 0; k < 3; ++k) sum[k] += out.vertex_rgb[3 * j + k];
          ++count;
        }
      if (count == 0) continue;
      for (int k = 0; k < 3; ++k) out.vertex_rgb[3 * i + k] = Byte(sum[k] / count);
      now.push_back(static_cast<uint32_t>(i));
    }
    for (uint32_t i : now) known[i] = 1;
    progress = !now.empty();
  }
}

// Each labelled face's corners in its view's image (u, v per corner), and its farthest corner's
// depth there (`depth`, for the texel size).
std::vector<double> ImageCorners(const imr::sdk::MeshView& mesh, const std::vector<View>& views,
                                 const std::vector<int32_t>& label, std::vector<double>* depth) {
  const std::size_t nf = mesh.face_count();
  const double* X = mesh.vertices.data();
  std::vector<double> img_uv(6 * nf, 0.0);
  depth->assign(nf, 0.0);
  for (std::size_t f = 0; f < nf; ++f) {
    if (label[f] < 0) continue;
    const View& view = views[static_cast<std::size_t>(label[f])];
    for (int k = 0; k < 3; ++k) {
      const Vec3 p = view.ToCamera(X + 3 * mesh.faces[3 * f + k]);
      Project(view, p, &img_uv[6 * f + 2 * k], &img_uv[6 * f + 2 * k + 1]);
      (*depth)[f] = std::max((*depth)[f], p[2]);
    }
  }
  return img_uv;
}

// Image pixels per texel for a face whose farthest corner lies `depth` from `view`: the largest
// whole number of pixels (of the larger of the two focal lengths' footprints) within texel_size.
int TexelStep(const View& view, double depth, double texel_size) {
  const double pixel = depth / std::max(view.fx, view.fy);
  if (!(texel_size > 0.0) || !(pixel > 0.0)) return 1;
  return static_cast<int>(std::clamp(std::floor(texel_size / pixel), 1.0, 1024.0));
}

// The patch grown from `seed`: connected faces with its label, breadth-first while the
// rectangle they need (with padding) still fits a page; false when the seed alone is larger than
// a page (left untextured). Marks its faces in out.face_patch.
bool GrowPatch(std::size_t seed, int32_t id, const Adjacency& adjacency, const std::vector<int32_t>& label,
               const std::vector<double>& img_uv, const std::vector<double>& face_depth,
               const std::vector<View>& views, const TexturingOptions& options, TexturedMesh& out,
               Patch* patch) {
  const int pad = options.padding, limit = options.atlas_size;
  double lo[2] = {std::numeric_limits<double>::infinity(), std::numeric_limits<double>::infinity()};
  double hi[2] = {-lo[0], -lo[1]};
  auto fits = [&](std::size_t f, double* nlo, double* nhi) {
    for (int a = 0; a < 2; ++a) {
      nlo[a] = lo[a], nhi[a] = hi[a];
      for (int k = 0; k < 3; ++k) {
        nlo[a] = std::min(nlo[a], img_uv[6 * f + 2 * k + a]);
        nhi[a] = std::max(nhi[a], img_uv[6 * f + 2 * k + a]);
      }
      if (std::ceil(nhi[a]) - std::floor(nlo[a]) + 1 + 2 * pad > limit) return false;
    }
    return true;
  };
  // With a texel size (a level of detail), a patch takes the step its seed allows and only faces
  // that allow it and less than twice it: none sampled coarser than the texel asked for, none
  // more than twice finer on each axis (a patch down a street spans 10 to 50 m).
  const View& view = views[static_cast<std::size_t>(label[seed])];
  auto step_of = [&](std::size_t f) { return TexelStep(view, face_depth[f], options.texel_size); };
  const int step = step_of(seed);
  double nlo[2], nhi[2];
  if (!fits(seed, nlo, nhi)) return false;
  std::copy(nlo, nlo + 2, lo);
  std::copy(nhi, nhi + 2, hi);
  out.face_patch[seed] = id;
  std::vector<uint32_t> queue(1, static_cast<uint32_t>(seed));
  for (std::size_t q = 0; q < queue.size(); ++q) {
    const uint32_t f = queue[q];
    for (uint32_t a = adjacency.begin[f]; a < adjacency.begin[f + 1]; ++a) {
      const uint32_t g = adjacency.adj[a];
      if (label[g] != label[seed] || out.face_patch[g] >= 0 || !fits(g, nlo, nhi)) continue;
      if (const int s = step_of(g); s < step || s >= 2 * step) continue;
      std::copy(nlo, nlo + 2, lo);
      std::copy(nhi, nhi + 2, hi);
      out.face_patch[g] = id;
      queue.push_back(g);
    }
  }
  Patch& p = *patch;
  p.view = label[seed];
  p.step = step;  // grown in image pixels (a page holds it at any step); the padding in texels
  const int margin = pad * p.step;
  p.x0 = std::max(0, static_cast<int>(std::floor(lo[0])) - margin);
  p.y0 = std::max(0, static_cast<int>(std::floor(lo[1])) - margin);
  p.width = std::min(view.width - 1, static_cast<int>(std::ceil(hi[0])) + margin) - p.x0 + 1;
  p.height = std::min(view.height - 1, static_cast<int>(std::ceil(hi[1])) + margin) - p.y0 + 1;
  return true;
}

// Shelf packing, tallest first, into pages of atlas_size^2; pages are cut to what they use.
void PackPatches(std::vector<Patch>& patches, int limit, TexturedMesh& out) {
  std::vector<std::size_t> order(patches.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
    const int ha = patches[a].texels_y(), hb = patches[b].texels_y();
    const int wa = patches[a].texels_x(), wb = patches[b].texels_x();
    return ha > hb || (ha == hb && (wa > wb || (wa == wb && a < b)));
  });
  int page = -1, x = 0, shelf_y = 0, shelf_h = 0;
  std::vector<std::array<int, 2>> used;
  for (std::size_t i : order) {
    Patch& p = patches[i];
    const int w = p.texels_x(), h = p.texels_y();
    if (page < 0 || x + w > limit) {  // next shelf
      shelf_y += shelf_h;
      x = 0;
      shelf_h = h;
    }
    if (page < 0 || shelf_y + h > limit) {  // next page
      ++page;
      used.push_back({0, 0});
      x = 0, shelf_y = 0, shelf_h = h;
    }
    p.page = page, p.px = x, p.py = shelf_y;
    x += w;
    used[static_cast<std::size_t>(page)][0] = std::max(used[static_cast<std::size_t>(page)][0], x);
    used[static_cast<std::size_t>(page)][1] = std::max(used[static_cast<std::size_t>(page)][1], shelf_y + h);
    out.stats.patch_pixels += static_cast<int64_t>(w) * h;
  }
  for (const auto& [w, h] : used) {
    AtlasPage pg;  // its pixels come in CopyPatches, one page at a time
    pg.width = (w + 3) / 4 * 4;  // rows of whole 4-byte groups: friendlier to every decoder
    pg.height = (h + 3) / 4 * 4;
    out.stats.atlas_pixels += static_cast<int64_t>(pg.width) * pg.height;
    out.pages.push_back(std::move(pg));
  }
}

// Texture coordinates: image pixel (x, y) lands on texel ((x - x0) / step + px, (y - y0) / step
// + py), whose centre is at +0.5 in texture space (a texel of n x n pixels: their centre).
void TextureCoordinates(const std::vector<Patch>& patches, const std::vector<View>& views,
                        const std::vector<double>& img_uv, std::vector<int32_t>& label, TexturedMesh& out) {
  for (std::size_t f = 0; f < label.size(); ++f) {
    if (out.face_patch[f] < 0) {
      label[f] = -1;  // larger than a page on its own: vertex colours
      continue;
    }
    const Patch& p = patches[static_cast<std::size_t>(out.face_patch[f])];
    const AtlasPage& pg = out.pages[static_cast<std::size_t>(p.page)];
    out.face_page[f] = p.page;
    out.face_view[f] = views[static_cast<std::size_t>(p.view)].index;
    for (int k = 0; k < 3; ++k) {
      out.face_uv[6 * f + 2 * k] =
          static_cast<float>(((img_uv[6 * f + 2 * k] - p.x0 + 0.5) / p.step + p.px) / pg.width);
      out.face_uv[6 * f + 2 * k + 1] =
          static_cast<float>(((img_uv[6 * f + 2 * k + 1] - p.y0 + 0.5) / p.step + p.py) / pg.height);
    }
    ++out.stats.faces_textured;
  }
}

// Labelling, patches, packing and texture coordinates: best view, then alpha-expansion with the
// Potts term; the faces of one label grown into patches that are packed into pages.
std::vector<Patch> LayOutAtlas(const imr::sdk::MeshView& mesh, const std::vector<View>& views,
                               std::vector<Candidate> candidates, const TexturingOptions& options,
                               TexturedMesh& out) {
  const std::size_t nf = mesh.face_count();
  out.stats.candidates = static_cast<int64_t>(candidates.size());
  const Adjacency adjacency = FaceAdjacency(mesh);
  std::vector<int32_t> label =
      SelectViewsOn(adjacency, nf, std::move(candidates), static_cast<int>(views.size()),
                    options.seam_penalty, &out.stats);
  std::vector<double> face_depth;
  const std::vector<double> img_uv = ImageCorners(mesh, views, label, &face_depth);
  std::vector<Patch> patches;
  for (std::size_t seed = 0; seed < nf; ++seed) {
    if (label[seed] < 0 || out.face_patch[seed] >= 0) continue;
    Patch p;
    if (GrowPatch(seed, static_cast<int32_t>(patches.size()), adjacency, label, img_uv, face_depth, views,
                  options, out, &p))
      patches.push_back(p);
  }
  out.stats.patches = static_cast<int64_t>(patches.size());
  PackPatches(patches, options.atlas_size, out);
  TextureCoordinates(patches, views, img_uv, label, out);
  return patches;
}

// A patch of step n: each texel the mean of its n x n pixels (those within the patch's rectangle).
void CopyMeans(const Patch& p, const imr::sdk::KeyframeImage& image, AtlasPage& pg) {
  const int ch = image.channels();
  std::vector<uint32_t> sum(3 * static_cast<std::size_t>(p.texels_x()));
  for (int ty = 0; ty < p.texels_y(); ++ty) {
    std::fill(sum.begin(), sum.end(), 0u);
    const int y_end = std::min(p.height, (ty + 1) * p.step);
    for (int y = ty * p.step; y < y_end; ++y) {
      const uint8_t* src = image.Row(p.y0 + y) + static_cast<std::ptrdiff_t>(p.x0) * ch;
      for (int x = 0; x < p.width; ++x, src += ch) {
        uint32_t* s = &sum[3 * static_cast<std::size_t>(x / p.step)];
        if (ch == 1) {
          s[0] += src[0], s[1] += src[0], s[2] += src[0];
        } else {
          s[0] += src[2], s[1] += src[1], s[2] += src[0];
        }
      }
    }
    uint8_t* dst = pg.rgb.data() + (static_cast<std::size_t>(p.py + ty) * pg.width + p.px) * 3;
    for (int tx = 0; tx < p.texels_x(); ++tx, dst += 3) {
      const uint32_t n = static_cast<uint32_t>((std::min(p.width, (tx + 1) * p.step) - tx * p.step) *
                                               (y_end - ty * p.step));
      for (int c = 0; c < 3; ++c) dst[c] = static_cast<uint8_t>((sum[3 * tx + c] + n / 2) / n);
    }
  }
}

// Pass 2: copy each patch's rectangle from its view's image (BGR or gray) into its page (RGB),
// page by page, each handed to `page_done` when whole: with a sink that encodes and frees it, one
// page's pixels (48 MiB at 4096^2) are held at a time, not every page's.
void CopyPatches(const std::vector<Patch>& patches, const std::vector<View>& views,
                 const KeyframeImageFetch& fetch, const std::function<void()>& check_cancelled,
                 const AtlasPageSink& page_done, TexturedMesh& out) {
  std::vector<std::vector<std::vector<std::size_t>>> by_page_view(
      out.pages.size(), std::vector<std::vector<std::size_t>>(views.size()));
  for (std::size_t i = 0; i < patches.size(); ++i)
    by_page_view[static_cast<std::size_t>(patches[i].page)][static_cast<std::size_t>(patches[i].view)].push_back(i);
  for (std::size_t page = 0; page < out.pages.size(); ++page) {
    AtlasPage& pg = out.pages[page];
    pg.rgb.assign(static_cast<std::size_t>(pg.width) * pg.height * 3, 0);
    const std::vector<std::vector<std::size_t>>& by_view = by_page_view[page];
    // The views in turn last to first, then first to last, ...: pass 1 went first to last, so
    // the host's cache (least recently used out, plugin/keyframe_images.h) still holds the views
    // each page starts with when the images do not all fit.
    const bool backwards = page % 2 == 0;
    for (std::size_t k = 0; k < views.size(); ++k) {
      const std::size_t vi = backwards ? views.size() - 1 - k : k;
      if (by_view[vi].empty()) continue;
      if (check_cancelled) check_cancelled();
      const imr::sdk::KeyframeImage image = fetch(static_cast<uint64_t>(views[vi].index));
      const int ch = image.channels();
      for (std::size_t i : by_view[vi]) {
        const Patch& p = patches[i];
        if (p.step > 1) {
          CopyMeans(p, image, pg);
          continue;
        }
        for (int y = 0; y < p.height; ++y) {
          const uint8_t* src = image.Row(p.y0 + y) + static_cast<std::ptrdiff_t>(p.x0) * ch;
          uint8_t* dst = pg.rgb.data() + (static_cast<std::size_t>(p.py + y) * pg.width + p.px) * 3;
          for (int x = 0; x < p.width; ++x, src += ch, dst += 3) {
            if (ch == 1) {
              dst[0] = dst[1] = dst[2] = src[0];
            } else {
              dst[0] = src[2], dst[1] = src[1], dst[2] = src[0];
            }
          }
        }
      }
    }
    if (page_done) page_done(page, pg);
  }
}

}  // namespace

TexturedMesh ColorAndTexture(const imr::sdk::MeshView& mesh, std::span<const imr_camera> keyframes,
                             const KeyframeImageFetch& fetch, const TexturingOptions& options,
                             const std::function<void()>& check_cancelled,
                             const AtlasPageSink& page_done) {
  if (const std::string e = options.Check(); !e.empty()) throw std::invalid_argument(e);
  const auto start = Clock::now();
  const std::size_t nf = mesh.face_count();
  TexturedMesh out;
  out.stats.faces = static_cast<int64_t>(nf);
  out.face_page.assign(nf, -1);
  out.face_view.assign(nf, -1);
  out.face_patch.assign(nf, -1);
  out.face_uv.assign(6 * nf, 0.0f);
  const std::vector<View> views = TexturingViews(keyframes, options);
  out.stats.views = static_cast<int>(views.size());
  if (views.empty() || nf == 0) {
    out.stats.seconds_total = Since(start);
    return out;
  }

  auto t0 = Clock::now();
  VisibilityPass pass(mesh, NearPlane(mesh, views), ColourReachOf(views), options.texture);
  for (std::size_t vi = 0; vi < views.size(); ++vi) {
    if (check_cancelled) check_cancelled();
    pass.See(vi, views[vi], fetch(static_cast<uint64_t>(views[vi].index)));
  }
  VertexColours(mesh, pass, out);
  out.stats.seconds_visibility = Since(t0);
  if (!options.texture) {
    out.stats.seconds_total = Since(start);
    return out;
  }

  t0 = Clock::now();
  const std::vector<Patch> patches = LayOutAtlas(mesh, views, std::move(pass.candidates()), options, out);
  out.stats.seconds_labelling = Since(t0);

  t0 = Clock::now();
  CopyPatches(patches, views, fetch, check_cancelled, page_done, out);
  out.stats.seconds_atlas = Since(t0);
  out.stats.seconds_total = Since(start);
  return out;
}

ColourFrame ColourFrameOf(std::span<const imr_camera> keyframes, const TexturingOptions& options,
                          double extent) {
  if (const std::string e = options.Check(); !e.empty()) throw std::invalid_argument(e);
  const std::vector<View> views = TexturingViews(keyframes, options);
  ColourFrame frame;
  for (const View& v : views) {
    frame.views.push_back(v.index);
    frame.centres.push_back(v.center);
  }
  frame.near = NearPlane(extent, views);
  frame.reach = ColourReachOf(views);
  return frame;
}

std::vector<uint8_t> ColourPiece(const imr::sdk::MeshView& mesh, std::span<const imr_camera> keyframes,
                                 std::span<const int> views, const KeyframeImageFetch& fetch,
                                 double near, double reach, const std::function<void()>& check_cancelled) {
  std::vector<View> piece_views;
  for (const int i : views) {
    if (i < 0 || static_cast<std::size_t>(i) >= keyframes.size() || !View::Usable(keyframes[static_cast<std::size_t>(i)]))
      throw std::invalid_argument("ColourPiece: keyframe " + std::to_string(i) + " is not a usable view");
    piece_views.emplace_back(i, keyframes[static_cast<std::size_t>(i)]);
  }
  TexturedMesh out;
  if (mesh.face_count() == 0) {
    out.vertex_rgb.assign(3 * mesh.vertex_count(), 128);
    return std::move(out.vertex_rgb);
  }
  VisibilityPass pass(mesh, near, reach, /*texture=*/false);
  for (std::size_t vi = 0; vi < piece_views.size(); ++vi) {
    if (check_cancelled) check_cancelled();
    pass.See(vi, piece_views[vi], fetch(static_cast<uint64_t>(piece_views[vi].index)));
  }
  VertexColours(mesh, pass, out);
  return std::move(out.vertex_rgb);
}

}  // namespace imr::exporter_assimp
