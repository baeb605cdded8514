// imr plugin SDK, C++ side for plugin authors: a plugin is one class and one macro.
//
//   #include <imr/sdk/plugin.hpp>
//
//   class MyPolicy : public imr::sdk::WeightPolicy {
//    public:
//     static constexpr const char* kId = "com.example.policy.max";
//     static constexpr const char* kVersion = "1.0.0";
//     static constexpr const char* kDescription = "New cells take the largest removed weight";
//     static constexpr const char* kParamsSchema = R"({})";
//     MyPolicy(const imr::sdk::Params& params, const imr::sdk::Host& host) {}
//     void Transfer(const imr::sdk::TransferRequest& request) override { ... }
//   };
//   IMR_PLUGIN_EXPORT(MyPolicy)            // several classes: IMR_PLUGIN_EXPORT(A, B, C)
//
// A mesh refiner (since ABI 1.4) derives from imr::sdk::MeshRefiner and overrides Refine: see
// plugins/refine_photometric in imr's source. A dense plugin (since ABI 1.5) derives from
// imr::sdk::Dense and overrides AddFrame: see plugins/dense_patchmatch.
// An exporter overrides Export (geometry) or, since ABI 1.1, ExportMesh (the request with the
// keyframe cameras; Host::GetKeyframeImage fetches their images): see the example
// vertex_color_exporter (installed with the SDK in share/doc/imr_sdk/examples).
//
// The wrapper builds the C descriptor (plugin.h), converts parameters, and catches every
// exception at the boundary: throw imr::sdk::InvalidArgument for bad parameters or input,
// imr::sdk::Cancelled (Host::CheckCancelled) to stop when asked, any other std::exception for
// failures; the host receives a status and the message. plugin.h's contract holds for the class
// as for the C functions: the constructor is `create` (a constructor that throws means no
// instance and no destructor), the destructor is `destroy`, and every call of one object comes
// from one thread at a time.
#pragma once

#include <imr/sdk/params_schema.hpp>
#include <imr/sdk/plugin.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <exception>
#include <nlohmann/json.hpp>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

namespace imr::sdk {

// Thrown by plugin code for bad parameters or bad input; reported as IMR_INVALID_ARGUMENT.
class InvalidArgument : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Thrown by plugin code when the host asked to stop; reported as IMR_CANCELLED.
class Cancelled : public std::runtime_error {
 public:
  Cancelled() : std::runtime_error("cancelled by the host") {}
};

// Plugin parameters: the job's `params` object, checked against the class's kParamsSchema and
// with its defaults filled in by the wrapper before the constructor runs (so every declared
// parameter is present, and a default is written once, in the schema).
class Params {
 public:
  Params() = default;
  explicit Params(nlohmann::json json) : json_(std::move(json)) {}

  static Params Parse(const char* text) {
    if (text == nullptr || *text == '\0') return Params(nlohmann::json::object());
    nlohmann::json j = nlohmann::json::parse(text, nullptr, /*allow_exceptions=*/false);
    if (j.is_discarded() || !j.is_object()) throw InvalidArgument("params: expected a JSON object");
    return Params(std::move(j));
  }

  bool Has(const std::string& name) const { return json_.contains(name); }

  // The value of a parameter declared in kParamsSchema (its default when the job gave none).
  template <typename T>
  T Get(const std::string& name) const {
    auto it = json_.find(name);
    if (it == json_.end() || it->is_null())
      throw InvalidArgument("params." + name + ": missing (is it declared in kParamsSchema?)");
    try {
      return it->get<T>();
    } catch (const std::exception&) {
      throw InvalidArgument("params." + name + ": unexpected type (" + it->dump() + ")");
    }
  }

  // The value of `name`, or `fallback` when absent. Throws InvalidArgument on a wrong type.
  template <typename T>
  T Get(const std::string& name, const T& fallback) const {
    auto it = json_.find(name);
    if (it == json_.end() || it->is_null()) return fallback;
    try {
      return it->get<T>();
    } catch (const std::exception&) {
      throw InvalidArgument("params." + name + ": unexpected type (" + it->dump() + ")");
    }
  }

  const nlohmann::json& Json() const { return json_; }

