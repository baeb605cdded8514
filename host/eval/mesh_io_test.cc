// Mesh and point readers on files written by hand: every format and encoding the exporter plugin
// writes (OBJ, binary PLY, glTF, GLB), OFF (other meshers' output) and the ground-truth point
// formats, plus the errors for bad files. The real exporter's files are read in
// tests/evaluate_test.cc.
#include "host/eval/mesh_io.h"

#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cstring>
#include <fstream>
#include <random>
#include <unistd.h>

namespace imr::eval {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

class MeshIo : public ::testing::Test {
 protected:
  MeshIo() {
    dir_ = fs::temp_directory_path() /
           ("imr-mesh-io-" + std::to_string(::getpid()) + "-" + std::to_string(std::random_device{}()));
    fs::create_directories(dir_);
  }
  ~MeshIo() override { fs::remove_all(dir_); }
  fs::path Write(const std::string& name, const std::string& bytes) {
    const fs::path p = dir_ / name;
    std::ofstream(p, std::ios::binary) << bytes;
    return p;
  }
  // The error message of ReadGeometry(p), "" when it succeeds.
  static std::string ErrorOf(const fs::path& p) {
    try {
      ReadGeometry(p);
    } catch (const std::runtime_error& e) {
      return e.what();
    }
    return "";
  }
  fs::path dir_;
};

template <typename T>
void Put(std::string* s, T v, bool big_endian = false) {
  char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  if (big_endian) std::reverse(b, b + sizeof(T));
  s->append(b, sizeof(T));
}

void ExpectVertex(const TriangleMesh& m, std::size_t i, Vec3 v, double tol = 1e-12) {
  ASSERT_LT(i, m.vertices.size());
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(m.vertices[i][k], v[k], tol) << "vertex " << i << " " << k;
}

TEST_F(MeshIo, ObjPolygonsAreFanTriangulatedAndIndexFormsAccepted) {
  const auto p = Write("quad.obj",
                       "# a unit quad and a triangle with negative indices\n"
                       "mtllib none.mtl\no quad\n"
                       "v 0 0 0\nv 1 0 0\r\nv 1 1 0\nv 0 1 0\n"
                       "vt 0 0\nvn 0 0 1\n"
                       "f 1/1/1 2/1/1 3/1/1 4/1/1\n"
                       "v 5 5 5\n"
                       "f -1//1 1//1 2//1\n"
                       "l 1 2\n");
  const TriangleMesh m = ReadMesh(p);
  ASSERT_EQ(m.vertices.size(), 5u);
  ASSERT_EQ(m.triangles.size(), 3u);
  EXPECT_EQ(m.triangles[0], (std::array<uint32_t, 3>{0, 1, 2}));
  EXPECT_EQ(m.triangles[1], (std::array<uint32_t, 3>{0, 2, 3}));
  EXPECT_EQ(m.triangles[2], (std::array<uint32_t, 3>{4, 0, 1}));
  EXPECT_DOUBLE_EQ(MeshArea({m.vertices, {m.triangles[0], m.triangles[1]}}), 1.0);
}

TEST_F(MeshIo, ObjErrorsNameTheFileAndLine) {
  auto e = ErrorOf(Write("bad.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n"));
  EXPECT_NE(e.find("bad.obj"), std::string::npos) << e;
  EXPECT_NE(e.find("vertex index 6"), std::string::npos) << e;
  e = ErrorOf(Write("bad2.obj", "v 0 0 zero\n"));
  EXPECT_NE(e.find("line 1"), std::string::npos) << e;
  EXPECT_NE(e.find("zero"), std::string::npos) << e;
  e = ErrorOf(Write("bad3.obj", "v 0 0 0\nf 1 1\n"));
  EXPECT_NE(e.find("line 2"), std::string::npos) << e;
}

TEST_F(MeshIo, PlyAsciiSkipsOtherPropertiesAndElements) {
  const auto p = Write("a.ply",
                       "ply\nformat ascii 1.0\ncomment hand made\n"
                       "element vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
                       "property float nx\nproperty int point_id\n"
                       "element face 1\nproperty list uchar int vertex_indices\nproperty uchar flags\n"
                       "element edge 1\nproperty int vertex1\nproperty int vertex2\n"
                       "end_header\n"
                       "0 0 0 1 7\n2 0 0 1 8\n2 2 0 1 -1\n0 2 0.5 1 9\n"
                       "4 0 1 2 3 5\n"
                       "0 1\n");
  const TriangleMesh m = ReadMesh(p);
  ASSERT_EQ(m.vertices.size(), 4u);
  ASSERT_EQ(m.triangles.size(), 2u);
  ExpectVertex(m, 3, {0, 2, 0.5});
  EXPECT_EQ(m.triangles[1], (std::array<uint32_t, 3>{0, 2, 3}));
}

// imr's exporter writes far-away vertices relative to "comment imr_origin X Y Z".
TEST_F(MeshIo, PlyImrOriginIsAddedBack) {
  const auto p = Write("far.ply",
                       "ply\nformat ascii 1.0\ncomment imr_origin 500000 5000000 -1000 (add it)\n"
                       "element vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                       "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
                       "0.125 0.5 1\n1 0 0\n0 1 0\n3 0 1 2\n");
  const TriangleMesh m = ReadMesh(p);
  ExpectVertex(m, 0, {500000.125, 5000000.5, -999});
  EXPECT_NE(ErrorOf(Write("bad.ply", "ply\nformat ascii 1.0\ncomment imr_origin 1 x 3 y\n"
                                     "element vertex 0\nproperty float x\nproperty float y\n"
                                     "property float z\nend_header\n")).find("bad imr_origin"),
            std::string::npos);
}

// Binary PLY as imr's exporter writes it (float xyz, normals, int point_id, uchar/int
// vertex_index), and in big-endian with double coordinates and uint indices.
std::string BinaryPly(bool big_endian) {
  std::string s = std::string("ply\nformat ") +
                  (big_endian ? "binary_big_endian" : "binary_little_endian") + " 1.0\n" +
                  "comment point_id: id of the vertex's 3D point\n"
                  "element vertex 3\n" +
                  (big_endian ? "property double x\nproperty double y\nproperty double z\n"
                              : "property float x\nproperty float y\nproperty float z\n") +
                  "property float nx\nproperty float ny\nproperty float nz\nproperty int point_id\n"
                  "element face 1\n" +
                  (big_endian ? "property list ushort uint vertex_indices\n"
                              : "property list uchar int vertex_index\n") +
                  "end_header\n";
  const double v[3][3] = {{1.5, 0, 0}, {0, 2.25, 0}, {0, 0, -3}};
  for (int i = 0; i < 3; ++i) {
    for (int k = 0; k < 3; ++k) {
      if (big_endian) Put<double>(&s, v[i][k], true);
      else Put<float>(&s, static_cast<float>(v[i][k]));
    }
    for (int k = 0; k < 3; ++k) Put<float>(&s, 0.5f, big_endian);
    Put<int32_t>(&s, 100 + i, big_endian);
  }
  if (big_endian) {
    Put<uint16_t>(&s, 3, true);
    for (uint32_t i : {2u, 1u, 0u}) Put<uint32_t>(&s, i, true);
  } else {
    Put<uint8_t>(&s, 3);
    for (int32_t i : {2, 1, 0}) Put<int32_t>(&s, i);
  }
  return s;
}

TEST_F(MeshIo, PlyBinaryLittleAndBigEndian) {
  for (bool be : {false, true}) {
    const TriangleMesh m = ReadMesh(Write(be ? "be.ply" : "le.ply", BinaryPly(be)));
    ASSERT_EQ(m.vertices.size(), 3u) << be;
    ASSERT_EQ(m.triangles.size(), 1u) << be;
    ExpectVertex(m, 0, {1.5, 0, 0});
    ExpectVertex(m, 2, {0, 0, -3});
    EXPECT_EQ(m.triangles[0], (std::array<uint32_t, 3>{2, 1, 0}));
  }
}

TEST_F(MeshIo, PlyErrors) {
  std::string truncated = BinaryPly(false);
  truncated.resize(truncated.size() - 5);
  auto e = ErrorOf(Write("cut.ply", truncated));
  EXPECT_NE(e.find("cut.ply"), std::string::npos) << e;
  EXPECT_NE(e.find("truncated: face 0 of 1"), std::string::npos) << e;
  e = ErrorOf(Write("nohead.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n"));
  EXPECT_NE(e.find("end_header"), std::string::npos) << e;
  e = ErrorOf(Write("noxyz.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\n1\n"));
  EXPECT_NE(e.find("no x, y and z"), std::string::npos) << e;
  e = ErrorOf(Write("garbage.ply", "\x01\x02garbage"));
  EXPECT_NE(e.find("not a PLY file"), std::string::npos) << e;
  e = ErrorOf(Write("range.ply", "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
                                 "property float y\nproperty float z\nelement face 1\n"
                                 "property list uchar int vertex_indices\nend_header\n"
                                 "0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n"));
  EXPECT_NE(e.find("vertex index 3"), std::string::npos) << e;
}

TEST_F(MeshIo, PointFiles) {
  const auto ply = Write("cloud.ply",
                         "ply\nformat ascii 1.0\nelement vertex 2\nproperty double x\n"
                         "property double y\nproperty double z\nproperty uchar red\nend_header\n"
                         "1 2 3 255\n4 5 6 0\n");
  TriangleMesh m = ReadGeometry(ply);
  EXPECT_EQ(m.vertices.size(), 2u);
  EXPECT_TRUE(m.triangles.empty());
  try {
    ReadMesh(ply);
    FAIL() << "a cloud is not a mesh";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("no triangles"), std::string::npos) << e.what();
  }
  m = ReadGeometry(Write("c.xyz", "# x y z intensity\n1 2 3 0.5\n\n4,5,6\n// comment\n-1e3\t2.5 +7 9 9 9\r\n"));
  ASSERT_EQ(m.vertices.size(), 3u);
  ExpectVertex(m, 2, {-1000, 2.5, 7});
  auto e = ErrorOf(Write("bad.xyz", "1 2 3\n1 2\n"));
  EXPECT_NE(e.find("bad.xyz: line 2"), std::string::npos) << e;
  EXPECT_EQ(GeometryFormat("A.TXT"), "xyz");
  EXPECT_EQ(GeometryFormat("a.stl"), "");
  e = ErrorOf(dir_ / "mesh.stl");
  EXPECT_NE(e.find("unknown extension '.stl'"), std::string::npos) << e;
  e = ErrorOf(dir_ / "missing.ply");
  EXPECT_NE(e.find("missing.ply: no such file"), std::string::npos) << e;
}

