#include "host/pipeline/streamed_surface.h"

#include "host/engine/mesh_topology.h"
#include "host/util/clock.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>

namespace imr::pipeline {
namespace fs = std::filesystem;

namespace {

// The spool's files (native byte order: they never leave the run).
constexpr const char* kVertices = "vertices.bin";  // per vertex: xyz (3 doubles), point id (int64)
constexpr const char* kNormals = "normals.bin";    // per vertex: normal sum (3 doubles)
constexpr const char* kFaces = "faces.bin";        // per face: 3 uint32 vertex indices
constexpr std::size_t kVertexRecord = 3 * sizeof(double) + sizeof(int64_t);
constexpr std::size_t kNormalRecord = 3 * sizeof(double);
constexpr uint32_t kNone = std::numeric_limits<uint32_t>::max();

std::string Errno() { return std::strerror(errno); }

// Reads `bytes` at `offset` of `file`; throws naming it.
void ReadAt(const fs::path& file, uint64_t offset, void* out, std::size_t bytes) {
  if (bytes == 0) return;
  const int fd = ::open(file.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) throw std::runtime_error(file.string() + ": cannot read the surface's spool: " + Errno());
  auto* p = static_cast<char*>(out);
  for (std::size_t done = 0; done < bytes;) {
    const ssize_t n = ::pread(fd, p + done, bytes - done, static_cast<off_t>(offset + done));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      const std::string why = n == 0 ? "it is truncated" : Errno();
      ::close(fd);
      throw std::runtime_error(file.string() + ": cannot read the surface's spool: " + why);
    }
    done += static_cast<std::size_t>(n);
  }
  ::close(fd);
}

}  // namespace

StreamedSurface::StreamedSurface(const engine::EngineOptions& options, fs::path spool, TileWriter* tiles)
    : stream_(engine::SurfaceStreamOptions::FromEngine(options)),
      planes_(engine::PlaneRetriangulationOptions::FromEngine(options)),
      flips_(engine::EdgeFlipOptions::FromEngine(options)),
      normal_filter_(engine::NormalFilterOptions::FromEngine(options)),
      pass_rounds_(std::max(1, options.mesh_pass_rounds)),
      spool_dir_(std::move(spool)),
      tiles_(tiles) {
  if (spool_dir_.empty()) return;
  vertices_.open(spool_dir_ / kVertices, std::ios::binary | std::ios::trunc);
  faces_file_.open(spool_dir_ / kFaces, std::ios::binary | std::ios::trunc);
  normals_fd_ = ::open((spool_dir_ / kNormals).c_str(), O_RDWR | O_CREAT | O_TRUNC | O_CLOEXEC, 0600);
  if (!vertices_ || !faces_file_ || normals_fd_ < 0)
    throw std::runtime_error(spool_dir_.string() + ": cannot write the surface's spool");
}

StreamedSurface::~StreamedSurface() {
  if (normals_fd_ >= 0) ::close(normals_fd_);
}

void StreamedSurface::Fail(const std::string& what) {
  throw std::runtime_error(spool_dir_.string() + ": cannot write the surface's spool (" + what + ")");
}

uint32_t StreamedSurface::NewSet(OpenSets& sets, int64_t open) {
  sets[next_label_] = {next_label_, open};
  return next_label_++;
}

uint32_t StreamedSurface::FindSet(OpenSets& sets, uint32_t label) {
  while (true) {
    OpenSet& s = sets.at(label);
    if (s.parent == label) return label;
    s.parent = sets.at(s.parent).parent;  // path halving
    label = s.parent;
  }
}

uint32_t StreamedSurface::UnionSets(OpenSets& sets, uint32_t a, uint32_t b) {
  a = FindSet(sets, a);
  b = FindSet(sets, b);
  if (a == b) return a;
  sets.at(b).parent = a;
  sets.at(a).open += sets.at(b).open;
  return a;
}

// The boundary edges (v, first) and (last, v) of a boundary vertex completed: each closes when
// its other end completes too; a loop with no edge left open is complete.
void StreamedSurface::CloseBoundary(const SeamVertex& v, uint32_t first, uint32_t last) {
  uint32_t label = NewSet(loops_, 0);
  std::vector<std::pair<uint32_t, uint32_t>> waiting;
  if (const auto it = loop_ends_.find(v.index); it != loop_ends_.end()) {
    waiting = std::move(it->second);
    loop_ends_.erase(it);
  }
  for (const uint32_t u : {first, last}) {
    const auto match = std::find_if(waiting.begin(), waiting.end(), [&](const auto& w) { return w.first == u; });
    if (match != waiting.end()) {
      label = UnionSets(loops_, label, match->second);
      --loops_.at(label).open;
      waiting.erase(match);
    } else {
      loop_ends_[u].emplace_back(v.index, label);
      ++loops_.at(FindSet(loops_, label)).open;
    }
  }
  const uint32_t root = FindSet(loops_, label);
  if (loops_.at(root).open == 0) {
    ++loops_done_;
    loops_.erase(root);
  }
}

