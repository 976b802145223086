#include "core/list_storage.hpp"

#include <algorithm>
#include <string>

#include "core/validation.hpp"
#include "raycut/host_memory.hpp"

namespace raycut::detail {

std::size_t HostListStorage::bytes() const {
  return offsets_.capacity() * sizeof(std::uint64_t) + indices_.capacity() * sizeof(std::uint32_t) +
         (distances_.capacity() + vectors_.capacity()) * sizeof(float) +
         shifts_.capacity() * sizeof(std::int32_t) +
         (rows_.capacity() + columns_.capacity()) * sizeof(std::int64_t);
}

NeighbourList HostListStorage::to_host() const {
  NeighbourList list;
  list.offsets.assign(offsets, offsets + n + 1);
  if (options.coo) {
    list.rows.assign(rows_.begin(), rows_.begin() + pairs);
    list.columns.assign(columns_.begin(), columns_.begin() + pairs);
  } else {
    list.indices.assign(indices_.begin(), indices_.begin() + pairs);
  }
  if (options.distances) list.distances.assign(distances_.begin(), distances_.begin() + pairs);
  if (options.vectors) list.vectors.assign(vectors_.begin(), vectors_.begin() + 3 * pairs);
  if (options.shifts) list.shifts.assign(shifts_.begin(), shifts_.begin() + 3 * pairs);
  return list;
}

void HostListStorage::set_empty(const ListOptions& list_options) {
  prepare_offsets(0, list_options)[0] = 0;
  pairs = 0;
  publish();
}

std::uint64_t* HostListStorage::prepare_offsets(std::size_t targets,
                                                const ListOptions& list_options) {
  n = targets;
  options = list_options;
  if (offsets_.size() < targets + 1)
    require_host_memory(8.0 * static_cast<double>(targets + 1 - offsets_.size()), [&] {
      return "the offsets of a neighbour list of " + std::to_string(targets) + " rows";
    });
  offsets_.resize(targets + 1);
  publish();
  return offsets_.data();
}

PairCutoffFilter pair_cutoff_filter(const PairCutoffs& cutoffs, const double* radius,
                                    const std::uint32_t* species, const double* table) {
  PairCutoffFilter filter;
  if (cutoffs.radii) {
    filter.radius = radius;
  } else if (cutoffs.table) {
    filter.species = species;
    filter.table = table;
    filter.kinds = cutoffs.kinds;
  }
  return filter;
}

PairCutoffFilter host_cutoff_filter(const PairCutoffs* cutoffs) {
  if (!cutoffs) return {};
  return pair_cutoff_filter(*cutoffs, cutoffs->radii, cutoffs->species, cutoffs->table);
}

void finish_static_pairs(const StaticPairs& out, std::uint64_t total) {
  *out.count = static_cast<std::int64_t>(total);
  for (std::uint64_t e = std::min<std::uint64_t>(total, out.capacity); e < out.capacity; ++e) {
    out.i[e] = out.j[e] = out.pad_index;
    if (out.shifts) out.shifts[3 * e] = out.shifts[3 * e + 1] = out.shifts[3 * e + 2] = 0;
  }
}

ListFill HostListStorage::prepare_fill(std::uint64_t entries, const ListFilter& filter) {
  pairs = entries;
  // Sized on demand (no shrinking: the buffers are reused by the next fill). What grows is
  // checked against the memory budget first: with overcommit a resize that does not fit is
  // rarely a std::bad_alloc, it is the OOM killer later.
  const auto growth = [&](std::size_t held, double wanted, double bytes) {
    return std::max(0.0, wanted - static_cast<double>(held)) * bytes;
  };
  const double count = static_cast<double>(entries);
  const double more =
      (options.coo ? growth(rows_.size(), count, 8) + growth(columns_.size(), count, 8)
                   : growth(indices_.size(), count, 4)) +
      (options.distances ? growth(distances_.size(), count, 4) : 0.0) +
      (options.vectors ? growth(vectors_.size(), 3 * count, 4) : 0.0) +
      (options.shifts ? growth(shifts_.size(), 3 * count, 4) : 0.0);
  const auto what = [&] {
    return "a neighbour list of " + std::to_string(entries) + " pairs (" +
           format_bytes(bytes_per_entry(options)) + " each)";
  };
  require_host_memory(more, what);
  try {
    if (!options.coo && indices_.size() < entries) indices_.resize(entries);
    if (options.coo && rows_.size() < entries) rows_.resize(entries);
    if (options.coo && columns_.size() < entries) columns_.resize(entries);
    if (options.distances && distances_.size() < entries) distances_.resize(entries);
    if (options.vectors && vectors_.size() < 3 * entries) vectors_.resize(3 * entries);
    if (options.shifts && shifts_.size() < 3 * entries) shifts_.resize(3 * entries);
  } catch (const std::bad_alloc&) {
    throw Error(ErrorCode::out_of_memory,
                "not enough host memory for " + what() + ": " + format_bytes(more) + " more");
  }
  publish();
  return {filter,
          offsets_.data(),
          options.coo ? nullptr : indices_.data(),
          options.distances ? distances_.data() : nullptr,
          options.vectors ? vectors_.data() : nullptr,
          options.shifts ? shifts_.data() : nullptr,
          options.coo ? rows_.data() : nullptr,
          options.coo ? columns_.data() : nullptr};
}

void HostListStorage::publish() {
  offsets = offsets_.data();
  indices = options.coo ? nullptr : data_or_null(indices_);
  distances = options.distances ? data_or_null(distances_) : nullptr;
  vectors = options.vectors ? data_or_null(vectors_) : nullptr;
  shifts = options.shifts ? data_or_null(shifts_) : nullptr;
  rows = options.coo ? data_or_null(rows_) : nullptr;
  columns = options.coo ? data_or_null(columns_) : nullptr;
}

double bytes_per_entry(const ListOptions& options) {
  return (options.coo ? 16.0 : 4.0) + (options.distances ? 4.0 : 0.0) +
         (options.vectors ? 12.0 : 0.0) + (options.shifts ? 12.0 : 0.0);
}

PaddedFill HostPaddedStorage::prepare(std::size_t targets, std::uint32_t width, bool half,
                                      bool with_shifts, PaddedOverflow* overflow) {
  n = targets;
  k = width;
  // The engine checked the matrix against the memory budget (with the bound on K in its
  // message); a failing resize is still a clear error.
  try {
    indices_.resize(targets * std::size_t{width});
    counts_.resize(targets);
    if (with_shifts) shifts_.resize(3 * targets * std::size_t{width});
  } catch (const std::bad_alloc&) {
    throw Error(ErrorCode::out_of_memory, "not enough host memory for a padded neighbour list [" +
                                              std::to_string(targets) + ", " +
                                              std::to_string(width) + "]");
  }
  indices = data_or_null(indices_);
  counts = data_or_null(counts_);
  shifts = with_shifts ? data_or_null(shifts_) : nullptr;
  return {{half, {}},      width,          padding,
          indices_.data(), counts_.data(), with_shifts ? shifts_.data() : nullptr,
          overflow};
}

void report_padded(const PaddedStorage& storage, bool throw_on_overflow) {
  if (!throw_on_overflow || !storage.report.overflowed()) return;
  throw Error(ErrorCode::capacity_exceeded,
              "padded neighbour list: " + std::to_string(storage.report.overflowed_rows) +
                  " rows have more than K = " + std::to_string(storage.k) +
                  " neighbours (the largest has " + std::to_string(storage.report.largest_count) +
                  "): grow K and retry");
}

}  // namespace raycut::detail
