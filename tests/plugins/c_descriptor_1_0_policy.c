/* A weight policy written in plain C11 against plugin.h, as a plugin from another team might be,
 * and built as one against an older, smaller descriptor would hand it: its descriptor ends at the
 * last field of ABI 1.0 (IMR_DESCRIPTOR_SIZE_1_0 bytes, no reserved tail). The host must load it
 * and read nothing past its struct_size. Compiled with -std=c11 -pedantic-errors -Werror, it is
 * also the test that plugin.h compiles as C, its layout checks (_Static_assert) included.
 *
 * The policy: every new cell takes the largest removed weight (0 when none). */
#include <imr/sdk/plugin.h>

#include <stdio.h>
#include <stdlib.h>

/* The descriptor's ABI 1.0 fields, nothing after them. */
typedef struct descriptor_1_0 {
  uint32_t struct_size;
  uint16_t abi_major;
  uint16_t abi_minor;
  int32_t kind;
  uint32_t reserved0;
  const char* id;
  const char* version;
  const char* description;
  const char* params_schema;
  imr_status (*create)(const char*, const imr_host_services*, imr_instance**, imr_error*);
  void (*destroy)(imr_instance*);
  const imr_features_api* features;
  const imr_refiner_api* refiner;
  const imr_weight_policy_api* weight_policy;
  const imr_exporter_api* exporter;
} descriptor_1_0;
_Static_assert(sizeof(descriptor_1_0) == IMR_DESCRIPTOR_SIZE_1_0, "the 1.0 descriptor");
_Static_assert(offsetof(descriptor_1_0, exporter) == offsetof(imr_plugin_descriptor, exporter),
               "the 1.0 fields at their offsets");

struct imr_instance {
  const imr_host_services* host;
};

static imr_status Create(const char* params_json, const imr_host_services* host,
                         imr_instance** out_instance, imr_error* error) {
  imr_instance* self;
  if (out_instance == NULL) return IMR_INVALID_ARGUMENT;
  *out_instance = NULL;
  if (params_json != NULL && params_json[0] != '\0' &&
      !(params_json[0] == '{' && params_json[1] == '}' && params_json[2] == '\0')) {
    snprintf(error->message, sizeof(error->message), "params: none accepted, got %s", params_json);
    return IMR_INVALID_ARGUMENT;
  }
  self = (imr_instance*)malloc(sizeof(imr_instance));
  if (self == NULL) {
    snprintf(error->message, sizeof(error->message), "out of memory");
    return IMR_ERROR;
  }
  self->host = host;
  *out_instance = self;
  return IMR_OK;
}

static void Destroy(imr_instance* instance) { free(instance); }

static imr_status Transfer(imr_instance* instance, const imr_transfer_request* r,
                           imr_error* error) {
  double largest = 0.0;
  uint64_t i;
  (void)instance;
  if (r == NULL || r->struct_size < IMR_TRANSFER_REQUEST_SIZE_1_0) {
    snprintf(error->message, sizeof(error->message), "transfer: request struct too small");
    return IMR_INVALID_ARGUMENT;
  }
  for (i = 0; i < r->removed_count; ++i)
    if (i == 0 || r->removed_weights[i] > largest) largest = r->removed_weights[i];
  for (i = 0; i < r->added_count; ++i) r->added_weights[i] = largest;
  return IMR_OK;
}

static const imr_weight_policy_api kApi = {sizeof(imr_weight_policy_api), 0, &Transfer};

static const descriptor_1_0 kDescriptor = {
    sizeof(descriptor_1_0), IMR_ABI_MAJOR, 0, IMR_KIND_WEIGHT_POLICY, 0,
    "org.imr.test.policy.c_descriptor_1_0", "1.0.0",
    "C plugin with the 1.0 descriptor: largest removed weight", "{}", &Create, &Destroy,
    NULL, NULL, &kApi, NULL};

IMR_PLUGIN_API const imr_plugin_descriptor* imr_plugin_entry(uint32_t index) {
  return index == 0 ? (const imr_plugin_descriptor*)(const void*)&kDescriptor : NULL;
}