// Keeps the labels something still names (a seam vertex's component, a waiting boundary edge's
// loop), each as its root: the sets stay as many as the seam's open things.
void StreamedSurface::CompactSets() {
  if (components_.size() > 2 * seam_.size() + 1024) {
    OpenSets kept;
    for (auto& [key, v] : seam_) {
      v.component = FindSet(components_, v.component);
      kept.emplace(v.component, components_.at(v.component));
    }
    components_.swap(kept);
  }
  std::size_t ends = 0;
  for (const auto& [u, w] : loop_ends_) ends += w.size();
  if (loops_.size() > 2 * ends + 1024) {
    OpenSets kept;
    for (auto& [u, w] : loop_ends_)
      for (auto& [from, label] : w) {
        label = FindSet(loops_, label);
        kept.emplace(label, loops_.at(label));
      }
    loops_.swap(kept);
  }
}

void StreamedSurface::Feed(const engine::SurfacePart& part) {
  ++stats_.engine_parts;
  if (const std::string e = stream_.Add(part); !e.empty())
    throw std::runtime_error("the surface handed out in parts does not fit together: " + e);
  engine::SurfacePart released = stream_.TakeReleased();
  // Planar regions of what was released, before the spool and the tiles write it: only vertices
  // whose whole fan is in this piece move (a seam vertex was, or will be, written elsewhere).
  // Then the flips, then the normal filter (its seam vertices stay too), mesh_pass_rounds times.
  // A piece whose fans the passes changed where other pieces meet it (a case their own rules
  // missed) is written as it came: it would fail the run at the seam.
  if (planes_.enabled() || flips_.enabled || normal_filter_.enabled()) {
    std::vector<uint32_t> faces = released.faces;
    std::vector<double> xyz = released.vertices;
    engine::PlaneRetriangulationStats planes;
    engine::EdgeFlipStats flips;
    engine::NormalFilterStats normals;
    for (int round = 0; round < pass_rounds_; ++round) {
      engine::AddRound(&planes, engine::RetriangulatePlanes(&released, planes_));
      engine::AddRound(&flips, engine::FlipEdges(&released, flips_));
      engine::AddRound(&normals, engine::FilterNormals(&released, normal_filter_));
    }
    if (const std::string e = engine::SameVertexLinks(faces, released.faces, released.keys.size()); !e.empty()) {
      released.faces.swap(faces);
      released.vertices.swap(xyz);
      if (stats_.pieces_undone++ == 0) stats_.undone_why = e;
    } else {
      stats_.planes += planes;
      stats_.flips += flips;
      stats_.normal_filter += normals;
    }
  }
  if (!spool_dir_.empty()) Spool(released);
  if (tiles_ != nullptr) tiles_->Add(released);
  stats_.stream = stream_.stats();
}

