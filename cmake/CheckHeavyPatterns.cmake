# Fails, naming it, on each HEAVY pattern of a test suite (plenopiv_test) that selects none of the
# suite's tests: a misspelt pattern would otherwise leave the tests it meant in .ci/run's ASan step
# without a word, whenever another pattern of the list matches. Run by ctest as
# cmake -DBINARY=<suite> -DPATTERNS=<pattern>:<pattern>... -P CheckHeavyPatterns.cmake.
string(REPLACE ":" ";" patterns "${PATTERNS}")
set(unmatched)
foreach(pattern IN LISTS patterns)
  execute_process(COMMAND "${BINARY}" --gtest_list_tests "--gtest_filter=${pattern}" OUTPUT_VARIABLE listed
                  RESULT_VARIABLE status)
  if(NOT status EQUAL 0)
    message(FATAL_ERROR "${BINARY} --gtest_list_tests failed (${status})")
  endif()
  # A test is an indented line under its suite's line.
  string(REGEX MATCH "\n  [^ \n]" test "${listed}")
  if(NOT test)
    list(APPEND unmatched "${pattern}")
  endif()
endforeach()
if(unmatched)
  list(JOIN unmatched ", " names)
  message(FATAL_ERROR "${BINARY}: HEAVY pattern(s) matching no test: ${names}")
endif()
message(STATUS "${BINARY}: each of ${PATTERNS} selects a test")