 private:
  nlohmann::json json_ = nlohmann::json::object();
};

// A keyframe image held from the host (Host::KeyframeImage): 8-bit gray or BGR pixels, valid
// while this object lives (and at most until the export call that asked for it returns). Released
// to the host on destruction. Move-only.
class KeyframeImage {
 public:
  KeyframeImage() = default;
  KeyframeImage(const imr_host_services* s, uint64_t index, const imr_image_view& view)
      : s_(s), index_(index), view_(view) {}
  KeyframeImage(KeyframeImage&& o) noexcept
      : s_(std::exchange(o.s_, nullptr)), index_(o.index_), view_(o.view_) {}
  KeyframeImage& operator=(KeyframeImage&& o) noexcept {
    if (this != &o) {
      Release();
      s_ = std::exchange(o.s_, nullptr);
      index_ = o.index_;
      view_ = o.view_;
    }
    return *this;
  }
  KeyframeImage(const KeyframeImage&) = delete;
  KeyframeImage& operator=(const KeyframeImage&) = delete;
  ~KeyframeImage() { Release(); }

  const imr_image_view& view() const { return view_; }
  int width() const { return view_.width; }
  int height() const { return view_.height; }
  int channels() const { return view_.channels; }
  // Row y (top to bottom), width() * channels() bytes.
  const uint8_t* Row(int y) const { return view_.pixels + static_cast<std::ptrdiff_t>(y) * view_.stride_bytes; }
  uint64_t index() const { return index_; }
  // Gives the image back to the host now.
  void Release() {
    if (s_ != nullptr && s_->release_keyframe_image != nullptr)
      s_->release_keyframe_image(s_->host_data, index_);
    s_ = nullptr;
  }

 private:
  const imr_host_services* s_ = nullptr;
  uint64_t index_ = 0;
  imr_image_view view_{};
};

// The host's services (logging, progress, cancellation; since 1.1 keyframe images), safe to call
// when the host gave none or an older table.
class Host {
 public:
  Host() = default;
  explicit Host(const imr_host_services* services) : s_(services) {}

  void Log(int32_t level, const std::string& message) const {
    if (Has(offsetof(imr_host_services, log)) && s_->log) s_->log(s_->host_data, level, message.c_str());
  }
  void Debug(const std::string& m) const { Log(IMR_LOG_DEBUG, m); }
  void Info(const std::string& m) const { Log(IMR_LOG_INFO, m); }
  void Warning(const std::string& m) const { Log(IMR_LOG_WARNING, m); }
  void Progress(double fraction, const char* message = nullptr) const {
    if (Has(offsetof(imr_host_services, progress)) && s_->progress)
      s_->progress(s_->host_data, fraction, message);
  }
  bool IsCancelled() const {
    return Has(offsetof(imr_host_services, is_cancelled)) && s_->is_cancelled &&
           s_->is_cancelled(s_->host_data) != 0;
  }
  // Throws Cancelled when the host asked to stop: call it between units of work.
  void CheckCancelled() const {
    if (IsCancelled()) throw Cancelled();
  }
  // True when the host's table has the keyframe-image services (a 1.1 host or newer).
  bool HasKeyframeImages() const {
    return Has(offsetof(imr_host_services, release_keyframe_image)) && s_->keyframe_image &&
           s_->release_keyframe_image;
  }
  // The image of keyframe `index` of the export (or refine) in progress (its keyframes). Throws
  // InvalidArgument with the host's message for an index out of range, std::runtime_error when
  // the host cannot give it (an older host, an image that does not decode, its budget exhausted).
  KeyframeImage GetKeyframeImage(uint64_t index) const {
    if (!HasKeyframeImages())
      throw std::runtime_error("keyframe images: the host does not provide them (its services "
                               "table predates plugin ABI 1.1)");
    imr_image_view view{};
    imr_error error{};
    const imr_status status = s_->keyframe_image(s_->host_data, index, &view, &error);
    if (status != IMR_OK) {
      const std::string message = error.message[0] != '\0'
                                      ? std::string(error.message)
                                      : "keyframe image " + std::to_string(index) + ": failed";
      if (status == IMR_INVALID_ARGUMENT) throw InvalidArgument(message);
      throw std::runtime_error(message);
    }
    if (view.pixels == nullptr || view.width <= 0 || view.height <= 0 ||
        (view.channels != 1 && view.channels != 3) ||
        view.stride_bytes < static_cast<int64_t>(view.width) * view.channels) {
      KeyframeImage release(s_, index, view);
      throw std::runtime_error("keyframe image " + std::to_string(index) +
                               ": the host gave an unusable view");
    }
    return KeyframeImage(s_, index, view);
  }