// The released triangles appended to the spool with the run's vertex indices (a vertex's index
// is the order it was first released in); a vertex's normal sum and link grow with its faces and
// are written and checked when the stream says the vertex is complete.
void StreamedSurface::Spool(const engine::SurfacePart& r) {
  if (r.faces.empty() && r.completed.empty()) return;
  std::vector<SeamVertex*> local(r.keys.size());
  for (std::size_t i = 0; i < r.keys.size(); ++i) {
    const auto [it, fresh] = seam_.try_emplace(r.keys[i]);
    if (fresh) {
      if (next_vertex_ >= kNone) Fail("more than 2^32 - 2 vertices");
      it->second.index = static_cast<uint32_t>(next_vertex_++);
      const double* p = &r.vertices[3 * i];
      for (int k = 0; k < 3; ++k) {
        bounds_[k] = it->second.index == 0 ? p[k] : std::min(bounds_[k], p[k]);
        bounds_[3 + k] = it->second.index == 0 ? p[k] : std::max(bounds_[3 + k], p[k]);
      }
      vertices_.write(reinterpret_cast<const char*>(p), 3 * sizeof(double));
      vertices_.write(reinterpret_cast<const char*>(&r.point_ids[i]), sizeof(int64_t));
      it->second.component = NewSet(components_, 1);
    }
    local[i] = &it->second;
  }
  std::vector<uint32_t> faces(r.faces.size());
  for (std::size_t f = 0; f + 2 < r.faces.size(); f += 3) {
    SeamVertex* v[3] = {local[r.faces[f]], local[r.faces[f + 1]], local[r.faces[f + 2]]};
    const double* a = &r.vertices[3 * r.faces[f]];
    const double* b = &r.vertices[3 * r.faces[f + 1]];
    const double* c = &r.vertices[3 * r.faces[f + 2]];
    // (b - a) x (c - a), as the exporters' vertex normals sum it (|n| = twice the area).
    const double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
    const double w[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    const double n[3] = {u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]};
    area_ += 0.5 * std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    for (int k = 0; k < 3; ++k) {
      faces[f + static_cast<std::size_t>(k)] = v[k]->index;
      for (int j = 0; j < 3; ++j) v[k]->normal_sum[static_cast<std::size_t>(j)] += n[j];
      v[k]->link.emplace_back(v[(k + 1) % 3]->index, v[(k + 2) % 3]->index);
    }
    UnionSets(components_, v[0]->component, UnionSets(components_, v[1]->component, v[2]->component));
  }
  faces_file_.write(reinterpret_cast<const char*>(faces.data()),
                    static_cast<std::streamsize>(faces.size() * sizeof(uint32_t)));
  faces_ += faces.size() / 3;
  for (int64_t k : r.completed)
    if (const auto it = seam_.find(k); it != seam_.end()) {
      Complete(it->second);
      seam_.erase(it);
    }
  CompactSets();
  stats_.peak_seam_vertices = std::max(stats_.peak_seam_vertices, static_cast<int64_t>(seam_.size()));
  if (!vertices_ || !faces_file_) Fail("disk full?");
  stats_.spool_bytes = static_cast<int64_t>(next_vertex_ * (kVertexRecord + kNormalRecord) +
                                            faces_ * 3 * sizeof(uint32_t));
}

// A vertex no later triangle names: its normal sum to the spool, its link checked (CheckMesh's
// test of one vertex: one fan), its boundary edges counted and joined into loops.
void StreamedSurface::Complete(SeamVertex& v) {
  const off_t at = static_cast<off_t>(uint64_t{v.index} * kNormalRecord);
  for (std::size_t done = 0; done < kNormalRecord;) {
    const ssize_t n = ::pwrite(normals_fd_, reinterpret_cast<const char*>(v.normal_sum.data()) + done,
                               kNormalRecord - done, at + static_cast<off_t>(done));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) Fail(Errno());
    done += static_cast<std::size_t>(n);
  }
  const uint32_t component = FindSet(components_, v.component);
  if (--components_.at(component).open == 0) {
    ++components_done_;
    components_.erase(component);
  }
  if (v.link.empty()) return;
  static thread_local std::vector<std::pair<uint32_t, uint32_t>> by_first;
  static thread_local std::vector<uint32_t> seconds;
  const engine::LinkShape shape = engine::CheckLink(v.link.data(), v.link.size(), &by_first, &seconds);
  if (shape == engine::LinkShape::kNotOneFan) {
    if (check_.ok) check_.message = "vertex " + std::to_string(v.index) + " is not one fan";
    check_.ok = false;
    ++statistics_.nonmanifold_vertices;
  }
  if (shape != engine::LinkShape::kPath) return;
  // A path b0 -> ... -> bn: the boundary edges at v are (v, b0) and (bn, v).
  std::vector<uint32_t>& s = seconds;
  uint32_t first = v.link[0].first, last = v.link[0].second;
  for (const auto& e : v.link) {
    if (!std::binary_search(s.begin(), s.end(), e.first)) first = e.first;
    if (std::none_of(v.link.begin(), v.link.end(), [&](const auto& o) { return o.first == e.second; }))
      last = e.second;
  }
  boundary_edges_ += 2;  // each counted again at its other end: halved in Finish
  CloseBoundary(v, first, last);
}

void StreamedSurface::Take(engine::Engine& engine) {
  const auto start = std::chrono::steady_clock::now();
  for (engine::SurfacePart& part : engine.TakeFinalParts()) {
    if (filter_) filter_(&part);
    Feed(part);
  }
  const double s = SecondsSince(start);
  stats_.seconds += s;
  stats_.max_update_seconds = std::max(stats_.max_update_seconds, s);
}

