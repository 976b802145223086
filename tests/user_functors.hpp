// Pair functors as a user writes them (the shape of include/raycut/kernels.hpp), with exactly the
// math of the built-in Lennard-Jones kernels but none of their code: what test_functors.cpp and
// test_functors_cuda.cu run through raycut::for_each_pair / raycut::cuda::for_each_pair and
// compare bit for bit with Engine::compute. The reciprocal is raycut::fast_reciprocal, the
// public helper the built-ins use (1 / b on the host, the hardware reciprocal on the device).
#pragma once

#include <cstddef>
#include <cstdint>

#include "raycut/kernels.hpp"

namespace user {

// sum_j 4 eps ((sigma/r)^12 - (sigma/r)^6), without combine().
struct LjNoCombine {
  using Accumulator = float;
  using options = raycut::functor_options<raycut::option::vanishes_at_infinity>;
  float sigma6, four_epsilon_sigma6;
  float* energy;
  RAYCUT_HD void operator()(float& acc, std::uint32_t, raycut::Vec3, float r2) const {
    const float t = raycut::fast_reciprocal(r2);
    const float w = t * t * t;
    acc += w * (sigma6 * w - 1.0f);
  }
  RAYCUT_HD void finish(std::uint32_t i, float& acc) const {
    energy[i] = acc * four_epsilon_sigma6;
  }
};
// The same, each pair computed once on the CPU cell list and added to both (option::mirror), as
// the built-in kernel is.
struct Lj : LjNoCombine {
  using options = raycut::functor_options<raycut::option::vanishes_at_infinity,
                                          raycut::option::combine, raycut::option::mirror>;
  RAYCUT_HD static void combine(float& a, const float& b) { a += b; }
  RAYCUT_HD static void mirror(float&) {}
};

// Energy, force and virial, as Kernel::lj_forces: each pair computed once on the CPU cell list
// and added to both particles (option::mirror), as the built-in kernel is.
struct LjForces {
  struct Accumulator {
    float energy = 0, f[3] = {0, 0, 0}, v[6] = {0, 0, 0, 0, 0, 0};
  };
  using options = raycut::functor_options<raycut::option::vanishes_at_infinity,
                                          raycut::option::combine, raycut::option::mirror>;
  float sigma2, four_epsilon;  // reduced units: u = (sigma^2 / r^2)^3
  float *energy, *force, *virial;
  RAYCUT_HD void operator()(Accumulator& acc, std::uint32_t, raycut::Vec3 r, float r2) const {
    const float t = raycut::fast_reciprocal(r2);
    const float s = sigma2 * t;
    const float u = s * s * s;
    acc.energy += u * (u - 1.0f);
    const float g = t * u * (2.0f * u - 1.0f);
    const float gx = g * r.x, gy = g * r.y, gz = g * r.z;
    acc.f[0] += gx;
    acc.f[1] += gy;
    acc.f[2] += gz;
    acc.v[0] += gx * r.x;
    acc.v[1] += gy * r.y;
    acc.v[2] += gz * r.z;
    acc.v[3] += gx * r.y;
    acc.v[4] += gx * r.z;
    acc.v[5] += gy * r.z;
  }
  RAYCUT_HD static void combine(Accumulator& a, const Accumulator& b) {
    a.energy += b.energy;
    for (int k = 0; k < 3; ++k) a.f[k] += b.f[k];
    for (int k = 0; k < 6; ++k) a.v[k] += b.v[k];
  }
  RAYCUT_HD static void mirror(Accumulator& a) {
    for (int k = 0; k < 3; ++k) a.f[k] = -a.f[k];
  }
  RAYCUT_HD void finish(std::uint32_t i, Accumulator& acc) const {
    energy[i] = acc.energy * (0.5f * four_epsilon);
    const float fs = -6.0f * four_epsilon, vs = 3.0f * four_epsilon;
    for (int k = 0; k < 3; ++k) force[3 * std::size_t{i} + k] = fs * acc.f[k];
    for (int k = 0; k < 6; ++k) virial[6 * std::size_t{i} + k] = vs * acc.v[k];
  }
};

// sigma^6 and 4 eps sigma^6 as raycut::with_kernel computes them from KernelOptions.
inline LjNoCombine lj_parameters(const raycut::KernelOptions& o, float* energy) {
  const float sigma2 = o.lj_sigma * o.lj_sigma, sigma6 = sigma2 * sigma2 * sigma2;
  return {sigma6, 4.0f * o.lj_epsilon * sigma6, energy};
}

// Neighbour count starting from init(i) = offset + i % 5, with a non-trivial state, no combine().
struct CountFromInit {
  struct Accumulator {
    // {} must be the identity of combine(): GPU lanes sharing a target start from {} and
    // init(i) is combined in once (include/raycut/detail/cuda/grid_pass.cuh).
    std::uint32_t count = 0;
    std::uint32_t calls = 0;
  };
  using options = raycut::functor_options<raycut::option::init>;
  std::uint32_t offset;
  std::uint32_t* out;
  RAYCUT_HD Accumulator init(std::uint32_t i) const { return {offset + i % 5, 0}; }
  // The pair call with j (unread): the traversal looks up each pair's source with images.
  RAYCUT_HD void operator()(Accumulator& acc, std::uint32_t, std::uint32_t, raycut::Vec3,
                            float) const {
    ++acc.count;
    ++acc.calls;
  }
  RAYCUT_HD void finish(std::uint32_t i, Accumulator& acc) const { out[i] = acc.count; }
};
// The same with combine(): lanes sharing a target add their pairs; init() seeds the total once.
struct CountFromInitCombine : CountFromInit {
  using options = raycut::functor_options<raycut::option::init, raycut::option::combine>;
  RAYCUT_HD static void combine(Accumulator& a, const Accumulator& b) {
    a.count += b.count;
    a.calls += b.calls;
  }
};

}  // namespace user
