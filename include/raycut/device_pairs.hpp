// Stream-ordered pair lists on the GPU, for the small systems and batches that machine-learned
// potentials and MD step loops run every step: no host synchronisation, no allocation outside
// the context's memory resource, a static capacity with the true count written on the device,
// and a fixed order of pairs, so that a CUDA graph can capture a call and its replays equal the
// eager results bit for bit (docs/streams.md). Host-only header: no CUDA types.
//
//   raycut::StaticPairBuffer pairs(capacity, ctx);
//   raycut::list_pairs_small_systems(ctx, systems, cutoff, {}, pairs.view(n));
//   // ... more work on ctx.stream; later, where the host may wait:
//   std::int64_t count = raycut::read_pair_count(ctx, pairs.count());
#pragma once

#include <cstddef>
#include <cstdint>

#include "raycut/context.hpp"
#include "raycut/static_pairs.hpp"

namespace raycut {

enum class Scalar { float32, float64 };

// Particles and their periodic systems, every array in memory of the current CUDA device.
struct DeviceSystems {
  const void* positions = nullptr;  // (size, 3) row-major, `scalar`; may be unwrapped
  Scalar scalar = Scalar::float32;  // of positions and cells
  std::size_t size = 0;             // N
  // (cell_count, 3, 3), rows the lattice vectors a, b, c, `scalar`; cell_count is 1 (every
  // system) or one per system. Null: open systems.
  const void* cells = nullptr;
  std::size_t cell_count = 0;
  // (pbc_count, 3): which rows repeat, 1 or one per system. Null with cells: all three.
  const bool* pbc = nullptr;
  std::size_t pbc_count = 0;
  // (N,) the system of each particle, sorted (torch_geometric's `batch`); null: one system.
  // Pairs never cross systems; indices stay global.
  const std::int64_t* batch = nullptr;
};

// Which sources a row of the small-system pass tests (the results are the same; the work is not).
enum class SourceSearch {
  // cells where a system is large enough to gain from them (small_pass_uses_cells), else every
  // particle of the system
  automatic,
  all_pairs,  // every particle of the row's system: n_s^2 tests, the least fixed cost
  // the particles of the 27 cells around the row's own, cells at least a cutoff wide along each
  // lattice axis: about 27 cells' worth of tests a row, for four more launches (a sort)
  cells,
};

// The automatic choice: cells when the systems hold 2,048 particles or more on average (the host
// knows the number of systems from the cells, the pbc rows or a list per system, else takes 1).
// Measured on an H100 (docs/benchmarks.md): all pairs is faster at 1,000 particles (36 against
// 98 us from a graph; 92 us at 2,000), cells ahead above, where all pairs grows as N^2 (4,000:
// 138 us with cells; 10,000: 270).
inline constexpr double cells_from_particles_per_system = 2048;
constexpr bool small_pass_uses_cells(std::size_t particles, std::size_t systems) {
  return static_cast<double>(particles) >=
         cells_from_particles_per_system * static_cast<double>(systems > 0 ? systems : 1);
}

struct PairOptions {
  // Each pair once: of (i, j, S) and (j, i, -S), the one with i < j, or i == j and S
  // lexicographically positive.
  bool half = false;
  SourceSearch search = SourceSearch::automatic;
  // A device int read by the pass's kernels: 0 leaves the outputs as they are (the pass does no
  // work), anything else runs it. Null: always run. What lets a captured step rebuild a list only
  // when needed (DeviceVerletList) without a conditional on the host.
  const int* run_if = nullptr;
};

// The small-system policy: the stream-ordered pass beats a grid build and its host
// synchronisations while its pair tests, at least particles^2 / systems (B systems of N
// particles in all; equal sizes give the least), stay within small_system_pair_tests, or while
// the particles are at most small_system_particles (cells then bound the tests by the density,
// not by N^2). Measured on an H100 through PyTorch, where the Engine's host waits cost most
// (docs/streams.md): 1,000 and 4,000 particles, 32 x 100, 256 x 100 and 512 x 128 (2^23 tests)
// list faster on the pass, 10,000 particles on the grid. A C++ caller of the Engine waits less:
// there the grid is already ahead at 4,000 particles (144 against 151 us), 256 x 100 and
// 512 x 128.
inline constexpr double small_system_pair_tests = 1 << 23;
inline constexpr std::size_t small_system_particles = 4096;
constexpr bool prefer_small_systems(std::size_t particles, std::size_t systems) {
  return systems > 0 && (particles <= small_system_particles ||
                         static_cast<double>(particles) * static_cast<double>(particles) <=
                             small_system_pair_tests * static_cast<double>(systems));
}

// Every pair (i, j, S) of the same system with r = x_j - x_i + S . cell, |r| < cutoff, except
// (i, i, 0), decided in double precision from the positions as given (float32 or float64): the
// float64 answer at every box size, with no band. A row's sources are its system's particles, or
// those of the cells around its own (PairOptions::search), each pair's images bounded and decided
// in double (docs/streams.md gives the crossover with the Engine). Pairs come row by row (i
// ascending); within a row, by j ascending (all pairs) or cell by cell in a fixed order, j
// ascending within a cell (cells); then by S lexicographically. The same input always gives the
// same bytes.
//
// Queues everything on ctx.stream and returns without waiting. Host-side argument errors
// (cutoff not finite and positive, null arrays, counts that do not fit) throw Error before any
// work; errors in device data show as a negative count. Error(unsupported) without CUDA.
void list_pairs_small_systems(const Context& ctx, const DeviceSystems& systems, double cutoff,
                              const PairOptions& options, const StaticPairs& out);

// The count of a finished pass, read back to the host: the one call of this header that waits
// (for ctx.stream). Throws Error(invalid_input) naming the problem for a negative count.
std::int64_t read_pair_count(const Context& ctx, const std::int64_t* device_count);

// i, j, S and count in device memory from a context's memory resource, freed with it.
class StaticPairBuffer {
 public:
  StaticPairBuffer() = default;
  StaticPairBuffer(std::size_t capacity, const Context& ctx);
  ~StaticPairBuffer();
  StaticPairBuffer(StaticPairBuffer&& o) noexcept;
  StaticPairBuffer& operator=(StaticPairBuffer&& o) noexcept;
  StaticPairBuffer(const StaticPairBuffer&) = delete;
  StaticPairBuffer& operator=(const StaticPairBuffer&) = delete;

