# A check that must fail on a tree of planted violations (ctest `docs_detects_violation`,
# `layering_detects_violation`): runs CHECK_SCRIPT on FIXTURE_DIR and fails unless the check
# fails, its report contains every line of EXPECTED and none of the strings of CLEAN (names that
# are fine and must not be reported). EXPECTATIONS is a CMake file that sets EXPECTED, CLEAN and
# WHAT (the check's name in the messages).
#   cmake -DCHECK_SCRIPT=<check.cmake> -DFIXTURE_DIR=<fixtures/bad> -DEXPECTATIONS=<file>
#         [-DLINK_GRAPH=<graph.cmake>] -P tests/expect_violations.cmake
foreach(_v CHECK_SCRIPT FIXTURE_DIR EXPECTATIONS)
  if(NOT DEFINED ${_v})
    message(FATAL_ERROR "expect_violations: -D${_v}=... is required")
  endif()
endforeach()
include(${EXPECTATIONS})
set(_args -DSOURCE_DIR=${FIXTURE_DIR})
if(DEFINED LINK_GRAPH)
  list(APPEND _args -DLINK_GRAPH=${LINK_GRAPH})
endif()
execute_process(
  COMMAND ${CMAKE_COMMAND} ${_args} -P ${CHECK_SCRIPT}
  RESULT_VARIABLE _rc OUTPUT_VARIABLE _out ERROR_VARIABLE _err)
set(_all "${_out}${_err}")
message("${_all}")
set(_failed FALSE)
if(_rc EQUAL 0)
  message(STATUS "expect_violations: the check passed on the bad fixture")
  set(_failed TRUE)
endif()
foreach(_e IN LISTS EXPECTED)
  string(FIND "${_all}" "${_e}" _pos)
  if(_pos EQUAL -1)
    message(STATUS "expect_violations: missing from the report: ${_e}")
    set(_failed TRUE)
  endif()
endforeach()
foreach(_clean IN LISTS CLEAN)
  string(FIND "${_all}" "${_clean}" _pos)
  if(NOT _pos EQUAL -1)
    message(STATUS "expect_violations: reported although clean: ${_clean}")
    set(_failed TRUE)
  endif()
endforeach()
if(_failed)
  message(FATAL_ERROR "expect_violations: the ${WHAT} does not detect the planted violations")
endif()
message(STATUS "expect_violations: every planted violation reported")
