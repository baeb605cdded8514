# Warnings for our own targets. Third-party headers come in as SYSTEM includes (imported targets).
add_library(imr_warnings INTERFACE)
target_compile_options(imr_warnings INTERFACE
  -Wall -Wextra -Wpedantic -Wshadow -Wnon-virtual-dtor -Wcast-align -Woverloaded-virtual
  -Wimplicit-fallthrough)
