// Comparing a method's answer with an oracle's: the one implementation behind `raycut check`
// and the conformance tests.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

#include "raycut/engine.hpp"

namespace raycut {

struct NeighbourComparison {
  std::size_t targets = 0;            // N
  std::size_t differing_targets = 0;  // targets whose neighbour multiset differs
  std::uint64_t pairs = 0;            // entries in the list compared
  std::uint64_t expected_pairs = 0;   // entries in the oracle's list
  std::string first_difference;       // "target i: ...; missing ...; extra ..." or empty
  bool equal() const { return differing_targets == 0 && first_difference.empty(); }
};

// Per-target comparison as multisets (order within a row ignored; a duplicate is a difference).
NeighbourComparison compare_neighbours(const NeighbourList& got, const NeighbourList& expected);

}  // namespace raycut
