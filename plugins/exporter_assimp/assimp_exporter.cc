// The assimp exporter (docs/user-guide.md, Colour, texture and upright glTF): writes the output surface as OBJ, binary
// PLY, glTF 2.0 or GLB, with per-vertex normals and, where the format has a place for them, the
// per-vertex point ids that trace the mesh back to its 3D points (host/engine/engine.h, `Mesh`).
// Since SDK 1.1 it colours the surface from the keyframe images (vertex colours, a texture atlas:
// texturing.hpp) and writes glTF upright (a root node's rotation).
#include <imr/sdk/plugin.hpp>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <array>
#include <assimp/DefaultIOSystem.h>
#include <assimp/Exporter.hpp>
#include <assimp/IOStream.hpp>
#include <assimp/material.h>
#include <assimp/mesh.h>
#include <assimp/scene.h>
#include <assimp/texture.h>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include <optional>
#include <unordered_map>

#include "obj_writer.hpp"
#include "page_encoder.hpp"
#include "streamed_colours.hpp"
#include "streamed_writers.hpp"
#include "point_id_channel.hpp"
#include "texturing.hpp"

namespace {

namespace fs = std::filesystem;
using imr::exporter_assimp::AtlasPage;
using imr::exporter_assimp::ColorAndTexture;
using imr::exporter_assimp::ConvertGltfPointIds;
using imr::exporter_assimp::ConvertGltfVertexKeys;
using imr::exporter_assimp::EncodeVertexKey;
using imr::exporter_assimp::kMaxVertexKey;
using imr::exporter_assimp::AddPlyOrigin;
using imr::exporter_assimp::EditGltf;
using imr::exporter_assimp::ExportOrigin;
using imr::exporter_assimp::SetGltfOrigin;
using imr::exporter_assimp::GltfDocument;
using imr::exporter_assimp::MtlText;
using imr::exporter_assimp::ObjGroup;
using imr::exporter_assimp::ObjMesh;
using imr::exporter_assimp::ObjNeedsMtl;
using imr::exporter_assimp::ObjText;
using imr::exporter_assimp::WriteStreamedObj;
using imr::exporter_assimp::WriteStreamedPly;
using imr::exporter_assimp::StreamedVertexColours;
using imr::exporter_assimp::ColourFrameOf;
using imr::exporter_assimp::VertexColourBlock;
using imr::exporter_assimp::SetUprightNode;
using imr::exporter_assimp::TexturedMesh;
using imr::exporter_assimp::TexturingOptions;
using imr::exporter_assimp::TexturingStats;
using imr::exporter_assimp::UprightRotation;
using imr::exporter_assimp::VertexNormals;
using imr::exporter_assimp::RewritePly;
using imr::exporter_assimp::EncodedPointId;
using imr::exporter_assimp::EncodePointId;
using imr::exporter_assimp::kMaxGltfPointId;
using imr::exporter_assimp::kMaxPointId;
using imr::exporter_assimp::kMinPointId;
using imr::sdk::InvalidArgument;

// assimp's own file streams ignore write errors: on a full disk it wrote a truncated file and
// reported success. Files are written through this stream instead; the first error is kept
// ("<file>: write failed: No space left on device") and fails the export.
class CheckedFile : public Assimp::IOStream {
 public:
  CheckedFile(int fd, std::string path, std::string* error)
      : fd_(fd), path_(std::move(path)), error_(error) {}
  ~CheckedFile() override {
    if (::close(fd_) != 0) Fail("close");
  }
  size_t Read(void*, size_t, size_t) override { return 0; }  // opened for writing only
  size_t Write(const void* buffer, size_t size, size_t count) override {
    const char* p = static_cast<const char*>(buffer);
    for (size_t left = size * count; left > 0;) {
      const ssize_t n = ::write(fd_, p, left);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) {
        Fail("write");
        return 0;
      }
      p += n;
      left -= static_cast<size_t>(n);
    }
    return count;
  }
  aiReturn Seek(size_t offset, aiOrigin origin) override {
    const int whence = origin == aiOrigin_SET ? SEEK_SET : origin == aiOrigin_CUR ? SEEK_CUR : SEEK_END;
    return ::lseek(fd_, static_cast<off_t>(offset), whence) < 0 ? aiReturn_FAILURE : aiReturn_SUCCESS;
  }
  size_t Tell() const override {
    const off_t at = ::lseek(fd_, 0, SEEK_CUR);
    return at < 0 ? 0 : static_cast<size_t>(at);
  }
  size_t FileSize() const override {
    struct stat st {};
    return ::fstat(fd_, &st) == 0 ? static_cast<size_t>(st.st_size) : 0;
  }
  void Flush() override {}

 private:
  void Fail(const char* what) {
    if (error_->empty()) *error_ = path_ + ": " + what + " failed: " + std::strerror(errno);
  }
  int fd_;
  std::string path_;
  std::string* error_;
};

