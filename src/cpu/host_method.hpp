// What every CPU method shares: results, lists and the caller's functors all run through the one
// CPU pair loop (raycut/pairs.hpp) over the candidates the method names. A method derives from
// HostMethod<Self> and provides:
//   build(xyz, n, cutoff)  (storing what candidate_runs() needs, and calling set_positions)
//   candidate_runs(i, out) writes CandidateRuns (detail/pair_pass.hpp, at most
//                          max_candidate_runs) holding every candidate point of target i (i
//                          allowed), each at most once, and returns how many: the longer the
//                          runs, the faster;
// and optionally target_order(): the targets in the order to visit them (else 0 .. n - 1), and
// target_order_xyz(): their positions in that order.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "core/list_storage.hpp"
#include "core/method.hpp"
#include "core/validation.hpp"
#include "cpu/list_rows.hpp"
#include "raycut/engine.hpp"
#include "raycut/host_memory.hpp"
#include "raycut/kernels.hpp"
#include "raycut/pairs.hpp"

namespace raycut::detail {

// Host results as the pointers a kernel writes, sized for `kernel` over n targets.
KernelOutputs prepare_host_results(Results& results, Kernel kernel, std::size_t n);
ResultsView view_of(const Results& results);

template <class Self>
class HostMethod : public Method {
 public:
  MemorySpace space() const override { return MemorySpace::host; }

  void compute(Kernel kernel, const KernelOptions& options) override {
    results_ = {};
    Results fresh;
    const KernelOutputs out = prepare_host_results(fresh, kernel, n_);
    with_kernel(kernel, options, cutoff_squared_, out, [&](const auto& f) { run(f); });
    results_ = std::move(fresh);
  }
  void compute_rows(Kernel kernel, const KernelOptions& options, const RowMap& rows,
                    const KernelOutputs& out) override {
    with_kernel(kernel, options, cutoff_squared_, out, [&](const auto& f) {
      run(RowPass<std::decay_t<decltype(f)>>{{f, rows}});
    });
  }
  void list_rows(const RowMap& rows, const ListCount& count) override {
    run(RowPass<ListCount>{{count, rows}});
  }
  void list_rows(const RowMap& rows, const ListFill& fill) override {
    run(RowPass<ListFill>{{fill, rows}});
  }
  Results results() const override { return results_; }
  ResultsView results_view() const override { return view_of(results_); }
  OwnedResults take_results() override {
    auto owned = std::make_shared<Results>(std::move(results_));
    results_ = {};
    return {view_of(*owned), owned};
  }

  std::unique_ptr<ListStorage> make_list_storage() const override {
    return std::make_unique<HostListStorage>();
  }
  std::unique_ptr<PaddedStorage> make_padded_storage() const override {
    return std::make_unique<HostPaddedStorage>();
  }

  void neighbours(ListStorage& storage, const ListOptions& options) override {
    auto& list = static_cast<HostListStorage&>(storage);
    std::uint64_t* offsets = list.prepare_offsets(n_, options);
    const ListFilter filter = list_filter(options);
    list_into(filter, RowFields{options.shifts, options.distances, options.vectors}, offsets,
              [&](std::uint64_t pairs) { return list.prepare_fill(pairs, filter); });
  }

  void static_neighbours(const StaticPairs& out, const ListOptions& options,
                         std::size_t n) override {
    if (n == 0) return finish_static_pairs(out, 0);
    std::vector<std::uint64_t> offsets(n_ + 1);
    const ListFilter filter = list_filter(options);
    ListFill fill{filter, offsets.data(), nullptr, nullptr, nullptr, out.shifts, out.i, out.j};
    fill.capacity = out.capacity;
    list_into(filter, RowFields{out.shifts != nullptr}, offsets.data(),
              [&](std::uint64_t) { return fill; });
    finish_static_pairs(out, offsets[n_]);
  }

  void padded_neighbours(PaddedStorage& storage, std::uint32_t k, bool half, bool shifts) override {
    padded(storage, k, half, shifts, false);
  }
  void padded_nearest(PaddedStorage& storage, std::uint32_t k, bool half, bool shifts) override {
    padded(storage, k, half, shifts, true);
  }

 private:
  void padded(PaddedStorage& storage, std::uint32_t k, bool half, bool shifts, bool nearest) {
    auto& list = static_cast<HostPaddedStorage&>(storage);
    PaddedOverflow overflow{0, 0};
    const PaddedFill fill = list.prepare(n_, k, half, shifts, &overflow);
    if (nearest) {
      PaddedNearestFill nearest_fill{fill, xyz_, {}};
      if (images_.exact) nearest_fill.exact = *images_.exact;
      run(nearest_fill);
    } else {
      run(fill);
    }
    // The largest row, overflowed or not (the fill records only rows over K: on the GPU an
    // atomic per row would cost more than the matrix).
    std::uint32_t largest = 0;
    for (std::size_t i = 0; i < n_; ++i) largest = std::max(largest, list.counts[i]);
    list.report = {overflow.rows, largest};
  }

