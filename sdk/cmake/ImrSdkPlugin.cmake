# imr_sdk_add_plugin(<target> <sources>...)
# Builds an imr plugin: a shared object with hidden visibility (only the entry symbol is
# exported) and --no-undefined (a missing symbol fails the link, not the host at load time).
function(imr_sdk_add_plugin target)
  add_library(${target} MODULE ${ARGN})
  target_link_libraries(${target} PRIVATE imr::sdk)
  set_target_properties(${target} PROPERTIES
    PREFIX ""
    CXX_VISIBILITY_PRESET hidden
    C_VISIBILITY_PRESET hidden
    VISIBILITY_INLINES_HIDDEN ON)
  target_compile_features(${target} PRIVATE cxx_std_20)
  target_link_options(${target} PRIVATE "LINKER:--no-undefined")
endfunction()
