/* A plugin built for a future ABI major: the host must refuse it, naming both versions. Written
 * in plain C against the C header, as a plugin from another team might be. */
#include <imr/sdk/plugin.h>

static const imr_plugin_descriptor kDescriptor = {
    sizeof(imr_plugin_descriptor), IMR_ABI_MAJOR + 1, 3, IMR_KIND_WEIGHT_POLICY, 0,
    "org.imr.test.future_abi", "9.9.9", "built against a future ABI", "{}", 0, 0, 0, 0, 0, 0,
    0, 0, {0}};

IMR_PLUGIN_API const imr_plugin_descriptor* imr_plugin_entry(uint32_t index) {
  return index == 0 ? &kDescriptor : 0;
}
