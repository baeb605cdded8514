// Evaluation inputs (host/eval): meshes and clouds read natively (mesh_io.h ReadGeometry: PLY,
// OBJ, glTF, GLB, OFF, XYZ) and KITTI Velodyne .bin scans (ground_truth.h ReadVelodyneScan). The
// first byte picks the format; the rest is the file.
#include <cstddef>
#include <cstdint>
#include <string>

#include "host/eval/ground_truth.h"
#include "host/eval/mesh_io.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  static const char* const kExt[] = {"ply", "obj", "gltf", "glb", "xyz", "bin", "off"};
  const std::string ext = kExt[data[0] % 7];
  const auto file = imr::fuzz::ScratchDir() / ("input." + ext);
  imr::fuzz::WriteFile(file, {reinterpret_cast<const char*>(data + 1), size - 1});
  imr::fuzz::ExpectOnlyDocumentedErrors([&] {
    if (ext == "bin") {
      (void)imr::eval::ReadVelodyneScan(file);
    } else {
      const imr::eval::TriangleMesh m = imr::eval::ReadGeometry(file);
      for (const auto& t : m.triangles)
        for (uint32_t v : t)
          if (v >= m.vertices.size()) __builtin_trap();  // a reader must never hand out a bad index
      (void)imr::eval::MeshArea(m);
    }
  });
  return 0;
}
