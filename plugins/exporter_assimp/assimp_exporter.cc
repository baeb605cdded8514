// The assimp exporter (DESIGN.md section 7, "Outputs"): writes the output surface as OBJ, binary
// PLY, glTF 2.0 or GLB, with per-vertex normals and, where the format has a place for them, the
// per-vertex point ids that trace the mesh back to its 3D points (DESIGN.md section 3, "Output").
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
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "point_id_channel.hpp"

namespace {

namespace fs = std::filesystem;
using imr::exporter_assimp::ConvertGltfPointIds;
using imr::exporter_assimp::ConvertPlyPointIds;
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
};

// "objnomtl": one file, no .mtl beside it (the mesh has one plain material anyway).
// "plyb": assimp's binary PLY, little-endian on this host.
constexpr std::array<Format, 4> kFormatTable = {{
    {"obj", "objnomtl", ".obj", 0},
    {"ply", "plyb", ".ply", kMaxPointId},
    {"gltf", "gltf2", ".gltf", kMaxGltfPointId},
    {"glb", "glb2", ".glb", kMaxGltfPointId},
}};

const Format& FindFormat(const std::string& name) {
  for (const Format& f : kFormatTable)
    if (name == f.name) return f;
  throw InvalidArgument("unknown format \"" + name + "\": expected one of obj, ply, gltf, glb");
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

// Area-weighted vertex normals from the counter-clockwise faces; (0, 0, 1) where undefined.
void ComputeNormals(const imr::sdk::MeshView& mesh, aiVector3D* out) {
  const std::size_t nv = mesh.vertex_count();
  std::vector<double> acc(3 * nv, 0.0);
  const double* v = mesh.vertices.data();
  for (std::size_t f = 0; f < mesh.face_count(); ++f) {
    const uint32_t a = mesh.faces[3 * f], b = mesh.faces[3 * f + 1], c = mesh.faces[3 * f + 2];
    double e1[3], e2[3];
    for (int k = 0; k < 3; ++k) {
      e1[k] = v[3 * b + k] - v[3 * a + k];
      e2[k] = v[3 * c + k] - v[3 * a + k];
    }
    const double n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
                         e1[0] * e2[1] - e1[1] * e2[0]};  // |n| = 2 * area
    for (const uint32_t i : {a, b, c})
      for (int k = 0; k < 3; ++k) acc[3 * i + k] += n[k];
  }
  for (std::size_t i = 0; i < nv; ++i) {
    const double* n = &acc[3 * i];
    const double len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    out[i] = len > 0 && std::isfinite(len)
                 ? aiVector3D(static_cast<ai_real>(n[0] / len), static_cast<ai_real>(n[1] / len),
                              static_cast<ai_real>(n[2] / len))
                 : aiVector3D(0, 0, 1);
  }
}

// A complete scene: one root node holding one triangle mesh with one plain material.
std::unique_ptr<aiScene> BuildScene(const imr::sdk::MeshView& mesh, const std::string& name,
                                    bool with_point_ids) {
  auto scene = std::make_unique<aiScene>();
  const auto nv = static_cast<unsigned>(mesh.vertex_count());
  const auto nf = static_cast<unsigned>(mesh.face_count());

  scene->mNumMaterials = 1;
  scene->mMaterials = new aiMaterial*[1]{new aiMaterial()};
  const aiString material_name("imr_surface");
  scene->mMaterials[0]->AddProperty(&material_name, AI_MATKEY_NAME);
  const aiColor3D grey(0.8f, 0.8f, 0.8f);
  scene->mMaterials[0]->AddProperty(&grey, 1, AI_MATKEY_COLOR_DIFFUSE);

  scene->mNumMeshes = 1;
  scene->mMeshes = new aiMesh*[1]{new aiMesh()};
  aiMesh& m = *scene->mMeshes[0];
  m.mName = aiString(name);
  m.mMaterialIndex = 0;
  m.mPrimitiveTypes = aiPrimitiveType_TRIANGLE;
  m.mNumVertices = nv;
  m.mVertices = new aiVector3D[nv];
  for (unsigned i = 0; i < nv; ++i)
    m.mVertices[i] = aiVector3D(static_cast<ai_real>(mesh.vertices[3 * i]),
                                static_cast<ai_real>(mesh.vertices[3 * i + 1]),
                                static_cast<ai_real>(mesh.vertices[3 * i + 2]));
  m.mNormals = new aiVector3D[nv];
  ComputeNormals(mesh, m.mNormals);
  if (with_point_ids) {
    m.mNumUVComponents[0] = 2;
    m.mTextureCoords[0] = new aiVector3D[nv];
    for (unsigned i = 0; i < nv; ++i) {
      const EncodedPointId e = EncodePointId(mesh.point_ids[i]);
      m.mTextureCoords[0][i] = aiVector3D(e.hi, e.lo, 0);
    }
  }
  m.mNumFaces = nf;
  m.mFaces = new aiFace[nf];
  for (unsigned f = 0; f < nf; ++f) {
    aiFace& face = m.mFaces[f];
    face.mNumIndices = 3;
    face.mIndices = new unsigned[3]{mesh.faces[3 * f], mesh.faces[3 * f + 1], mesh.faces[3 * f + 2]};
  }

  scene->mRootNode = new aiNode(name);
  scene->mRootNode->mNumMeshes = 1;
  scene->mRootNode->mMeshes = new unsigned[1]{0};
  return scene;
}

