// PLY and OBJ written from a mesh read in blocks (SDK 1.3's mesh stream): the single mesh of a
// long drive, which the host keeps on disk, is never held whole here either. For a plain mesh
// (no colours, no texture) these are the files the whole-mesh path writes: the same vertex
// records (float positions relative to the origin, normals normalised from the host's sums as
// VertexNormals does, point ids), faces and OBJ text; the PLY header names this writer where the
// other names assimp.
#pragma once

#include <imr/sdk/plugin.hpp>

#include <array>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>

namespace imr::exporter_assimp {

// The colours of vertices [first, first + count), 3 bytes (RGB) each into rgb.
using VertexColourBlock = std::function<void(std::size_t first, std::size_t count, uint8_t* rgb)>;

// Binary little-endian PLY: x y z nx ny nz (float) [int point_id] [uchar red green blue], faces
// as uchar 3 + 3 int (the whole-mesh path's layout). `origin` non-zero: "comment imr_origin" and
// positions relative to it. Throws std::runtime_error naming the file when a write fails,
// imr::sdk::InvalidArgument naming the vertex when a point id is outside -1 .. max_point_id (the
// host discards what was written). `poll` runs between blocks; `colours`, when set, is asked for
// each block of vertices in order.
void WriteStreamedPly(const imr::sdk::MeshStream& mesh, const std::filesystem::path& path,
                      bool point_ids, int64_t max_point_id, const std::array<double, 3>& origin,
                      const std::function<void()>& poll, const VertexColourBlock& colours = {});

// OBJ as ObjText writes a mesh with one untextured group named `name`.
void WriteStreamedObj(const imr::sdk::MeshStream& mesh, const std::filesystem::path& path,
                      const std::string& name, const std::function<void()>& poll);

}  // namespace imr::exporter_assimp
