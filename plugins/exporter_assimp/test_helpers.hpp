// Helpers shared by the exporter's tests: raw file reading, a small glTF loader (JSON + buffer)
// and the Khronos glTF validator (node, tools/node). Test code only.
#pragma once

#include <sys/wait.h>

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

}  // namespace imr::exporter_assimp::testing
