// A mesh refiner built against the frozen ABI 1.4 C header (tests/sdk_1_4), as a plugin shipped
// before ABI 1.5 (the dense kind) would be: it answers every refine call with the request's
// vertices, each moved by a fixed offset along z (`lift`, 0 by default), and counts its calls in
// the log. Its descriptor's tail, where 1.5 put the dense table, is its zeroed reserved[0].
// tests/sdk_compat_test runs it beside 1.5 plugins in today's host.
#include <imr/sdk/plugin.h>

#include <cstdio>
#include <cstring>
#include <new>
#include <vector>

static_assert(IMR_ABI_MINOR == 4, "this plugin must build against the ABI 1.4 copy of the SDK");

namespace {

struct Instance {
  const imr_host_services* host = nullptr;
  std::vector<double> vertices;
  int calls = 0;
};

imr_status Create(const char*, const imr_host_services* host, imr_instance** out, imr_error*) {
  Instance* i = new (std::nothrow) Instance;
  if (i == nullptr) return IMR_ERROR;
  i->host = host;
  *out = reinterpret_cast<imr_instance*>(i);
  return IMR_OK;
}

void Destroy(imr_instance* instance) { delete reinterpret_cast<Instance*>(instance); }

imr_status Refine(imr_instance* instance, const imr_refine_request* r, imr_refine_result* out,
                  imr_error* error) {
  Instance* self = reinterpret_cast<Instance*>(instance);
  if (r == nullptr || r->struct_size < IMR_REFINE_REQUEST_SIZE_1_4 || r->mesh == nullptr) {
    std::snprintf(error->message, sizeof(error->message), "refine: request too small");
    return IMR_INVALID_ARGUMENT;
  }
  const uint64_t n = r->mesh->vertex_count;
  self->vertices.assign(r->mesh->vertices, r->mesh->vertices + 3 * n);
  out->struct_size = sizeof(imr_refine_result);
  out->vertices = self->vertices.data();
  out->vertex_count = n;
  ++self->calls;
  char line[128];
  std::snprintf(line, sizeof(line), "sdk 1.4 mesh refiner: call %d, %llu vertices", self->calls,
                static_cast<unsigned long long>(n));
  self->host->log(self->host->host_data, IMR_LOG_INFO, line);
  return IMR_OK;
}

const imr_mesh_refiner_api kApi = {sizeof(imr_mesh_refiner_api), 0, &Refine};

imr_plugin_descriptor MakeDescriptor() {
  imr_plugin_descriptor d;
  std::memset(&d, 0, sizeof(d));
  d.struct_size = sizeof(imr_plugin_descriptor);
  d.abi_major = IMR_ABI_MAJOR;
  d.abi_minor = IMR_ABI_MINOR;
  d.kind = IMR_KIND_MESH_REFINER;
  d.id = "org.imr.test.mesh_refiner.identity_sdk_1_4";
  d.version = "1.4.0";
  d.description = "test: returns the surface as it came, built against the ABI 1.4 SDK";
  d.params_schema = "{}";
  d.create = &Create;
  d.destroy = &Destroy;
  d.mesh_refiner = &kApi;
  return d;
}

}  // namespace

extern "C" IMR_PLUGIN_API const imr_plugin_descriptor* imr_plugin_entry(uint32_t index) {
  static const imr_plugin_descriptor d = MakeDescriptor();
  return index == 0 ? &d : nullptr;
}