 public:
  PairPass pair_pass() const override {
    PairPass pass;
    pass.kind = PassKind::host;
    pass.n = n_;
    pass.points = points_;
    pass.images = images_;
    pass.cutoff_squared = cutoff_squared_;
    pass.host.method = this;
    pass.host.xyz = xyz_;
    pass.host.order = static_cast<const Self*>(this)->target_order();
    pass.host.order_xyz = static_cast<const Self*>(this)->target_order_xyz();
    pass.host.slots = static_cast<const Self*>(this)->target_slots();
    pass.host.runs = [](const void* method, std::size_t i, CandidateRun* out) {
      return static_cast<const Self*>(method)->candidate_runs(i, out);
    };
    return pass;
  }

  // The visiting order of targets; a method whose candidates lie in cell order gives its own.
  const std::uint32_t* target_order() const { return nullptr; }
  // With target_order(): the targets' positions in that order, 3 each (null: none).
  const float* target_order_xyz() const { return nullptr; }
  // Each target's slot in the order of its runs' points (HostPass::slots; null: none).
  const std::uint32_t* target_slots() const { return nullptr; }

 protected:
  // Lists index particles with 32 bits: called first by build(), before any copy.
  static void require_indexable(std::size_t n, const char* method) {
    if (n >= (std::size_t{1} << 32))
      throw Error(ErrorCode::invalid_argument,
                  std::string(method) + " supports fewer than 2^32 = 4294967296 particles " +
                      "(32-bit indices), got N = " + std::to_string(n));
  }
  // The points candidate_runs() reads targets from (the first `targets`; the caller's order), their
  // images, and the cutoff.
  void set_positions(const float* xyz, std::size_t points, float cutoff, std::size_t targets,
                     const ImageTables& images = {}) {
    xyz_ = xyz;
    points_ = points;
    n_ = targets;
    images_ = images;
    cutoff_squared_ = squared_cutoff(cutoff);
  }
  void set_positions(const float* xyz, std::size_t n, float cutoff) {
    set_positions(xyz, n, cutoff, n);
  }

 private:
  // What a list keeps: its half orientation and per-pair cutoffs (decided in double with the
  // points' images, ExactImages).
  ListFilter list_filter(const ListOptions& options) const {
    ListFilter filter{options.half, host_cutoff_filter(options.cutoffs),
                      options.half && options.any_row};
    if (images_.exact) filter.cutoffs.exact = *images_.exact;
    return filter;
  }
  // A list's offsets (n + 1) and entries, into the fill that fill_at(pairs) returns: one pass
  // into rows per thread, then copied into place (list_rows.hpp); two passes (count, then fill in
  // place) where the rows would not fit.
  template <class FillAt>
  void list_into(const ListFilter& filter, RowFields fields, std::uint64_t* offsets,
                 FillAt&& fill_at) {
    if (rows_.collect(n_, filter, fields, [&](const auto& f) { run(f); })) {
      rows_.scan(offsets);
      rows_.copy_into(fill_at(offsets[n_]));
      return;
    }
    count_rows(filter, offsets);
    rows_.note_two_pass_list(offsets[n_], fields);
    run(fill_at(offsets[n_]));
  }

  // The count pass into offsets[1 .. n], then their running sum: offsets[i] is row i's first.
  void count_rows(const ListFilter& filter, std::uint64_t* offsets) const {
    require_host_memory(4.0 * static_cast<double>(n_), [&] {
      return "the row counts of a neighbour list of " + std::to_string(n_) + " rows";
    });
    std::vector<std::uint32_t> counts(n_);
    count_list(filter, counts.data(), [&](const auto& f) { run(f); });
    offsets[0] = 0;
    for (std::size_t i = 0; i < n_; ++i) offsets[i + 1] = offsets[i] + counts[i];
  }

  template <class F>
  void run(const F& f) const {
    const auto* self = static_cast<const Self*>(this);
    run_host_pass(
        pair_pass(),
        [self](std::size_t i, CandidateRun* out) { return self->candidate_runs(i, out); }, f);
  }

  const float* xyz_ = nullptr;
  std::size_t n_ = 0, points_ = 0;  // targets, points
  ImageTables images_;
  float cutoff_squared_ = 0;
  Results results_;
  ListRows rows_;  // the one-pass lists' rows, kept between lists
};

}  // namespace raycut::detail
