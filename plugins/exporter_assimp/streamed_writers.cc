#include "streamed_writers.hpp"

#include "obj_writer.hpp"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <vector>

namespace imr::exporter_assimp {
namespace fs = std::filesystem;

namespace {

constexpr std::size_t kBlock = 1 << 16;  // vertices or faces per read

// A file written in blocks; the first failure throws with the file's name.
class Output {
 public:
  explicit Output(const fs::path& path) : path_(path), out_(path, std::ios::binary | std::ios::trunc) {
    if (!out_) Fail("cannot write");
  }
  void Write(const void* bytes, std::size_t size) {
    out_.write(static_cast<const char*>(bytes), static_cast<std::streamsize>(size));
    if (!out_) Fail("write failed");
  }
  void Write(const std::string& text) { Write(text.data(), text.size()); }
  void Close() {
    out_.close();
    if (!out_) Fail("write failed");
  }

 private:
  [[noreturn]] void Fail(const char* what) {
    throw std::runtime_error(path_.string() + ": " + what + ": " + std::strerror(errno));
  }
  fs::path path_;
  std::ofstream out_;
};

// The unit normal VertexNormals gives from a sum, and the (0, 0, 1) the writers put for none.
std::array<float, 3> UnitNormal(const double* sum) {
  const double len = std::sqrt(sum[0] * sum[0] + sum[1] * sum[1] + sum[2] * sum[2]);
  if (!(len > 0 && std::isfinite(len))) return {0.0f, 0.0f, 1.0f};
  std::array<double, 3> n{};
  for (int k = 0; k < 3; ++k) n[static_cast<std::size_t>(k)] = sum[k] / len;
  if (n[0] == 0 && n[1] == 0 && n[2] == 0) return {0.0f, 0.0f, 1.0f};
  return {static_cast<float>(n[0]), static_cast<float>(n[1]), static_cast<float>(n[2])};
}

}  // namespace

void WriteStreamedPly(const imr::sdk::MeshStream& mesh, const fs::path& path, bool point_ids,
                      int64_t max_point_id, const std::array<double, 3>& origin,
                      const std::function<void()>& poll, const VertexColourBlock& colours) {
  const std::size_t nv = mesh.vertex_count(), nf = mesh.face_count();
  std::ostringstream h;
  h << "ply\nformat binary_little_endian 1.0\n";
  if (origin != std::array<double, 3>{}) {
    h.precision(17);
    h << "comment imr_origin " << origin[0] << ' ' << origin[1] << ' ' << origin[2]
      << " (add it to every vertex for the sequence's coordinates)\n";
  }
  if (point_ids) h << "comment point_id: id of the vertex's 3D point, -1 for Steiner points\n";
  h << "comment Written in blocks by org.imr.exporter.assimp (the mesh was too long to hold)\n"
    << "element vertex " << nv << "\n"
    << "property float x\nproperty float y\nproperty float z\n"
    << "property float nx\nproperty float ny\nproperty float nz\n";
  if (point_ids) h << "property int point_id\n";
  if (colours) h << "property uchar red\nproperty uchar green\nproperty uchar blue\n";
  h << "element face " << nf << "\nproperty list uchar int vertex_index\nend_header\n";
  Output out(path);
  out.Write(h.str());

  const std::size_t id_at = 6 * sizeof(float), rgb_at = id_at + (point_ids ? sizeof(int32_t) : 0);
  const std::size_t record = rgb_at + (colours ? 3 : 0);
  std::vector<double> xyz(3 * kBlock), sums(3 * kBlock);
  std::vector<int64_t> ids(kBlock);
  std::vector<uint8_t> rgb(colours ? 3 * kBlock : 0);
  std::vector<unsigned char> bytes;
  for (std::size_t first = 0; first < nv; first += kBlock) {
    const std::size_t n = std::min(kBlock, nv - first);
    mesh.ReadVertices(first, n, xyz.data(), point_ids ? ids.data() : nullptr, sums.data());
    if (colours) colours(first, n, rgb.data());
    bytes.resize(n * record);
    for (std::size_t i = 0; i < n; ++i) {
      float f[6];
      for (int k = 0; k < 3; ++k) f[k] = static_cast<float>(xyz[3 * i + static_cast<std::size_t>(k)] - origin[static_cast<std::size_t>(k)]);
      const std::array<float, 3> normal = UnitNormal(&sums[3 * i]);
      std::copy(normal.begin(), normal.end(), f + 3);
      unsigned char* r = bytes.data() + i * record;
      std::memcpy(r, f, sizeof(f));
      if (point_ids) {
        if (ids[i] < -1 || ids[i] > max_point_id)
          throw imr::sdk::InvalidArgument(
              "point id of vertex " + std::to_string(first + i) + " is " + std::to_string(ids[i]) +
              ": ply holds ids -1 (Steiner) .. " + std::to_string(max_point_id) +
              " exactly (export without point ids: \"point_ids\": false)");
        const auto id = static_cast<int32_t>(ids[i]);
        std::memcpy(r + id_at, &id, sizeof(id));
      }
      if (colours) std::memcpy(r + rgb_at, &rgb[3 * i], 3);
    }
    out.Write(bytes.data(), bytes.size());
    poll();
  }
  std::vector<uint32_t> faces(3 * kBlock);
  for (std::size_t first = 0; first < nf; first += kBlock) {
    const std::size_t n = std::min(kBlock, nf - first);
    mesh.ReadFaces(first, n, faces.data());
    bytes.resize(n * 13);
    for (std::size_t f = 0; f < n; ++f) {
      unsigned char* r = bytes.data() + f * 13;
      r[0] = 3;
      for (int k = 0; k < 3; ++k) {
        const auto v = static_cast<int32_t>(faces[3 * f + static_cast<std::size_t>(k)]);
        std::memcpy(r + 1 + 4 * k, &v, sizeof(v));
      }
    }
    out.Write(bytes.data(), bytes.size());
    poll();
  }
  out.Close();
}

void WriteStreamedObj(const imr::sdk::MeshStream& mesh, const fs::path& path, const std::string& name,
                      const std::function<void()>& poll) {
  const std::size_t nv = mesh.vertex_count(), nf = mesh.face_count();
  Output out(path);
  out.Write("# imr (org.imr.exporter.assimp): one v per mesh vertex, in the mesh's order\n# " +
            std::to_string(nv) + " vertices\n");
  std::vector<double> xyz(3 * kBlock), sums(3 * kBlock);
  std::string text;
  for (std::size_t first = 0; first < nv; first += kBlock) {
    const std::size_t n = std::min(kBlock, nv - first);
    mesh.ReadVertices(first, n, xyz.data(), nullptr, nullptr);
    text.clear();
    for (std::size_t i = 0; i < n; ++i) {
      text += "v";
      for (std::size_t k = 0; k < 3; ++k) text += ' ', Append(&text, xyz[3 * i + k]);
      text += '\n';
    }
    out.Write(text);
    poll();
  }
  for (std::size_t first = 0; first < nv; first += kBlock) {
    const std::size_t n = std::min(kBlock, nv - first);
    mesh.ReadVertices(first, n, nullptr, nullptr, sums.data());
    text.clear();
    for (std::size_t i = 0; i < n; ++i) {
      const std::array<float, 3> normal = UnitNormal(&sums[3 * i]);
      text += "vn";
      for (float x : normal) text += ' ', Append(&text, x);
      text += '\n';
    }
    out.Write(text);
    poll();
  }
  out.Write("g " + name + "\n");
  std::vector<uint32_t> faces(3 * kBlock);
  for (std::size_t first = 0; first < nf; first += kBlock) {
    const std::size_t n = std::min(kBlock, nf - first);
    mesh.ReadFaces(first, n, faces.data());
    text.clear();
    for (std::size_t f = 0; f < n; ++f) {
      text += "f";
      for (std::size_t k = 0; k < 3; ++k) {
        const std::string v = std::to_string(faces[3 * f + k] + 1);
        text += ' ' + v + "//" + v;
      }
      text += '\n';
    }
    out.Write(text);
    poll();
  }
  out.Close();
}

}  // namespace imr::exporter_assimp
