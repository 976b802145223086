// Factories of the OptiX methods (host-only declarations).
#pragma once

#include <memory>
#include <string>

#include "core/method.hpp"

namespace raycut::detail::optix {

// Empty when OptiX runs here; otherwise why not.
std::string unavailable_reason();

// Custom AABBs with zero-length rays; `sorted` adds the Morton-order spatial sort; `fused` does
// the pair work in the intersection program (the paper's way) instead of a single any-hit call.
std::unique_ptr<Method> make_aabb(bool sorted, bool fused = false);
// Built-in spheres, three axis rays per target.
std::unique_ptr<Method> make_spheres();
// Double squares: two face triangles per source, four corner rays per target.
std::unique_ptr<Method> make_triangles();

}  // namespace raycut::detail::optix