// ASCII OFF as the Piazza et al. 2018 mesher writes it ("OFF", counts with an edge count, float
// vertices with a trailing blank, "3 i j k"), plus comments, blank lines, CRLF, a quad with a
// colour after its indices (fan-triangulated) and the counts on the keyword's line.
TEST_F(MeshIo, OffTriangleQuadCommentsAndBlankLines) {
  TriangleMesh m = ReadMesh(Write("tri.off", "OFF\n3 1 0\n0 0 0 \n1 0 0 \n0 1 0 \n3 0 1 2\n"));
  ASSERT_EQ(m.vertices.size(), 3u);
  ASSERT_EQ(m.triangles.size(), 1u);
  EXPECT_EQ(m.triangles[0], (std::array<uint32_t, 3>{0, 1, 2}));
  EXPECT_DOUBLE_EQ(MeshArea(m), 0.5);
  m = ReadMesh(Write("quad.off",
                     "# written by hand\nOFF # keyword\r\n\n# counts next\n5 2\r\n"
                     "0 0 0\n2 0 0\n2 2 0 # a comment after a vertex\n\n0 2 -1.5e0\n"
                     "9 9 9\n4 0 1 2 3 255 0 0\n"
                     "# between faces\n3 4 0 1\n"));
  ASSERT_EQ(m.vertices.size(), 5u);
  ASSERT_EQ(m.triangles.size(), 3u);
  EXPECT_EQ(m.triangles[0], (std::array<uint32_t, 3>{0, 1, 2}));
  EXPECT_EQ(m.triangles[1], (std::array<uint32_t, 3>{0, 2, 3}));
  EXPECT_EQ(m.triangles[2], (std::array<uint32_t, 3>{4, 0, 1}));
  ExpectVertex(m, 3, {0, 2, -1.5});
  m = ReadMesh(Write("COLOURS.OFF",
                     "COFF 3 1 3\n0 0 0 1 0 0 1\n1 0 0 0 1 0 1\n0 0 1 0 0 1 1\n3 2 1 0\n"));
  ASSERT_EQ(m.triangles.size(), 1u);
  EXPECT_EQ(m.triangles[0], (std::array<uint32_t, 3>{2, 1, 0}));
  EXPECT_EQ(GeometryFormat("m.OFF"), "off");
}

