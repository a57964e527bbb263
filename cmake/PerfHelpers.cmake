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

# perf_add_test(NAME SRCS a_test.cc DEPS lib LABELS unit [slow])
# Registers each GoogleTest case with CTest so labels and timeouts apply per case.
function(perf_add_test name)
  cmake_parse_arguments(ARG "" "TIMEOUT" "SRCS;DEPS;LABELS" ${ARGN})
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
  gtest_discover_tests(${name}
    PROPERTIES LABELS "${ARG_LABELS}" TIMEOUT ${ARG_TIMEOUT}
    DISCOVERY_TIMEOUT 60)
endfunction()