void StreamedSurface::Finish(engine::SurfacePart last) {
  const auto start = std::chrono::steady_clock::now();
  if (filter_) filter_(&last);
  Feed(last);
  if (const std::string e = stream_.Finish(); !e.empty())
    throw std::runtime_error("the surface handed out in parts is not whole: " + e);
  if (tiles_ != nullptr) tiles_->Finish();
  if (!spool_dir_.empty()) {
    // Vertices the stream released and never named complete (it keeps none once finished).
    for (auto& [key, v] : seam_) Complete(v);
    seam_ = {};
    vertices_.close();
    faces_file_.close();
    if (!vertices_ || !faces_file_ || ::fsync(normals_fd_) != 0) Fail("disk full?");
    // The topology the report gives (mesh_stats.h), without the per-component list.
    eval::MeshStatistics& s = statistics_;
    s.vertices = s.used_vertices = static_cast<int64_t>(next_vertex_);
    s.faces = static_cast<int64_t>(faces_);
    s.boundary_edges = boundary_edges_ / 2;
    s.edges = (3 * s.faces + s.boundary_edges) / 2;
    s.euler_characteristic = s.vertices - s.edges + s.faces;
    s.components = components_done_;
    s.boundary_loops = loops_done_;
    s.manifold = s.orientable = s.consistently_oriented = check_.ok;
    s.closed = s.boundary_edges == 0;
    // Every component orientable and manifold: the sum of (2 - chi_i - b_i) / 2 over them.
    s.genus = check_.ok ? (2 * s.components - s.euler_characteristic - s.boundary_loops) / 2 : -1;
    s.area = area_;
    std::copy(bounds_.begin(), bounds_.begin() + 3, s.bbox_min.begin());
    std::copy(bounds_.begin() + 3, bounds_.end(), s.bbox_max.begin());
    check_.boundary_triangles = static_cast<int64_t>(faces_);
    check_.boundary_vertices = static_cast<int64_t>(next_vertex_);
    components_ = {};
    loops_ = {};
    loop_ends_ = {};
  }
  stats_.seconds += SecondsSince(start);
}

void StreamedSurface::ReadVertices(uint64_t first, uint64_t count, double* xyz, int64_t* point_ids,
                                   double* normal_sums) const {
  if (first + count > next_vertex_) throw std::out_of_range("vertices beyond the spool's");
  if (xyz != nullptr || point_ids != nullptr) {
    std::vector<char> block(count * kVertexRecord);
    ReadAt(spool_dir_ / kVertices, first * kVertexRecord, block.data(), block.size());
    for (uint64_t i = 0; i < count; ++i) {
      const char* r = block.data() + i * kVertexRecord;
      if (xyz != nullptr) std::memcpy(xyz + 3 * i, r, 3 * sizeof(double));
      if (point_ids != nullptr) std::memcpy(point_ids + i, r + 3 * sizeof(double), sizeof(int64_t));
    }
  }
  if (normal_sums != nullptr)
    ReadAt(spool_dir_ / kNormals, first * kNormalRecord, normal_sums, count * kNormalRecord);
}

void StreamedSurface::ReadFaces(uint64_t first, uint64_t count, uint32_t* faces) const {
  if (first + count > faces_) throw std::out_of_range("faces beyond the spool's");
  ReadAt(spool_dir_ / kFaces, first * 3 * sizeof(uint32_t), faces, count * 3 * sizeof(uint32_t));
}

void StreamedSurface::ForEachTriangleBlock(
    const std::function<void(const std::vector<double>&, const std::vector<uint32_t>&)>& fn) const {
  constexpr uint64_t kBlock = 1 << 16;
  std::vector<uint32_t> faces;
  std::vector<double> vertices;
  for (uint64_t first = 0; first < faces_; first += kBlock) {
    const uint64_t n = std::min(kBlock, faces_ - first);
    faces.resize(3 * n);
    ReadFaces(first, n, faces.data());
    const auto [lo, hi] = std::minmax_element(faces.begin(), faces.end());
    const uint32_t base = *lo;
    vertices.resize(3 * (uint64_t{*hi} - base + 1));
    ReadVertices(base, *hi - base + 1, vertices.data(), nullptr, nullptr);
    for (uint32_t& v : faces) v -= base;
    fn(vertices, faces);
  }
}

engine::Mesh StreamedSurface::ReadMesh(bool canonical) const {
  engine::Mesh m;
  if (spool_dir_.empty()) return m;
  m.vertices.resize(3 * next_vertex_);
  m.point_ids.resize(next_vertex_);
  m.faces.resize(3 * faces_);
  constexpr uint64_t kBlock = 1 << 16;
  for (uint64_t i = 0; i < next_vertex_; i += kBlock)
    ReadVertices(i, std::min(kBlock, next_vertex_ - i), &m.vertices[3 * i], &m.point_ids[i], nullptr);
  for (uint64_t i = 0; i < faces_; i += kBlock)
    ReadFaces(i, std::min(kBlock, faces_ - i), &m.faces[3 * i]);
  if (canonical) engine::CanonicalizeMesh(&m);
  return m;
}

}  // namespace imr::pipeline