TEST_F(MeshIo, OffErrorsNameTheFileAndLine) {
  // A face count larger than the faces present: truncated, with where the file ends.
  auto e = ErrorOf(Write("short.off", "OFF\n3 2 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"));
  EXPECT_NE(e.find("short.off: truncated: 1 of 2 faces (the file ends at line 6)"),
            std::string::npos) << e;
  // A vertex count larger than the vertex lines: the first face line is read as a vertex...
  e = ErrorOf(Write("count.off", "OFF\n4 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"));
  EXPECT_NE(e.find("count.off: truncated: 0 of 1 faces"), std::string::npos) << e;
  // ...and a smaller one makes a vertex line a face, or leaves lines over.
  e = ErrorOf(Write("fewer.off", "OFF\n2 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"));
  EXPECT_NE(e.find("fewer.off: line 5: face 0 of 1: a face needs at least 3 vertices, has 0"),
            std::string::npos) << e;
  e = ErrorOf(Write("extra.off", "OFF\n3 1\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 0 1 2\n"));
  EXPECT_NE(e.find("extra.off: line 7: more lines than the counts say"), std::string::npos) << e;
  e = ErrorOf(Write("neg.off", "OFF\n-3 1 0\n"));
  EXPECT_NE(e.find("neg.off: line 2: negative count"), std::string::npos) << e;
  e = ErrorOf(Write("nocounts.off", "OFF\n3 x\n"));
  EXPECT_NE(e.find("nocounts.off: line 2: expected the counts 'vertices faces [edges]'"),
            std::string::npos) << e;
  // Truncated in the vertices (a cut file).
  e = ErrorOf(Write("cut.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n"));
  EXPECT_NE(e.find("cut.off: truncated: 2 of 3 vertices (the file ends at line 4)"),
            std::string::npos) << e;
  e = ErrorOf(Write("headonly.off", "OFF\n"));
  EXPECT_NE(e.find("headonly.off: truncated: no counts line"), std::string::npos) << e;
  e = ErrorOf(Write("empty.off", "\n# nothing\n"));
  EXPECT_NE(e.find("empty.off: empty"), std::string::npos) << e;
  // Bad contents.
  e = ErrorOf(Write("range.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n"));
  EXPECT_NE(e.find("range.off: line 6: face 0 of 1: vertex index 3 is out of range (3 vertices)"),
            std::string::npos) << e;
  e = ErrorOf(Write("few.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n4 0 1 2\n"));
  EXPECT_NE(e.find("few.off: line 6: face 0 of 1: says 4 vertices, lists 3"), std::string::npos)
      << e;
  e = ErrorOf(Write("coord.off", "OFF\n3 1 0\n0 0 0\n1 nan 0\n0 1 0\n3 0 1 2\n"));
  EXPECT_NE(e.find("coord.off: line 4: bad vertex coordinate 'nan'"), std::string::npos) << e;
  e = ErrorOf(Write("ply.off", "ply\nformat ascii 1.0\n"));
  EXPECT_NE(e.find("ply.off: line 1: not an OFF file"), std::string::npos) << e;
  e = ErrorOf(Write("bin.off", "OFF BINARY\n"));
  EXPECT_NE(e.find("binary OFF is not supported"), std::string::npos) << e;
  e = ErrorOf(Write("4d.off", "4OFF\n1 0 0\n0 0 0 1\n"));
  EXPECT_NE(e.find("'4OFF' is not supported"), std::string::npos) << e;
  // Vertices but no face: geometry, not a mesh.
  const auto pts = Write("points.off", "OFF\n2 0 0\n0 0 0\n1 1 1\n");
  EXPECT_EQ(ReadGeometry(pts).vertices.size(), 2u);
  try {
    ReadMesh(pts);
    FAIL() << "no faces is not a mesh";
  } catch (const std::runtime_error& ex) {
    EXPECT_NE(std::string(ex.what()).find("no triangles"), std::string::npos) << ex.what();
  }
}