 private:
  // A field exists when the host's struct is long enough to hold it (older hosts: fewer fields).
  bool Has(std::size_t field_offset) const {
    return s_ != nullptr && s_->struct_size >= field_offset + sizeof(void*);
  }
  const imr_host_services* s_ = nullptr;
};

// ---- kinds ---------------------------------------------------------------------------------

// Base of every plugin class: virtual destructor so the wrapper can delete through it.
class PluginBase {
 public:
  virtual ~PluginBase() = default;
};

struct TransferRequest {
  std::span<const double> removed_centroids;  // 3 per removed cell, packed xyz
  std::span<const double> removed_weights;    // 1 per removed cell
  std::span<const double> added_centroids;    // 3 per new cell, packed xyz
  std::span<double> added_weights;            // out: 1 per new cell
  std::size_t removed_count() const { return removed_weights.size(); }
  std::size_t added_count() const { return added_weights.size(); }
};

// Weight-transfer policy: give each new cell a weight from the removed ones (plugin.h, "weight
// policy").
class WeightPolicy : public PluginBase {
 public:
  static constexpr imr_plugin_kind kKind = IMR_KIND_WEIGHT_POLICY;
  virtual void Transfer(const TransferRequest& request) = 0;
};

struct MeshView {
  std::span<const double> vertices;   // 3 per vertex
  std::span<const uint32_t> faces;    // 3 per triangle, counter-clockwise seen from free space
  std::span<const int64_t> point_ids; // 1 per vertex (-1: Steiner), or empty
  std::span<const uint8_t> vertex_colors;  // since 1.1: 3 per vertex (RGB) from the input, or empty
  std::span<const int64_t> vertex_keys;    // since 1.2: 1 per vertex (tiles), or empty
  std::size_t vertex_count() const { return vertices.size() / 3; }
  std::size_t face_count() const { return faces.size() / 3; }
};

// Everything an export call carries (since 1.1; a 1.0 host gives no keyframes).
struct ExportRequest {
  MeshView mesh;
  std::string directory;  // existing staging folder to write into
  std::string stem;       // file name without extension
  std::string format;     // one of kFormats
  // The keyframe cameras, in order (imr_camera: K, R, t world -> camera, image size). K is zero
  // for a camera whose input gives no intrinsics.
  std::span<const imr_camera> keyframes;
  // True when Host::GetKeyframeImage(i) gives keyframe i's image (inputs with images).
  bool keyframe_images = false;
  // Since 1.2 (plugin.h, imr_export_request): the origin PLY and glTF vertices are written
  // relative to, and the glTF root node's rotation (row-major, world -> glTF), when the host sets
  // them (3D Tiles).
  std::optional<std::array<double, 3>> origin;
  std::optional<std::array<double, 9>> gltf_rotation;
  // Since 1.6: the world length of one texel the content needs (a 3D Tiles level of detail,
  // seen only from afar), or 0: the images' own resolution.
  double texel_size = 0.0;
};

// Since 1.3 (plugin.h, imr_mesh_stream): a mesh read in blocks, the same vertices and faces in
// the same order as a MeshView of it. The calls throw std::runtime_error with the host's message.
class MeshStream {
 public:
  explicit MeshStream(const imr_mesh_stream& s) : s_(s) {}
  std::size_t vertex_count() const { return static_cast<std::size_t>(s_.vertex_count); }
  std::size_t face_count() const { return static_cast<std::size_t>(s_.face_count); }
  // Min x y z, max x y z.
  std::array<double, 6> bounds() const {
    std::array<double, 6> b;
    std::copy_n(s_.bounds, 6, b.begin());
    return b;
  }
  // Vertices [first, first + count): xyz (3 each), point ids, normal sums (3 each: plugin.h);
  // a null pointer skips that array.
  void ReadVertices(std::size_t first, std::size_t count, double* xyz, int64_t* point_ids,
                    double* normal_sums) const {
    imr_error e{};
    if (s_.read_vertices(s_.context, first, count, xyz, point_ids, normal_sums, &e) != IMR_OK)
      throw std::runtime_error(std::string("reading the mesh's vertices: ") + e.message);
  }
  // Faces [first, first + count): 3 indices each.
  void ReadFaces(std::size_t first, std::size_t count, uint32_t* faces) const {
    imr_error e{};
    if (s_.read_faces(s_.context, first, count, faces, &e) != IMR_OK)
      throw std::runtime_error(std::string("reading the mesh's faces: ") + e.message);
  }

