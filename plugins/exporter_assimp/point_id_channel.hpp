// Point ids through assimp. assimp has no per-vertex integer attribute, and its glTF exporter
// always runs JoinIdenticalVertices (which reorders vertices and drops unused ones). So each
// vertex's id rides through assimp in texture-coordinate channel 0 as two exactly representable
// floats, and once assimp has written the file that channel is turned into a proper integer
// attribute: PLY `property int point_id`, glTF `_POINT_ID` (SCALAR FLOAT). (Behind a texture
// atlas's coordinates, channel 0, the ids ride in channel 1.) Because the id travels with its vertex, whatever assimp does to vertex order stays right, and two vertices
// with different ids are never merged (their texture coordinates differ).
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <limits>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

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

// Vertex keys (SDK 1.2, tiles): 0 .. 2^48 - 1, split into 24-bit halves (exact in float), which
// is also how `_VERTEX_KEY` (VEC2 FLOAT) holds them: key = x * 2^24 + y.
constexpr int64_t kMaxVertexKey = (int64_t{1} << 48) - 1;
struct EncodedVertexKey {
  float hi;
  float lo;
};
EncodedVertexKey EncodeVertexKey(int64_t key);

// Rewrite a binary little-endian PLY written by assimp: with `point_ids`, the float properties
// `s t` become `int point_id`; vertex colours become `uchar red green blue` (assimp 5.2 declares
// uchar but writes four floats; alpha is dropped). Throws std::runtime_error naming the file on
// any surprise.
void RewritePly(const std::filesystem::path& ply, bool point_ids);

// A glTF as assimp wrote it, loaded for editing: the JSON and its one buffer.
struct GltfDocument {
  std::filesystem::path file;
  bool binary = false;                 // GLB (else .gltf + the .bin its buffer names)
  nlohmann::json doc;
  std::vector<uint8_t> buffer;         // buffers[0], byteLength bytes
  std::filesystem::path buffer_file;   // .gltf only
};

// Loads `file` (GLB when `binary`), lets `edit` change it, and writes it back (the .bin too).
// Throws std::runtime_error naming the file on any surprise.
void EditGltf(const std::filesystem::path& file, bool binary,
              const std::function<void(GltfDocument&)>& edit);

// Every primitive's point-id channel (its highest-numbered TEXCOORD_n: TEXCOORD_0, or TEXCOORD_1
// behind a texture's coordinates) becomes `_POINT_ID` (SCALAR FLOAT, Steiner = -1; ids must not
// exceed kMaxGltfPointId), and the freed bytes are removed from the buffer.
void ConvertGltfPointIds(GltfDocument& gltf);

// The vertex-key channel (the last texture channel, behind the point ids: ConvertGltfPointIds
// after this) becomes `_VERTEX_KEY` (VEC2 FLOAT, key = x * 2^24 + y) in place.
void ConvertGltfVertexKeys(GltfDocument& gltf);

// Puts the scene's root nodes under a new root node "imr_upright" whose matrix is `rotation`
// (row-major 3x3, world -> glTF), marked with extras {"imr_upright": {...}} so that imr's own
// readers can read the vertices in the sequence's frame. `view_from` and `view_to` (world
// coordinates: the first keyframe's centre and one a few keyframes on; both may be null) are
// recorded there in glTF coordinates, for viewers that want to open at the start of the camera
// path. `about` says where the rotation comes from.
void SetUprightNode(GltfDocument& gltf, const double rotation[9], const double view_from[3],
                    const double view_to[3], const std::string& about);

// Geo-referenced coordinates (UTM-sized) lose centimetres in float32, which assimp writes: PLY
// and glTF/GLB vertices are written relative to a local origin. ExportOrigin: 0 when every
// coordinate is within kOriginFreeRange (float keeps better than a millimetre there, and the
// files stay as they were), else the bounding box's centre rounded to a whole kilometre. The host
// records the same rule's origin in report.json (host/pipeline/mesh_export.h); keep both equal.
constexpr double kOriginFreeRange = 1e4;
std::array<double, 3> ExportOrigin(const double* vertices, std::size_t vertex_count);
// Adds "comment imr_origin X Y Z" (shortest round-trip decimals) after the PLY's format line:
// the vertices are relative to it (imr's PLY reader adds it back).
void AddPlyOrigin(const std::filesystem::path& ply, const std::array<double, 3>& origin);
// Sets `translation` (double, as JSON numbers are) on the scene's root nodes, which hold the
// mesh: call before SetUprightNode, which puts them under its rotation.
void SetGltfOrigin(GltfDocument& gltf, const std::array<double, 3>& origin);

}  // namespace imr::exporter_assimp