std::string Base64(const std::string& in) {
  static const char* k = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  std::size_t i = 0;
  for (; i + 2 < in.size(); i += 3) {
    const uint32_t v = (uint8_t(in[i]) << 16) | (uint8_t(in[i + 1]) << 8) | uint8_t(in[i + 2]);
    for (int s = 18; s >= 0; s -= 6) out += k[(v >> s) & 63];
  }
  if (i + 1 == in.size()) {
    const uint32_t v = uint8_t(in[i]) << 16;
    out += std::string{k[(v >> 18) & 63], k[(v >> 12) & 63]} + "==";
  } else if (i + 2 == in.size()) {
    const uint32_t v = (uint8_t(in[i]) << 16) | (uint8_t(in[i + 1]) << 8);
    out += std::string{k[(v >> 18) & 63], k[(v >> 12) & 63], k[(v >> 6) & 63]} + "=";
  }
  return out;
}

// A unit square (4 float positions, 6 uint16 indices padded to 4 bytes) in one buffer, with an
// interleaved float attribute after the positions (stride 16) as a writer may do.
std::string SquareBuffer() {
  std::string b;
  const float v[4][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};
  for (int i = 0; i < 4; ++i) {
    for (int k = 0; k < 3; ++k) Put<float>(&b, v[i][k]);
    Put<float>(&b, static_cast<float>(i));  // _POINT_ID, interleaved
  }
  for (uint16_t i : {0, 1, 2, 0, 2, 3}) Put<uint16_t>(&b, i);
  return b;  // 64 + 12 = 76 bytes
}

