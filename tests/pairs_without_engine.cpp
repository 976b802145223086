// <raycut/pairs.hpp> on its own: the CPU traversal of a caller's functor needs only a declared
// Engine (detail::PairPassAccess is defined in the library). This file must not include
// <raycut/engine.hpp>, directly or through another header: the static_assert below checks it.
#include <cstdint>
#include <type_traits>
#include <vector>

#include "raycut/pairs.hpp"

namespace {

template <class T, class = void>
struct is_complete : std::false_type {};
template <class T>
struct is_complete<T, std::void_t<decltype(sizeof(T))>> : std::true_type {};

static_assert(!is_complete<raycut::Engine>::value,
              "raycut/pairs.hpp includes the Engine class: it should only declare it");

// Neighbours per target, as Kernel::count counts them.
struct CountNeighbours {
  using Accumulator = std::uint32_t;
  std::uint32_t* counts;
  void operator()(Accumulator& acc, std::uint32_t, raycut::Vec3, float) const { ++acc; }
  void finish(std::uint32_t i, Accumulator& acc) const { counts[i] = acc; }
};

}  // namespace

// Called by test_functors.cpp (PairsHeaderNeedsOnlyADeclaredEngine), which builds the engine.
std::vector<std::uint32_t> neighbour_counts_through_pairs_header(const raycut::Engine& engine,
                                                                 std::size_t size) {
  std::vector<std::uint32_t> counts(size, 0xffffffffu);
  raycut::for_each_pair(engine, CountNeighbours{counts.data()});
  return counts;
}
