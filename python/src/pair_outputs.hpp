// The pairs of a host neighbour list written into a caller's fixed-size outputs (the PyTorch
// operators' static-capacity mode): the first min(pairs, capacity)
// entries, then padding (i = pad_i, j = pad_j, S = 0) up to the capacity. Returns the number of
// pairs found, which exceeds the capacity when the list was cut.
#pragma once

#include <algorithm>
#include <cstdint>
#include <cstring>

#include "raycut/engine.hpp"

namespace raycut_py {

template <class Index>
std::uint64_t write_pairs(const raycut::NeighbourListBuffer& list, std::uint64_t capacity, Index* i,
                          Index* j, std::int32_t* shifts, Index pad_i, Index pad_j) {
  const std::uint64_t found = list.pairs();
  const std::uint64_t kept = std::min(found, capacity);
  const std::int64_t* rows = list.rows();
  const std::int64_t* columns = list.columns();
  if constexpr (sizeof(Index) == sizeof(std::int64_t)) {
    if (kept > 0) {
      std::memcpy(i, rows, kept * sizeof(Index));
      std::memcpy(j, columns, kept * sizeof(Index));
    }
  } else {
    for (std::uint64_t k = 0; k < kept; ++k) {
      i[k] = static_cast<Index>(rows[k]);
      j[k] = static_cast<Index>(columns[k]);
    }
  }
  if (kept > 0) std::memcpy(shifts, list.shifts(), 3 * kept * sizeof(std::int32_t));
  std::fill(i + kept, i + capacity, pad_i);
  std::fill(j + kept, j + capacity, pad_j);
  std::fill(shifts + 3 * kept, shifts + 3 * capacity, 0);
  return found;
}

}  // namespace raycut_py
