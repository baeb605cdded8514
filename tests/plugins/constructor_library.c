/* A shared library that is no imr plugin and does something as soon as it is loaded (as
 * libmemusage prints its heap report): the host must refuse it without loading it. The
 * constructor writes the file named by IMR_TEST_CONSTRUCTOR_MARKER, if set. */
#include <stdio.h>
#include <stdlib.h>

__attribute__((constructor)) static void Announce(void) {
  const char* marker = getenv("IMR_TEST_CONSTRUCTOR_MARKER");
  if (marker == NULL) return;
  FILE* f = fopen(marker, "w");
  if (f == NULL) return;
  fputs("constructor ran\n", f);
  fclose(f);
}

__attribute__((visibility("default"))) int imr_test_not_a_plugin(void) { return 1; }
