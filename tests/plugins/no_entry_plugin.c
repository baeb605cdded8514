/* A shared object without the imr entry symbol: the host must refuse it by name. */
#include <imr/sdk/plugin.h>

IMR_PLUGIN_API int not_an_imr_plugin(void) { return 42; }