 private:
  imr_mesh_stream s_;
};

// Mesh exporter: declare `static constexpr const char* kFormats = "obj,ply";` and override one
// of the two calls: Export (geometry only, the 1.0 call) or ExportMesh (the whole request, with
// the keyframe cameras and images). A long drive's single mesh may come as a MeshStream
// (ExportMeshStream, since 1.3) to an exporter that overrides that call too.
class Exporter : public PluginBase {
 public:
  static constexpr imr_plugin_kind kKind = IMR_KIND_EXPORTER;
  // Write directory/stem.<format extension> (and companions). `format` is one of kFormats.
  virtual void Export(const MeshView& mesh, const std::string& directory, const std::string& stem,
                      const std::string& format) {
    (void)mesh, (void)directory, (void)stem, (void)format;
    throw std::logic_error("exporter overrides neither Export nor ExportMesh");
  }
  // The same with the keyframes (since 1.1). By default, Export with the geometry.
  virtual void ExportMesh(const ExportRequest& request) {
    Export(request.mesh, request.directory, request.stem, request.format);
  }
  // The same for a mesh read in blocks (since 1.3; `request.mesh` is empty). Return false, with
  // nothing written, when this request needs the whole mesh: the host then reads it whole and
  // calls ExportMesh. By default, false.
  virtual bool ExportMeshStream(const ExportRequest& request, const MeshStream& mesh) {
    (void)request, (void)mesh;
    return false;
  }
};

// Feature tracker: return every track observed in this frame; storage stays with the plugin.
class Features : public PluginBase {
 public:
  static constexpr imr_plugin_kind kKind = IMR_KIND_FEATURES;
  virtual std::span<const imr_track_observation> ProcessFrame(const imr_camera& camera,
                                                             const imr_image_view& image,
                                                             bool is_keyframe) = 0;
};

// What a refiner reports at a keyframe (the storage behind imr_refiner_update). A point's
// observing cameras are camera_ids[first_camera, first_camera + camera_count).
struct RefinerUpdate {
  std::vector<imr_point_estimate> new_points;
  std::vector<imr_point_estimate> moved_points;
  std::vector<uint64_t> removed_ids;
  std::vector<uint64_t> camera_ids;

  void Clear() {
    new_points.clear();
    moved_points.clear();
    removed_ids.clear();
    camera_ids.clear();
  }
  // The C view of this update, valid while it is neither changed nor destroyed.
  imr_refiner_update View() const {
    return {new_points.data(), new_points.size(),  moved_points.data(), moved_points.size(),
            removed_ids.data(), removed_ids.size(), camera_ids.data(),  camera_ids.size()};
  }
};

// Point refiner: override Refine (fill a RefinerUpdate, which the wrapper keeps until the next
// call and hands to the host) or, as plugins written before RefinerUpdate do, AddFrame (fill the
// C view with storage of your own).
class Refiner : public PluginBase {
 public:
  static constexpr imr_plugin_kind kKind = IMR_KIND_REFINER;
  // Feed one frame; on keyframes put the new, moved and removed points into `update` (empty on
  // entry).
  virtual void Refine(const imr_camera& camera, std::span<const imr_track_observation> observations,
                      bool is_keyframe, RefinerUpdate* update) {
    (void)camera, (void)observations, (void)is_keyframe, (void)update;
    throw std::logic_error("refiner overrides neither Refine nor AddFrame");
  }
  // The same, filling the C view. By default, Refine into storage the wrapper keeps.
  virtual void AddFrame(const imr_camera& camera,
                        std::span<const imr_track_observation> observations, bool is_keyframe,
                        imr_refiner_update* out) {
    update_.Clear();
    Refine(camera, observations, is_keyframe, &update_);
    *out = update_.View();
  }

