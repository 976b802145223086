// What NeighbourListBuffer and PaddedNeighbourBuffer hold: the buffers of a list where its
// method works. Methods make the storage of their memory space and fill it; buffers only grow.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "core/list_functors.hpp"
#include "raycut/engine.hpp"

namespace raycut::detail {

// A vector's data, or null when it is empty (what views of absent outputs hold).
template <class T>
const T* data_or_null(const std::vector<T>& v) {
  return v.empty() ? nullptr : v.data();
}

class ListStorage {
 public:
  virtual ~ListStorage() = default;
  virtual MemorySpace space() const = 0;
  virtual std::size_t bytes() const = 0;
  virtual NeighbourList to_host() const = 0;
  // The list of N = 0: offsets = {0}.
  virtual void set_empty(const ListOptions& options) = 0;

  std::size_t n = 0;
  std::uint64_t pairs = 0;
  ListOptions options;
  const std::uint64_t* offsets = nullptr;
  const std::uint32_t* indices = nullptr;
  const float* distances = nullptr;
  const float* vectors = nullptr;
  const std::int32_t* shifts = nullptr;
  const std::int64_t* rows = nullptr;     // ListOptions::coo
  const std::int64_t* columns = nullptr;  // ListOptions::coo
};

// The filter over per-pair cutoffs whose arrays, in the pass's memory space, are `radius`,
// `species` and `table` (null where `cutoffs` has none).
PairCutoffFilter pair_cutoff_filter(const PairCutoffs& cutoffs, const double* radius,
                                    const std::uint32_t* species, const double* table);

// The filter over per-pair cutoffs (or null) given in host memory, read there.
PairCutoffFilter host_cutoff_filter(const PairCutoffs* cutoffs);

// A static-capacity list's end in host memory: the true count, then padding from it (or from
// the capacity) to the capacity.
void finish_static_pairs(const StaticPairs& out, std::uint64_t total);

// The bytes one list entry takes with these options.
double bytes_per_entry(const ListOptions& options);

class PaddedStorage {
 public:
  virtual ~PaddedStorage() = default;
  virtual MemorySpace space() const = 0;
  virtual std::vector<std::uint32_t> indices_to_host() const = 0;
  virtual std::vector<std::uint32_t> counts_to_host() const = 0;

  std::size_t n = 0;
  std::uint32_t k = 0;
  // The invalid index after each row's entries: N, the number of sources (not of the rows:
  // with query points they differ). Set by the engine before each fill.
  std::uint32_t padding = 0;
  PaddedReport report;
  const std::uint32_t* indices = nullptr;
  const std::uint32_t* counts = nullptr;
  const std::int32_t* shifts = nullptr;                          // 3 per entry, when asked
  virtual std::vector<std::int32_t> shifts_to_host() const = 0;  // empty when not asked
};

// Host memory (the CPU methods).
class HostListStorage final : public ListStorage {
 public:
  MemorySpace space() const override { return MemorySpace::host; }
  std::size_t bytes() const override;
  NeighbourList to_host() const override;
  void set_empty(const ListOptions& options) override;
  // Sizes the arrays for n targets and `pairs` entries (offsets already hold the scan) and
  // returns the fill functor writing them, keeping what `filter` keeps.
  ListFill prepare_fill(std::uint64_t pairs, const ListFilter& filter);
  // Only the offsets, for n targets (the count pass writes n counts into offsets + 1).
  std::uint64_t* prepare_offsets(std::size_t n, const ListOptions& options);

 private:
  void publish();
  std::vector<std::uint64_t> offsets_;
  std::vector<std::uint32_t> indices_;
  std::vector<float> distances_, vectors_;
  std::vector<std::int32_t> shifts_;
  std::vector<std::int64_t> rows_, columns_;
};

class HostPaddedStorage final : public PaddedStorage {
 public:
  MemorySpace space() const override { return MemorySpace::host; }
  std::vector<std::uint32_t> indices_to_host() const override { return indices_; }
  std::vector<std::uint32_t> counts_to_host() const override { return counts_; }
  std::vector<std::int32_t> shifts_to_host() const override {
    return shifts ? shifts_ : std::vector<std::int32_t>{};
  }
  // Sizes the matrix [n, k] (and its shifts when asked) and returns the functor filling it
  // (overflow in `overflow`).
  PaddedFill prepare(std::size_t n, std::uint32_t k, bool half, bool shifts,
                     PaddedOverflow* overflow);

 private:
  std::vector<std::uint32_t> indices_, counts_;
  std::vector<std::int32_t> shifts_;
};

// Throws Error(capacity_exceeded) for an overflowing padded list when asked to.
void report_padded(const PaddedStorage& storage, bool throw_on_overflow);

}  // namespace raycut::detail