// Root node: translation (10, 0, 0), scale 2, holding the mesh; its child rotates 90 degrees about
// z and holds the mesh again.
json SquareGltf(const json& buffer) {
  const double s = std::sqrt(0.5);
  return {{"asset", {{"version", "2.0"}}},
          {"scene", 0},
          {"scenes", {{{"nodes", {0}}}}},
          {"nodes",
           {{{"mesh", 0}, {"translation", {10, 0, 0}}, {"scale", {2, 2, 2}}, {"children", {1}}},
            {{"mesh", 0}, {"rotation", {0, 0, s, s}}}}},
          {"meshes",
           {{{"primitives",
              {{{"attributes", {{"POSITION", 0}, {"_POINT_ID", 2}}}, {"indices", 1}, {"mode", 4}}}}}}},
          {"accessors",
           {{{"bufferView", 0}, {"componentType", 5126}, {"count", 4}, {"type", "VEC3"}},
            {{"bufferView", 1}, {"componentType", 5123}, {"count", 6}, {"type", "SCALAR"}},
            {{"bufferView", 0}, {"byteOffset", 12}, {"componentType", 5126}, {"count", 4}, {"type", "SCALAR"}}}},
          {"bufferViews",
           {{{"buffer", 0}, {"byteOffset", 0}, {"byteLength", 64}, {"byteStride", 16}},
            {{"buffer", 0}, {"byteOffset", 64}, {"byteLength", 12}}}},
          {"buffers", {buffer}}};
}