// Reads as assimp does; writes through CheckedFile.
class CheckedIOSystem : public Assimp::DefaultIOSystem {
 public:
  explicit CheckedIOSystem(std::string* error) : error_(error) {}
  Assimp::IOStream* Open(const char* file, const char* mode) override {
    if (mode == nullptr || mode[0] != 'w') return DefaultIOSystem::Open(file, mode);
    const int fd = ::open(file, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    if (fd < 0) {
      if (error_->empty()) *error_ = std::string(file) + ": cannot write: " + std::strerror(errno);
      return nullptr;
    }
    return new CheckedFile(fd, file, error_);
  }
  void Close(Assimp::IOStream* stream) override { delete stream; }

 private:
  std::string* error_;
};

struct Format {
  const char* name;       // as in kFormats and the request
  const char* assimp_id;  // assimp's exporter id
  const char* extension;
  int64_t max_point_id;  // largest id the format's attribute holds exactly; 0: no ids
  bool texture;          // has a place for a texture atlas
};

// OBJ is written by obj_writer.hpp, not assimp (no exporter id): assimp's merges the vertices
// the engine split. "plyb": assimp's binary PLY, little-endian on this host.
constexpr std::array<Format, 4> kFormatTable = {{
    {"obj", nullptr, ".obj", 0, true},
    {"ply", "plyb", ".ply", kMaxPointId, false},
    {"gltf", "gltf2", ".gltf", kMaxGltfPointId, true},
    {"glb", "glb2", ".glb", kMaxGltfPointId, true},
}};

const Format& FindFormat(const std::string& name) {
  for (const Format& f : kFormatTable)
    if (name == f.name) return f;
  throw InvalidArgument("unknown format \"" + name + "\": expected one of obj, ply, gltf, glb");
}

// The request's file name: no folder, no "." or "..".
void CheckStem(const std::string& stem) {
  if (stem.empty() || stem.find('/') != std::string::npos || stem == "." || stem == "..")
    throw InvalidArgument("stem \"" + stem + "\" is not a plain file name");
}

// Everything assimp would choke on, or silently write wrong, named precisely.
void CheckMesh(const imr::sdk::MeshView& mesh, const Format& format, bool check_point_ids) {
  const std::size_t nv = mesh.vertex_count(), nf = mesh.face_count();
  if (nf == 0)
    throw InvalidArgument("mesh has no faces (" + std::to_string(nv) +
                          " vertices): nothing to export; skip the export of an empty surface");
  if (nv > std::numeric_limits<uint32_t>::max())
    throw InvalidArgument("mesh has " + std::to_string(nv) + " vertices, more than 2^32 - 1");
  if (mesh.vertices.data() == nullptr || mesh.faces.data() == nullptr)
    throw InvalidArgument("mesh vertices or faces pointer is null");
  constexpr double kFloatMax = std::numeric_limits<float>::max();
  for (std::size_t i = 0; i < nv; ++i) {
    for (int k = 0; k < 3; ++k) {
      const double x = mesh.vertices[3 * i + k];
      if (!std::isfinite(x) || std::fabs(x) > kFloatMax)
        throw InvalidArgument("vertex " + std::to_string(i) + " coordinate " + "xyz"[k] + " is " +
                              std::to_string(x) + ": not a finite float");
    }
  }
  for (std::size_t f = 0; f < nf; ++f) {
    const uint32_t* t = &mesh.faces[3 * f];
    for (int k = 0; k < 3; ++k)
      if (t[k] >= nv)
        throw InvalidArgument("face " + std::to_string(f) + " vertex index " +
                              std::to_string(t[k]) + " is out of range (the mesh has " +
                              std::to_string(nv) + " vertices)");
    if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2])
      throw InvalidArgument("face " + std::to_string(f) + " repeats a vertex (" +
                            std::to_string(t[0]) + ", " + std::to_string(t[1]) + ", " +
                            std::to_string(t[2]) + ")");
  }
  for (std::size_t i = 0; i < mesh.vertex_keys.size(); ++i)
    if (mesh.vertex_keys[i] < 0 || mesh.vertex_keys[i] > kMaxVertexKey)
      throw InvalidArgument("vertex key of vertex " + std::to_string(i) + " is " +
                            std::to_string(mesh.vertex_keys[i]) + ": expected 0 .. 2^48 - 1");
  if (check_point_ids) {
    for (std::size_t i = 0; i < mesh.point_ids.size(); ++i) {
      const int64_t id = mesh.point_ids[i];
      if (id < kMinPointId || id > format.max_point_id)
        throw InvalidArgument("point id of vertex " + std::to_string(i) + " is " +
                              std::to_string(id) + ": " + format.name +
                              " holds ids -1 (Steiner) .. " + std::to_string(format.max_point_id) +
                              " exactly (export without point ids: \"point_ids\": false)");
    }
  }
}

// What goes into the files beside the geometry.
struct Appearance {
  const uint8_t* vertex_rgb = nullptr;    // 3 per input vertex, or null: no colours
  const TexturedMesh* texture = nullptr;  // faces with a page are textured; null: none
  std::vector<std::string> page_paths;    // the material's texture path per page ("*i": embedded)
};

// One output mesh (one material): the input faces it holds, and its vertices as (input vertex,
// patch) pairs so that a vertex on a seam between patches is split (it has two texture
// coordinates there).
struct Part {
  std::vector<uint32_t> faces;   // input face indices
  int page = -1;                 // atlas page, -1: no texture
};

