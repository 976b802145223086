# Refusals of the command-line tool that name the option, its value and what is accepted (exit 2),
# and sizes refused up front against the memory budget (RAYCUT_MAX_MEMORY), quickly, before
# anything that large is allocated: never the OOM killer.
include(${CMAKE_CURRENT_LIST_DIR}/cli_helpers.cmake)

# Runs raycut with RAYCUT_MAX_MEMORY=`budget` and ARGN, fails unless it exits with `code` within
# 60 s; leaves last_out / last_err.
function(expect_exit_with_budget budget code)
  execute_process(COMMAND ${CMAKE_COMMAND} -E env RAYCUT_MAX_MEMORY=${budget} ${RAYCUT} ${ARGN}
                  RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err TIMEOUT 60)
  if(NOT rc EQUAL code)
    message(FATAL_ERROR "RAYCUT_MAX_MEMORY=${budget} raycut ${ARGN}: exit ${rc}, expected ${code}\n"
                        "stdout:\n${out}\nstderr:\n${err}")
  endif()
  set(last_out "${out}" PARENT_SCOPE)
  set(last_err "${err}" PARENT_SCOPE)
endfunction()

# --seed outside [0, 2^64): -1 and 2^64 + ... both became 2^64 - 1 silently.
foreach(sub check bench generate)
  foreach(seed -1 99999999999999999999 1.5)
    set(extra)
    if(sub STREQUAL "generate")
      set(extra -o ${WORK}/seed.xyz)
    endif()
    expect_exit(2 ${sub} --seed ${seed} ${extra})
    expect_match("${last_err}" "--seed.*must be a whole number in \\[0, 2\\^64 - 1 = 18446744073709551615\\], got '${seed}'")
  endforeach()
endforeach()
expect_exit(0 generate --seed 18446744073709551615 -n 10 -o ${WORK}/seed.xyz)

# A cutoff is checked as given (a double), not after it rounds to 0 or inf in float.
foreach(cutoff 1e-50 1e39)
  expect_exit(2 check -m cell-list -f uniform -n 10 -c ${cutoff})
  expect_match("${last_err}" "--cutoff.*\\[2\\^-60, 2\\^60\\].*got '${cutoff}'")
endforeach()

# The SPH scenario's own parameter is named, not the particle_mass derived from it.
expect_exit(2 sph --scenario dam-break --column-width 1e-30 --frames 1 -q)
expect_match("${last_err}" "column_width = 1e-30")
expect_match("${last_err}" "column_width must be in \\[")
if("${last_err}" MATCHES "particle_mass must")
  message(FATAL_ERROR "the refusal names particle_mass:\n${last_err}")
endif()

# 0 where 0 is special says so in --help.
expect_exit(0 bench --help)
expect_match("${last_out}" "more particles than this \\(0, the default: no limit\\)")
expect_match("${last_out}" "instead of --reps \\(0, the default: never\\)")
expect_exit(0 sph --help)
expect_match("${last_out}" "Steps to run \\(default: the scenario's, 200; 0 runs none\\)")

# The memory budget. 12,000 points within 10 of each other: 1.44e8 pairs, a list of 0.54 GiB at
# least: refused with the size, the budget and the knob, exit 2 (it was the OOM killer, exit 137,
# in a container with less memory).
# The uniform family made for cutoff 0.01 fits in a box of side < 1: at cutoff 10 every pair.
expect_exit(0 generate -f uniform -n 12000 -c 0.01 -o ${WORK}/dense.xyz)
expect_exit_with_budget(300M 2 check -m cell-list -i ${WORK}/dense.xyz -c 10)
expect_match("${last_err}" "out of memory: a neighbour list of 143988000 pairs .* needs [0-9.]+ MiB of host memory, more than the budget: 300.00 MiB is available \\(RAYCUT_MAX_MEMORY=300M")
# A suite configuration larger than the budget (64^3 x 32 particles, 16 bytes each).
expect_exit_with_budget(100M 2 bench --suite uniform -m cell-list --param 64 --p 32 -o ${WORK}/b.csv)
expect_match("${last_err}" "out of memory: .*N = 8388608 particles.*RAYCUT_MAX_MEMORY=100M")
# A malformed budget is named with its value and the accepted form.
expect_exit_with_budget(lots 2 check -m cell-list -f uniform -n 10)
expect_match("${last_err}" "RAYCUT_MAX_MEMORY must be a number of bytes.*K, M, G or T.*got 'lots'")
# Within the budget: as before.
expect_exit_with_budget(300M 0 check -m cell-list -f uniform -n 100)
