# imr_add_test(NAME <module/name> SOURCES ... [LIBS ...] [LABELS ...])
# One GoogleTest executable per test source set, registered per test case with ctest.
function(imr_add_test)
  cmake_parse_arguments(T "" "NAME" "SOURCES;LIBS;LABELS" ${ARGN})
  string(REPLACE "/" "_" exe "${T_NAME}")
  add_executable(${exe} ${T_SOURCES})
  target_link_libraries(${exe} PRIVATE ${T_LIBS} GTest::gtest GTest::gtest_main imr_warnings)
  target_include_directories(${exe} PRIVATE ${CMAKE_SOURCE_DIR})  # host/io/testing/temp_dir.h
  set_target_properties(${exe} PROPERTIES RUNTIME_OUTPUT_DIRECTORY ${CMAKE_BINARY_DIR}/tests)
  set(props ENVIRONMENT "IMR_SHARED_DIR=${IMR_SHARED_DIR}")
  if(T_LABELS)
    list(APPEND props LABELS "${T_LABELS}")
  endif()
  gtest_discover_tests(${exe}
    TEST_PREFIX "${T_NAME}."
    DISCOVERY_MODE PRE_TEST
    # Listing the tests loads the executable's libraries: OpenCV's imgcodecs pulls in 143 of them,
    # 9 s from a cold disk cache on a fresh CI machine (CMake's default timeout is 5 s).
    DISCOVERY_TIMEOUT 300
    PROPERTIES ${props})
endfunction()
