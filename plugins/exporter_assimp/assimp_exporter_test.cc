// The assimp exporter through the real shared object and the C ABI, as the host drives it.
// OBJ and PLY are read back with assimp's importer and compared with the input; glTF and GLB are
// checked by the Khronos glTF validator (node) and read back too. Point ids are read from the
// files with small readers below, independent of the plugin's own code.
#include <imr/sdk/host.hpp>

#include <gtest/gtest.h>
#include <sys/wait.h>

#include <algorithm>
#include <array>
#include <assimp/Importer.hpp>
#include <assimp/scene.h>
#include <boost/dll/shared_library.hpp>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <iterator>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "test_helpers.hpp"

namespace {

namespace fs = std::filesystem;
using nlohmann::json;
using namespace imr::exporter_assimp::testing;
using Point = std::array<float, 3>;
using Triangle = std::array<float, 9>;  // three corners in winding order

constexpr const char* kId = "org.imr.exporter.assimp";
const std::vector<std::string> kFormats = {"obj", "ply", "gltf", "glb"};

// ---- meshes built in code ---------------------------------------------------------------------

struct TestMesh {
  std::vector<double> vertices;
  std::vector<uint32_t> faces;
  std::vector<int64_t> ids;  // empty: no point ids

  imr_mesh_view View() const {
    imr_mesh_view v{};
    v.struct_size = sizeof(v);
    v.vertices = vertices.data();
    v.vertex_count = vertices.size() / 3;
    v.faces = faces.data();
    v.face_count = faces.size() / 3;
    v.point_ids = ids.empty() ? nullptr : ids.data();
    return v;
  }
  Point At(std::size_t i) const {
    return {static_cast<float>(vertices[3 * i]), static_cast<float>(vertices[3 * i + 1]),
            static_cast<float>(vertices[3 * i + 2])};
  }
};

// Counter-clockwise seen from outside (normals toward free space).
TestMesh Tetrahedron() {
  return {{0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1},
          {0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3},
          {0, 7, 65535, 65536}};  // around the 16-bit split of the id channel
}

// 12 triangles, away from the origin so that float rounding of positions is exercised.
TestMesh Cube() {
  TestMesh m;
  const double c[3] = {1000.1, -20.3, 3.7};  // not exact in float
  for (int i = 0; i < 8; ++i) {
    m.vertices.insert(m.vertices.end(), {c[0] + ((i & 1) ? 0.5 : -0.5),
                                         c[1] + ((i & 2) ? 0.5 : -0.5),
                                         c[2] + ((i & 4) ? 0.5 : -0.5)});
    m.ids.push_back(100 + i);
  }
  // Quads (a, b, c, d) counter-clockwise from outside, split into (a, b, c) and (a, c, d).
  const uint32_t quads[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4},
                                {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  for (const auto& q : quads) m.faces.insert(m.faces.end(), {q[0], q[1], q[2], q[0], q[2], q[3]});
  return m;
}

// An octahedron whose poles are Steiner points (-1) and whose ids reach the glTF limit (2^24).
TestMesh SteinerOctahedron() {
  return {{0, 0, 2, 1, 0, 0, 0, 1, 0, -1, 0, 0, 0, -1, 0, 0, 0, -2},
          {0, 1, 2, 0, 2, 3, 0, 3, 4, 0, 4, 1, 5, 2, 1, 5, 3, 2, 5, 4, 3, 5, 1, 4},
          {-1, 3, 65535, 1 << 24, 42, -1}};
}

// A height field of 2 * (n - 1)^2 triangles, counter-clockwise seen from above.
TestMesh Grid(int n) {
  TestMesh m;
  m.vertices.reserve(3 * n * n);
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) {
      m.vertices.insert(m.vertices.end(), {0.5 * i, 0.5 * j, 0.01 * ((i * j) % 13)});
      m.ids.push_back((i + j) % 17 == 0 ? -1 : int64_t{i} * n + j);
    }
  for (int i = 0; i + 1 < n; ++i)
    for (int j = 0; j + 1 < n; ++j) {
      const auto a = static_cast<uint32_t>(i * n + j), b = a + static_cast<uint32_t>(n);
      m.faces.insert(m.faces.end(), {a, b, b + 1, a, b + 1, a + 1});
    }
  return m;
}

// ---- comparisons ------------------------------------------------------------------------------

// The same triangle whatever corner comes first; the cyclic order (winding) is kept.
Triangle Canonical(const Point& a, const Point& b, const Point& c) {
  const std::array<Point, 3> p = {a, b, c};
  const std::size_t s = std::min_element(p.begin(), p.end()) - p.begin();
  Triangle t;
  for (std::size_t k = 0; k < 3; ++k)
    std::copy(p[(s + k) % 3].begin(), p[(s + k) % 3].end(), t.begin() + 3 * k);
  return t;
}

std::vector<Triangle> InputTriangles(const TestMesh& m) {
  std::vector<Triangle> out;
  for (std::size_t f = 0; f < m.faces.size() / 3; ++f)
    out.push_back(Canonical(m.At(m.faces[3 * f]), m.At(m.faces[3 * f + 1]), m.At(m.faces[3 * f + 2])));
  std::sort(out.begin(), out.end());
  return out;
}

std::map<Point, int64_t> InputIds(const TestMesh& m) {
  std::map<Point, int64_t> out;
  for (std::size_t i = 0; i < m.ids.size(); ++i) out[m.At(i)] = m.ids[i];
  return out;
}

struct ReadBack {
  std::vector<Triangle> triangles;  // sorted
  std::vector<std::pair<Point, Point>> position_normal;
  std::string error;
};

Point ToPoint(const aiVector3D& v) { return {v.x, v.y, v.z}; }

ReadBack ReadWithAssimp(const fs::path& file) {
  ReadBack r;
  Assimp::Importer importer;
  const aiScene* scene = importer.ReadFile(file.string(), 0);
  if (scene == nullptr) {
    r.error = importer.GetErrorString();
    return r;
  }
  for (unsigned i = 0; i < scene->mNumMeshes; ++i) {
    const aiMesh& m = *scene->mMeshes[i];
    for (unsigned f = 0; f < m.mNumFaces; ++f) {
      const aiFace& face = m.mFaces[f];
      if (face.mNumIndices != 3) {
        r.error = "face with " + std::to_string(face.mNumIndices) + " corners";
        return r;
      }
      r.triangles.push_back(Canonical(ToPoint(m.mVertices[face.mIndices[0]]),
                                      ToPoint(m.mVertices[face.mIndices[1]]),
                                      ToPoint(m.mVertices[face.mIndices[2]])));
    }
    for (unsigned v = 0; m.mNormals != nullptr && v < m.mNumVertices; ++v)
      r.position_normal.emplace_back(ToPoint(m.mVertices[v]), ToPoint(m.mNormals[v]));
  }
  std::sort(r.triangles.begin(), r.triangles.end());
  return r;
}

// Every normal is a unit vector pointing away from the centre of a convex mesh.
void ExpectOutwardUnitNormals(const ReadBack& r, const Point& centre, std::size_t vertex_count) {
  ASSERT_GE(r.position_normal.size(), vertex_count) << "normals missing";
  for (const auto& [p, n] : r.position_normal) {
    const double len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    EXPECT_NEAR(len, 1.0, 1e-5);
    const double dot = n[0] * (p[0] - centre[0]) + n[1] * (p[1] - centre[1]) + n[2] * (p[2] - centre[2]);
    EXPECT_GT(dot, 0.0) << "normal points inward at " << p[0] << " " << p[1] << " " << p[2];
  }
}

// ---- readers for point ids --------------------------------------------------------------------

struct PlyVertices {
  std::vector<std::string> properties;  // "type name"
  std::map<Point, int64_t> ids;         // empty when there is no point_id property
  std::size_t count = 0;
  bool binary_little_endian = false;
};

// Binary little-endian PLY whose vertex properties are 4-byte floats or ints.
PlyVertices ReadPly(const fs::path& file) {
  PlyVertices out;
  const std::vector<uint8_t> bytes = Slurp(file);
  const std::string text(bytes.begin(), bytes.end());
  const std::size_t end = text.find("end_header\n");
  if (end == std::string::npos) return out;
  std::istringstream header(text.substr(0, end));
  std::string line, element;
  while (std::getline(header, line)) {
    std::istringstream w(line);
    std::string key, a, b;
    w >> key >> a >> b;
    if (key == "format") out.binary_little_endian = a == "binary_little_endian";
    if (key == "element") {
      element = a;
      if (a == "vertex") out.count = std::stoul(b);
    }
    if (key == "property" && element == "vertex") out.properties.push_back(a + " " + b);
  }
  const std::size_t record = 4 * out.properties.size();
  const auto find = [&](const std::string& p) {
    return static_cast<std::size_t>(
        std::find(out.properties.begin(), out.properties.end(), p) - out.properties.begin());
  };
  const std::size_t x = find("float x"), id = find("int point_id");
  if (id == out.properties.size() || x != 0) return out;
  const uint8_t* data = bytes.data() + end + std::strlen("end_header\n");
  for (std::size_t i = 0; i < out.count; ++i) {
    const uint8_t* r = data + i * record;
    out.ids[{LoadLE<float>(r), LoadLE<float>(r + 4), LoadLE<float>(r + 8)}] =
        LoadLE<int32_t>(r + 4 * id);
  }
  return out;
}

// Position -> _POINT_ID of every primitive; empty when there is no _POINT_ID attribute.
std::map<Point, int64_t> GltfIds(const Gltf& g) {
  std::map<Point, int64_t> out;
  for (const json& mesh : g.doc["meshes"])
    for (const json& prim : mesh["primitives"]) {
      const json& attrs = prim["attributes"];
      if (!attrs.contains("_POINT_ID")) continue;
      const json& a = g.doc["accessors"][attrs["_POINT_ID"].get<std::size_t>()];
      EXPECT_EQ(a["componentType"], 5126);
      EXPECT_EQ(a["type"], "SCALAR");
      const auto pos = AccessorFloats(g, attrs["POSITION"].get<std::size_t>());
      const auto ids = AccessorFloats(g, attrs["_POINT_ID"].get<std::size_t>());
      for (std::size_t i = 0; i < ids.size(); ++i)
        out[{pos[3 * i], pos[3 * i + 1], pos[3 * i + 2]}] = static_cast<int64_t>(ids[i]);
    }
  return out;
}

// ---- fixture ----------------------------------------------------------------------------------

class AssimpExporter : public ::testing::Test {
 protected:
  void SetUp() override {
    lib_.load(IMR_EXPORTER_SO, boost::dll::load_mode::rtld_now);
    auto entry = lib_.get<const imr_plugin_descriptor*(uint32_t)>("imr_plugin_entry");
    descriptor_ = entry(0);
    ASSERT_NE(descriptor_, nullptr);
    ASSERT_EQ(entry(1), nullptr);
    dir_ = fs::temp_directory_path() /
           ("imr_exporter_test_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  // Exports and returns the main file's path; throws imr::sdk::PluginCallError on failure.
  fs::path Export(const TestMesh& mesh, const std::string& format, const std::string& params = "{}",
                  const std::string& stem = "mesh", const fs::path& dir = {}) {
    imr::sdk::Instance inst(descriptor_, params, nullptr);
    const imr_mesh_view view = mesh.View();
    const fs::path out_dir = dir.empty() ? dir_ : dir;
    const std::string d = out_dir.string();
    imr_export_request req{};
    req.mesh = &view;
    req.directory = d.c_str();
    req.stem = stem.c_str();
    req.format = format.c_str();
    inst.ExportMesh(&req);
    return out_dir / (stem + "." + format);
  }

  // The failure's status and message, or IMR_OK.
  std::pair<imr_status, std::string> ExportError(const TestMesh& mesh, const std::string& format,
                                                 const fs::path& dir = {}) {
    try {
      Export(mesh, format, "{}", "mesh", dir);
      return {IMR_OK, ""};
    } catch (const imr::sdk::PluginCallError& e) {
      return {e.status(), e.what()};
    }
  }

  void ExpectValid(const fs::path& file) { ExpectValidGltf(file); }

  boost::dll::shared_library lib_;
  const imr_plugin_descriptor* descriptor_ = nullptr;
  fs::path dir_;
};

// ---- tests ------------------------------------------------------------------------------------

TEST_F(AssimpExporter, DescriptorDeclaresFormatsAndParams) {
  EXPECT_EQ(imr::sdk::CheckDescriptor(descriptor_), "");
  EXPECT_EQ(descriptor_->kind, IMR_KIND_EXPORTER);
  EXPECT_STREQ(descriptor_->id, kId);
  EXPECT_STREQ(descriptor_->version, "1.3.0");
  EXPECT_EQ(descriptor_->abi_minor, IMR_ABI_MINOR);
  EXPECT_STREQ(descriptor_->exporter->formats, "obj,ply,gltf,glb");
  const json schema = json::parse(descriptor_->params_schema);
  ASSERT_TRUE(schema.contains("point_ids"));
  EXPECT_EQ(schema["point_ids"]["type"], "boolean");
  EXPECT_EQ(schema["point_ids"]["default"], true);
  // Colour and texture (issue 17): the job options a user sets.
  EXPECT_EQ(schema["texture"]["default"], true);
  EXPECT_EQ(schema["vertex_colors"]["default"], true);
  EXPECT_EQ(schema["atlas_size"]["default"], 4096);
  EXPECT_EQ(schema["keyframe_step"]["default"], 1);
  EXPECT_EQ(schema["upright"]["default"], true);
  EXPECT_EQ(schema.size(), 9u);
}

TEST_F(AssimpExporter, RoundTripKeepsPositionsTrianglesWindingAndNormals) {
  struct Case {
    const char* name;
    TestMesh mesh;
    Point centre;
  };
  const std::vector<Case> cases = {{"tetrahedron", Tetrahedron(), {0.25f, 0.25f, 0.25f}},
                                   {"cube", Cube(), {1000.1f, -20.3f, 3.7f}},
                                   {"steiner octahedron", SteinerOctahedron(), {0, 0, 0}}};
  for (const Case& c : cases) {
    const std::vector<Triangle> want = InputTriangles(c.mesh);
    for (const std::string& format : kFormats) {
      SCOPED_TRACE(std::string(c.name) + " as " + format);
      const fs::path file = Export(c.mesh, format, "{}", c.name[0] == 's' ? "steiner" : c.name);
      ASSERT_TRUE(fs::exists(file));
      const ReadBack r = ReadWithAssimp(file);
      ASSERT_EQ(r.error, "");
      // Same triangles, same corners in the same cyclic order: positions exact in float, and a
      // flipped winding would not match.
      EXPECT_EQ(r.triangles, want);
      ExpectOutwardUnitNormals(r, c.centre, c.mesh.vertices.size() / 3);
    }
  }
}

TEST_F(AssimpExporter, ObjIsOneFileWithoutPointIds) {
  Export(Cube(), "obj");
  std::vector<std::string> files;
  for (const auto& e : fs::directory_iterator(dir_)) files.push_back(e.path().filename().string());
  EXPECT_EQ(files, std::vector<std::string>{"mesh.obj"});  // no .mtl beside it
}

// Two tetrahedra touching at one point, as the engine leaves a pinched vertex: split into two
// vertices at the same position, one per fan (vertices 0 and 4).
TestMesh PinchedTetrahedra() {
  TestMesh m = Tetrahedron();
  m.vertices.insert(m.vertices.end(), {0, 0, 0, -1, 0, 0, 0, -1, 0, 0, 0, -1});
  m.faces.insert(m.faces.end(), {4, 6, 5, 4, 5, 7, 4, 7, 6, 5, 6, 7});
  for (double& x : m.vertices) x += 4.1e5 + 0.123456789;  // beyond float's centimetres
  m.ids.insert(m.ids.end(), {0, 8, 9, 10});
  return m;
}

// An OBJ read as MeshLab or CGAL read it: the `v` lines in order, faces by their position index.
struct ObjByIndex {
  std::vector<std::array<double, 3>> v;
  std::vector<std::array<uint32_t, 3>> f;
};

ObjByIndex ReadObjByIndex(const fs::path& file) {
  ObjByIndex out;
  const std::vector<uint8_t> bytes = Slurp(file);
  std::istringstream in(std::string(bytes.begin(), bytes.end()));
  for (std::string line; std::getline(in, line);) {
    std::istringstream l(line);
    std::string key;
    l >> key;
    if (key == "v") {
      std::array<double, 3> p{};
      l >> p[0] >> p[1] >> p[2];
      out.v.push_back(p);
    } else if (key == "f") {
      std::array<uint32_t, 3> t{};
      for (uint32_t& i : t) {
        std::string corner;
        l >> corner;
        i = static_cast<uint32_t>(std::stoul(corner.substr(0, corner.find('/')))) - 1;
      }
      out.f.push_back(t);
    }
  }
  return out;
}

TEST_F(AssimpExporter, ObjKeepsSplitVerticesAndDoublePositions) {
  const TestMesh m = PinchedTetrahedra();
  const ObjByIndex obj = ReadObjByIndex(Export(m, "obj"));
  // One `v` per mesh vertex, in order, in double: the pinched point stays two vertices.
  ASSERT_EQ(obj.v.size(), m.vertices.size() / 3);
  for (std::size_t i = 0; i < obj.v.size(); ++i)
    for (int k = 0; k < 3; ++k) EXPECT_EQ(obj.v[i][k], m.vertices[3 * i + k]) << i << " " << k;
  ASSERT_EQ(obj.f.size(), m.faces.size() / 3);
  for (std::size_t f = 0; f < obj.f.size(); ++f)
    for (int k = 0; k < 3; ++k) EXPECT_EQ(obj.f[f][k], m.faces[3 * f + k]) << f << " " << k;
}

// Vertex positions as written, in the sequence's coordinates: PLY's float x y z plus its
// "comment imr_origin", glTF's POSITION plus the root node's translation.
std::vector<std::array<double, 3>> WrittenPositions(const fs::path& file) {
  std::vector<std::array<double, 3>> out;
  std::array<double, 3> origin{};
  if (file.extension() == ".ply") {
    const std::vector<uint8_t> bytes = Slurp(file);
    const std::string text(bytes.begin(), bytes.end());
    const std::size_t body = text.find("end_header\n") + 11;
    std::istringstream header(text.substr(0, body));
    std::size_t count = 0, stride = 0;
    std::string element;
    for (std::string line; std::getline(header, line);) {
      std::istringstream w(line);
      std::string key, a, b;
      w >> key >> a >> b;
      if (key == "comment" && a == "imr_origin") {
        origin[0] = std::stod(b);
        w >> origin[1] >> origin[2];
      }
      if (key == "element") element = a, count = element == "vertex" ? std::stoul(b) : count;
      if (key == "property" && element == "vertex") stride += a == "uchar" ? 1 : 4;
    }
    for (std::size_t i = 0; i < count; ++i) {
      std::array<double, 3> p{};
      for (int k = 0; k < 3; ++k) p[k] = origin[k] + LoadLE<float>(&bytes[body + i * stride + 4 * k]);
      out.push_back(p);
    }
    return out;
  }
  const Gltf g = LoadGltf(file);
  const json& root = g.doc["nodes"][g.doc["scenes"][0]["nodes"][0].get<std::size_t>()];
  if (root.contains("translation"))
    for (int k = 0; k < 3; ++k) origin[k] = root["translation"][k].get<double>();
  const std::vector<double> v = AccessorValues(
      g, g.doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"].get<std::size_t>());
  for (std::size_t i = 0; i + 2 < v.size(); i += 3)
    out.push_back({origin[0] + v[i], origin[1] + v[i + 1], origin[2] + v[i + 2]});
  return out;
}

// Geo-referenced coordinates (UTM-sized: 5e5 east, 5e6 north) keep their centimetres in every
// format: float32 alone keeps 3 cm at 5e5 and 50 cm at 5e6.
TEST_F(AssimpExporter, FarFromTheOriginPositionsKeepCentimetres) {
  for (const double offset : {5e5, 5e6}) {
    TestMesh m = Grid(12);
    for (std::size_t i = 0; i < m.vertices.size(); ++i) m.vertices[i] += offset + 0.123456 * (i % 3);
    for (const char* format : {"ply", "gltf", "glb"}) {
      SCOPED_TRACE(std::string(format) + " at " + std::to_string(offset));
      const std::vector<std::array<double, 3>> written = WrittenPositions(Export(m, format));
      ASSERT_EQ(written.size(), m.vertices.size() / 3);
      for (const auto& p : written) {  // each written vertex is an input vertex, within 1 cm
        double best = 1e30;
        for (std::size_t i = 0; i < m.vertices.size() / 3; ++i)
          best = std::min(best, std::hypot(p[0] - m.vertices[3 * i], p[1] - m.vertices[3 * i + 1],
                                           p[2] - m.vertices[3 * i + 2]));
        EXPECT_LT(best, 0.01);
      }
    }
  }
  // Near the origin nothing changes: no origin comment, no translation.
  const std::vector<uint8_t> ply = Slurp(Export(Cube(), "ply"));
  EXPECT_EQ(std::string(ply.begin(), ply.end()).find("imr_origin"), std::string::npos);
  EXPECT_FALSE(LoadGltf(Export(Cube(), "gltf")).doc["nodes"][0].contains("translation"));
}

TEST_F(AssimpExporter, PlyKeepsPointIdsIncludingSteinerAndLargeIds) {
  TestMesh big = Tetrahedron();
  big.ids = {-1, 2147483647, 16777217, 123456789};  // beyond glTF's float range, fine in PLY
  for (const TestMesh& m : {Tetrahedron(), Cube(), SteinerOctahedron(), big}) {
    const PlyVertices ply = ReadPly(Export(m, "ply"));
    EXPECT_TRUE(ply.binary_little_endian);
    EXPECT_EQ(ply.properties, (std::vector<std::string>{"float x", "float y", "float z", "float nx",
                                                        "float ny", "float nz", "int point_id"}));
    EXPECT_EQ(ply.ids, InputIds(m));
  }
}

TEST_F(AssimpExporter, GltfAndGlbPassTheKhronosValidatorAndKeepPointIds) {
  for (const TestMesh& m : {Tetrahedron(), Cube(), SteinerOctahedron()}) {
    for (const char* format : {"gltf", "glb"}) {
      SCOPED_TRACE(format);
      const fs::path file = Export(m, format);
      ExpectValid(file);
      const Gltf g = LoadGltf(file);
      EXPECT_EQ(GltfIds(g), InputIds(m));
      const json& attrs = g.doc["meshes"][0]["primitives"][0]["attributes"];
      EXPECT_FALSE(attrs.contains("TEXCOORD_0")) << attrs.dump();  // the id channel is gone
      EXPECT_TRUE(attrs.contains("NORMAL"));
      EXPECT_EQ(g.doc["buffers"][0]["byteLength"].get<std::size_t>(),
                (6 * 4 + 4) * (m.vertices.size() / 3) + 4 * m.faces.size())
          << "buffer holds exactly positions, normals, ids and 32-bit indices";
    }
  }
  EXPECT_TRUE(fs::exists(dir_ / "mesh.bin"));  // the .gltf's companion
}

// SDK 1.2, what the host asks of 3D Tiles content: every vertex's key as `_VERTEX_KEY` (two
// vertices at one position with one point id, a pinched vertex's copies, stay two), vertices
// relative to the host's origin, the host's root rotation.
TEST_F(AssimpExporter, TileContentKeepsVertexKeysOriginAndRotation) {
  TestMesh m;
  m.vertices = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 0, -1, 0, 0, 0, -1, 0};
  for (double& x : m.vertices) x += 1000.25;
  m.faces = {0, 1, 2, 3, 4, 5};
  m.ids = {5, 6, 7, 5, 8, 9};
  const std::vector<int64_t> keys = {10, 11, (int64_t{1} << 48) - 1, (int64_t{1} << 40) + 3, 16777216, 0};
  const std::array<double, 3> origin = {1000, 1000, 1000};
  const double rotation[9] = {1, 0, 0, 0, 0, 1, 0, -1, 0};
  auto export_tile = [&](const std::vector<int64_t>& k, const std::string& format) {
    imr::sdk::Instance inst(descriptor_, "{}", nullptr);
    imr_mesh_view view = m.View();
    view.vertex_keys = k.data();
    const std::string d = dir_.string();
    imr_export_request req{};
    req.mesh = &view;
    req.directory = d.c_str();
    req.stem = "tile";
    req.format = format.c_str();
    req.origin = origin.data();
    req.gltf_rotation = rotation;
    inst.ExportMesh(&req);
    return dir_ / ("tile." + format);
  };
  const fs::path file = export_tile(keys, "glb");
  ExpectValid(file);
  const Gltf g = LoadGltf(file);
  const json& attrs = g.doc["meshes"][0]["primitives"][0]["attributes"];
  ASSERT_TRUE(attrs.contains("_VERTEX_KEY")) << attrs.dump();
  EXPECT_TRUE(attrs.contains("_POINT_ID"));
  EXPECT_FALSE(attrs.contains("TEXCOORD_0")) << attrs.dump();
  const json& a = g.doc["accessors"][attrs["_VERTEX_KEY"].get<std::size_t>()];
  EXPECT_EQ(a["type"], "VEC2");
  EXPECT_EQ(a["componentType"], 5126);
  const auto pos = AccessorFloats(g, attrs["POSITION"].get<std::size_t>());
  const auto key = AccessorFloats(g, attrs["_VERTEX_KEY"].get<std::size_t>());
  ASSERT_EQ(pos.size(), 18u);  // six vertices: the two at (0, 0, 0) are kept apart
  std::map<int64_t, std::size_t> seen;
  for (std::size_t i = 0; i < 6; ++i) {
    const int64_t k = static_cast<int64_t>(key[2 * i]) * 16777216 + static_cast<int64_t>(key[2 * i + 1]);
    const auto at = std::find(keys.begin(), keys.end(), k);
    ASSERT_NE(at, keys.end()) << k;
    const std::size_t v = static_cast<std::size_t>(at - keys.begin());
    seen[k] = v;
    for (int c = 0; c < 3; ++c) EXPECT_DOUBLE_EQ(pos[3 * i + c] + origin[c], m.vertices[3 * v + c]);
  }
  EXPECT_EQ(seen.size(), 6u);
  // The host's rotation at the root (column-major), the origin on the node of the mesh.
  const json& root = g.doc["nodes"][g.doc["scenes"][0]["nodes"][0].get<std::size_t>()];
  EXPECT_EQ(root["name"], "imr_upright");
  EXPECT_EQ(root["matrix"], json({1, 0, 0, 0, 0, 0, -1, 0, 0, 1, 0, 0, 0, 0, 0, 1}));
  const json& child = g.doc["nodes"][root["children"][0].get<std::size_t>()];
  EXPECT_EQ(child["translation"], json({1000.0, 1000.0, 1000.0}));
  // PLY has no place for keys: written without them. A key beyond 48 bits is refused.
  const PlyVertices ply = ReadPly(export_tile(keys, "ply"));
  EXPECT_EQ(ply.count, 6u);
  std::vector<int64_t> bad = keys;
  bad[1] = int64_t{1} << 48;
  try {
    export_tile(bad, "glb");
    ADD_FAILURE() << "a 49-bit key was accepted";
  } catch (const imr::sdk::PluginCallError& e) {
    EXPECT_EQ(e.status(), IMR_INVALID_ARGUMENT);
    EXPECT_NE(std::string(e.what()).find("vertex key of vertex 1"), std::string::npos) << e.what();
  }
}

TEST_F(AssimpExporter, PointIdsOffOrAbsentWritesNoIdAttribute) {
  TestMesh no_ids = Cube();
  no_ids.ids.clear();
  const std::vector<std::pair<TestMesh, std::string>> cases = {{Cube(), R"({"point_ids": false})"},
                                                               {no_ids, "{}"}};
  for (const auto& [mesh, params] : cases) {
    SCOPED_TRACE(params);
    const PlyVertices ply = ReadPly(Export(mesh, "ply", params));
    EXPECT_EQ(ply.properties.size(), 6u);  // x y z nx ny nz
    EXPECT_TRUE(ply.ids.empty());
    for (const char* format : {"gltf", "glb"}) {
      const fs::path file = Export(mesh, format, params);
      ExpectValid(file);
      const Gltf g = LoadGltf(file);
      const json& attrs = g.doc["meshes"][0]["primitives"][0]["attributes"];
      EXPECT_EQ(attrs.size(), 2u) << attrs.dump();  // POSITION, NORMAL
      EXPECT_TRUE(ReadWithAssimp(file).error.empty());
    }
  }
}

TEST_F(AssimpExporter, MillionTrianglesExportInLinearTime) {
  const TestMesh grid = Grid(708);  // 1,000,000 triangles, 501,264 vertices
  ASSERT_EQ(grid.faces.size() / 3, 2u * 707 * 707);
  for (const std::string& format : kFormats) {
    const auto t0 = std::chrono::steady_clock::now();
    const fs::path file = Export(grid, format, "{}", "grid");
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::cout << format << ": " << seconds << " s, " << fs::file_size(file) << " bytes\n";
    // ~0.2-0.8 s here; anything quadratic in 1e6 would take hours.
    EXPECT_LT(seconds, 30.0) << format;
  }
  ExpectValid(dir_ / "grid.glb");
  EXPECT_EQ(GltfIds(LoadGltf(dir_ / "grid.glb")), InputIds(grid));
  EXPECT_EQ(ReadPly(dir_ / "grid.ply").ids, InputIds(grid));
}

TEST_F(AssimpExporter, EmptyMeshIsAClearErrorAndWritesNothing) {
  const TestMesh empty = {{0, 0, 0}, {}, {5}};
  for (const std::string& format : kFormats) {
    const auto [status, message] = ExportError(empty, format);
    EXPECT_EQ(status, IMR_INVALID_ARGUMENT) << format;
    EXPECT_NE(message.find("no faces"), std::string::npos) << message;
  }
  EXPECT_TRUE(fs::is_empty(dir_));
}

TEST_F(AssimpExporter, BadInputIsAnInvalidArgumentNamingTheProblem) {
  const auto expect = [&](const TestMesh& m, const std::string& format,
                          std::vector<std::string> words) {
    const auto [status, message] = ExportError(m, format);
    EXPECT_EQ(status, IMR_INVALID_ARGUMENT) << format << ": " << message;
    for (const std::string& w : words) EXPECT_NE(message.find(w), std::string::npos) << message;
  };
  expect(Cube(), "stl", {"unknown format \"stl\"", "obj, ply, gltf, glb"});
  TestMesh m = Tetrahedron();
  m.faces[4] = 9;
  for (const std::string& f : kFormats) expect(m, f, {"face 1", "index 9", "out of range", "4 vertices"});
  m = Tetrahedron();
  m.vertices[7] = std::numeric_limits<double>::quiet_NaN();
  for (const std::string& f : kFormats) expect(m, f, {"vertex 2", "coordinate y", "not a finite"});
  m = Tetrahedron();
  m.vertices[0] = 1e300;  // finite in double, infinite in float
  expect(m, "ply", {"vertex 0", "coordinate x"});
  m = Tetrahedron();
  m.faces[2] = m.faces[0];
  expect(m, "glb", {"face 0", "repeats a vertex"});
  m = Tetrahedron();
  m.ids[3] = (int64_t{1} << 24) + 1;  // not exact in glTF's FLOAT attribute
  expect(m, "gltf", {"point id of vertex 3", "16777217", "\"point_ids\": false"});
  expect(m, "glb", {"point id of vertex 3"});
  EXPECT_NO_THROW(Export(m, "gltf", R"({"point_ids": false})"));
  EXPECT_NO_THROW(Export(m, "obj"));  // OBJ keeps no ids: nothing to check
  m.ids[3] = -2;
  expect(m, "ply", {"point id of vertex 3", "-2"});
  m.ids[3] = int64_t{1} << 31;
  expect(m, "ply", {"2147483648"});
  const auto [status, message] = [&] {
    try {
      Export(Cube(), "ply", "{}", "../escape");
      return std::pair<imr_status, std::string>{IMR_OK, ""};
    } catch (const imr::sdk::PluginCallError& e) {
      return std::pair<imr_status, std::string>{e.status(), e.what()};
    }
  }();
  EXPECT_EQ(status, IMR_INVALID_ARGUMENT) << message;
  EXPECT_NE(message.find("stem"), std::string::npos) << message;
}

TEST_F(AssimpExporter, UnknownOrMistypedParamsAreRefused) {
  for (const char* params : {R"({"point_id": true})", R"({"point_ids": "yes"})", "[1"}) {
    try {
      imr::sdk::Instance inst(descriptor_, params, nullptr);
      ADD_FAILURE() << "accepted " << params;
    } catch (const imr::sdk::PluginCallError& e) {
      EXPECT_EQ(e.status(), IMR_INVALID_ARGUMENT) << params;
      EXPECT_NE(std::string(e.what()).find("params"), std::string::npos) << e.what();
    }
  }
}

TEST_F(AssimpExporter, UnwritableDirectoryIsAnErrorNamingThePath) {
  const fs::path missing = dir_ / "does_not_exist";
  std::ofstream(dir_ / "a_file") << "x";
  for (const fs::path& dir : {missing, dir_ / "a_file"}) {
    for (const std::string& format : kFormats) {
      const auto [status, message] = ExportError(Cube(), format, dir);
      EXPECT_EQ(status, IMR_ERROR) << format << ": " << message;
      EXPECT_NE(message.find((dir / ("mesh." + format)).string()), std::string::npos)
          << format << ": " << message;
    }
  }
  EXPECT_FALSE(fs::exists(missing));
}

// ---- meshes in blocks (SDK 1.3) ---------------------------------------------------------------

// Whether the plugin took the stream (false: it asked for the whole mesh and wrote nothing).
bool ExportStream(const imr_plugin_descriptor* d, StreamedTestMesh& m, const std::string& format,
                  const fs::path& dir, const std::string& params = "{}", bool images = false) {
  imr::sdk::Instance inst(d, params, nullptr);
  const imr_mesh_stream stream = m.Stream();
  const std::string dir_text = dir.string();
  imr_export_request req{};
  req.directory = dir_text.c_str();
  req.stem = "mesh";
  req.format = format.c_str();
  imr_camera camera{};
  if (images) {
    req.keyframes = &camera;
    req.keyframe_count = 1;
    req.keyframe_images = 1;
  }
  return inst.ExportMeshStream(&req, &stream);
}

// The mesh with its vertices renumbered in the order the faces first name them: the order the
// host's spool gives a long drive's vertices (the order they are first released), and the one
// the whole-mesh PLY writes (assimp's vertices are made corner by corner).
TestMesh InFirstUseOrder(const TestMesh& m) {
  TestMesh out;
  std::vector<uint32_t> index(m.vertices.size() / 3, UINT32_MAX);
  for (uint32_t v : m.faces) {
    if (index[v] == UINT32_MAX) {
      index[v] = static_cast<uint32_t>(out.vertices.size() / 3);
      out.vertices.insert(out.vertices.end(), &m.vertices[3 * v], &m.vertices[3 * v] + 3);
      if (!m.ids.empty()) out.ids.push_back(m.ids[v]);
    }
    out.faces.push_back(index[v]);
  }
  return out;
}

// PLY and OBJ in blocks are the whole-mesh files byte for byte (PLY: but the line that names the
// writer), far from the origin too; a grid larger than one block is read in several.
TEST_F(AssimpExporter, MeshInBlocksWritesTheSameFilesAsTheWholeMesh) {
  TestMesh far = Grid(300);  // 89,401 vertices, 178,802 triangles: more than a block of each
  for (std::size_t i = 0; i < far.vertices.size(); ++i) far.vertices[i] += 5e5 + 0.123456 * (i % 3);
  far = InFirstUseOrder(far);
  for (const TestMesh* m : {&far}) {
    for (const std::string format : {"ply", "obj"})
      for (const std::string params : {"{}", R"({"point_ids": false})"}) {
        SCOPED_TRACE(format + " " + params);
        const fs::path whole_dir = dir_ / "whole", blocks_dir = dir_ / "blocks";
        fs::create_directories(whole_dir);
        fs::create_directories(blocks_dir);
        const fs::path whole = Export(*m, format, params, "mesh", whole_dir);
        StreamedTestMesh streamed(m->vertices, m->faces, m->ids);
        ASSERT_TRUE(ExportStream(descriptor_, streamed, format, blocks_dir, params));
        EXPECT_GT(streamed.reads, 4);
        EXPECT_LE(streamed.largest_read, std::size_t{1} << 16);
        std::string a = [&] { auto b = Slurp(whole); return std::string(b.begin(), b.end()); }();
        std::string b = [&] { auto x = Slurp(blocks_dir / ("mesh." + format)); return std::string(x.begin(), x.end()); }();
        if (format == "ply") {
          const std::size_t at = a.find("comment Created by Open Asset Import Library");
          const std::size_t bt = b.find("comment Written in blocks by org.imr.exporter.assimp");
          ASSERT_NE(at, std::string::npos);
          ASSERT_NE(bt, std::string::npos);
          a.erase(at, a.find('\n', at) - at);
          b.erase(bt, b.find('\n', bt) - bt);
          EXPECT_NE(a.find("comment imr_origin 500000 500000 500000"), std::string::npos);
        }
        EXPECT_EQ(a.size(), b.size());
        const auto diff = std::mismatch(a.begin(), a.end(), b.begin(), b.end());
        EXPECT_TRUE(a == b) << "the files differ from byte " << (diff.first - a.begin()) << " of "
                            << a.size() << " (the header ends at " << a.find("end_header") + 11 << ")";
        fs::remove_all(whole_dir);
        fs::remove_all(blocks_dir);
      }
  }
}

// What needs the whole mesh is refused with nothing written: glTF/GLB, and an OBJ with colours or
// a texture from keyframe images; a host that fails to read is an error naming what it read.
TEST_F(AssimpExporter, MeshInBlocksRefusesWhatNeedsTheWholeMesh) {
  const TestMesh cube = Cube();
  StreamedTestMesh streamed(cube.vertices, cube.faces, cube.ids);
  for (const char* format : {"gltf", "glb"}) EXPECT_FALSE(ExportStream(descriptor_, streamed, format, dir_));
  EXPECT_FALSE(ExportStream(descriptor_, streamed, "obj", dir_, "{}", /*images=*/true));
  EXPECT_FALSE(ExportStream(descriptor_, streamed, "obj", dir_, R"({"vertex_colors": false})", /*images=*/true));
  EXPECT_TRUE(fs::is_empty(dir_));
  EXPECT_TRUE(ExportStream(descriptor_, streamed, "obj", dir_,
                           R"({"vertex_colors": false, "texture": false})", /*images=*/true));
  // A coloured PLY is made in blocks (texture_test: the same file as the whole mesh's); without a
  // usable keyframe (this one has no intrinsics) it has no colours, as the whole mesh's has none.
  EXPECT_TRUE(ExportStream(descriptor_, streamed, "ply", dir_, "{}", /*images=*/true));
  const std::vector<uint8_t> ply = Slurp(dir_ / "mesh.ply");
  const std::string text(ply.begin(), ply.end());
  EXPECT_EQ(text.substr(0, text.find("end_header")).find("red"), std::string::npos);
  StreamedTestMesh lying(cube.vertices, cube.faces, cube.ids);
  lying.claimed_faces = 13;  // one more than it can read
  try {
    ExportStream(descriptor_, lying, "ply", dir_);
    ADD_FAILURE() << "a failed read was not an error";
  } catch (const imr::sdk::PluginCallError& e) {
    EXPECT_EQ(e.status(), IMR_ERROR);
    EXPECT_NE(std::string(e.what()).find("reading the mesh's faces: faces 0.. beyond the mesh"),
              std::string::npos) << e.what();
  }
}

}  // namespace
