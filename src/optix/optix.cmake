# OptiX methods, included from the root CMakeLists (generated sources must be added in the scope
# of the raycut target): host code into the library; device programs compiled to OptiX IR (CUDA
# 13's ptxas rejects the OptiX intrinsics in PTX) and embedded as a byte array.
list(GET CMAKE_CUDA_ARCHITECTURES 0 raycut_optix_arch)
string(REGEX MATCH "[0-9]+" raycut_optix_arch "${raycut_optix_arch}")

file(MAKE_DIRECTORY ${PROJECT_BINARY_DIR}/optix_programs)

function(raycut_optix_programs name source)
  set(ir ${PROJECT_BINARY_DIR}/optix_programs/${name}.optixir)
  set(embedded ${PROJECT_BINARY_DIR}/optix_programs/${name}_embedded.cpp)
  add_custom_command(OUTPUT ${ir}
    COMMAND ${CMAKE_CUDA_COMPILER} -std=c++17 -O3 -arch=compute_${raycut_optix_arch} -rdc=true
      -optix-ir -I${OptiX_INCLUDE_DIR} -I${PROJECT_SOURCE_DIR}/include -I${PROJECT_SOURCE_DIR}/src
      ${CMAKE_CURRENT_LIST_DIR}/${source} -o ${ir}
    DEPENDS ${CMAKE_CURRENT_LIST_DIR}/${source} ${ARGN}
    COMMENT "OptiX IR: ${source}")
  add_custom_command(OUTPUT ${embedded}
    COMMAND ${CMAKE_COMMAND} -DINPUT=${ir} -DOUTPUT=${embedded} -DNAME=raycut_${name}
      -P ${PROJECT_SOURCE_DIR}/cmake/embed_binary.cmake
    DEPENDS ${ir} ${PROJECT_SOURCE_DIR}/cmake/embed_binary.cmake)
  target_sources(raycut PRIVATE ${embedded})
endfunction()

set(raycut_optix_program_headers
  ${CMAKE_CURRENT_LIST_DIR}/device_common.cuh
  ${CMAKE_CURRENT_LIST_DIR}/launch_params.hpp
  ${PROJECT_SOURCE_DIR}/src/geometry/ray_geometry.hpp
  ${PROJECT_SOURCE_DIR}/include/raycut/kernels.hpp
  ${PROJECT_SOURCE_DIR}/include/raycut/predicate.hpp
  ${PROJECT_SOURCE_DIR}/src/cuda/device_results.cuh)
foreach(method aabb spheres triangles)
  raycut_optix_programs(${method}_programs ${method}/programs.cu ${raycut_optix_program_headers})
  target_sources(raycut PRIVATE ${CMAKE_CURRENT_LIST_DIR}/${method}/host.cu)
endforeach()
target_sources(raycut PRIVATE ${CMAKE_CURRENT_LIST_DIR}/context.cpp
  ${CMAKE_CURRENT_LIST_DIR}/ray_method.cu)
target_include_directories(raycut PRIVATE ${OptiX_INCLUDE_DIR})
target_link_libraries(raycut PRIVATE ${CMAKE_DL_LIBS})