void ExpectSquareScene(const TriangleMesh& m) {
  ASSERT_EQ(m.vertices.size(), 8u);
  ASSERT_EQ(m.triangles.size(), 4u);
  ExpectVertex(m, 1, {12, 0, 0}, 1e-6);   // root: (1, 0, 0) * 2 + (10, 0, 0)
  ExpectVertex(m, 5, {10, 2, 0}, 1e-6);   // child: rotated to (0, 1, 0), then the root's transform
  ExpectVertex(m, 6, {8, 2, 0}, 1e-6);    // (1, 1, 0) -> (-1, 1, 0) -> (8, 2, 0)
  EXPECT_EQ(m.triangles[3], (std::array<uint32_t, 3>{4, 6, 7}));
  EXPECT_NEAR(MeshArea(m), 8.0, 1e-9);
}

// Indices read through a signed or float accessor (a writer's mistake, or a fuzzer's): a
// negative or fractional index is refused by name, not cast to an integer (undefined: the fuzz
// smoke test's UBSan found it).
TEST_F(MeshIo, GltfIndicesThatAreNoVertexIndexAreRefused) {
  const std::string buf = SquareBuffer();
  for (const int type : {5122, 5126}) {  // SHORT, FLOAT
    std::string b = buf.substr(0, 64);
    json doc = SquareGltf({});
    if (type == 5122) {
      for (int16_t i : {0, 1, 2, 0, 2, -30208}) Put<int16_t>(&b, i);
    } else {
      for (float f : {0.0f, 1.0f, 2.0f, 0.0f, 2.0f, 2.5f}) Put<float>(&b, f);
      doc["bufferViews"][1]["byteLength"] = 24;
    }
    doc["accessors"][1]["componentType"] = type;
    doc["buffers"] = {{{"byteLength", b.size()},
                       {"uri", "data:application/octet-stream;base64," + Base64(b)}}};
    const fs::path f = Write("bad_indices.gltf", doc.dump());
    try {
      ReadMesh(f);
      ADD_FAILURE() << "indices of component type " << type << " accepted";
    } catch (const std::exception& e) {
      const std::string want = type == 5122 ? "index -30208 is not a vertex index" : "index 2.5 is not a vertex index";
      EXPECT_NE(std::string(e.what()).find(want), std::string::npos) << e.what();
    }
  }
}

TEST_F(MeshIo, GltfWithDataUriExternalBinAndGlb) {
  const std::string buf = SquareBuffer();
  // Data URI.
  ExpectSquareScene(ReadMesh(Write("uri.gltf", SquareGltf({{"byteLength", buf.size()},
      {"uri", "data:application/octet-stream;base64," + Base64(buf)}}).dump())));
  // External .bin (with a space in its name, percent-encoded).
  Write("sq data.bin", buf);
  ExpectSquareScene(ReadMesh(Write("ext.gltf", SquareGltf({{"byteLength", buf.size()},
      {"uri", "sq%20data.bin"}}).dump())));
  // GLB: JSON chunk padded with spaces, BIN chunk padded with zeros.
  std::string js = SquareGltf({{"byteLength", buf.size()}}).dump();
  while (js.size() % 4) js += ' ';
  std::string bin = buf;
  while (bin.size() % 4) bin += '\0';
  std::string glb;
  Put<uint32_t>(&glb, 0x46546C67u);
  Put<uint32_t>(&glb, 2);
  Put<uint32_t>(&glb, static_cast<uint32_t>(12 + 8 + js.size() + 8 + bin.size()));
  Put<uint32_t>(&glb, static_cast<uint32_t>(js.size()));
  Put<uint32_t>(&glb, 0x4E4F534Au);
  glb += js;
  Put<uint32_t>(&glb, static_cast<uint32_t>(bin.size()));
  Put<uint32_t>(&glb, 0x004E4942u);
  glb += bin;
  ExpectSquareScene(ReadMesh(Write("sq.glb", glb)));
  // Truncated GLB.
  auto e = ErrorOf(Write("cut.glb", glb.substr(0, glb.size() - 8)));
  EXPECT_NE(e.find("cut.glb: truncated"), std::string::npos) << e;
}

