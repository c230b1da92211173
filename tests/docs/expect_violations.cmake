# ctest `docs_detects_violation`: cmake/check_docs.cmake run on fixtures/bad must fail and name
# each planted violation (a missing path named or linked, an unnamed source, a source in no
# section), and nothing else.
#   cmake -DCHECK_SCRIPT=<check_docs.cmake> -DFIXTURE_DIR=<fixtures/bad> -P expect_violations.cmake
execute_process(
  COMMAND ${CMAKE_COMMAND} -DSOURCE_DIR=${FIXTURE_DIR} -P ${CHECK_SCRIPT}
  RESULT_VARIABLE _rc OUTPUT_VARIABLE _out ERROR_VARIABLE _err)
set(_all "${_out}${_err}")
message("${_all}")
set(_failed FALSE)
if(_rc EQUAL 0)
  message(STATUS "expect_violations: the check passed on the bad fixture")
  set(_failed TRUE)
endif()
set(_expected
  "docs/ARCHITECTURE.md:3: names `lib/missing.cpp`, which does not exist"
  "docs/ARCHITECTURE.md:3: names `ghost.hpp`, which does not exist"
  "docs/ARCHITECTURE.md:3: links docs/nothere.md, which does not exist"
  "docs/ARCHITECTURE.md:9: names `gone.hpp`, which does not exist"
  "lib/README.md:2: names `also_gone.cpp`, which does not exist"
  "lib/README.md:2: names `sub/`, which does not exist"
  "lib/orphan.cpp: not named in the section \"### lib\""
  "loose/b.cpp: in no component section"
  "docs: 8 violation(s)")
foreach(_e IN LISTS _expected)
  string(FIND "${_all}" "${_e}" _pos)
  if(_pos EQUAL -1)
    message(STATUS "expect_violations: missing from the report: ${_e}")
    set(_failed TRUE)
  endif()
endforeach()
foreach(_clean "lib/a.cpp" "lib/a.hpp" "`lib/a.*`" "`a.*`" "`a.cpp`")
  string(FIND "${_all}" "${_clean}" _pos)
  if(NOT _pos EQUAL -1)
    message(STATUS "expect_violations: reported although clean: ${_clean}")
    set(_failed TRUE)
  endif()
endforeach()
if(_failed)
  message(FATAL_ERROR "expect_violations: the docs check does not detect the planted violations")
endif()
message(STATUS "expect_violations: every planted violation reported")
