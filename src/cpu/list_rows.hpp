// A CPU neighbour list in one pass over the pairs: each thread appends the rows it visits (j,
// and S, d, D where asked) to buffers of its own, row after row, and every row is then copied to
// its place in the list, the offsets being the running sum of the rows' counts. A row's entries
// keep the order of its candidates, so the list is the one the count-then-fill passes make, bit
// for bit; the pass over the pairs runs once instead of twice (docs/pair-pass.md, "CPU lists in
// one pass").
//
// The buffers hold as much as the list and are kept from list to list: fresh memory would cost
// its page faults every call, more than the pass saved (the 100,000-particle periodic list with
// S, one thread: 113-130 ms with the buffers kept, 196 ms freed each call, 180 ms in two passes).
// So they are kept up to kept_bytes: a list that needs more (or more than half the memory
// budget) is made in two passes (count, then fill in place), as is every list after one that was.
#pragma once

#include <omp.h>

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <cstring>
#include <memory>
#include <new>
#include <vector>

#include "core/list_functors.hpp"
#include "raycut/detail/host_threads.hpp"
#include "raycut/host_memory.hpp"

namespace raycut::detail {

// Which values a list keeps beside j.
struct RowFields {
  bool shifts = false, distances = false, vectors = false;
  bool operator==(const RowFields&) const = default;
  double bytes_per_entry() const {
    return 4.0 + (shifts ? 12.0 : 0.0) + (distances ? 4.0 : 0.0) + (vectors ? 12.0 : 0.0);
  }
};

class ListRows {
 public:
  // Runs run(f) with a functor f of the pair pass that appends the rows of n targets, keeping
  // what `filter` keeps. False, with nothing usable collected, when the rows do not fit in
  // kept_bytes or the memory budget, or when the last list did not (then nothing is run).
  template <class Run>
  bool collect(std::size_t n, const ListFilter& filter, RowFields fields, Run&& run) {
    if (too_large_) return false;
    if (fields != fields_) release();  // buffers for other values
    fields_ = fields;
    counts_.resize(n);
    begin_.resize(n);
    thread_.resize(n);
    threads_.resize(static_cast<std::size_t>(std::max(1, omp_get_max_threads())));
    for (Buffers& b : threads_) b.used = 0;
    failed_.store(false, std::memory_order_relaxed);
    run(Append{filter, this});
    if (failed_.load(std::memory_order_relaxed)) {
      release();
      too_large_ = true;
      return false;
    }
    return true;
  }

  // After a list made in two passes: whether the next one may be collected (its `pairs` would
  // have fitted).
  void note_two_pass_list(std::uint64_t pairs, RowFields fields) {
    // Twice the list: the buffers grow by doubling.
    too_large_ = 2.0 * static_cast<double>(pairs) * fields.bytes_per_entry() > kept_bytes;
  }

  // offsets[0] = 0 and offsets[i + 1] = offsets[i] + the count of row i.
  void scan(std::uint64_t* offsets) const {
    offsets[0] = 0;
    for (std::size_t i = 0; i < counts_.size(); ++i) offsets[i + 1] = offsets[i] + counts_[i];
  }

  // The rows into the arrays of `fill` (the list's), each from fill.offsets[i]; entries at or
  // past fill.capacity are left out (a static-capacity list), as the fill pass leaves them.
  void copy_into(const ListFill& fill) const {
    for_each_index(counts_.size(), parallel_targets, 0, [&](std::size_t i) {
      const std::uint64_t first = fill.offsets[i];
      if (first >= fill.capacity) return;
      const std::uint64_t count = std::min<std::uint64_t>(counts_[i], fill.capacity - first);
      const Buffers& b = threads_[thread_[i]];
      const std::uint64_t from = begin_[i];
      if (fill.columns) {
        for (std::uint64_t k = 0; k < count; ++k) {
          fill.rows[first + k] = static_cast<std::int64_t>(i);
          fill.columns[first + k] = b.j[from + k];
        }
      } else {
        std::memcpy(fill.indices + first, b.j.get() + from, 4 * count);
      }
      if (fill.shifts) std::memcpy(fill.shifts + 3 * first, b.s.get() + 3 * from, 12 * count);
      if (fill.distances) std::memcpy(fill.distances + first, b.d.get() + from, 4 * count);
      if (fill.vectors) std::memcpy(fill.vectors + 3 * first, b.v.get() + 3 * from, 12 * count);
    });
  }

  void release() {
    threads_.clear();
    threads_.shrink_to_fit();
    reserved_.store(0, std::memory_order_relaxed);
  }