aiMesh* BuildPart(const imr::sdk::MeshView& mesh, const std::vector<double>& normals,
                  const Part& part, const Appearance& look, bool with_point_ids, bool with_keys,
                  const std::string& name, unsigned material,
                  const std::array<double, 3>& origin) {
  const TexturedMesh* tex = part.page >= 0 ? look.texture : nullptr;
  std::unordered_map<uint64_t, uint32_t> index;
  std::vector<uint32_t> source;  // input vertex of each output vertex
  std::vector<uint32_t> corner;  // output vertex of each corner, 3 per face of the part
  std::vector<aiVector3D> uv;
  corner.reserve(3 * part.faces.size());
  for (const uint32_t f : part.faces)
    for (int k = 0; k < 3; ++k) {
      const uint32_t v = mesh.faces[3 * f + k];
      const uint64_t key = tex ? (uint64_t{static_cast<uint32_t>(tex->face_patch[f])} << 32 | v) : v;
      const auto [it, added] = index.emplace(key, static_cast<uint32_t>(source.size()));
      if (added) {
        source.push_back(v);
        // assimp's convention: v up from the bottom (its glTF writer flips it back to glTF's).
        if (tex) uv.emplace_back(tex->face_uv[6 * f + 2 * k], 1.0f - tex->face_uv[6 * f + 2 * k + 1], 0.0f);
      }
      corner.push_back(it->second);
    }
  auto* m = new aiMesh();
  const auto nv = static_cast<unsigned>(source.size());
  const auto nf = static_cast<unsigned>(part.faces.size());
  m->mName = aiString(name);
  m->mMaterialIndex = material;
  m->mPrimitiveTypes = aiPrimitiveType_TRIANGLE;
  m->mNumVertices = nv;
  m->mVertices = new aiVector3D[nv];
  m->mNormals = new aiVector3D[nv];
  for (unsigned i = 0; i < nv; ++i) {
    const std::size_t s = source[i];
    m->mVertices[i] = aiVector3D(static_cast<ai_real>(mesh.vertices[3 * s] - origin[0]),
                                 static_cast<ai_real>(mesh.vertices[3 * s + 1] - origin[1]),
                                 static_cast<ai_real>(mesh.vertices[3 * s + 2] - origin[2]));
    const double* n = &normals[3 * s];
    m->mNormals[i] = n[0] == 0 && n[1] == 0 && n[2] == 0
                         ? aiVector3D(0, 0, 1)
                         : aiVector3D(static_cast<ai_real>(n[0]), static_cast<ai_real>(n[1]),
                                      static_cast<ai_real>(n[2]));
  }
  unsigned channel = 0;
  if (tex) {
    m->mNumUVComponents[channel] = 2;
    m->mTextureCoords[channel] = new aiVector3D[nv];
    std::copy(uv.begin(), uv.end(), m->mTextureCoords[channel]);
    ++channel;
  }
  if (with_point_ids) {  // the last texture channel (point_id_channel.hpp)
    m->mNumUVComponents[channel] = 2;
    m->mTextureCoords[channel] = new aiVector3D[nv];
    for (unsigned i = 0; i < nv; ++i) {
      const EncodedPointId e = EncodePointId(mesh.point_ids[source[i]]);
      m->mTextureCoords[channel][i] = aiVector3D(e.hi, e.lo, 0);
    }
    ++channel;
  }
  if (with_keys) {  // behind the point ids (ConvertGltfVertexKeys): also keeps split copies apart
    m->mNumUVComponents[channel] = 2;
    m->mTextureCoords[channel] = new aiVector3D[nv];
    for (unsigned i = 0; i < nv; ++i) {
      const auto e = EncodeVertexKey(mesh.vertex_keys[source[i]]);
      m->mTextureCoords[channel][i] = aiVector3D(e.hi, e.lo, 0);
    }
  }
  if (with_keys) {
    // assimp's JoinIdenticalVertices compares texture channel 0 only (assimp 5.2: the copies of
    // a pinched vertex, one position and one point id, became one vertex whatever their keys).
    // Its third component is compared and not written: each vertex's own number there keeps
    // every vertex of the mesh apart.
    for (unsigned i = 0; i < nv; ++i) m->mTextureCoords[0][i].z = static_cast<ai_real>(i);
  }
  if (look.vertex_rgb != nullptr && !tex) {
    m->mColors[0] = new aiColor4D[nv];
    for (unsigned i = 0; i < nv; ++i) {
      const uint8_t* c = look.vertex_rgb + 3 * static_cast<std::size_t>(source[i]);
      // (b + 0.5) / 255: exact bytes again after the writers' truncating * 255.
      m->mColors[0][i] = aiColor4D((c[0] + 0.5f) / 255.0f, (c[1] + 0.5f) / 255.0f,
                                   (c[2] + 0.5f) / 255.0f, 1.0f);
    }
  }
  m->mNumFaces = nf;
  m->mFaces = new aiFace[nf];
  for (unsigned f = 0; f < nf; ++f) {
    aiFace& face = m->mFaces[f];
    face.mNumIndices = 3;
    face.mIndices = new unsigned[3]{corner[3 * f], corner[3 * f + 1], corner[3 * f + 2]};
  }
  return m;
}

