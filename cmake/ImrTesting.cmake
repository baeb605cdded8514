# imr_add_test(NAME <module/name> SOURCES ... [LIBS ...] [LABELS ...])
# One GoogleTest executable per test source set, registered per test case with ctest.
function(imr_add_test)
  cmake_parse_arguments(T "" "NAME" "SOURCES;LIBS;LABELS" ${ARGN})
  string(REPLACE "/" "_" exe "${T_NAME}")
  add_executable(${exe} ${T_SOURCES})
  target_link_libraries(${exe} PRIVATE ${T_LIBS} GTest::gtest GTest::gtest_main imr_warnings)
  set_target_properties(${exe} PROPERTIES RUNTIME_OUTPUT_DIRECTORY ${CMAKE_BINARY_DIR}/tests)
  gtest_discover_tests(${exe}
    TEST_PREFIX "${T_NAME}."
    DISCOVERY_MODE PRE_TEST
    PROPERTIES LABELS "${T_LABELS}" ENVIRONMENT "IMR_SHARED_DIR=${IMR_SHARED_DIR}")
endfunction()
