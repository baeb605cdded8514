// Helpers shared by the exporter's tests: raw file reading, a small glTF loader (JSON + buffer),
// the Khronos glTF validator (node, tools/node) and a mesh behind the SDK's mesh stream. Test
// code only.
#pragma once

#include <imr/sdk/plugin.h>
#include <sys/wait.h>

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <gtest/gtest.h>
#include <iostream>
#include <iterator>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace imr::exporter_assimp::testing {

namespace fs = std::filesystem;
using nlohmann::json;

inline std::vector<uint8_t> Slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

template <typename T>
inline T LoadLE(const uint8_t* p) {
  T v;
  std::memcpy(&v, p, sizeof(T));
  return v;
}

struct Gltf {
  json doc;
  std::vector<uint8_t> bin;
};

inline Gltf LoadGltf(const fs::path& file) {
  Gltf g;
  const std::vector<uint8_t> bytes = Slurp(file);
  if (file.extension() == ".glb") {
    const auto json_len = LoadLE<uint32_t>(bytes.data() + 12);
    g.doc = json::parse(bytes.begin() + 20, bytes.begin() + 20 + json_len);
    const std::size_t bin_at = 20 + json_len;
    g.bin.assign(bytes.begin() + static_cast<std::ptrdiff_t>(bin_at + 8), bytes.end());
  } else {
    g.doc = json::parse(bytes.begin(), bytes.end());
    g.bin = Slurp(file.parent_path() / g.doc["buffers"][0]["uri"].get<std::string>());
  }
  return g;
}

// The numbers of an accessor (FLOAT, or unsigned integer components, e.g. indices), by element
// and component, as doubles; normalised integers are not scaled.
inline std::vector<double> AccessorValues(const Gltf& g, std::size_t index) {
  const json& a = g.doc["accessors"][index];
  const json& v = g.doc["bufferViews"][a["bufferView"].get<std::size_t>()];
  const std::string type = a["type"];
  const std::size_t components = type == "SCALAR" ? 1 : type == "VEC2" ? 2 : type == "VEC3" ? 3 : 4;
  const int ct = a["componentType"];
  const std::size_t size = ct == 5126 || ct == 5125 ? 4 : ct == 5123 ? 2 : 1;
  const std::size_t stride = v.value("byteStride", components * size);
  const std::size_t at = v.value("byteOffset", std::size_t{0}) + a.value("byteOffset", std::size_t{0});
  const std::size_t n = a["count"].get<std::size_t>();
  std::vector<double> out;
  out.reserve(n * components);
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t c = 0; c < components; ++c) {
      const uint8_t* p = g.bin.data() + at + i * stride + c * size;
      out.push_back(ct == 5126   ? LoadLE<float>(p)
                    : ct == 5125 ? LoadLE<uint32_t>(p)
                    : ct == 5123 ? LoadLE<uint16_t>(p)
                                 : *p);
    }
  return out;
}

// Floats of a FLOAT accessor.
inline std::vector<float> AccessorFloats(const Gltf& g, std::size_t index) {
  const std::vector<double> v = AccessorValues(g, index);
  return {v.begin(), v.end()};
}

// ---- the validator ----------------------------------------------------------------------------

struct Validation {
  int exit_code = -1;
  std::string output;
};

inline Validation RunValidator(const fs::path& file) {
  Validation v;
  const std::string cmd = std::string("'") + IMR_NODE_EXECUTABLE + "' '" + IMR_VALIDATE_GLTF_JS +
                          "' '" + IMR_NODE_MODULES + "' '" + file.string() + "' 2>&1";
  FILE* pipe = popen(cmd.c_str(), "r");
  if (pipe == nullptr) return v;
  char buf[4096];
  while (std::fgets(buf, sizeof(buf), pipe) != nullptr) v.output += buf;
  const int status = pclose(pipe);
  v.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return v;
}

