/* A plugin whose code needs a symbol no library provides: the loader refuses it (RTLD_NOW), and
 * the refusal must name the symbol. */
#include <imr/sdk/plugin.h>

extern int imr_test_missing_symbol(void);

IMR_PLUGIN_API const imr_plugin_descriptor* imr_plugin_entry(uint32_t index) {
  (void)index;
  return imr_test_missing_symbol() == 0 ? (const imr_plugin_descriptor*)0 : (const imr_plugin_descriptor*)0;
}
