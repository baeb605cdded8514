// imr plugin SDK, C++ side for hosts: check a descriptor and drive an instance with RAII,
// turning statuses into exceptions. Loading the shared object is the host's business (the imr
// host uses Boost.DLL); this header only needs the descriptor.
#pragma once

#include <imr/sdk/plugin.h>

#include <stdexcept>
#include <string>
#include <utility>

namespace imr::sdk {

inline const char* KindName(int32_t kind) {
  switch (kind) {
    case IMR_KIND_FEATURES: return "features";
    case IMR_KIND_REFINER: return "refiner";
    case IMR_KIND_WEIGHT_POLICY: return "weight_policy";
    case IMR_KIND_EXPORTER: return "exporter";
    case IMR_KIND_MESH_REFINER: return "mesh_refiner";
    case IMR_KIND_DENSE: return "dense";
    default: return "unknown";
  }
}

inline const char* StatusName(imr_status s) {
  switch (s) {
    case IMR_OK: return "ok";
    case IMR_ERROR: return "error";
    case IMR_INVALID_ARGUMENT: return "invalid argument";
    case IMR_CANCELLED: return "cancelled";
    case IMR_UNSUPPORTED: return "unsupported";
    default: return "unknown status";
  }
}

// Error raised by the host wrapper when a plugin call fails; carries the plugin's status.
class PluginCallError : public std::runtime_error {
 public:
  PluginCallError(imr_status status, const std::string& message)
      : std::runtime_error(message), status_(status) {}
  imr_status status() const { return status_; }

 private:
  imr_status status_;
};

// Checks what a host must check before using a descriptor. Returns an empty string when usable,
// otherwise what is wrong (without the file name, which the caller adds). A plugin of any minor
// of this major is usable: its descriptor and function table need only their ABI 1.0 size (a
// plugin built against an older, smaller struct), and this host reads no field past that.
inline std::string CheckDescriptor(const imr_plugin_descriptor* d) {
  if (d == nullptr) return "null descriptor";
  if (d->abi_major != IMR_ABI_MAJOR)
    return "built for plugin ABI " + std::to_string(d->abi_major) + "." +
           std::to_string(d->abi_minor) + ", this host speaks ABI " +
           std::to_string(IMR_ABI_MAJOR) + "." + std::to_string(IMR_ABI_MINOR) +
           " (the ABI major must match: rebuild the plugin against this SDK)";
  if (d->struct_size < IMR_DESCRIPTOR_SIZE_1_0)
    return "descriptor is " + std::to_string(d->struct_size) + " bytes, expected at least " +
           std::to_string(IMR_DESCRIPTOR_SIZE_1_0) + " (its ABI 1.0 size)";
  if (d->id == nullptr || *d->id == '\0') return "descriptor has no id";
  if (d->version == nullptr) return "descriptor has no version";
  if (d->create == nullptr || d->destroy == nullptr) return "descriptor lacks create/destroy";
  // The kind's function table: at least its ABI 1.0 size, with its function.
  const auto table = [&](const auto* t, std::size_t min_size, bool complete) -> std::string {
    const std::string kind = KindName(d->kind);
    if (t == nullptr) return "kind is " + kind + " but its function table is missing";
    if (t->struct_size < min_size)
      return kind + " table is " + std::to_string(t->struct_size) + " bytes, expected at least " +
             std::to_string(min_size) + " (its ABI " +
             (d->kind == IMR_KIND_MESH_REFINER ? "1.4" : d->kind == IMR_KIND_DENSE ? "1.5" : "1.0") +
             " size)";
    if (!complete) return kind + " table lacks its function";
    return {};
  };
  switch (d->kind) {
    case IMR_KIND_FEATURES:
      return table(d->features, IMR_FEATURES_API_SIZE_1_0, d->features && d->features->process_frame);
    case IMR_KIND_REFINER:
      return table(d->refiner, IMR_REFINER_API_SIZE_1_0, d->refiner && d->refiner->add_frame);
    case IMR_KIND_WEIGHT_POLICY:
      return table(d->weight_policy, IMR_WEIGHT_POLICY_API_SIZE_1_0,
                   d->weight_policy && d->weight_policy->transfer);
    case IMR_KIND_EXPORTER:
      return table(d->exporter, IMR_EXPORTER_API_SIZE_1_0,
                   d->exporter && d->exporter->formats && d->exporter->export_mesh);
    case IMR_KIND_MESH_REFINER:  // a kind of 1.4: its table is in the descriptor's 1.4 tail
      if (d->struct_size < IMR_DESCRIPTOR_SIZE_1_4)
        return "kind is mesh_refiner (ABI 1.4) but the descriptor is " +
               std::to_string(d->struct_size) + " bytes, expected at least " +
               std::to_string(IMR_DESCRIPTOR_SIZE_1_4);
      return table(d->mesh_refiner, IMR_MESH_REFINER_API_SIZE_1_4,
                   d->mesh_refiner && d->mesh_refiner->refine);
    case IMR_KIND_DENSE:  // a kind of 1.5: its table is in the descriptor's 1.5 tail
      if (d->struct_size < IMR_DESCRIPTOR_SIZE_1_5)
        return "kind is dense (ABI 1.5) but the descriptor is " + std::to_string(d->struct_size) +
               " bytes, expected at least " + std::to_string(IMR_DESCRIPTOR_SIZE_1_5);
      return table(d->dense, IMR_DENSE_API_SIZE_1_5, d->dense && d->dense->add_frame);
    default: return "unknown plugin kind " + std::to_string(d->kind);
  }
}

// One plugin instance: created from params, destroyed with the object. Move-only. A failed
// create throws PluginCallError and leaves no instance: destroy follows only a successful create
// (plugin.h's contract). Every call on the instance must come from one thread at a time.
class Instance {
 public:
  Instance() = default;
  Instance(const imr_plugin_descriptor* d, const std::string& params_json,
           const imr_host_services* host)
      : d_(d) {
    imr_error error{};
    imr_status s = d_->create(params_json.c_str(), host, &h_, &error);
    if (s != IMR_OK || h_ == nullptr)
      throw PluginCallError(s, std::string(d_->id) + ": create failed: " + error.message);
  }
  Instance(Instance&& o) noexcept : d_(std::exchange(o.d_, nullptr)), h_(std::exchange(o.h_, nullptr)) {}
  Instance& operator=(Instance&& o) noexcept {
    if (this != &o) {
      Reset();
      d_ = std::exchange(o.d_, nullptr);
      h_ = std::exchange(o.h_, nullptr);
    }
    return *this;
  }
  Instance(const Instance&) = delete;
  Instance& operator=(const Instance&) = delete;
  ~Instance() { Reset(); }