// Asserts that the Khronos validator reports no error for `file` (and prints its report).
inline void ExpectValidGltf(const fs::path& file) {
  ASSERT_FALSE(std::string(IMR_NODE_EXECUTABLE).empty())
      << "node was not found when configuring: run the set-up script in tools/ "
         "(it installs nodejs and runs npm ci --prefix tools/node), then re-run cmake";
  ASSERT_TRUE(fs::exists(IMR_NODE_EXECUTABLE)) << "node missing: " << IMR_NODE_EXECUTABLE;
  ASSERT_TRUE(fs::exists(fs::path(IMR_NODE_MODULES) / "gltf-validator" / "package.json"))
      << "the glTF validator is not installed in " << IMR_NODE_MODULES
      << ": run the set-up script in tools/ (npm ci --prefix tools/node)";
  const Validation v = RunValidator(file);
  EXPECT_EQ(v.exit_code, 0) << "glTF validator report for " << file << ":\n" << v.output;
  EXPECT_NE(v.output.find("summary: 0 errors"), std::string::npos) << v.output;
  std::cout << v.output;  // warnings and infos, for the record
}

// A mesh in memory behind imr_mesh_stream, as the host serves a long drive's spool: normal sums as
// plugin.h defines them (face order, (b - a) x (c - a)); every read counted.
struct StreamedTestMesh {
  const std::vector<double>* vertices = nullptr;
  const std::vector<uint32_t>* faces = nullptr;
  const std::vector<int64_t>* ids = nullptr;  // empty: no point ids
  std::vector<double> sums;
  int reads = 0;
  std::size_t largest_read = 0;
  std::size_t claimed_faces = 0;  // non-zero: the face count the stream claims

  StreamedTestMesh(const std::vector<double>& v, const std::vector<uint32_t>& f,
                   const std::vector<int64_t>& point_ids)
      : vertices(&v), faces(&f), ids(&point_ids), sums(v.size(), 0.0) {
    for (std::size_t t = 0; t + 2 < f.size(); t += 3) {
      const uint32_t a = f[t], b = f[t + 1], c = f[t + 2];
      const double u[3] = {v[3 * b] - v[3 * a], v[3 * b + 1] - v[3 * a + 1], v[3 * b + 2] - v[3 * a + 2]};
      const double w[3] = {v[3 * c] - v[3 * a], v[3 * c + 1] - v[3 * a + 1], v[3 * c + 2] - v[3 * a + 2]};
      const double n[3] = {u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]};
      for (uint32_t i : {a, b, c})
        for (int k = 0; k < 3; ++k) sums[3 * i + k] += n[k];
    }
  }
  imr_mesh_stream Stream() {
    imr_mesh_stream s{};
    s.struct_size = sizeof(s);
    s.vertex_count = (*vertices).size() / 3;
    s.face_count = claimed_faces != 0 ? claimed_faces : (*faces).size() / 3;
    for (int k = 0; k < 3; ++k) {
      s.bounds[k] = s.bounds[3 + k] = (*vertices)[k];
      for (std::size_t i = 0; i < s.vertex_count; ++i) {
        s.bounds[k] = std::min(s.bounds[k], (*vertices)[3 * i + k]);
        s.bounds[3 + k] = std::max(s.bounds[3 + k], (*vertices)[3 * i + k]);
      }
    }
    s.context = this;
    s.read_vertices = [](void* c, uint64_t first, uint64_t count, double* xyz, int64_t* out_ids,
                         double* normal_sums, imr_error*) -> imr_status {
      auto* self = static_cast<StreamedTestMesh*>(c);
      ++self->reads;
      self->largest_read = std::max<std::size_t>(self->largest_read, count);
      for (uint64_t i = first; i < first + count; ++i) {
        for (int k = 0; k < 3; ++k) {
          if (xyz) xyz[3 * (i - first) + k] = (*self->vertices)[3 * i + k];
          if (normal_sums) normal_sums[3 * (i - first) + k] = self->sums[3 * i + k];
        }
        if (out_ids) out_ids[i - first] = (*self->ids).empty() ? -1 : (*self->ids)[i];
      }
      return IMR_OK;
    };
    s.read_faces = [](void* c, uint64_t first, uint64_t count, uint32_t* out_faces, imr_error* e) -> imr_status {
      auto* self = static_cast<StreamedTestMesh*>(c);
      ++self->reads;
      if (first + count > (*self->faces).size() / 3) {
        std::snprintf(e->message, sizeof(e->message), "faces %llu.. beyond the mesh",
                      static_cast<unsigned long long>(first));
        return IMR_ERROR;
      }
      std::copy_n((*self->faces).begin() + static_cast<std::ptrdiff_t>(3 * first), 3 * count, out_faces);
      return IMR_OK;
    };
    return s;
  }
};


}  // namespace imr::exporter_assimp::testing
