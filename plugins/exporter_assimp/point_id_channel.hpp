// Point ids through assimp. assimp has no per-vertex integer attribute, and its glTF exporter
// always runs JoinIdenticalVertices (which reorders vertices and drops unused ones). So each
// vertex's id rides through assimp in texture-coordinate channel 0 as two exactly representable
// floats, and once assimp has written the file that channel is turned into a proper integer
// attribute: PLY `property int point_id`, glTF `_POINT_ID` (SCALAR FLOAT). Because the
// id travels with its vertex, whatever assimp does to vertex order stays right, and two vertices
// with different ids are never merged (their texture coordinates differ).
#pragma once

#include <cstdint>
#include <filesystem>
#include <limits>

namespace imr::exporter_assimp {

// Ids the channel carries: -1 (Steiner) .. INT32_MAX (a PLY int).
constexpr int64_t kMinPointId = -1;
constexpr int64_t kMaxPointId = std::numeric_limits<int32_t>::max();
// glTF forbids UNSIGNED_INT vertex attributes (validator: MESH_PRIMITIVE_ATTRIBUTES_ACCESSOR_
// UNSIGNED_INT), so `_POINT_ID` is FLOAT, as EXT_mesh_features does for feature ids: exact for
// integers up to 2^24.
constexpr int64_t kMaxGltfPointId = int64_t{1} << 24;

// id + 1 split into 16-bit halves: both below 2^24, so exact in float.
struct EncodedPointId {
  float hi;
  float lo;
};
EncodedPointId EncodePointId(int64_t id);
// Inverse of EncodePointId; false when (hi, lo) is not an encoding (never happens unless a
// writer changed the channel).
bool DecodePointId(double hi, double lo, int64_t* id);

// Rewrite a binary little-endian PLY written by assimp: the float properties `s t` become
// `int point_id`. Throws std::runtime_error naming the file on any surprise.
void ConvertPlyPointIds(const std::filesystem::path& ply);

// Rewrite a glTF (JSON + .bin) or GLB written by assimp: every primitive's TEXCOORD_0 becomes
// `_POINT_ID` (SCALAR FLOAT, Steiner = -1; ids must not exceed kMaxGltfPointId), and the freed
// bytes are removed from the buffer. Throws std::runtime_error naming the file.
void ConvertGltfPointIds(const std::filesystem::path& gltf_or_glb, bool binary);

}  // namespace imr::exporter_assimp
