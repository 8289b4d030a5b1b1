# Helpers that give every plenopiv target the same requirements: C++20, warnings, an alias.

function(plenopiv_defaults target)
  target_compile_features(${target} PUBLIC cxx_std_20)
  target_compile_options(${target} PRIVATE -Wall -Wextra)
  if(PLENOPIV_WERROR)
    target_compile_options(${target} PRIVATE -Werror)
  endif()
  # A GNU build ID in every executable (the toolchains' default, asked for explicitly): results
  # cached on disk are keyed by it (executable_build_id in core/base/build_info.hpp).
  target_link_options(${target} PRIVATE LINKER:--build-id)
  plenopiv_instrument(${target})
endfunction()

# PLENOPIV_SANITIZE on one target: its code is instrumented, and an executable links the sanitizer
# runtimes. UBSan reports stay recoverable so that UBSAN_OPTIONS decides (halt_on_error=1 and a
# suppression file in .ci/run). libFuzzer's coverage goes only to the code the fuzz targets feed
# (tests/fuzz/CMakeLists.txt).
function(plenopiv_instrument target)
  if(PLENOPIV_SANITIZE)
    target_compile_options(${target} PRIVATE -fsanitize=${PLENOPIV_SANITIZE} -fno-omit-frame-pointer)
    target_link_options(${target} PRIVATE -fsanitize=${PLENOPIV_SANITIZE})
  endif()
endfunction()

# The compute kernels built per instruction set (core/base/isa.hpp) are built without
# ThreadSanitizer: their loops work on disjoint data their callers give out (the callers' TBB loops
# stay instrumented), and instrumenting every load and store of them would multiply a TSan run's
# time. Call in the folder that builds them (source properties are per folder).
function(plenopiv_dispatched_sources)
  if(PLENOPIV_SANITIZE MATCHES "thread")
    set_property(SOURCE ${ARGN} APPEND PROPERTY COMPILE_OPTIONS -fno-sanitize=thread)
  endif()
endfunction()

# plenopiv_library(<name> SOURCES ... [PUBLIC_LIBS ...] [PRIVATE_LIBS ...])
# creates plenopiv_<name> with alias plenopiv::<name>; headers are included as
# "<folder>/<header>" from the repository root.
function(plenopiv_library name)
  cmake_parse_arguments(ARG "" "" "SOURCES;PUBLIC_LIBS;PRIVATE_LIBS" ${ARGN})
  add_library(plenopiv_${name} ${ARG_SOURCES})
  add_library(plenopiv::${name} ALIAS plenopiv_${name})
  target_include_directories(plenopiv_${name} PUBLIC
    $<BUILD_INTERFACE:${PROJECT_SOURCE_DIR}> $<INSTALL_INTERFACE:include/plenopiv>)
  target_link_libraries(plenopiv_${name} PUBLIC ${ARG_PUBLIC_LIBS} PRIVATE ${ARG_PRIVATE_LIBS})
  set_target_properties(plenopiv_${name} PROPERTIES POSITION_INDEPENDENT_CODE ON)
  plenopiv_defaults(plenopiv_${name})
endfunction()

# plenopiv_executable(<name> SOURCES ... [LIBS ...]) puts the binary in build/bin.
function(plenopiv_executable name)
  cmake_parse_arguments(ARG "" "" "SOURCES;LIBS" ${ARGN})
  add_executable(${name} ${ARG_SOURCES})
  target_link_libraries(${name} PRIVATE ${ARG_LIBS})
  set_target_properties(${name} PROPERTIES RUNTIME_OUTPUT_DIRECTORY ${PROJECT_BINARY_DIR}/bin)
  plenopiv_defaults(${name})
endfunction()