 private:
  RefinerUpdate update_;
};

// Everything a refine call carries (since 1.4; plugin.h, imr_refine_request).
struct RefineRequest {
  MeshView mesh;                           // the surface (vertex_keys empty)
  std::span<const uint8_t> vertex_flags;   // 1 per vertex: IMR_REFINE_VERTEX_* bits
  std::span<const imr_camera> keyframes;   // every keyframe so far; images: Host::GetKeyframeImage
  std::size_t recent_keyframes_begin = 0;  // keyframes from here on arrived since the last call
  bool keyframe_images = false;            // Host::GetKeyframeImage(i) gives keyframe i's image
  bool final_call = false;                 // the last call, before the exports
  bool Fixed(std::size_t v) const { return (vertex_flags[v] & IMR_REFINE_VERTEX_FIXED) != 0; }
  bool Changed(std::size_t v) const { return (vertex_flags[v] & IMR_REFINE_VERTEX_CHANGED) != 0; }
};

// What a refine call returns; the wrapper keeps it until the next call.
struct RefineResult {
  std::vector<double> vertices;  // 3 per vertex: the request's at their new positions, then added
  std::vector<uint32_t> faces;   // 3 per face; empty: the request's faces unchanged
};

// Mesh refiner (since 1.4): move the surface's vertices (and perhaps subdivide) to agree with the
// keyframe images (plugin.h, "mesh refiner"). `result` is empty on entry.
class MeshRefiner : public PluginBase {
 public:
  static constexpr imr_plugin_kind kKind = IMR_KIND_MESH_REFINER;
  virtual void Refine(const RefineRequest& request, RefineResult* result) = 0;
  // The C view of the call: by default, Refine into storage the wrapper keeps.
  virtual void RefineC(const RefineRequest& request, imr_refine_result* out) {
    result_.vertices.clear();
    result_.faces.clear();
    Refine(request, &result_);
    const std::size_t n = request.mesh.vertex_count();
    if (result_.vertices.size() % 3 != 0 || result_.vertices.size() / 3 < n)
      throw std::logic_error("refine: the result holds fewer vertices than the request");
    if (result_.faces.empty() && result_.vertices.size() / 3 != n)
      throw std::logic_error("refine: vertices added without faces");
    out->struct_size = sizeof(imr_refine_result);
    out->vertices = result_.vertices.data();
    out->vertex_count = result_.vertices.size() / 3;
    out->faces = result_.faces.empty() ? nullptr : result_.faces.data();
    out->face_count = result_.faces.size() / 3;
  }

 private:
  RefineResult result_;
};

// Dense (since 1.5): points from the images (plugin.h, "dense"), called per frame; keep the frames
// you need yourself (copy: the image is valid during the call only). `update` is empty on entry;
// on keyframes fill new_points (and removed_ids) with camera ids of frames already given; on
// other frames the host ignores it.
struct DenseRequest {
  const imr_camera& camera;
  const imr_image_view& image;
  bool is_keyframe = false;
  bool final_call = false;  // the last frame: report whatever is pending
};
class Dense : public PluginBase {
 public:
  static constexpr imr_plugin_kind kKind = IMR_KIND_DENSE;
  virtual void AddFrame(const DenseRequest& request, RefinerUpdate* update) = 0;
  // The C view of the call: by default, AddFrame into storage the wrapper keeps.
  virtual void AddFrameC(const DenseRequest& request, imr_refiner_update* out) {
    update_.Clear();
    AddFrame(request, &update_);
    *out = update_.View();
  }

