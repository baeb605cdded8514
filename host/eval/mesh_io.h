// Reading meshes and point clouds for evaluation, natively: the host does not link assimp (only
// the exporter plugin does), yet must read every format that plugin writes (plugins/
// exporter_assimp/README.md), OFF (what other meshers write, for side-by-side benchmarks) and the
// usual ground-truth point formats.
//
//   .obj          v / f lines (f "i", "i/t", "i//n", "i/t/n", negative = relative); polygons are
//                 fan-triangulated; everything else (vn, vt, g, usemtl, ...) is ignored.
//   .ply          ascii, binary_little_endian, binary_big_endian; element vertex with x, y, z of
//                 any numeric type (other properties, e.g. imr's nx ny nz point_id, are skipped);
//                 element face with a list "vertex_indices" or "vertex_index" (any integer count
//                 and index types), polygons fan-triangulated; other elements skipped.
//   .gltf / .glb  glTF 2.0: every triangle primitive (mode 4, 5, 6) of the nodes of the default
//                 scene, with the nodes' transforms (matrix or TRS) applied — except the
//                 rotation of a node marked extras.imr_upright (the exporter's upright root:
//                 imr's own glTF reads back in its sequence's frame); POSITION of any
//                 component type (normalised integers as KHR_mesh_quantization), indices of any
//                 unsigned type or none; buffers from files beside it, base64 data URIs, or the
//                 GLB BIN chunk. Other attributes (NORMAL, imr's _POINT_ID) are ignored.
//   .off          ASCII OFF (what the Piazza et al. 2018 mesher writes): an "OFF" line (also COFF,
//                 NOFF, STOFF...: what follows x y z is ignored), the counts "vertices faces
//                 [edges]", one vertex per line, one face per line as "n i_1 ... i_n" (0-based;
//                 trailing colour ignored), polygons fan-triangulated; '#' comments and blank
//                 lines anywhere. Binary OFF, 4OFF and nOFF are refused.
//   .xyz .txt .asc  points only: one point per line, x y z then any further columns ignored
//                 (separated by spaces, tabs or commas); empty lines, '#' and '//' lines skipped.
//
// Every error is a std::runtime_error whose message starts with the file's path and says what is
// wrong and where (line, element, accessor), e.g. "m.ply: truncated: face 12 of 40 ends past the
// end of the file".
//
// Why not CGAL's readers (CGAL::IO::read_OBJ / read_PLY, linked here anyway; issue 19, checked on
// CGAL 5.5.1): they are less strict and lose the error. They return a bool, printing at most a
// line without the file or the field to std::cerr; they accept faces that name no vertex (OBJ
// "f 1 2 4" or "f 0 1 2" with 3 vertices, a PLY index 7 with 3 vertices), two-vertex faces and
// "0junk" as 0; and they refuse a whole OBJ for one "l" line and a PLY whose indices are uchar.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "host/util/geometry.h"

namespace imr::eval {

using ::imr::Vec3;

struct TriangleMesh {
  std::vector<Vec3> vertices;
  std::vector<std::array<uint32_t, 3>> triangles;  // indices into vertices
};

// "obj", "ply", "gltf", "glb", "off" or "xyz" (also for .txt / .asc) from the extension,
// case-insensitive; "" when it is none of them.
std::string GeometryFormat(const std::filesystem::path& path);

// Vertices and triangles of any format above (a point format gives no triangles). Throws on an
// unknown extension, a missing or unreadable file, or bad contents.
TriangleMesh ReadGeometry(const std::filesystem::path& path);

// As ReadGeometry, and also throws when the file holds no triangle or is a point format.
TriangleMesh ReadMesh(const std::filesystem::path& path);

// As ReadMesh for a .gltf / .glb, also the named per-vertex attributes of every primitive read
// (e.g. imr's `_POINT_ID`, SCALAR, and `_VERTEX_KEY`, VEC2: 3D Tiles tiles): `values[i]` holds
// attribute i for every vertex, `components[i]` values each (1 for SCALAR .. 4 for VEC4). A
// primitive without one of them, or two that disagree in type, is an error naming it.
TriangleMesh ReadGltfWithAttributes(const std::filesystem::path& path,
                                    const std::vector<std::string>& names,
                                    std::vector<std::vector<double>>* values,
                                    std::vector<int>* components);

// Total area of the triangles.
double MeshArea(const TriangleMesh& mesh);

}  // namespace imr::eval
