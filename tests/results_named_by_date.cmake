# Every committed benchmark result is named by the date it was measured (YYYY-MM-DD in its file or
# folder name), so a reader can tell which run a number comes from. Prints every file that is
# not; fails if any.
# Usage: cmake -DSOURCE=<repository root> -P results_named_by_date.cmake
cmake_policy(SET CMP0007 NEW)
if(NOT SOURCE)
  message(FATAL_ERROR "results_named_by_date: pass -DSOURCE=<repository root>")
endif()
find_package(Git QUIET)
if(NOT GIT_FOUND OR NOT EXISTS "${SOURCE}/.git")
  message(STATUS "results_named_by_date: not a git checkout, nothing to check")
  return()
endif()
execute_process(COMMAND "${GIT_EXECUTABLE}" ls-files bench/results WORKING_DIRECTORY "${SOURCE}"
                OUTPUT_VARIABLE listing RESULT_VARIABLE status)
if(NOT status EQUAL 0)
  message(FATAL_ERROR "results_named_by_date: git ls-files failed in ${SOURCE}")
endif()
string(REPLACE "\n" ";" files "${listing}")
set(undated 0)
foreach(file IN LISTS files)
  if(file AND NOT file MATCHES "[0-9][0-9][0-9][0-9]-[0-9][0-9]-[0-9][0-9]")
    message("${file}: no date (YYYY-MM-DD) in its name")
    math(EXPR undated "${undated} + 1")
  endif()
endforeach()
if(undated GREATER 0)
  message(FATAL_ERROR "results_named_by_date: ${undated} result files without a date")
endif()
