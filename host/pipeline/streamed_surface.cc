#include "host/pipeline/streamed_surface.h"

#include "host/util/clock.h"

#include <algorithm>
#include <chrono>
#include <cstring>
#include <stdexcept>
#include <unordered_map>

namespace imr::pipeline {
namespace fs = std::filesystem;

namespace {

// The spool: one record per released part, native byte order (it never leaves the run):
// vertex count, index count, then keys, point ids, xyz, face indices.
template <typename T>
void Put(std::ofstream& out, const std::vector<T>& v) {
  out.write(reinterpret_cast<const char*>(v.data()), static_cast<std::streamsize>(v.size() * sizeof(T)));
}
template <typename T>
bool Get(std::ifstream& in, std::vector<T>* v, std::size_t n) {
  v->resize(n);
  return static_cast<bool>(in.read(reinterpret_cast<char*>(v->data()), static_cast<std::streamsize>(n * sizeof(T))));
}

}  // namespace

StreamedSurface::StreamedSurface(const engine::EngineOptions& options, fs::path spool, TileWriter* tiles)
    : stream_(engine::SurfaceStreamOptions::FromEngine(options)), spool_path_(std::move(spool)), tiles_(tiles) {
  if (!spool_path_.empty()) {
    spool_.open(spool_path_, std::ios::binary | std::ios::trunc);
    if (!spool_) throw std::runtime_error(spool_path_.string() + ": cannot write the surface's spool");
  }
}

void StreamedSurface::Feed(const engine::SurfacePart& part) {
  ++stats_.engine_parts;
  if (const std::string e = stream_.Add(part); !e.empty())
    throw std::runtime_error("the surface handed out in parts does not fit together: " + e);
  const engine::SurfacePart released = stream_.TakeReleased();
  if (spool_.is_open() && !released.faces.empty()) {
    const uint64_t counts[2] = {released.keys.size(), released.faces.size()};
    spool_.write(reinterpret_cast<const char*>(counts), sizeof(counts));
    Put(spool_, released.keys);
    Put(spool_, released.point_ids);
    Put(spool_, released.vertices);
    Put(spool_, released.faces);
    if (!spool_) throw std::runtime_error(spool_path_.string() + ": cannot write the surface's spool (disk full?)");
    stats_.spool_bytes = static_cast<int64_t>(spool_.tellp());
  }
  if (tiles_ != nullptr) tiles_->Add(released);
  stats_.stream = stream_.stats();
}

void StreamedSurface::Take(engine::Engine& engine) {
  const auto start = std::chrono::steady_clock::now();
  for (const engine::SurfacePart& part : engine.TakeFinalParts()) Feed(part);
  const double s = SecondsSince(start);
  stats_.seconds += s;
  stats_.max_update_seconds = std::max(stats_.max_update_seconds, s);
}

void StreamedSurface::Finish(engine::Engine& engine) {
  const auto start = std::chrono::steady_clock::now();
  Feed(engine.FinishSurface());
  if (const std::string e = stream_.Finish(); !e.empty())
    throw std::runtime_error("the surface handed out in parts is not whole: " + e);
  if (tiles_ != nullptr) tiles_->Finish();
  if (spool_.is_open()) {
    spool_.close();
    if (!spool_) throw std::runtime_error(spool_path_.string() + ": cannot write the surface's spool");
  }
  stats_.seconds += SecondsSince(start);
}

engine::Mesh StreamedSurface::ReadMesh(bool canonical) {
  engine::Mesh m;
  if (spool_path_.empty()) return m;
  std::ifstream in(spool_path_, std::ios::binary);
  if (!in) throw std::runtime_error(spool_path_.string() + ": cannot read the surface's spool");
  std::unordered_map<int64_t, uint32_t> index;
  std::vector<int64_t> keys, ids;
  std::vector<double> xyz;
  std::vector<uint32_t> faces;
  for (uint64_t counts[2]; in.read(reinterpret_cast<char*>(counts), sizeof(counts));) {
    if (!Get(in, &keys, counts[0]) || !Get(in, &ids, counts[0]) || !Get(in, &xyz, 3 * counts[0]) ||
        !Get(in, &faces, counts[1]))
      throw std::runtime_error(spool_path_.string() + ": the surface's spool is truncated");
    std::vector<uint32_t> local(keys.size());
    for (std::size_t i = 0; i < keys.size(); ++i) {
      const auto [it, fresh] = index.emplace(keys[i], static_cast<uint32_t>(m.point_ids.size()));
      if (fresh) {
        m.vertices.insert(m.vertices.end(), &xyz[3 * i], &xyz[3 * i] + 3);
        m.point_ids.push_back(ids[i]);
      }
      local[i] = it->second;
    }
    for (uint32_t f : faces) m.faces.push_back(local.at(f));
  }
  index = {};
  if (canonical) engine::CanonicalizeMesh(&m);
  return m;
}

}  // namespace imr::pipeline
