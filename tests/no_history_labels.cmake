# The repository speaks of the product, not of its history: no tracked file outside bench/results
# carries a numbered work-log label ("session" or "issue" followed by a number) or points at a spec file
# that is not in the repository (spec/<NAME>.md, "spec <NAME>.md" or "spec section <n>"). Prints every offending line; fails if any.
# Usage: cmake -DSOURCE=<repository root> -P no_history_labels.cmake
cmake_policy(SET CMP0007 NEW)  # keep the list semantics of this CMake, no warning
if(NOT SOURCE)
  message(FATAL_ERROR "no_history_labels: pass -DSOURCE=<repository root>")
endif()

find_package(Git QUIET)
set(files "")
if(GIT_FOUND AND EXISTS "${SOURCE}/.git")
  execute_process(COMMAND "${GIT_EXECUTABLE}" ls-files WORKING_DIRECTORY "${SOURCE}"
                  OUTPUT_VARIABLE listing RESULT_VARIABLE status)
  if(status EQUAL 0)
    string(REPLACE "\n" ";" files "${listing}")
  endif()
endif()
if(NOT files)
  # Not a git checkout (a source archive): every file under the root but build outputs.
  file(GLOB_RECURSE files RELATIVE "${SOURCE}" "${SOURCE}/*")
  list(FILTER files EXCLUDE REGEX "^(build[^/]*|\\.venv|\\.git)/")
endif()
list(FILTER files EXCLUDE REGEX "^bench/results/")
list(FILTER files EXCLUDE REGEX "\\.(png|jpg|jpeg|gif|pdf|ico|gz|zip|npz|npy|bin)$")

# CMake regexes have no \b or case folding: spell both out.
set(session_label "(^|[^A-Za-z0-9_])([Ss][Ee][Ss][Ss][Ii][Oo][Nn]|[Ii][Ss][Ss][Uu][Ee])[Ss]?[ -]?[0-9]+")
set(spec_file "spec[/ ][A-Z]+[.]md|spec sections? [0-9]")

list(LENGTH files file_count)
set(offending 0)
foreach(file IN LISTS files)
  if(NOT file OR NOT EXISTS "${SOURCE}/${file}" OR IS_DIRECTORY "${SOURCE}/${file}")
    continue()
  endif()
  file(STRINGS "${SOURCE}/${file}" hits REGEX "${session_label}|${spec_file}")
  foreach(line IN LISTS hits)
    # A label followed by more digits or letters is a name (e.g. an identifier), not a label.
    if(line MATCHES "${spec_file}" OR line MATCHES "${session_label}([^A-Za-z0-9_]|$)")
      message("${file}: ${line}")
      math(EXPR offending "${offending} + 1")
    endif()
  endforeach()
endforeach()

if(offending GREATER 0)
  message(FATAL_ERROR "no_history_labels: ${offending} line(s) above carry a work-log label or "
                      "point at a spec file outside the repository; say what the reader needs "
                      "instead (a date and GPU for a measurement, or a docs/ page for a contract)")
endif()
message(STATUS "no_history_labels: ${file_count} files, no work-log label and no outside spec file")
