# Code that shares a process with libtorch, jaxlib or Python's own extensions (raycut's Python
# modules, the AOTInductor runner) must share their C++ standard library too. Code that carries a
# static copy of libstdc++ has a locale of its own that is never set up: numbers written into its
# error messages come out empty (GCC 12) or crash the process (GCC 13, seen on a toolchain
# installed in /opt/gcc). Such a copy comes from -static-libstdc++ in the linker flags (LDFLAGS),
# or from a toolchain that has no libstdc++.so. Included in a directory, this drops the flag for
# that directory's targets; raycut_shared_libstdcxx(target) links the shared libstdc++
# explicitly where the compiler has none, ahead of any static one.
if(NOT CMAKE_CXX_COMPILER_ID MATCHES "GNU|Clang")
  function(raycut_shared_libstdcxx target)
  endfunction()
  return()
endif()

foreach(flags CMAKE_SHARED_LINKER_FLAGS CMAKE_MODULE_LINKER_FLAGS CMAKE_EXE_LINKER_FLAGS)
  if(${flags} MATCHES "-static-libstdc\\+\\+")
    string(REPLACE "-static-libstdc++" "" ${flags} "${${flags}}")
    message(STATUS "raycut: -static-libstdc++ dropped from ${flags} in ${CMAKE_CURRENT_SOURCE_DIR} "
                   "(its targets share the process's libstdc++)")
  endif()
endforeach()

execute_process(COMMAND ${CMAKE_CXX_COMPILER} -print-file-name=libstdc++.so
                OUTPUT_VARIABLE raycut_compiler_libstdcxx OUTPUT_STRIP_TRAILING_WHITESPACE
                ERROR_QUIET)
set(raycut_explicit_libstdcxx "")
if(NOT IS_ABSOLUTE "${raycut_compiler_libstdcxx}" OR NOT EXISTS "${raycut_compiler_libstdcxx}")
  # The compiler would link libstdc++.a: the system's shared library instead, the one that
  # Python and libtorch load.
  find_library(RAYCUT_SHARED_LIBSTDCXX NAMES libstdc++.so.6 libstdc++.so
               DOC "The shared libstdc++ linked where the compiler has none")
  if(NOT RAYCUT_SHARED_LIBSTDCXX)
    message(FATAL_ERROR "raycut: ${CMAKE_CXX_COMPILER} has no shared libstdc++ and none was "
                        "found (set RAYCUT_SHARED_LIBSTDCXX to libstdc++.so.6): code loaded "
                        "beside libtorch cannot carry a static copy of its own")
  endif()
  set(raycut_explicit_libstdcxx "${RAYCUT_SHARED_LIBSTDCXX}")
  message(STATUS "raycut: ${CMAKE_CXX_COMPILER} has no libstdc++.so; linking "
                 "${raycut_explicit_libstdcxx} instead")
endif()

function(raycut_shared_libstdcxx target)
  if(raycut_explicit_libstdcxx)
    target_link_libraries(${target} PRIVATE "${raycut_explicit_libstdcxx}")
  endif()
endfunction()
