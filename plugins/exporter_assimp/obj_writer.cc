#include "obj_writer.hpp"

#include <charconv>
#include <set>

namespace imr::exporter_assimp {
namespace {

template <typename T>
void AppendShortestOf(std::string* out, T x) {
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof(buf), x);
  out->append(buf, r.ptr);
}

}  // namespace

void Append(std::string* out, double x) { AppendShortestOf(out, x); }
void Append(std::string* out, float x) { AppendShortestOf(out, x); }

bool ObjNeedsMtl(const ObjMesh& mesh) {
  for (const ObjGroup& g : mesh.groups)
    if (!g.texture.empty()) return true;
  return false;
}

std::string ObjText(const ObjMesh& mesh, const std::string& mtl_file) {
  const bool mtl = ObjNeedsMtl(mesh);
  std::string out = "# imr (org.imr.exporter.assimp): one v per mesh vertex, in the mesh's order\n";
  if (mtl) out += "mtllib " + mtl_file + "\n";
  out += "# " + std::to_string(mesh.vertex_count) + " vertices\n";
  for (std::size_t i = 0; i < mesh.vertex_count; ++i) {
    out += "v";
    for (int k = 0; k < 3; ++k) out += ' ', Append(&out, mesh.vertices[3 * i + k]);
    // (b + 0.5) / 255: the same byte again after a reader's truncating * 255.
    if (mesh.vertex_rgb != nullptr)
      for (int k = 0; k < 3; ++k) out += ' ', Append(&out, (mesh.vertex_rgb[3 * i + k] + 0.5f) / 255.0f);
    out += '\n';
  }
  for (std::size_t i = 0; i < mesh.vertex_count; ++i) {
    const double* n = &(*mesh.normals)[3 * i];
    const bool zero = n[0] == 0 && n[1] == 0 && n[2] == 0;
    out += "vn";
    for (int k = 0; k < 3; ++k)
      out += ' ', Append(&out, zero ? (k == 2 ? 1.0f : 0.0f) : static_cast<float>(n[k]));
    out += '\n';
  }
  std::size_t vt = 0;  // texture coordinates written so far (one per textured corner)
  for (const ObjGroup& g : mesh.groups) {
    out += "g " + g.name + "\n";
    if (mtl) out += "usemtl " + g.material + "\n";
    for (std::size_t c = 0; c < g.uv.size(); c += 2) {
      out += "vt ";
      Append(&out, g.uv[c]);
      out += ' ';
      Append(&out, g.uv[c + 1]);
      out += '\n';
    }
    for (std::size_t f = 0; f < g.faces.size() / 3; ++f) {
      out += "f";
      for (int k = 0; k < 3; ++k) {
        const std::string v = std::to_string(g.faces[3 * f + k] + 1);
        out += ' ' + v + '/';
        if (!g.corner_uv.empty()) out += std::to_string(vt + g.corner_uv[3 * f + k] + 1);
        out += '/' + v;
      }
      out += '\n';
    }
    vt += g.uv.size() / 2;
  }
  return out;
}

std::string MtlText(const ObjMesh& mesh) {
  std::string out = "# imr (org.imr.exporter.assimp)\n";
  std::set<std::string> written;
  for (const ObjGroup& g : mesh.groups) {
    if (!written.insert(g.material).second) continue;
    out += "\nnewmtl " + g.material + "\n";
    out += g.white ? "Kd 1 1 1\n" : "Kd 0.8 0.8 0.8\n";
    out += "illum 1\n";
    if (!g.texture.empty()) out += "map_Kd " + g.texture + "\n";
  }
  return out;
}

}  // namespace imr::exporter_assimp
