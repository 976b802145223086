// A tiny deterministic RNG for the generators: splitmix64, plus the few draws they need. We never
// use std:: distributions, whose output differs between standard libraries.
//
// Streams are counter-based: the numbers of point i come from stream_for(seed, i), so a parallel
// loop gives the same bits whatever the thread count or schedule.
#pragma once

#include <cmath>
#include <cstdint>
#include <numbers>

namespace raycut::detail {

inline constexpr std::uint64_t golden_gamma = 0x9e3779b97f4a7c15ULL;

// splitmix64's output function: a bijection of 64-bit words with good avalanche.
constexpr std::uint64_t mix64(std::uint64_t z) {
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}

class SplitMix64 {
 public:
  explicit constexpr SplitMix64(std::uint64_t state) : state_(state) {}

  constexpr std::uint64_t next() {
    state_ += golden_gamma;
    return mix64(state_);
  }

  // [0,1) with 24 random bits: every value is exactly representable in float.
  constexpr float uniform_float() { return static_cast<float>(next() >> 40) * 0x1.0p-24f; }
  // [0,1) with 53 random bits: every value is exactly representable in double.
  constexpr double uniform_double() { return static_cast<double>(next() >> 11) * 0x1.0p-53; }
  // Standard normal by Box-Muller in double (one of the pair is dropped: simpler, and the
  // generators are not limited by it). 1 - u keeps log() away from 0.
  double normal() {
    const double radius = std::sqrt(-2.0 * std::log(1.0 - uniform_double()));
    const double angle = 2.0 * std::numbers::pi * uniform_double();
    return radius * std::cos(angle);
  }

 private:
  std::uint64_t state_;
};

// The stream of item `index` under `seed`. Both are hashed (not just added) so that streams of
// neighbouring indices or seeds do not overlap: splitmix64 steps its state by golden_gamma, so
// states seed + index * golden_gamma would make stream i+1 a shifted copy of stream i.
constexpr SplitMix64 stream_for(std::uint64_t seed, std::uint64_t index) {
  return SplitMix64(mix64(mix64(seed ^ 0x6a09e667f3bcc909ULL) + index));
}

}  // namespace raycut::detail
