#include "streamed_colours.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <unordered_map>
#include <utility>

namespace imr::exporter_assimp {

namespace {

using Box = std::array<double, 6>;
using Point = std::array<double, 3>;

// Indices at most this far apart are read in one run (the rest of the run is read and dropped).
constexpr uint32_t kRunGap = 64;
// Pixels of footprint the box around the views is widened by: visibility looks a pixel around a
// vertex's projection (rounded), so a face up to ~2.2 pixels off the line of sight can decide it.
constexpr double kMarginPixels = 4.0;

Box EmptyBox() {
  constexpr double inf = std::numeric_limits<double>::infinity();
  return {inf, inf, inf, -inf, -inf, -inf};
}
bool IsEmpty(const Box& b) { return !(b[0] <= b[3]); }
void Grow(Box& b, const double* p) {
  for (int k = 0; k < 3; ++k) {
    b[static_cast<std::size_t>(k)] = std::min(b[static_cast<std::size_t>(k)], p[k]);
    b[static_cast<std::size_t>(k) + 3] = std::max(b[static_cast<std::size_t>(k) + 3], p[k]);
  }
}
void Grow(Box& b, const Box& o) {
  Grow(b, o.data());
  Grow(b, o.data() + 3);
}
bool Meets(const Box& a, const Box& b) {
  for (std::size_t k = 0; k < 3; ++k)
    if (a[k] > b[k + 3] || b[k] > a[k + 3]) return false;
  return true;
}
double Distance(const Point& p, const Box& b) {
  double d2 = 0.0;
  for (std::size_t k = 0; k < 3; ++k) {
    const double d = std::max({b[k] - p[k], 0.0, p[k] - b[k + 3]});
    d2 += d * d;
  }
  return std::sqrt(d2);
}
double FarthestCorner(const Point& p, const Box& b) {
  double d2 = 0.0;
  for (std::size_t k = 0; k < 3; ++k) {
    const double d = std::max(std::fabs(p[k] - b[k]), std::fabs(p[k] - b[k + 3]));
    d2 += d * d;
  }
  return std::sqrt(d2);
}

// Whether the camera may see some of the box: none when the box lies behind the camera's plane;
// when it straddles the plane, it may; else its corners' projections must meet the image
// (widened by a pixel).
bool MaySee(const imr_camera& c, const Box& b) {
  double lo[2] = {std::numeric_limits<double>::infinity(), std::numeric_limits<double>::infinity()};
  double hi[2] = {-lo[0], -lo[1]};
  int behind = 0;
  for (int corner = 0; corner < 8; ++corner) {
    double p[3], x[3];
    for (int k = 0; k < 3; ++k) p[k] = ((corner >> k) & 1) ? b[static_cast<std::size_t>(k) + 3] : b[static_cast<std::size_t>(k)];
    for (int r = 0; r < 3; ++r) x[r] = c.R[3 * r] * p[0] + c.R[3 * r + 1] * p[1] + c.R[3 * r + 2] * p[2] + c.t[r];
    if (!(x[2] > 0.0)) {
      ++behind;
      continue;
    }
    const double u = c.K[0] * x[0] / x[2] + c.K[2];  // as the rasteriser projects (no skew)
    const double v = c.K[4] * x[1] / x[2] + c.K[5];
    lo[0] = std::min(lo[0], u), hi[0] = std::max(hi[0], u);
    lo[1] = std::min(lo[1], v), hi[1] = std::max(hi[1], v);
  }
  if (behind == 8) return false;
  if (behind > 0) return true;
  return hi[0] >= -1.0 && hi[1] >= -1.0 && lo[0] <= c.width + 1.0 && lo[1] <= c.height + 1.0;
}

}  // namespace

StreamedVertexColours::StreamedVertexColours(const imr::sdk::MeshStream& mesh,
                                             std::span<const imr_camera> keyframes,
                                             KeyframeImageFetch fetch, const TexturingOptions& options,
                                             std::function<void()> check_cancelled)
    : mesh_(mesh), keyframes_(keyframes), fetch_(std::move(fetch)),
      check_cancelled_(std::move(check_cancelled)) {
  const auto start = std::chrono::steady_clock::now();
  double extent = 0.0;
  for (double x : mesh.bounds()) extent = std::max(extent, std::fabs(x));
  frame_ = ColourFrameOf(keyframes, options, extent);
  std::vector<uint32_t> faces(3 * kFaceBlock), ids;
  std::vector<double> xyz;
  for (std::size_t first = 0; first < mesh.face_count(); first += kFaceBlock) {
    const std::size_t n = std::min(kFaceBlock, mesh.face_count() - first);
    mesh.ReadFaces(first, n, faces.data());
    ids.assign(faces.begin(), faces.begin() + static_cast<std::ptrdiff_t>(3 * n));
    std::sort(ids.begin(), ids.end());
    ids.erase(std::unique(ids.begin(), ids.end()), ids.end());
    ReadPositions(ids, &xyz);
    FaceBlock block;
    block.lo = ids.front();
    block.hi = ids.back();
    block.box = EmptyBox();
    for (std::size_t i = 0; i < ids.size(); ++i) Grow(block.box, &xyz[3 * i]);
    blocks_.push_back(block);
    if (check_cancelled_) check_cancelled_();
  }
  stats_.seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

void StreamedVertexColours::ReadPositions(const std::vector<uint32_t>& indices, std::vector<double>* xyz) const {
  xyz->resize(3 * indices.size());
  std::vector<double> run;
  for (std::size_t i = 0; i < indices.size();) {
    std::size_t j = i + 1;
    while (j < indices.size() && indices[j] - indices[j - 1] <= kRunGap) ++j;
    const uint32_t lo = indices[i], count = indices[j - 1] - lo + 1;
    run.resize(3 * static_cast<std::size_t>(count));
    mesh_.ReadVertices(lo, count, run.data(), nullptr, nullptr);
    for (std::size_t k = i; k < j; ++k)
      std::copy_n(&run[3 * static_cast<std::size_t>(indices[k] - lo)], 3, &(*xyz)[3 * k]);
    i = j;
  }
}

void StreamedVertexColours::Colour(std::size_t first, std::size_t count, uint8_t* rgb) {
  const auto start = std::chrono::steady_clock::now();
  std::fill(rgb, rgb + 3 * count, uint8_t{128});
  if (count == 0) return;
  ++stats_.blocks;
  const std::size_t last = first + count - 1;
  std::vector<uint32_t> faces(3 * kFaceBlock), ids;
  std::vector<double> xyz;
  // Reads face block b; fn(face's three indices, its box) per face.
  auto for_each_face = [&](std::size_t b, const auto& fn) {
    const std::size_t f0 = b * kFaceBlock, n = std::min(kFaceBlock, mesh_.face_count() - f0);
    mesh_.ReadFaces(f0, n, faces.data());
    ids.assign(faces.begin(), faces.begin() + static_cast<std::ptrdiff_t>(3 * n));
    std::sort(ids.begin(), ids.end());
    ids.erase(std::unique(ids.begin(), ids.end()), ids.end());
    ReadPositions(ids, &xyz);
    auto at = [&](uint32_t v) {
      return &xyz[3 * static_cast<std::size_t>(std::lower_bound(ids.begin(), ids.end(), v) - ids.begin())];
    };
    for (std::size_t f = 0; f < n; ++f) {
      const uint32_t* t = &faces[3 * f];
      const double* p[3] = {at(t[0]), at(t[1]), at(t[2])};
      Box box = EmptyBox();
      for (const double* q : p) Grow(box, q);
      fn(t, p, box);
    }
  };

  // The box of the block's faces: each vertex's whole fan lies in it.
  Box block = EmptyBox();
  for (std::size_t b = 0; b < blocks_.size(); ++b) {
    if (blocks_[b].hi < first || blocks_[b].lo > last) continue;
    for_each_face(b, [&](const uint32_t* t, const double* const*, const Box& box) {
      for (int k = 0; k < 3; ++k)
        if (t[k] >= first && t[k] <= last) {
          Grow(block, box);
          break;
        }
    });
  }
  if (IsEmpty(block)) return;  // vertices without faces: grey, as in the whole mesh

  // The views within reach that may see it, and the box around them and it.
  std::vector<int> views;
  Box piece = block;
  double far = 0.0, focal = std::numeric_limits<double>::infinity();
  for (std::size_t j = 0; j < frame_.views.size(); ++j) {
    const Point& c = frame_.centres[j];
    const imr_camera& cam = keyframes_[static_cast<std::size_t>(frame_.views[j])];
    if (Distance(c, block) > frame_.reach || !MaySee(cam, block)) continue;
    views.push_back(frame_.views[j]);
    Grow(piece, c.data());
    far = std::max(far, FarthestCorner(c, block));
    focal = std::min({focal, cam.K[0], cam.K[4]});
  }
  if (!views.empty()) {
    const double margin = kMarginPixels * far / focal;
    for (std::size_t k = 0; k < 3; ++k) piece[k] -= margin, piece[k + 3] += margin;
  }

  // The piece: every face that meets that box, in file order.
  std::vector<double> vertices;
  std::vector<uint32_t> piece_faces;
  std::unordered_map<uint32_t, uint32_t> local;
  for (std::size_t b = 0; b < blocks_.size(); ++b) {
    if (!Meets(blocks_[b].box, piece)) continue;
    for_each_face(b, [&](const uint32_t* t, const double* const* p, const Box& box) {
      if (!Meets(box, piece)) return;
      for (int k = 0; k < 3; ++k) {
        const auto [it, added] = local.try_emplace(t[k], static_cast<uint32_t>(local.size()));
        if (added) vertices.insert(vertices.end(), p[k], p[k] + 3);
        piece_faces.push_back(it->second);
      }
    });
    if (check_cancelled_) check_cancelled_();
  }
  const imr::sdk::MeshView view{{vertices.data(), vertices.size()}, {piece_faces.data(), piece_faces.size()}, {}, {}, {}};
  const std::vector<uint8_t> colours =
      ColourPiece(view, keyframes_, views, fetch_, frame_.near, frame_.reach, check_cancelled_);
  for (const auto& [global, l] : local)
    if (global >= first && global <= last)
      std::copy_n(&colours[3 * static_cast<std::size_t>(l)], 3, rgb + 3 * (global - first));

  const auto nf = static_cast<int64_t>(piece_faces.size() / 3);
  stats_.piece_faces += nf;
  stats_.max_piece_faces = std::max(stats_.max_piece_faces, nf);
  stats_.views += static_cast<int64_t>(views.size());
  stats_.seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace imr::exporter_assimp
