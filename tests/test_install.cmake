# Installs raycut into a scratch prefix, then configures, builds and runs tests/consumer and
# examples/coulomb there (its CUDA program too when the install has CUDA: without a GPU it runs
# the CPU method through raycut::cuda::for_each_pair and exits 0).
file(REMOVE_RECURSE ${WORK})
function(run)
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "${ARGN} failed (${rc}):\n${out}\n${err}")
  endif()
  set(out "${out}" PARENT_SCOPE)
endfunction()
run(${CMAKE_COMMAND} --install ${BUILD} --prefix ${WORK}/prefix)
run(${CMAKE_COMMAND} -S ${SOURCE}/tests/consumer -B ${WORK}/build -DCMAKE_PREFIX_PATH=${WORK}/prefix
    -DCMAKE_BUILD_TYPE=Release)
run(${CMAKE_COMMAND} --build ${WORK}/build)
run(${WORK}/build/consumer)
run(${WORK}/build/consumer_sph)
message(STATUS "install: find_package(raycut) consumer built and ran")

# The example, with the CUDA compiler and architectures raycut was built with.
load_cache(${BUILD} READ_WITH_PREFIX raycut_ CMAKE_CUDA_COMPILER CMAKE_CUDA_ARCHITECTURES)
file(GLOB config ${WORK}/prefix/lib*/cmake/raycut/raycutConfig.cmake)
file(STRINGS ${config} cuda_line REGEX "set\\(raycut_HAVE_CUDA ON\\)")
set(cuda_args)
if(cuda_line)
  set(cuda_args -DCMAKE_CUDA_COMPILER=${raycut_CMAKE_CUDA_COMPILER}
      -DCMAKE_CUDA_ARCHITECTURES=${raycut_CMAKE_CUDA_ARCHITECTURES})
endif()
run(${CMAKE_COMMAND} -S ${SOURCE}/examples/coulomb -B ${WORK}/coulomb
    -DCMAKE_PREFIX_PATH=${WORK}/prefix -DCMAKE_BUILD_TYPE=Release ${cuda_args})
run(${CMAKE_COMMAND} --build ${WORK}/coulomb)
run(${WORK}/coulomb/coulomb)
message(STATUS "${out}")
if(cuda_line)
  if(NOT EXISTS ${WORK}/coulomb/coulomb_cuda)
    message(FATAL_ERROR "raycut has CUDA but examples/coulomb built no coulomb_cuda")
  endif()
  run(${WORK}/coulomb/coulomb_cuda)
  message(STATUS "${out}")
  message(STATUS "install: examples/coulomb built and ran (CPU and CUDA programs)")
else()
  message(STATUS "install: examples/coulomb built and ran (CPU program; raycut without CUDA)")
endif()