 private:
  static constexpr double kept_bytes = 256.0 * 1024 * 1024;
  // Below this the scratch is not compared with the system's free memory (reading it costs tens
  // of microseconds), as require_host_memory does not.
  static constexpr double checked_from = 16.0 * 1024 * 1024;

  // A cache line each: a thread appends to its own alone (threads' counters sharing a line made
  // the two-thread pass slower than the two passes it replaced).
  struct alignas(64) Buffers {
    std::unique_ptr<std::uint32_t[]> j;
    std::unique_ptr<std::int32_t[]> s;
    std::unique_ptr<float[]> d, v;
    std::size_t used = 0, capacity = 0;
  };

  // Room for at least one more entry in b; false (and the pass marked failed) when the memory
  // budget or the allocator refuses it. Called inside the pass's parallel loop: nothing throws.
  bool grow(Buffers& b) {
    const std::size_t capacity = std::max<std::size_t>(4096, 2 * b.capacity);
    const double more = static_cast<double>(capacity - b.capacity) * fields_.bytes_per_entry();
    const double total = reserved_.fetch_add(more, std::memory_order_relaxed) + more;
    try {
      if (total > kept_bytes) throw std::bad_alloc();
      // Twice the growth: the list these rows are copied into takes as much again.
      if (total > checked_from && 2.0 * more > host_memory_budget().bytes) throw std::bad_alloc();
      Buffers bigger;
      bigger.j = std::make_unique_for_overwrite<std::uint32_t[]>(capacity);
      if (fields_.shifts) bigger.s = std::make_unique_for_overwrite<std::int32_t[]>(3 * capacity);
      if (fields_.distances) bigger.d = std::make_unique_for_overwrite<float[]>(capacity);
      if (fields_.vectors) bigger.v = std::make_unique_for_overwrite<float[]>(3 * capacity);
      if (b.used > 0) {
        std::memcpy(bigger.j.get(), b.j.get(), 4 * b.used);
        if (fields_.shifts) std::memcpy(bigger.s.get(), b.s.get(), 12 * b.used);
        if (fields_.distances) std::memcpy(bigger.d.get(), b.d.get(), 4 * b.used);
        if (fields_.vectors) std::memcpy(bigger.v.get(), b.v.get(), 12 * b.used);
      }
      bigger.used = b.used;
      bigger.capacity = capacity;
      b = std::move(bigger);
      return true;
    } catch (...) {  // the budget, a bad RAYCUT_MAX_MEMORY, or the allocator
      failed_.store(true, std::memory_order_relaxed);
      return false;
    }
  }

  // The pass's functor: row i's entries appended to its thread's buffers.
  struct Append : ListFilter {
    struct Accumulator {
      Buffers* buffers = nullptr;
      std::uint32_t count = 0;
    };
    using options = functor_options<option::accepts, option::init>;
    ListRows* rows;
    RowFields fields;
    Append(const ListFilter& filter, ListRows* r)
        : ListFilter(filter), rows(r), fields(r->fields_) {}

    Accumulator init(std::uint32_t i) const {
      const auto t = static_cast<std::uint32_t>(omp_get_thread_num());
      Buffers& b = rows->threads_[t];
      rows->thread_[i] = t;
      rows->begin_[i] = b.used;
      return {&b, 0};
    }
    void operator()(Accumulator& a, std::uint32_t i, std::uint32_t j, Vec3 r, float r2,
                    const Shift& s) const {
      if (!within(i, j, s, r2)) return;
      Buffers& b = *a.buffers;
      if (b.used == b.capacity && (rows->failed_.load(std::memory_order_relaxed) || !rows->grow(b)))
        return;
      const std::size_t e = b.used++;
      b.j[e] = j;
      if (fields.shifts) {
        b.s[3 * e] = s.a;
        b.s[3 * e + 1] = s.b;
        b.s[3 * e + 2] = s.c;
      }
      if (fields.distances) b.d[e] = pair_distance(r, r2);
      if (fields.vectors) {
        b.v[3 * e] = r.x;
        b.v[3 * e + 1] = r.y;
        b.v[3 * e + 2] = r.z;
      }
      ++a.count;
    }
    void finish(std::uint32_t i, Accumulator& a) const { rows->counts_[i] = a.count; }
  };

  RowFields fields_;
  bool too_large_ = false;  // the last list did not fit: two passes
  std::vector<Buffers> threads_;
  std::vector<std::uint32_t> counts_, thread_;
  std::vector<std::uint64_t> begin_;
  std::atomic<double> reserved_{0};
  std::atomic<bool> failed_{false};
};

}  // namespace raycut::detail