aiMaterial* Material(const std::string& name, bool white, const std::string& texture) {
  auto* material = new aiMaterial();
  const aiString n(name);
  material->AddProperty(&n, AI_MATKEY_NAME);
  // White under a texture or vertex colours (glTF multiplies them); light grey on plain meshes.
  const aiColor3D color = white ? aiColor3D(1.0f, 1.0f, 1.0f) : aiColor3D(0.8f, 0.8f, 0.8f);
  material->AddProperty(&color, 1, AI_MATKEY_COLOR_DIFFUSE);
  if (!texture.empty()) {
    const aiString path(texture);
    material->AddProperty(&path, AI_MATKEY_TEXTURE_DIFFUSE(0));
  }
  return material;
}

// One part per atlas page and one for the faces without texture, the empty ones left out.
std::vector<Part> Parts(const imr::sdk::MeshView& mesh, const Appearance& look) {
  std::vector<Part> parts;
  if (look.texture != nullptr) {
    parts.resize(look.texture->pages.size() + 1);
    for (std::size_t p = 0; p + 1 < parts.size(); ++p) parts[p].page = static_cast<int>(p);
    for (std::size_t f = 0; f < mesh.face_count(); ++f) {
      const int page = look.texture->face_page[f];
      parts[page >= 0 ? static_cast<std::size_t>(page) : parts.size() - 1].faces.push_back(
          static_cast<uint32_t>(f));
    }
  } else {
    parts.resize(1);
    parts[0].faces.resize(mesh.face_count());
    for (std::size_t f = 0; f < mesh.face_count(); ++f) parts[0].faces[f] = static_cast<uint32_t>(f);
  }
  std::erase_if(parts, [](const Part& p) { return p.faces.empty(); });
  return parts;
}

std::string MaterialName(const Part& part) {
  return part.page >= 0 ? "imr_atlas" + std::to_string(part.page) : "imr_surface";
}

std::string PartName(const std::string& name, const Part& part, std::size_t parts) {
  return parts == 1 ? name : part.page >= 0 ? name + "_atlas" + std::to_string(part.page)
                                            : name + "_untextured";
}

// The OBJ of the same parts (obj_writer.hpp): every mesh vertex one `v`, in the mesh's order.
// The result points into `mesh`, `normals` and `look`.
ObjMesh ObjOf(const imr::sdk::MeshView& mesh, const std::vector<double>& normals,
              const std::string& name, const Appearance& look) {
  ObjMesh obj;
  obj.vertices = mesh.vertices.data();
  obj.vertex_count = mesh.vertex_count();
  obj.normals = &normals;
  obj.vertex_rgb = look.vertex_rgb;
  const std::vector<Part> parts = Parts(mesh, look);
  for (const Part& part : parts) {
    ObjGroup g;
    g.name = PartName(name, part, parts.size());
    g.material = MaterialName(part);
    g.white = part.page >= 0 || look.vertex_rgb != nullptr;
    const TexturedMesh* tex = part.page >= 0 ? look.texture : nullptr;
    if (tex) g.texture = look.page_paths[static_cast<std::size_t>(part.page)];
    std::unordered_map<uint64_t, uint32_t> index;  // (patch, vertex) -> vt, as BuildPart
    for (const uint32_t f : part.faces)
      for (int k = 0; k < 3; ++k) {
        const uint32_t v = mesh.faces[3 * f + k];
        g.faces.push_back(v);
        if (!tex) continue;
        const uint64_t key = uint64_t{static_cast<uint32_t>(tex->face_patch[f])} << 32 | v;
        const auto [it, added] = index.emplace(key, static_cast<uint32_t>(g.uv.size() / 2));
        if (added)
          g.uv.insert(g.uv.end(), {tex->face_uv[6 * f + 2 * k], 1.0f - tex->face_uv[6 * f + 2 * k + 1]});
        g.corner_uv.push_back(it->second);
      }
    obj.groups.push_back(std::move(g));
  }
  return obj;
}

// A complete scene: one root node holding one mesh per atlas page (with its textured material)
// and one for the faces without texture (vertex colours, or the plain grey material).
std::unique_ptr<aiScene> BuildScene(const imr::sdk::MeshView& mesh, const std::string& name,
                                    bool with_point_ids, bool with_keys, const Appearance& look,
                                    const std::array<double, 3>& origin) {
  auto scene = std::make_unique<aiScene>();
  const std::vector<double> normals = VertexNormals(mesh);
  const std::vector<Part> parts = Parts(mesh, look);
  std::vector<aiMaterial*> materials;
  std::vector<aiMesh*> meshes;
  for (const Part& part : parts) {
    const bool textured = part.page >= 0;
    const auto material = static_cast<unsigned>(materials.size());
    materials.push_back(Material(MaterialName(part), textured || look.vertex_rgb != nullptr,
                                 textured ? look.page_paths[static_cast<std::size_t>(part.page)] : ""));
    const std::string mesh_name = PartName(name, part, parts.size());
    meshes.push_back(BuildPart(mesh, normals, part, look, with_point_ids, with_keys, mesh_name,
                               material, origin));
  }
  scene->mNumMaterials = static_cast<unsigned>(materials.size());
  scene->mMaterials = new aiMaterial*[materials.size()];
  std::copy(materials.begin(), materials.end(), scene->mMaterials);
  scene->mNumMeshes = static_cast<unsigned>(meshes.size());
  scene->mMeshes = new aiMesh*[meshes.size()];
  std::copy(meshes.begin(), meshes.end(), scene->mMeshes);
  scene->mRootNode = new aiNode(name);
  scene->mRootNode->mNumMeshes = scene->mNumMeshes;
  scene->mRootNode->mMeshes = new unsigned[scene->mNumMeshes];
  for (unsigned i = 0; i < scene->mNumMeshes; ++i) scene->mRootNode->mMeshes[i] = i;
  return scene;
}