# plenopiv_test(<name> LABEL unit|integration|slow SOURCES ... [LIBS ...] [TIMEOUT s]
#               [RESOURCE_LOCK name] [FIXTURES name] [HEAVY pattern...])
#   tests sharing a lock never run at the same time (ctest -j); FIXTURES: a ctest fixture set up
#   before them; HEAVY: GoogleTest filter patterns (--gtest_filter's, on the suite's own test names:
#   a parameterised case's values by index) of its tests that are accuracy studies at the sizes
#   accuracy needs, or further values of a parameterised case. They carry the label `heavy` besides
#   LABEL, and .ci/run's ASan step leaves them out: the same code runs under ASan in the
#   suites' other tests. The test <name>_heavy_patterns fails on a pattern that selects no test.
function(plenopiv_test name)
  cmake_parse_arguments(ARG "" "LABEL;TIMEOUT;RESOURCE_LOCK;FIXTURES" "SOURCES;LIBS;HEAVY" ${ARGN})
  if(NOT ARG_LABEL)
    message(FATAL_ERROR "plenopiv_test(${name}): LABEL unit|integration|slow is required")
  endif()
  if(NOT ARG_TIMEOUT)
    set(ARG_TIMEOUT 300)
  endif()
  set(lock)
  if(ARG_RESOURCE_LOCK)
    set(lock RESOURCE_LOCK ${ARG_RESOURCE_LOCK})
  endif()
  # FIXTURES: a ctest fixture the tests need set up first (python_package: the installed Python package).
  set(fixtures)
  if(ARG_FIXTURES)
    set(fixtures FIXTURES_REQUIRED ${ARG_FIXTURES})
  endif()
  add_executable(${name} ${ARG_SOURCES})
  target_link_libraries(${name} PRIVATE ${ARG_LIBS} GTest::gtest GTest::gtest_main)
  # Never a unity build (CMAKE_UNITY_BUILD, .ci/run's sanitizer builds): a suite has one to four
  # files, each with helpers of its own in an anonymous namespace.
  set_target_properties(${name} PROPERTIES RUNTIME_OUTPUT_DIRECTORY ${PROJECT_BINARY_DIR}/tests UNITY_BUILD OFF)
  target_compile_definitions(${name} PRIVATE
    PLENOPIV_SOURCE_DIR="${PROJECT_SOURCE_DIR}" PLENOPIV_BINARY_DIR="${PROJECT_BINARY_DIR}")
  plenopiv_defaults(${name})
  # A suite's own code sets cases up and checks results; the code under test is in the libraries,
  # built at the build type's level. At -O1 the suites, most of a build's compile time, compile
  # much faster than at -O2 (a Debug build keeps -O0).
  target_compile_options(${name} PRIVATE $<$<CONFIG:Release,RelWithDebInfo,MinSizeRel>:-O1>)
  # The CLIs' weight-table cache goes to the build folder, not the user's ~/.cache.
  set(discovery
    WORKING_DIRECTORY ${PROJECT_BINARY_DIR}
    PROPERTIES LABELS ${ARG_LABEL} TIMEOUT ${ARG_TIMEOUT} ${lock} ${fixtures}
               ENVIRONMENT PLENOPIV_CACHE_DIR=${PROJECT_BINARY_DIR}/test-cache
    DISCOVERY_TIMEOUT 60)
  if(NOT ARG_HEAVY)
    gtest_discover_tests(${name} ${discovery})
    return()
  endif()
  # Discovered twice, each half by its filter; the heavy half's second label is set when ctest
  # reads the tests (a label list cannot pass through gtest_discover_tests' PROPERTIES).
  list(JOIN ARG_HEAVY ":" heavy)
  gtest_discover_tests(${name} ${discovery} TEST_FILTER "${heavy}" TEST_LIST ${name}_heavy)
  gtest_discover_tests(${name} ${discovery} TEST_FILTER "-${heavy}")
  set(label_file ${CMAKE_CURRENT_BINARY_DIR}/${name}_heavy_label.cmake)
  file(WRITE ${label_file} "set_tests_properties(\${${name}_heavy} PROPERTIES LABELS \"${ARG_LABEL};heavy\")\n")
  set_property(DIRECTORY APPEND PROPERTY TEST_INCLUDE_FILES ${label_file})
  # Each pattern selects a test of the suite (cmake/CheckHeavyPatterns.cmake).
  add_test(NAME ${name}_heavy_patterns
           COMMAND ${CMAKE_COMMAND} -DBINARY=$<TARGET_FILE:${name}> -DPATTERNS=${heavy} -P
                   ${PROJECT_SOURCE_DIR}/cmake/CheckHeavyPatterns.cmake)
  set_tests_properties(${name}_heavy_patterns PROPERTIES LABELS unit)
endfunction()