  const imr_plugin_descriptor* descriptor() const { return d_; }
  imr_instance* handle() const { return h_; }

  void Transfer(imr_transfer_request* request) const {
    request->struct_size = sizeof(imr_transfer_request);
    Check(d_->weight_policy->transfer(h_, request, &error_), "transfer");
  }
  void ExportMesh(imr_export_request* request) const {
    request->struct_size = sizeof(imr_export_request);
    Check(d_->exporter->export_mesh(h_, request, &error_), "export");
  }
  // export_mesh_stream (since 1.3): false when the plugin has no such call or answers
  // IMR_UNSUPPORTED (it needs the whole mesh: call ExportMesh), else as ExportMesh.
  bool ExportMeshStream(imr_export_request* request, const imr_mesh_stream* stream) const {
    const imr_exporter_api* api = d_->exporter;
    if (api->struct_size < offsetof(imr_exporter_api, export_mesh_stream) + sizeof(void*) ||
        api->export_mesh_stream == nullptr)
      return false;
    request->struct_size = sizeof(imr_export_request);
    request->mesh = nullptr;
    const imr_status s = api->export_mesh_stream(h_, request, stream, &error_);
    if (s == IMR_UNSUPPORTED) {
      error_.message[0] = '\0';
      return false;
    }
    Check(s, "export");
    return true;
  }
  imr_track_view ProcessFrame(const imr_camera& camera, const imr_image_view& image,
                              bool is_keyframe) const {
    imr_track_view out{};
    Check(d_->features->process_frame(h_, &camera, &image, is_keyframe ? 1 : 0, &out, &error_),
          "process_frame");
    return out;
  }
  // refine (a mesh refiner, since 1.4): `*out` is the plugin's, valid until its next call.
  void Refine(imr_refine_request* request, imr_refine_result* out) const {
    request->struct_size = sizeof(imr_refine_request);
    *out = imr_refine_result{};
    Check(d_->mesh_refiner->refine(h_, request, out, &error_), "refine");
  }
  // add_frame of a dense plugin (since 1.5): the update is the plugin's, valid until its next call.
  imr_refiner_update AddDenseFrame(imr_dense_request* request) const {
    request->struct_size = sizeof(imr_dense_request);
    imr_refiner_update out{};
    Check(d_->dense->add_frame(h_, request, &out, &error_), "add_frame");
    return out;
  }
  imr_refiner_update AddFrame(const imr_camera& camera, const imr_track_observation* obs,
                              uint64_t count, bool is_keyframe) const {
    imr_refiner_update out{};
    Check(d_->refiner->add_frame(h_, &camera, obs, count, is_keyframe ? 1 : 0, &out, &error_),
          "add_frame");
    return out;
  }

 private:
  void Reset() {
    if (d_ != nullptr && h_ != nullptr) d_->destroy(h_);
    h_ = nullptr;
  }
  void Check(imr_status s, const char* what) const {
    if (s == IMR_OK) return;
    std::string msg = std::string(d_->id) + ": " + what + " failed (" + StatusName(s) + ")";
    if (error_.message[0] != '\0') msg += ": " + std::string(error_.message);
    error_.message[0] = '\0';
    throw PluginCallError(s, msg);
  }

  const imr_plugin_descriptor* d_ = nullptr;
  imr_instance* h_ = nullptr;
  mutable imr_error error_{};
};

}  // namespace imr::sdk