// An atlas page encoded as PNG or JPEG (page_encoder.hpp), its pixels consumed: turned to BGR
// in place for the encoder (a converted copy was a second page's bytes at the end's peak).
std::vector<uint8_t> EncodePage(AtlasPage& page, const std::string& format, int jpeg_quality) {
  for (std::size_t i = 0; i + 2 < page.rgb.size(); i += 3) std::swap(page.rgb[i], page.rgb[i + 2]);
  return imr::exporter_assimp::EncodeAtlasPage(page.rgb.data(), page.width, page.height, format,
                                               jpeg_quality);
}

void WriteBytes(const fs::path& path, const void* bytes, std::size_t size) {
  std::string error;
  {
    CheckedIOSystem io(&error);
    std::unique_ptr<Assimp::IOStream> out(io.Open(path.string().c_str(), "wb"));
    if (out) out->Write(bytes, 1, size);
  }
  if (!error.empty()) throw std::runtime_error(error);
}
void WriteBytes(const fs::path& path, const std::vector<uint8_t>& bytes) {
  WriteBytes(path, bytes.data(), bytes.size());
}
void WriteBytes(const fs::path& path, const std::string& text) {
  WriteBytes(path, text.data(), text.size());
}

// C = -R^T t.
void CameraCenter(const imr_camera& c, double out[3]) {
  for (int k = 0; k < 3; ++k) out[k] = -(c.R[k] * c.t[0] + c.R[3 + k] * c.t[1] + c.R[6 + k] * c.t[2]);
}

// FNV-1a over raw bytes: the key of the texturing cache (the same mesh for every format).
uint64_t Hash(uint64_t h, const void* data, std::size_t bytes) {
  const auto* p = static_cast<const uint8_t*>(data);
  for (std::size_t i = 0; i < bytes; ++i) h = (h ^ p[i]) * 0x100000001b3ull;
  return h;
}

