# IMR_FUZZ=ON (clang only): every target of this build is compiled with
# -fsanitize=fuzzer-no-link,address,undefined and tests/fuzz adds the libFuzzer executables
# (<name>_fuzz, all built by the target imr_fuzzers). A build of its own, e.g. the one
# tools/fuzz/subbuild.sh makes under build/fuzz-build for the fuzz/* tests; its engine and io
# tests are the sanitize/* run (the coverage hooks are no-ops outside a fuzzer).
option(IMR_FUZZ "Build the libFuzzer targets of tests/fuzz (clang; ASan + UBSan)" OFF)
if(IMR_FUZZ)
  if(NOT CMAKE_CXX_COMPILER_ID STREQUAL "Clang")
    message(FATAL_ERROR "IMR_FUZZ needs clang (-DCMAKE_CXX_COMPILER=clang++ "
                        "-DCMAKE_C_COMPILER=clang), not ${CMAKE_CXX_COMPILER_ID}")
  endif()
  if(IMR_SANITIZE)
    message(FATAL_ERROR "IMR_FUZZ already builds with address,undefined; leave IMR_SANITIZE empty")
  endif()
  add_compile_options(-fsanitize=fuzzer-no-link,address,undefined -fno-sanitize-recover=all
                      -fsanitize-recover=enum,signed-integer-overflow
                      -fno-omit-frame-pointer -gline-tables-only)
  add_link_options(-fsanitize=address,undefined)
  add_subdirectory(${CMAKE_SOURCE_DIR}/tests/fuzz ${CMAKE_BINARY_DIR}/tests/fuzz)
endif()
