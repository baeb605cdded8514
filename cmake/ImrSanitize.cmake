# IMR_SANITIZE=address,undefined (any -fsanitize= list, gcc or clang): the whole build, tests
# included, with those sanitizers; a finding stops the program (no recovery), so a test fails.
# (The sanitize/* tests use the clang IMR_FUZZ build, and this one with g++ when clang is missing.)
set(IMR_SANITIZE "" CACHE STRING "Sanitizers for the whole build, e.g. address,undefined")
if(IMR_SANITIZE)
  add_compile_options(-fsanitize=${IMR_SANITIZE} -fno-sanitize-recover=all -fno-omit-frame-pointer)
  if(IMR_SANITIZE MATCHES "undefined")
    # Recoverable so that tools/fuzz/ubsan.supp can silence one known CGAL report (see there).
    add_compile_options(-fsanitize-recover=enum,signed-integer-overflow)
  endif()
  add_link_options(-fsanitize=${IMR_SANITIZE})
endif()
