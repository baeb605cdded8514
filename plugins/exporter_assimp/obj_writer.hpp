// OBJ (+ MTL) written by the plugin itself, not by assimp: assimp 5.2's OBJ writer keys its `v`
// lines by position (and colour), so the vertices the engine split at a pinched point (same
// position, different fans) became one `v` again and a reader that indexes by position (MeshLab,
// CGAL) saw a singular vertex. Here every mesh vertex is one `v` line, in the mesh's order, its
// position in double (shortest text that reads back to the same double), so OBJ needs no local
// origin.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace imr::exporter_assimp {

// One group of faces with one material (an atlas page, or the faces without texture).
struct ObjGroup {
  std::string name;      // `g` name
  std::string material;  // `usemtl` name
  std::string texture;   // the material's map_Kd (a file beside the .obj), "" for none
  bool white = false;    // Kd 1 1 1 (under a texture or vertex colours), else 0.8 grey
  std::vector<uint32_t> faces;  // 3 mesh vertex indices per face
  // Texture coordinates (u, v; v up from the bottom as OBJ has it), 2 per `vt`, and the `vt`
  // (0-based, into this group's) of each corner, 3 per face; both empty: none.
  std::vector<float> uv;
  std::vector<uint32_t> corner_uv;
};

struct ObjMesh {
  const double* vertices = nullptr;  // 3 per vertex
  std::size_t vertex_count = 0;
  const std::vector<double>* normals = nullptr;  // 3 per vertex; a zero normal is written 0 0 1
  const uint8_t* vertex_rgb = nullptr;           // 3 per vertex, or null: no colours
  std::vector<ObjGroup> groups;
};

// The shortest text that reads back to the same value, appended.
void Append(std::string* out, double x);
void Append(std::string* out, float x);

// The .obj text (and `mtl_file` named by mtllib when some group has a texture).
std::string ObjText(const ObjMesh& mesh, const std::string& mtl_file);
// The .mtl text: each material the groups name, once, in group order.
std::string MtlText(const ObjMesh& mesh);
// True when some group has a texture (an .mtl goes beside the .obj).
bool ObjNeedsMtl(const ObjMesh& mesh);

}  // namespace imr::exporter_assimp
