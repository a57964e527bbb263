# Small helpers so adding a file is one line (COLMAP's COLMAP_ADD_LIBRARY style).

set(PERF_WARNINGS -Wall -Wextra -Wpedantic -Wno-unused-parameter)

# perf_add_library(NAME SRCS a.cc b.cc DEPS lib1 lib2 [PRIVATE_DEPS ...])
function(perf_add_library name)
  cmake_parse_arguments(ARG "" "" "SRCS;DEPS;PRIVATE_DEPS" ${ARGN})
  add_library(${name} STATIC ${ARG_SRCS})
  target_include_directories(${name} PUBLIC ${PROJECT_SOURCE_DIR})
  target_link_libraries(${name} PUBLIC ${ARG_DEPS} PRIVATE ${ARG_PRIVATE_DEPS})
  target_compile_options(${name} PRIVATE $<$<COMPILE_LANGUAGE:CXX>:${PERF_WARNINGS}>)
endfunction()

# perf_add_test(NAME SRCS a_test.cc DEPS lib LABELS unit [slow] [SERIAL])
# SERIAL: its cases run alone (CTest RUN_SERIAL), for those that measure the time they take.
# Registers each GoogleTest case with CTest so labels and timeouts apply per case.
function(perf_add_test name)
  cmake_parse_arguments(ARG "SERIAL" "TIMEOUT" "SRCS;DEPS;LABELS" ${ARGN})
  add_executable(${name} ${ARG_SRCS})
  target_link_libraries(${name} PRIVATE ${ARG_DEPS} GTest::gtest GTest::gtest_main)
  target_compile_options(${name} PRIVATE $<$<COMPILE_LANGUAGE:CXX>:${PERF_WARNINGS}>)
  target_compile_definitions(${name} PRIVATE
    PERF_SHARED_DATA_DIR="${PROJECT_SOURCE_DIR}/../shared/data"
    PERF_SOURCE_DIR="${PROJECT_SOURCE_DIR}"
    PERF_BINARY_DIR="${PROJECT_BINARY_DIR}")
  if(NOT ARG_LABELS)
    set(ARG_LABELS unit)
  endif()
  if(NOT ARG_TIMEOUT)
    set(ARG_TIMEOUT 600)
  endif()
  include(GoogleTest)
  gtest_discover_tests(${name} DISCOVERY_TIMEOUT 60)
  # gtest_discover_tests splits list-valued PROPERTIES (LABELS "slow;integration"), so labels
  # and timeout are applied after discovery by a file CTest includes.
  set(props_file "${CMAKE_CURRENT_BINARY_DIR}/${name}_props.cmake")
  set(env "")
  if(PERF_SANITIZE)
    # Library leaks we cannot fix (tests/sanitizers/lsan.supp); UBSan findings abort already
    # (-fno-sanitize-recover).
    set(env " ENVIRONMENT \"LSAN_OPTIONS=suppressions=${PROJECT_SOURCE_DIR}/tests/sanitizers/lsan.supp\"")
  endif()
  if(ARG_SERIAL)
    set(env "${env} RUN_SERIAL TRUE")
  endif()
  file(WRITE "${props_file}"
    "set_tests_properties(\${${name}_TESTS} PROPERTIES LABELS \"${ARG_LABELS}\" TIMEOUT ${ARG_TIMEOUT}${env})\n")
  set_property(DIRECTORY APPEND PROPERTY TEST_INCLUDE_FILES "${props_file}")
endfunction()