TEST_F(MeshIo, GltfMatrixStripAndNoIndices) {
  std::string b;
  const float v[4][3] = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 1, 0}};
  for (auto& p : v)
    for (float x : p) Put<float>(&b, x);
  const json doc = {
      {"asset", {{"version", "2.0"}}},
      {"scenes", {{{"nodes", {0}}}}},
      {"nodes", {{{"mesh", 0}, {"matrix", {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 5, 1}}}}},
      {"meshes", {{{"primitives", {{{"attributes", {{"POSITION", 0}}}, {"mode", 5}}}}}}},
      {"accessors", {{{"bufferView", 0}, {"componentType", 5126}, {"count", 4}, {"type", "VEC3"}}}},
      {"bufferViews", {{{"buffer", 0}, {"byteLength", 48}}}},
      {"buffers", {{{"byteLength", 48}, {"uri", "data:application/gltf-buffer;base64," + Base64(b)}}}}};
  const TriangleMesh m = ReadMesh(Write("strip.gltf", doc.dump()));
  ASSERT_EQ(m.triangles.size(), 2u);
  EXPECT_EQ(m.triangles[0], (std::array<uint32_t, 3>{0, 1, 2}));
  EXPECT_EQ(m.triangles[1], (std::array<uint32_t, 3>{2, 1, 3}));  // odd strip triangle reordered
  ExpectVertex(m, 3, {1, 1, 5});
}

// The exporter's upright root (a display rotation, extras.imr_upright) is not applied: imr's glTF
// reads back in the sequence's frame; any other node's rotation still is.
TEST_F(MeshIo, GltfImrUprightRootIsTheSequencesFrame) {
  const std::string buf = SquareBuffer();
  json doc = SquareGltf({{"byteLength", buf.size()},
                         {"uri", "data:application/octet-stream;base64," + Base64(buf)}});
  doc["nodes"].push_back({{"name", "imr_upright"},
                          {"children", {0}},
                          {"matrix", {1, 0, 0, 0, 0, 0, -1, 0, 0, 1, 0, 0, 0, 0, 0, 1}},
                          {"extras", {{"imr_upright", "display rotation"}}}});
  doc["scenes"][0]["nodes"] = {2};
  ExpectSquareScene(ReadMesh(Write("upright.gltf", doc.dump())));
  doc["nodes"][2].erase("extras");  // an ordinary root: its rotation counts (y -> -z)
  const TriangleMesh m = ReadMesh(Write("rotated.gltf", doc.dump()));
  ExpectVertex(m, 5, {10, 0, -2}, 1e-6);
}

TEST_F(MeshIo, GltfErrors) {
  const std::string buf = SquareBuffer();
  auto e = ErrorOf(Write("nobin.gltf", SquareGltf({{"byteLength", buf.size()}, {"uri", "gone.bin"}}).dump()));
  EXPECT_NE(e.find("nobin.gltf: buffers[0] (\"gone.bin\")"), std::string::npos) << e;
  EXPECT_NE(e.find("no such file"), std::string::npos) << e;
  Write("short.bin", buf.substr(0, 40));
  e = ErrorOf(Write("short.gltf", SquareGltf({{"byteLength", 40}, {"uri", "short.bin"}}).dump()));
  EXPECT_NE(e.find("ends past the end"), std::string::npos) << e;
  e = ErrorOf(Write("json.gltf", "{\"asset\": "));
  EXPECT_NE(e.find("json.gltf: not valid JSON"), std::string::npos) << e;
  json v1 = SquareGltf({{"byteLength", 0}});
  v1["asset"]["version"] = "1.0";
  e = ErrorOf(Write("v1.gltf", v1.dump()));
  EXPECT_NE(e.find("version '1.0'"), std::string::npos) << e;
}

}  // namespace
}  // namespace imr::eval