class AssimpExporter : public imr::sdk::Exporter {
 public:
  static constexpr const char* kId = "org.imr.exporter.assimp";
  static constexpr const char* kVersion = "1.3.0";
  static constexpr const char* kDescription =
      "Mesh files through assimp: OBJ, binary PLY, glTF 2.0, GLB; normals in all, point ids in "
      "PLY and glTF/GLB, colours and a texture atlas from the keyframe images, glTF upright";
  static constexpr const char* kParamsSchema = R"({
  "point_ids": {"type": "boolean", "default": true,
    "description": "Write each vertex's 3D point id (-1 for Steiner points) where the format has a per-vertex attribute: PLY 'property int point_id' (ids up to 2^31 - 1), glTF/GLB attribute '_POINT_ID' (SCALAR FLOAT as glTF forbids UNSIGNED_INT attributes; ids up to 2^24, exact). OBJ cannot keep them. An id beyond the format's range is an error."},
  "vertex_colors": {"type": "boolean", "default": true,
    "description": "Per-vertex colours: from the keyframe images that see each vertex when the input has images, else the colours the input gives its points (COLMAP points3D). PLY 'red green blue alpha' (uchar), glTF/GLB COLOR_0 (on the faces without texture when there is one), OBJ 'v x y z r g b'."},
  "texture": {"type": "boolean", "default": true,
    "description": "OBJ, glTF and GLB get a texture atlas from the keyframe images (inputs with images): each triangle from one view (resolution, angle, visibility; neighbours prefer the same view), patches packed into atlas pages; glTF baseColorTexture (embedded in GLB, files beside .gltf and .obj/.mtl). Triangles no keyframe sees whole keep vertex colours."},
  "atlas_size": {"type": "integer", "default": 4096, "minimum": 64, "maximum": 16384,
    "description": "Pixels on a side of an atlas page (pages are cut to what they hold; more pages when one is full)."},
  "atlas_format": {"type": "string", "default": "jpg", "enum": ["jpg", "png"],
    "description": "Atlas image format: JPEG (small) or PNG (lossless)."},
  "jpeg_quality": {"type": "integer", "default": 90, "minimum": 1, "maximum": 100,
    "description": "JPEG quality of the atlas pages."},
  "keyframe_step": {"type": "integer", "default": 1, "minimum": 1,
    "description": "Colour and texture from every n-th keyframe (and the last one)."},
  "seam_penalty": {"type": "number", "default": 1.0, "minimum": 0.0,
    "description": "Smoothness weight of the view selection: the cost of two adjacent triangles taking different views, against a data term in [0, 1] (1 - projected area / the triangle's best). 0: every triangle takes its best view."},
  "upright": {"type": "boolean", "default": true,
    "description": "glTF/GLB: put the mesh under a root node 'imr_upright' whose rotation makes the world's up (the keyframe cameras' mean up) glTF's +Y and their mean viewing direction -Z, so viewers open it standing and facing the way the cameras looked. Vertex data stays in the sequence's frame; OBJ and PLY keep the sequence's frame."}
})";
  static constexpr const char* kFormats = "obj,ply,gltf,glb";

  AssimpExporter(const imr::sdk::Params& params, const imr::sdk::Host& host) : host_(host) {
    point_ids_ = params.Get<bool>("point_ids", true);
    vertex_colors_ = params.Get<bool>("vertex_colors", true);
    texturing_.texture = params.Get<bool>("texture", true);
    texturing_.atlas_size = params.Get<int>("atlas_size", 4096);
    texturing_.keyframe_step = params.Get<int>("keyframe_step", 1);
    texturing_.seam_penalty = params.Get<double>("seam_penalty", 1.0);
    atlas_format_ = params.Get<std::string>("atlas_format", "jpg");
    jpeg_quality_ = params.Get<int>("jpeg_quality", 90);
    upright_ = params.Get<bool>("upright", true);
    if (const std::string e = texturing_.Check(); !e.empty()) throw InvalidArgument("params." + e);
  }

  void ExportMesh(const imr::sdk::ExportRequest& request) override {
    const imr::sdk::MeshView& mesh = request.mesh;
    const std::string& stem = request.stem;
    const Format& f = FindFormat(request.format);
    CheckStem(stem);
    const bool write_ids = point_ids_ && f.max_point_id > 0 && !mesh.point_ids.empty();
    CheckMesh(mesh, f, write_ids);
    host_.CheckCancelled();

    // Colours and texture: from the images when there are any, else the input's point colours.
    Appearance look;
    const TexturedMesh* tm = nullptr;
    if ((vertex_colors_ || texturing_.texture) && request.keyframe_images && !request.keyframes.empty())
      tm = Texturing(request, /*atlas=*/f.texture && texturing_.texture);
    if (vertex_colors_) {
      if (tm != nullptr && !tm->vertex_rgb.empty()) look.vertex_rgb = tm->vertex_rgb.data();
      else if (mesh.vertex_colors.size() == 3 * mesh.vertex_count()) look.vertex_rgb = mesh.vertex_colors.data();
    }
    const fs::path path = fs::path(request.directory) / (stem + f.extension);
    if (f.texture && tm != nullptr && texturing_.texture && tm->stats.faces_textured > 0) {
      look.texture = tm;
      for (std::size_t p = 0; p < tm->pages.size(); ++p) {
        const std::vector<uint8_t>& bytes = EncodedPage(p);
        if (std::string(f.name) == "glb") {
          look.page_paths.push_back("*" + std::to_string(p));  // embedded (scene->mTextures[p])
        } else {
          const std::string file = stem + "_atlas" + std::to_string(p) + "." + atlas_format_;
          WriteBytes(fs::path(request.directory) / file, bytes);
          look.page_paths.push_back(file);
        }
      }
    }
    host_.CheckCancelled();

    if (std::string(f.name) == "obj") {  // not through assimp (obj_writer.hpp)
      const std::vector<double> normals = VertexNormals(mesh);
      const ObjMesh obj = ObjOf(mesh, normals, stem, look);
      if (ObjNeedsMtl(obj)) WriteBytes(fs::path(request.directory) / (stem + ".mtl"), MtlText(obj));
      WriteBytes(path, ObjText(obj, stem + ".mtl"));
      host_.Debug("wrote " + path.string() + ": " + std::to_string(mesh.vertex_count()) +
                  " vertices, " + std::to_string(mesh.face_count()) + " triangles" +
                  (look.vertex_rgb ? ", vertex colours" : "") +
                  (look.texture ? ", " + std::to_string(tm->pages.size()) + " atlas page(s)" : ""));
      return;
    }
    // Vertices relative to a local origin: the host's (tiles), else 0 near the origin
    // (point_id_channel.hpp).
    const std::array<double, 3> origin =
        request.origin ? *request.origin : ExportOrigin(mesh.vertices.data(), mesh.vertex_count());
    const bool shifted = origin != std::array<double, 3>{};
    const bool gltf = f.max_point_id == kMaxGltfPointId;
    const bool write_keys = gltf && !mesh.vertex_keys.empty();
    std::unique_ptr<aiScene> scene = BuildScene(mesh, stem, write_ids, write_keys, look, origin);
    if (look.texture != nullptr && std::string(f.name) == "glb") {
      scene->mNumTextures = static_cast<unsigned>(tm->pages.size());
      scene->mTextures = new aiTexture*[scene->mNumTextures];
      for (unsigned p = 0; p < scene->mNumTextures; ++p) {
        const std::vector<uint8_t>& bytes = EncodedPage(p);
        auto* t = new aiTexture();
        t->mWidth = static_cast<unsigned>(bytes.size());  // compressed: mHeight 0, mWidth bytes
        t->mHeight = 0;
        t->pcData = new aiTexel[(bytes.size() + sizeof(aiTexel) - 1) / sizeof(aiTexel)];
        std::memcpy(t->pcData, bytes.data(), bytes.size());
        std::snprintf(t->achFormatHint, sizeof(t->achFormatHint), "%s", atlas_format_.c_str());
        t->mFilename = aiString(stem + "_atlas" + std::to_string(p) + "." + atlas_format_);
        scene->mTextures[p] = t;
      }
    }
    const char* assimp_id = f.assimp_id;
    {
      std::string write_error;
      Assimp::Exporter exporter;
      exporter.SetIOHandler(new CheckedIOSystem(&write_error));  // the exporter owns it
      const aiReturn r = exporter.Export(scene.get(), assimp_id, path.string());
      if (!write_error.empty()) throw std::runtime_error(write_error);
      if (r != aiReturn_SUCCESS)
        throw std::runtime_error("assimp could not write " + path.string() + " (" + assimp_id +
                                 "): " + exporter.GetErrorString());
    }
    scene.reset();
    // The root's rotation: the host's (3D Tiles: z-up to y-up), else upright from the cameras.
    double rotation[9];
    const bool given = gltf && request.gltf_rotation.has_value();
    if (given) std::copy(request.gltf_rotation->begin(), request.gltf_rotation->end(), rotation);
    const bool upright = gltf && (given || (upright_ && UprightRotation(request.keyframes, rotation)));
    if (std::string(f.name) == "ply") {
      if (write_ids || look.vertex_rgb != nullptr) RewritePly(path, write_ids);
      if (shifted) AddPlyOrigin(path, origin);
    } else if (write_ids || write_keys || upright || shifted) {
      EditGltf(path, std::string(f.name) == "glb", [&](GltfDocument& g) {
        if (write_keys) ConvertGltfVertexKeys(g);
        if (write_ids) ConvertGltfPointIds(g);
        if (shifted) SetGltfOrigin(g, origin);
        if (upright) {
          // A viewer's natural start: from the first keyframe, toward one a few keyframes on.
          const auto& k = request.keyframes;
          double from[3], to[3];
          if (!k.empty()) {
            CameraCenter(k.front(), from);
            CameraCenter(k[std::min<std::size_t>(k.size() - 1, 4)], to);
          }
          SetUprightNode(g, rotation, k.empty() ? nullptr : from, k.empty() ? nullptr : to,
                         given ? "this node's rotation is the one the host asked for (3D Tiles "
                                 "content: the tileset's z-up frame to glTF's +Y up)"
                               : "this node's rotation takes the sequence's world frame (the vertex "
                                 "data's) to glTF's +Y up: the keyframe cameras' mean up is +Y, "
                                 "their mean viewing direction -Z");
        }
      });
    }
    host_.Debug("wrote " + path.string() + ": " + std::to_string(mesh.vertex_count()) +
                " vertices, " + std::to_string(mesh.face_count()) + " triangles" +
                (write_ids ? ", point ids" : "") + (write_keys ? ", vertex keys" : "") +
                (look.vertex_rgb ? ", vertex colours" : "") +
                (look.texture ? ", " + std::to_string(tm->pages.size()) + " atlas page(s)" : "") +
                (upright ? ", upright" : "") +
                (shifted ? ", relative to the origin " + std::to_string(origin[0]) + " " +
                               std::to_string(origin[1]) + " " + std::to_string(origin[2])
                         : ""));
  }

  // A long drive's single mesh in blocks (SDK 1.3): PLY (vertex colours included, made block by
  // block: streamed_colours.hpp) and OBJ of a plain mesh, written as they are read
  // (streamed_writers.hpp); glTF/GLB, a coloured OBJ and a texture need the whole mesh.
  bool ExportMeshStream(const imr::sdk::ExportRequest& request, const imr::sdk::MeshStream& mesh) override {
    const Format& f = FindFormat(request.format);
    const std::string& stem = request.stem;
    CheckStem(stem);
    const bool images = request.keyframe_images && !request.keyframes.empty();
    const std::string name = f.name;
    if (name != "ply" && name != "obj") return false;
    if (name == "obj" && images && (vertex_colors_ || texturing_.texture)) return false;
    // As the whole mesh's: colours when some keyframe can give them.
    const bool coloured = name == "ply" && images && vertex_colors_ &&
                          !ColourFrameOf(request.keyframes, texturing_, 0.0).views.empty();
    if (mesh.face_count() == 0) throw InvalidArgument("mesh has no faces: nothing to export");
    if (mesh.vertex_count() > std::numeric_limits<uint32_t>::max())
      throw InvalidArgument("mesh has " + std::to_string(mesh.vertex_count()) + " vertices, more than 2^32 - 1");
    const std::array<double, 6> b = mesh.bounds();
    constexpr double kFloatMax = std::numeric_limits<float>::max();
    for (double x : b)
      if (!std::isfinite(x) || std::fabs(x) > kFloatMax)
        throw InvalidArgument("a vertex coordinate is " + std::to_string(x) + ": not a finite float");
    const fs::path path = fs::path(request.directory) / (stem + f.extension);
    const auto poll = [&] { host_.CheckCancelled(); };
    if (name == "obj") {
      WriteStreamedObj(mesh, path, stem, poll);
    } else {
      // The local origin of ExportOrigin, from the bounds (the same rule).
      std::array<double, 3> origin{};
      if (request.origin) {
        origin = *request.origin;
      } else {
        const double corners[6] = {b[0], b[1], b[2], b[3], b[4], b[5]};
        origin = ExportOrigin(corners, 2);
      }
      std::optional<StreamedVertexColours> colours;
      if (coloured)
        colours.emplace(mesh, request.keyframes, [&](uint64_t i) { return host_.GetKeyframeImage(i); },
                        texturing_, poll);
      WriteStreamedPly(mesh, path, point_ids_, f.max_point_id, origin, poll,
                       colours ? VertexColourBlock([&](std::size_t first, std::size_t count, uint8_t* rgb) {
                         colours->Colour(first, count, rgb);
                       })
                               : VertexColourBlock());
      if (colours) {
        const auto& s = colours->stats();
        host_.Info("vertex colours in blocks: " + std::to_string(s.blocks) + " blocks, pieces of " +
                   std::to_string(s.piece_faces / std::max<int64_t>(s.blocks, 1)) + " faces on average (" +
                   std::to_string(s.max_piece_faces) + " at most), " +
                   std::to_string(s.views / std::max<int64_t>(s.blocks, 1)) + " views per block, " +
                   std::to_string(s.seconds) + " s");
      }
    }
    host_.Debug("wrote " + path.string() + " in blocks: " + std::to_string(mesh.vertex_count()) +
                " vertices, " + std::to_string(mesh.face_count()) + " triangles" +
                (coloured ? ", vertex colours" : ""));
    return true;
  }

 private:
  // The colours (and, when `atlas`, the atlas) of this request's mesh, computed once for all its
  // formats: a PLY-only export builds no atlas; a later format that needs one builds it then.
  const TexturedMesh* Texturing(const imr::sdk::ExportRequest& request, bool atlas) {
    const imr::sdk::MeshView& mesh = request.mesh;
    uint64_t key = 0xcbf29ce484222325ull;
    key = Hash(key, mesh.vertices.data(), mesh.vertices.size() * sizeof(double));
    key = Hash(key, mesh.faces.data(), mesh.faces.size() * sizeof(uint32_t));
    key = Hash(key, request.keyframes.data(), request.keyframes.size() * sizeof(imr_camera));
    key = Hash(key, &request.texel_size, sizeof(double));
    if (cache_ && cache_key_ == key && (cache_atlas_ || !atlas)) return &*cache_;
    cache_.reset();
    encoded_.clear();
    TexturingOptions o = texturing_;
    o.texture = atlas;
    o.texel_size = request.texel_size;  // a level of detail's coarser texture (ABI 1.6)
    cache_atlas_ = atlas;
    // Each page encoded as soon as it is whole and its pixels freed: one page's pixels held at a
    // time (the default job's three 4096^2 pages took 150 MB at once, the end's peak).
    cache_ = ColorAndTexture(
        mesh, request.keyframes,
        [&](uint64_t i) { return host_.GetKeyframeImage(i); }, o, [&] { host_.CheckCancelled(); },
        [&](std::size_t index, AtlasPage& page) {
          if (encoded_.size() <= index) encoded_.resize(index + 1);
          encoded_[index] = EncodePage(page, atlas_format_, jpeg_quality_);
          std::vector<uint8_t>().swap(page.rgb);
        });
    cache_key_ = key;
    const TexturingStats& s = cache_->stats;
    host_.Info("texturing: " + std::to_string(s.views) + " keyframes, " +
               std::to_string(s.faces_textured) + " of " + std::to_string(s.faces) +
               " triangles textured in " + std::to_string(s.patches) + " patches (seams " +
               std::to_string(s.seams_best_view) + " -> " + std::to_string(s.seams) + ", " +
               std::to_string(s.seams_forced) + " unavoidable, " +
               std::to_string(s.expansion_cycles) + " expansion cycles), " +
               std::to_string(cache_->pages.size()) + " atlas page(s), " +
               std::to_string(s.atlas_pixels) + " pixels, " + std::to_string(s.seconds_total) + " s");
    return &*cache_;
  }

  const std::vector<uint8_t>& EncodedPage(std::size_t page) const {
    return encoded_.at(page);  // every page was encoded when whole (Texturing)
  }

  imr::sdk::Host host_;
  bool point_ids_ = true;
  bool vertex_colors_ = true;
  bool upright_ = true;
  TexturingOptions texturing_;
  std::string atlas_format_ = "jpg";
  int jpeg_quality_ = 90;
  std::optional<TexturedMesh> cache_;
  uint64_t cache_key_ = 0;
  bool cache_atlas_ = false;  // the cached result has the atlas
  std::vector<std::vector<uint8_t>> encoded_;  // per page, encoded once for all formats (its pixels gone)
};

}  // namespace

IMR_PLUGIN_EXPORT(AssimpExporter)
