# raycut sph through the command line: the small scenario on the CPU cell list writes the .pvd
# series, one .vtp per saved frame and the PNG renders, appends a CSV row, and refuses bad usage.
include(${CMAKE_CURRENT_LIST_DIR}/cli_helpers.cmake)

expect_exit(0 sph --help)
if(NOT last_out MATCHES "--scenario")
  message(FATAL_ERROR "sph --help does not list --scenario:\n${last_out}")
endif()

expect_exit(0 sph --scenario small --n 1000 --method cell-list --frames 5 --every 5
  --out ${WORK}/run --png --csv ${WORK}/sph.csv)
foreach(file frames.pvd frames_000000.vtp frames_000001.vtp frame_000000.png frame_000005.png)
  if(NOT EXISTS ${WORK}/run/${file})
    message(FATAL_ERROR "raycut sph did not write ${WORK}/run/${file}")
  endif()
endforeach()
file(READ ${WORK}/run/frames.pvd pvd)
if(NOT pvd MATCHES "frames_000001.vtp")
  message(FATAL_ERROR "frames.pvd does not list the second frame:\n${pvd}")
endif()
file(READ ${WORK}/run/frame_000005.png png_head LIMIT 8 HEX)
if(NOT png_head STREQUAL "89504e470d0a1a0a")
  message(FATAL_ERROR "frame_000005.png is not a PNG (starts with ${png_head})")
endif()
foreach(word "steps/s" "density" "force" "integrate")
  if(NOT last_out MATCHES "${word}")
    message(FATAL_ERROR "the summary lacks '${word}':\n${last_out}")
  endif()
endforeach()
file(STRINGS ${WORK}/sph.csv rows)
list(LENGTH rows row_count)
list(GET rows 0 header)
if(NOT row_count EQUAL 2 OR NOT header MATCHES "^scenario,method,N,frames,steps_per_s,update_ms")
  message(FATAL_ERROR "unexpected CSV:\n${rows}")
endif()

# The hydrostatic profile: one row per particle layer (8 at 4 particles across a, H = 2a), each
# layer keeping its 4 x 4 particles however the column compresses.
expect_exit(0 sph --scenario hydrostatic -m cell-list --resolution 4 --end-time 0.05
  --damping-time 0.03 --result-csv ${WORK}/hydrostatic.csv -q)
file(STRINGS ${WORK}/hydrostatic.csv rows)
list(LENGTH rows row_count)
list(GET rows 0 header)
if(NOT row_count EQUAL 9 OR NOT header MATCHES "^layer,y,y_now,count,p_mean,rho_mean,")
  message(FATAL_ERROR "unexpected hydrostatic CSV:\n${rows}")
endif()
list(SUBLIST rows 1 8 layers)
foreach(row ${layers})
  if(NOT row MATCHES "^[0-7],[0-9.]+,[0-9.]+,16.00,")
    message(FATAL_ERROR "a layer without its 16 particles: ${row}")
  endif()
endforeach()

# Bad usage: exit 2 with one line.
expect_exit(2 sph --scenario nowhere)
expect_exit(2 sph --scenario small --method no-such-method --frames 1)
expect_exit(2 sph --scenario small --png --frames 1)