 private:
  RefinerUpdate update_;
};

// ---- the wrapper behind IMR_PLUGIN_EXPORT ----------------------------------------------------
namespace detail {

inline void WriteError(imr_error* error, const char* message) {
  if (error == nullptr) return;
  std::snprintf(error->message, sizeof(error->message), "%s", message ? message : "");
}

// Runs `body`, mapping exceptions to statuses: nothing escapes across the C boundary.
template <typename F>
imr_status Guard(imr_error* error, F&& body) noexcept {
  try {
    body();
    return IMR_OK;
  } catch (const InvalidArgument& e) {
    WriteError(error, e.what());
    return IMR_INVALID_ARGUMENT;
  } catch (const Cancelled& e) {
    WriteError(error, e.what());
    return IMR_CANCELLED;
  } catch (const std::exception& e) {
    WriteError(error, e.what());
    return IMR_ERROR;
  } catch (...) {
    WriteError(error, "unknown exception in plugin");
    return IMR_ERROR;
  }
}

// Checks `params` against a schema in the language of plugin.h with the host's own validator
// (params_schema.hpp: the host validates jobs too; this covers hosts and tests that do not) and
// returns them with the schema's defaults filled in. Throws InvalidArgument naming the first
// unknown, mistyped or out-of-range parameter.
inline Params CheckedAgainstSchema(const char* schema_text, const Params& params) {
  const nlohmann::json schema = nlohmann::json::parse(
      schema_text && *schema_text ? schema_text : "{}", nullptr, /*allow_exceptions=*/false);
  if (!schema.is_object()) throw std::runtime_error("plugin bug: kParamsSchema is not a JSON object");
  const std::vector<ParamProblem> problems = ValidateParams(schema, params.Json());
  if (!problems.empty())
    throw InvalidArgument("params" + (problems[0].name.empty() ? "" : "." + problems[0].name) +
                          ": " + problems[0].message);
  return Params(WithSchemaDefaults(schema, params.Json()));
}

template <typename T>
T* Self(imr_instance* instance) {
  return static_cast<T*>(reinterpret_cast<PluginBase*>(instance));
}

template <typename T>
imr_status Create(const char* params_json, const imr_host_services* host, imr_instance** out,
                  imr_error* error) noexcept {
  if (out == nullptr) return IMR_INVALID_ARGUMENT;
  *out = nullptr;
  return Guard(error, [&] {
    PluginBase* p = new T(CheckedAgainstSchema(T::kParamsSchema, Params::Parse(params_json)),
                          Host(host));
    *out = reinterpret_cast<imr_instance*>(p);
  });
}

inline void Destroy(imr_instance* instance) noexcept {
  delete reinterpret_cast<PluginBase*>(instance);
}

template <typename T>
imr_status Transfer(imr_instance* instance, const imr_transfer_request* r,
                    imr_error* error) noexcept {
  return Guard(error, [&] {
    if (r == nullptr || r->struct_size < IMR_TRANSFER_REQUEST_SIZE_1_0)
      throw InvalidArgument("transfer: request struct too small");
    const auto nr = static_cast<std::size_t>(r->removed_count);
    const auto na = static_cast<std::size_t>(r->added_count);
    TransferRequest req{{r->removed_centroids, 3 * nr},
                        {r->removed_weights, nr},
                        {r->added_centroids, 3 * na},
                        {r->added_weights, na}};
    Self<T>(instance)->Transfer(req);
  });
}

// The request's fields but the mesh, as this SDK's minor reads them from the host's struct.
inline ExportRequest RequestOf(const imr_export_request* r) {
  ExportRequest req;
  req.directory = r->directory ? r->directory : ".";
  req.stem = r->stem ? r->stem : "mesh";
  req.format = r->format ? r->format : "";
  if (r->struct_size >= offsetof(imr_export_request, reserved1) + sizeof(uint32_t) &&
      r->keyframes != nullptr) {
    req.keyframes = {r->keyframes, static_cast<std::size_t>(r->keyframe_count)};
    req.keyframe_images = r->keyframe_images != 0;
  }
  if (r->struct_size >= offsetof(imr_export_request, gltf_rotation) + sizeof(void*)) {
    if (r->origin != nullptr) req.origin = std::array<double, 3>{r->origin[0], r->origin[1], r->origin[2]};
    if (r->gltf_rotation != nullptr) {
      std::array<double, 9> rotation;
      std::copy_n(r->gltf_rotation, 9, rotation.begin());
      req.gltf_rotation = rotation;
    }
  }
  if (r->struct_size >= offsetof(imr_export_request, texel_size) + sizeof(double) &&
      std::isfinite(r->texel_size) && r->texel_size > 0.0)
    req.texel_size = r->texel_size;
  return req;
}

template <typename T>
imr_status ExportMesh(imr_instance* instance, const imr_export_request* r,
                      imr_error* error) noexcept {
  return Guard(error, [&] {
    if (r == nullptr || r->struct_size < IMR_EXPORT_REQUEST_SIZE_1_0 || r->mesh == nullptr ||
        r->mesh->struct_size < IMR_MESH_VIEW_SIZE_1_0)
      throw InvalidArgument("export: no mesh, or a request or mesh struct too small");
    const imr_mesh_view& m = *r->mesh;
    const auto nv = static_cast<std::size_t>(m.vertex_count);
    // Fields of a newer minor exist only when the host's struct is long enough (1.0 hosts).
    const bool colors = m.struct_size >= offsetof(imr_mesh_view, vertex_colors) + sizeof(void*) &&
                        m.vertex_colors != nullptr;
    const bool keys = m.struct_size >= offsetof(imr_mesh_view, vertex_keys) + sizeof(void*) &&
                      m.vertex_keys != nullptr;
    ExportRequest req = RequestOf(r);
    req.mesh = MeshView{{m.vertices, 3 * nv},
                        {m.faces, 3 * static_cast<std::size_t>(m.face_count)},
                        {m.point_ids, m.point_ids ? nv : 0},
                        {m.vertex_colors, colors ? 3 * nv : 0},
                        {m.vertex_keys, keys ? nv : 0}};
    static_cast<Exporter*>(Self<T>(instance))->ExportMesh(req);
  });
}

template <typename T>
imr_status ExportMeshStream(imr_instance* instance, const imr_export_request* r,
                            const imr_mesh_stream* stream, imr_error* error) noexcept {
  bool written = false;
  const imr_status s = Guard(error, [&] {
    if (r == nullptr || r->struct_size < IMR_EXPORT_REQUEST_SIZE_1_0 || stream == nullptr ||
        stream->struct_size < sizeof(imr_mesh_stream) || stream->read_vertices == nullptr ||
        stream->read_faces == nullptr)
      throw InvalidArgument("export: no mesh stream, or a request or stream struct too small");
    written = static_cast<Exporter*>(Self<T>(instance))->ExportMeshStream(RequestOf(r), MeshStream(*stream));
  });
  if (s != IMR_OK || written) return s;
  WriteError(error, "this request needs the whole mesh");
  return IMR_UNSUPPORTED;
}

template <typename T>
imr_status ProcessFrame(imr_instance* instance, const imr_camera* camera,
                        const imr_image_view* image, int32_t is_keyframe, imr_track_view* out,
                        imr_error* error) noexcept {
  return Guard(error, [&] {
    if (camera == nullptr || image == nullptr || out == nullptr)
      throw InvalidArgument("process_frame: null argument");
    auto tracks = Self<T>(instance)->ProcessFrame(*camera, *image, is_keyframe != 0);
    out->observations = tracks.data();
    out->count = tracks.size();
  });
}

template <typename T>
imr_status AddFrame(imr_instance* instance, const imr_camera* camera,
                    const imr_track_observation* obs, uint64_t count, int32_t is_keyframe,
                    imr_refiner_update* out, imr_error* error) noexcept {
  return Guard(error, [&] {
    if (camera == nullptr || out == nullptr || (obs == nullptr && count > 0))
      throw InvalidArgument("add_frame: null argument");
    *out = imr_refiner_update{};
    Self<T>(instance)->AddFrame(*camera, {obs, static_cast<std::size_t>(count)}, is_keyframe != 0,
                                out);
  });
}

template <typename T>
imr_status RefineMesh(imr_instance* instance, const imr_refine_request* r, imr_refine_result* out,
                      imr_error* error) noexcept {
  return Guard(error, [&] {
    if (r == nullptr || out == nullptr || r->struct_size < IMR_REFINE_REQUEST_SIZE_1_4 ||
        r->mesh == nullptr || r->mesh->struct_size < IMR_MESH_VIEW_SIZE_1_0)
      throw InvalidArgument("refine: no mesh or result, or a request or mesh struct too small");
    const imr_mesh_view& m = *r->mesh;
    const auto nv = static_cast<std::size_t>(m.vertex_count);
    const bool colors = m.struct_size >= offsetof(imr_mesh_view, vertex_colors) + sizeof(void*) &&
                        m.vertex_colors != nullptr;
    if (r->vertex_flags == nullptr && nv > 0) throw InvalidArgument("refine: no vertex flags");
    RefineRequest req;
    req.mesh = MeshView{{m.vertices, 3 * nv},
                        {m.faces, 3 * static_cast<std::size_t>(m.face_count)},
                        {m.point_ids, m.point_ids ? nv : 0},
                        {m.vertex_colors, colors ? 3 * nv : 0},
                        {}};
    req.vertex_flags = {r->vertex_flags, nv};
    if (r->keyframes != nullptr)
      req.keyframes = {r->keyframes, static_cast<std::size_t>(r->keyframe_count)};
    req.recent_keyframes_begin =
        std::min(static_cast<std::size_t>(r->recent_keyframes_begin), req.keyframes.size());
    req.keyframe_images = r->keyframe_images != 0;
    req.final_call = r->final_call != 0;
    *out = imr_refine_result{};
    static_cast<MeshRefiner*>(Self<T>(instance))->RefineC(req, out);
  });
}

template <typename T>
imr_status AddDenseFrame(imr_instance* instance, const imr_dense_request* r, imr_refiner_update* out,
                         imr_error* error) noexcept {
  return Guard(error, [&] {
    if (r == nullptr || out == nullptr || r->struct_size < IMR_DENSE_REQUEST_SIZE_1_5 ||
        r->camera == nullptr || r->image == nullptr || r->image->pixels == nullptr)
      throw InvalidArgument("add_frame: no camera, image or update, or a request too small");
    *out = imr_refiner_update{};
    static_cast<Dense*>(Self<T>(instance))
        ->AddFrameC(DenseRequest{*r->camera, *r->image, r->is_keyframe != 0, r->final_call != 0}, out);
  });
}

template <typename T>
const imr_plugin_descriptor* DescriptorFor() noexcept {
  static_assert(std::is_base_of_v<PluginBase, T>, "a plugin class derives from an imr::sdk kind");
  static const imr_plugin_descriptor d = [] {
    imr_plugin_descriptor x{};
    x.struct_size = sizeof(imr_plugin_descriptor);
    x.abi_major = IMR_ABI_MAJOR;
    x.abi_minor = IMR_ABI_MINOR;
    x.kind = T::kKind;
    x.id = T::kId;
    x.version = T::kVersion;
    x.description = T::kDescription;
    x.params_schema = T::kParamsSchema;
    x.create = &Create<T>;
    x.destroy = &Destroy;
    // Only the table of the class's own kind is instantiated.
    if constexpr (T::kKind == IMR_KIND_WEIGHT_POLICY) {
      static const imr_weight_policy_api api{sizeof(api), 0, &Transfer<T>};
      x.weight_policy = &api;
    } else if constexpr (T::kKind == IMR_KIND_FEATURES) {
      static const imr_features_api api{sizeof(api), 0, &ProcessFrame<T>};
      x.features = &api;
    } else if constexpr (T::kKind == IMR_KIND_REFINER) {
      static const imr_refiner_api api{sizeof(api), 0, &AddFrame<T>};
      x.refiner = &api;
    } else if constexpr (T::kKind == IMR_KIND_EXPORTER) {
      static const imr_exporter_api api{sizeof(api), 0, T::kFormats, &ExportMesh<T>,
                                        &ExportMeshStream<T>};
      x.exporter = &api;
    } else if constexpr (T::kKind == IMR_KIND_MESH_REFINER) {
      static const imr_mesh_refiner_api api{sizeof(api), 0, &RefineMesh<T>};
      x.mesh_refiner = &api;
    } else if constexpr (T::kKind == IMR_KIND_DENSE) {
      static const imr_dense_api api{sizeof(api), 0, &AddDenseFrame<T>};
      x.dense = &api;
    }
    return x;
  }();
  return &d;
}

template <typename... Ts>
const imr_plugin_descriptor* Entry(uint32_t index) noexcept {
  static const imr_plugin_descriptor* const table[] = {DescriptorFor<Ts>()...};
  return index < sizeof...(Ts) ? table[index] : nullptr;
}

}  // namespace detail
}  // namespace imr::sdk

// Export the plugin classes of this library through the one entry symbol.
#define IMR_PLUGIN_EXPORT(...)                                                               \
  extern "C" IMR_PLUGIN_API const imr_plugin_descriptor* imr_plugin_entry(uint32_t index) { \
    return ::imr::sdk::detail::Entry<__VA_ARGS__>(index);                                  \
  }