class AssimpExporter : public imr::sdk::Exporter {
 public:
  static constexpr const char* kId = "org.imr.exporter.assimp";
  static constexpr const char* kVersion = "1.0.0";
  static constexpr const char* kDescription =
      "Mesh files through assimp: OBJ, binary PLY, glTF 2.0, GLB; normals in all, point ids in "
      "PLY and glTF/GLB (OBJ has no place for them)";
  static constexpr const char* kParamsSchema = R"({
  "point_ids": {"type": "boolean", "default": true,
    "description": "Write each vertex's 3D point id (-1 for Steiner points) where the format has a per-vertex attribute: PLY 'property int point_id' (ids up to 2^31 - 1), glTF/GLB attribute '_POINT_ID' (SCALAR FLOAT as glTF forbids UNSIGNED_INT attributes; ids up to 2^24, exact). OBJ cannot keep them. An id beyond the format's range is an error."}
})";
  static constexpr const char* kFormats = "obj,ply,gltf,glb";

  AssimpExporter(const imr::sdk::Params& params, const imr::sdk::Host& host) : host_(host) {
    for (const auto& [key, value] : params.Json().items())
      if (key != "point_ids")
        throw InvalidArgument("params." + key + ": unknown parameter (known: point_ids)");
    point_ids_ = params.Get<bool>("point_ids", true);
  }

  void Export(const imr::sdk::MeshView& mesh, const std::string& directory,
              const std::string& stem, const std::string& format) override {
    const Format& f = FindFormat(format);
    if (stem.empty() || stem.find('/') != std::string::npos || stem == "." || stem == "..")
      throw InvalidArgument("stem \"" + stem + "\" is not a plain file name");
    const bool write_ids = point_ids_ && f.max_point_id > 0 && !mesh.point_ids.empty();
    CheckMesh(mesh, f, write_ids);
    host_.CheckCancelled();

    const fs::path path = fs::path(directory) / (stem + f.extension);
    std::unique_ptr<aiScene> scene = BuildScene(mesh, stem, write_ids);
    {
      std::string write_error;
      Assimp::Exporter exporter;
      exporter.SetIOHandler(new CheckedIOSystem(&write_error));  // the exporter owns it
      const aiReturn r = exporter.Export(scene.get(), f.assimp_id, path.string());
      if (!write_error.empty()) throw std::runtime_error(write_error);
      if (r != aiReturn_SUCCESS)
        throw std::runtime_error("assimp could not write " + path.string() + " (" + f.assimp_id +
                                 "): " + exporter.GetErrorString());
    }
    scene.reset();
    if (write_ids) {
      if (format == "ply") ConvertPlyPointIds(path);
      else ConvertGltfPointIds(path, format == "glb");
    }
    host_.Debug("wrote " + path.string() + ": " + std::to_string(mesh.vertex_count()) +
                " vertices, " + std::to_string(mesh.face_count()) + " triangles" +
                (write_ids ? ", point ids" : ""));
  }

 private:
  imr::sdk::Host host_;
  bool point_ids_ = true;
};

}  // namespace

IMR_PLUGIN_EXPORT(AssimpExporter)