  std::size_t capacity() const { return capacity_; }
  bool allocated() const { return block_ != nullptr; }
  std::int64_t* i() const;
  std::int64_t* j() const;
  std::int32_t* shifts() const;
  std::int64_t* count() const;
  // Where a pass writes, padding with `pad_index` (N, by convention).
  StaticPairs view(std::int64_t pad_index) const;

 private:
  void release() noexcept;
  void* block_ = nullptr;
  std::size_t bytes_ = 0, capacity_ = 0;
  Context ctx_;
};

// Exact sizing on top of static capacity: runs the pass, reads the count back, and when it
// exceeds the buffer's capacity grows the buffer (to the count plus an eighth) and runs again.
// Returns the count. The only helper that waits; a step loop that keeps the buffer pays for
// growth once.
std::int64_t list_pairs_small_systems_growing(const Context& ctx, const DeviceSystems& systems,
                                              double cutoff, const PairOptions& options,
                                              StaticPairBuffer& buffer);

// A Verlet list on the stream-ordered path: the pairs within cutoff + skin, rebuilt only when
// some particle has moved more than skin / 2 since the last rebuild (then no pair within the
// cutoff can be missing). The check, the conditional rebuild and the copy of the reference
// positions are kernels on the context's stream that read a device flag: update() never waits,
// and a CUDA graph can capture it. Kernels that use the list filter by the cutoff themselves.
// The first update() always rebuilds: run one before capturing a step. Only positions are
// watched: cells must stay as they were at the last rebuild, and options.run_if is the list's own
// flag (one given is not read).
class DeviceVerletList {
 public:
  DeviceVerletList(const Context& ctx, double cutoff, double skin, std::size_t capacity,
                   const PairOptions& options = {});
  ~DeviceVerletList();
  DeviceVerletList(const DeviceVerletList&) = delete;
  DeviceVerletList& operator=(const DeviceVerletList&) = delete;

  // New positions of the same systems (the same N after the first call).
  void update(const DeviceSystems& systems);
  // The list (valid iff 0 <= count <= capacity, as StaticPairs says).
  const StaticPairBuffer& pairs() const { return pairs_; }
  // A device int: 1 when the last update() rebuilt the list, else 0.
  const int* rebuilt() const { return flag_; }
  // Grows the list to `capacity` (waits for the stream); the next update() rebuilds. The old
  // buffers are freed: a CUDA graph captured before holds their addresses and must be captured
  // again (after one eager update()).
  void reserve(std::size_t capacity);
  double cutoff() const { return cutoff_; }
  double skin() const { return skin_; }

 private:
  Context ctx_;
  double cutoff_ = 0, skin_ = 0;
  PairOptions options_;
  StaticPairBuffer pairs_;
  int* flag_ = nullptr;        // device
  void* reference_ = nullptr;  // positions at the last rebuild, device
  std::size_t reference_bytes_ = 0, size_ = 0;
  Scalar scalar_ = Scalar::float32;
  bool first_ = true;
};

}  // namespace raycut
