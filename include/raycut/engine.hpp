// The raycut engine: choose a method, build it over positions, then compute a fused pair kernel
// or a neighbour list. Host-only header: no CUDA or OptiX types.
//
//   raycut::Engine engine("auto");
//   engine.build({xyz.data(), n, raycut::MemorySpace::host}, cutoff);
//   raycut::Results r = engine.compute(raycut::Kernel::count);
//   raycut::NeighbourList list = engine.neighbours();
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "raycut/box.hpp"
#include "raycut/error.hpp"
#include "raycut/kernels.hpp"
#include "raycut/static_pairs.hpp"

namespace raycut {

enum class MemorySpace { host, device };

// (N,3) float32 positions, row-major (x0 y0 z0 x1 y1 z1 ...), on the host or the CUDA device.
// The engine does not keep the pointer beyond build().
struct PositionsView {
  const float* xyz = nullptr;
  std::size_t size = 0;  // N, the number of particles
  MemorySpace space = MemorySpace::host;
};

// (N,3) float64 positions in host memory. The search runs on them rounded to float; on the CPU
// methods every pair that rounding could decide is decided in double from these, so the pairs
// are the float64 answer (docs/limits.md). The engine does not keep the pointer beyond build().
struct Float64Positions {
  const double* xyz = nullptr;
  std::size_t size = 0;
};

// What build() takes beyond positions and a cutoff (docs/periodic.md, "Semantics"): periodic
// boxes, batches of independent systems, and a second point set. The default is one open system.
//
// A pair is a triple (i, j, S), S an integer vector (0 on non-periodic axes), with
// r_ij = x_j - x_i + S . cell; in range iff |r_ij| < C. Boxes thinner than 2C give a pair once
// per image, and (i, i, S != 0) self-images. Positions may be unwrapped: S refers to them as given.
struct Systems {
  Box box;                 // every system's box (default: open)
  std::vector<Box> boxes;  // or one box per system of a batch (then `box` is unused)
  // A batch: system s holds particles [offsets[s], offsets[s + 1]) (contiguous), S + 1 entries
  // from 0 to N, non-decreasing. Empty: one system. Pairs never cross systems; indices stay
  // global; systems of 0 and 1 particles are valid.
  std::vector<std::uint64_t> offsets;
  // Two point sets: when `queries` holds points (size > 0 or xyz set), they are the targets
  // and build()'s positions the sources; pairs (q, p) with |p - q + S . cell| < C, no
  // self-exclusion. In a batch, query_offsets gives each system's queries as offsets does its
  // sources. Same memory space as the sources.
  PositionsView queries;
  std::vector<std::uint64_t> query_offsets;

  static Systems periodic(const Box& b) {
    Systems s;
    s.box = b;
    return s;
  }
  // No periodic axis, one system, no queries: what build(positions, cutoff) means (a cell
  // without a periodic axis, a file's Lattice with pbc F F F, makes no images).
  bool plain() const {
    return !box.periodic() && boxes.empty() && offsets.empty() && !has_queries();
  }
  bool has_queries() const { return queries.xyz != nullptr || queries.size > 0; }
};

// Per-target results on the host; a vector is empty when the kernel does not produce it
// (raycut::produces(kernel) says which it does; docs/kernels.md lists them per kernel).
struct Results {
  std::vector<std::uint32_t> count;  // 1 per target
  std::vector<float> energy;         // 1 per target
  std::vector<float> force;          // 3 per target (fx fy fz)
  std::vector<float> virial;         // 6 per target (xx yy zz xy xz yz)
  std::vector<float> density;        // 1 per target
};

// The results of the last run() where the method keeps them (Engine::space()), without a copy:
// valid until the next build(), update() or run(). Null where the kernel does not produce it.
struct ResultsView {
  const std::uint32_t* count = nullptr;
  const float* energy = nullptr;
  const float* force = nullptr;
  const float* virial = nullptr;
  const float* density = nullptr;
  MemorySpace space = MemorySpace::host;
};

// Results that own their arrays (Engine::take_results): `view` is valid while `owner` lives.
struct OwnedResults {
  ResultsView view;
  std::shared_ptr<const void> owner;
};

// Host neighbour list in CSR form: the in-range sources of target i are
// indices[offsets[i] .. offsets[i+1]); their order within a row is unspecified. A copy of the
// list a method builds where it works (NeighbourListBuffer).
struct NeighbourList {
  std::vector<std::uint64_t> offsets;  // N + 1 entries
  std::vector<std::uint32_t> indices;
  std::vector<float> distances;      // |r_ij| per entry, when asked
  std::vector<float> vectors;        // r_ij = x_j - x_i + S . cell per entry (3 floats), when asked
  std::vector<std::int32_t> shifts;  // S per entry (3 ints), when asked
  // With ListOptions::coo: the (i, j) of every entry, int64; `indices` is then empty.
  std::vector<std::int64_t> rows, columns;
};

// Per-pair cutoffs, as ASE's neighbor_list takes them: pair (i, j, S) is listed only when
// |r_ij| < c_ij, its own cutoff, decided in double (exactly, from the caller's positions, where
// the search is: docs/limits.md). Either radii, c_ij = r_i + r_j (ASE's natural_cutoffs), or a
// species per particle and a symmetric kinds x kinds table, c_ij = table[s_i * kinds + s_j].
// Every c_ij must be finite, >= 0 and at most the engine's cutoff (the search runs there).
// Host memory, read during the call; not with query sets.
struct PairCutoffs {
  const double* radii = nullptr;           // N, one per particle; or null
  const std::uint32_t* species = nullptr;  // N, each < kinds; with `table`
  const double* table = nullptr;           // kinds * kinds, symmetric
  std::uint32_t kinds = 0;
  bool active() const { return radii != nullptr || table != nullptr; }
};

// What a neighbour list holds (docs/periodic.md, "Semantics", for shifts and half lists).
struct ListOptions {
  // Each pair once: of (i, j, S) and (j, i, -S), the one with i < j, or i == j and S
  // lexicographically positive, in row i. Not with query sets (their pairs are not symmetric).
  bool half = false;
  bool distances = false;  // |r_ij| per entry
  bool vectors = false;    // r_ij = x_j - x_i + S . cell per entry
  bool shifts = false;     // the image shift S per entry (3 int32; zeros without a box)
  // Entries as COO pairs: rows() and columns(), the (i, j) of every entry as int64 (ASE's
  // neighbor_list and PyTorch Geometric's edge_index), written by the list pass itself, in place
  // of the uint32 indices() (null then). The offsets are there all the same.
  bool coo = false;
  // Per-pair cutoffs, read during the call (null: every pair within the engine's cutoff).
  const PairCutoffs* cutoffs = nullptr;
  // With half: each pair once still, but in the row of whichever of its two particles the method
  // meets it from, not necessarily the lower index (LAMMPS's newton-on lists own their pairs
  // the same way). The CUDA grid and the CPU cell list then walk half of their cells' stencil:
  // less work than a half list in the lower index's row. The brute forces keep the lower
  // index's row, which is one such choice. For loops that add each pair's share to both
  // particles.
  bool any_row = false;
};

namespace detail {
class ListStorage;
class PaddedStorage;
}  // namespace detail

// A CSR neighbour list where the method works (device memory for GPU methods), in buffers that
// are reused from call to call and only grow: in a step loop the list allocates once. Filled by
// Engine::neighbours(buffer, options); the pointers stay valid until the next fill.
class NeighbourListBuffer {
 public:
  NeighbourListBuffer();
  ~NeighbourListBuffer();
  NeighbourListBuffer(const NeighbourListBuffer&) = delete;
  NeighbourListBuffer(NeighbourListBuffer&&) noexcept;
  NeighbourListBuffer& operator=(NeighbourListBuffer&&) noexcept;

  std::size_t size() const;              // N, the number of targets
  std::uint64_t pairs() const;           // entries (offsets()[N])
  const std::uint64_t* offsets() const;  // N + 1
  const std::uint32_t* indices() const;  // pairs(), or null with ListOptions::coo
  const std::int64_t* rows() const;      // pairs() with ListOptions::coo, else null
  const std::int64_t* columns() const;   // pairs() with ListOptions::coo, else null
  const float* distances() const;        // pairs(), or null when not asked
  const float* vectors() const;          // 3 pairs(), or null when not asked
  const std::int32_t* shifts() const;    // 3 pairs(), or null when not asked
  MemorySpace space() const;
  const ListOptions& options() const;
  std::size_t bytes() const;      // memory held
  NeighbourList to_host() const;  // a copy on the host

 private:
  friend class Engine;
  std::unique_ptr<detail::ListStorage> storage_;
};

// What Engine::padded_neighbours writes: the [N, K] matrix of each row's first K neighbours.
struct PaddedOptions {
  std::uint32_t k = 0;  // K, the matrix's width (>= 1 unless N = 0)
  // Each pair once, as ListOptions::half says (not with query sets).
  bool half = false;
  // The image shift S of each entry too (3 int32; with a periodic box a row can hold one source
  // once per image).
  bool shifts = false;
  // Rows over K raise Error(capacity_exceeded) (after the matrix is written); otherwise they
  // are only reported. Never truncated silently either way.
  bool throw_on_overflow = false;
  // Each row's K nearest, nearest first (|r| in double from the positions the engine holds,
  // float64 ones when built from them; equal distances by j, then S), in place of its first K
  // in the traversal's order: the k-nearest-neighbour search within the cutoff. Counts stay
  // the rows' full counts. CPU methods (Error(unsupported) on the others).
  bool nearest = false;
};

// Rows past K of a padded list, never truncated silently.
struct PaddedReport {
  std::uint64_t overflowed_rows = 0;  // rows with more than K neighbours
  // The largest row's count, overflowed or not (GPU methods: the largest row over K, 0 if none):
  // grow K to it and retry.
  std::uint32_t largest_count = 0;
  bool overflowed() const { return overflowed_rows > 0; }
};

// A padded [N, K] neighbour matrix and per-row counts, where the method works (jax-md's and
// LAMMPS's shape). Row i holds min(count_i, K) neighbours, then N (an invalid index) up to K.
class PaddedNeighbourBuffer {
 public:
  PaddedNeighbourBuffer();
  ~PaddedNeighbourBuffer();
  PaddedNeighbourBuffer(PaddedNeighbourBuffer&&) noexcept;
  PaddedNeighbourBuffer& operator=(PaddedNeighbourBuffer&&) noexcept;

  std::size_t size() const;              // N
  std::uint32_t width() const;           // K
  const std::uint32_t* indices() const;  // N * K, row-major
  const std::uint32_t* counts() const;   // N: the true number of neighbours of each row
  const std::int32_t* shifts() const;    // 3 N K: S of each entry (0 in padding), or null
  MemorySpace space() const;
  const PaddedReport& report() const;
  // Host copies.
  std::vector<std::uint32_t> indices_to_host() const;
  std::vector<std::uint32_t> counts_to_host() const;
  std::vector<std::int32_t> shifts_to_host() const;  // empty when not asked

 private:
  friend class Engine;
  std::unique_ptr<detail::PaddedStorage> storage_;
};

// Wall-clock milliseconds of the last build()/update() and run(), each phase synchronised.
// device_* are the CUDA-event times of the same phases for GPU methods, negative for CPU
// methods. Both build times negative for builds not timed (Engine::set_timed). refit: the last
// update() refitted the structure instead of rebuilding it.
struct Timings {
  double build_ms = 0, compute_ms = 0;
  double device_build_ms = -1, device_compute_ms = -1;
  bool refit = false;
};

// How update() treats moved particles. skin = 0: rebuild every time (what the paper does).
// skin > 0: methods that can (the OptiX methods) refit their acceleration structure to the new
// positions (always exact: the primitives move with the particles) while no particle has moved
// more than skin / 2 since the last full build, and rebuild beyond that, when the refitted
// tree has lost too much quality.
struct UpdatePolicy {
  float skin = 0;
};

// What a method's traversal can do, declared by the method (not found by trying it): callers
// such as the distributed engine choose their scheme from it before building anything.
struct MethodCapabilities {
  bool periodic_boxes = false;  // Systems with a periodic box (and batches of systems)
  bool query_points = false;    // Systems::queries: targets other than the sources
  bool pair_functors = false;   // raycut::for_each_pair with a caller's functor
};

struct MethodDescription {
  std::string name;
  std::string summary;
  bool available = false;  // built in, and its hardware is present
  std::string why_unavailable;
};

// Every method raycut knows, available or not, in a stable order.
std::vector<MethodDescription> list_methods();
// What "auto" picks on this machine.
std::string auto_method();
// The capabilities of a method of list_methods() (or "auto": those of auto_method()), whether or
// not it is available in this process. Error(invalid_argument) for an unknown name.
MethodCapabilities method_capabilities(std::string_view method);
// True when a CUDA device is usable in this process.
bool cuda_device_available();
// A cutoff given in double (Python, option parsers) as the float Engine::build takes: checked as
// given first, so that 1e-50 (0 in float) and 1e39 (inf) are refused naming the value passed and
// the supported range [2^-60, 2^60]: Error(invalid_argument).
float checked_cutoff(double cutoff);

namespace detail {
class Method;
class ImagePoints;
struct ImagePlan;
struct PairPass;
struct EngineAccess;
struct PairPassAccess;
}  // namespace detail

class Engine {
 public:
  // `method` is a name from list_methods() or "auto". Throws Error(invalid_argument) for an
  // unknown name, Error(unsupported) for a method not available here.
  explicit Engine(std::string_view method = "auto");
  ~Engine();
  // A moved-from Engine throws Error(invalid_argument) from every call but method().
  Engine(Engine&&) noexcept;
  Engine& operator=(Engine&&) noexcept;

  const std::string& method() const { return method_; }
  // Where the method works: positions given there avoid a copy (and an untimed transfer).
  MemorySpace space() const;

  // The CUDA stream (a cudaStream_t) the engine's GPU work is queued on; null: the engine's own
  // (the legacy default stream). Every call waits for its own work on this stream only.
  void set_stream(void* cuda_stream);
  void* stream() const { return stream_; }

  // Whether build() and update() time themselves (last_timings(); the default). Timing a GPU
  // build waits for it to finish. Untimed, they return once their work is queued on the
  // stream, and the host waits only where a size must come back (the grid's plan): what a step
  // loop that never reads the build's time wants. run() is always timed.
  void set_timed(bool timed) { timed_ = timed; }
  bool timed() const { return timed_; }

  // Whether a build with Systems (periodic boxes, batches) reuses the sizes of the previous one
  // (off by default). On a GPU method that can (the grid) with device positions, a build of the
  // same systems, particle count and cutoff then reads nothing back: it takes the previous
  // build's room for periodic images, its float band and its grid, and the device checks that
  // they still fit. A static-capacity list of a build that no longer fits gets the count
  // count_plan_outgrown (raycut/static_pairs.hpp); every other result (lists, padded lists,
  // kernels, functors) waits for the check first and, if the plan no longer fits, builds again
  // from the same positions with a fresh plan, so the positions must stay valid until then. A
  // build plans afresh when the previous plan was found not to fit (as soon as the host has
  // seen it), and the sizes it records have room to spare (about 1/8 more images, a grid box
  // wider by half the cutoff).
  void set_reuse_plan(bool reuse) { reuse_plan_ = reuse; }
  bool reuse_plan() const { return reuse_plan_; }
  // Whether build(positions, cutoff, systems) would reuse the plan recorded last, and so read
  // nothing back: what a caller asks before building on a stream it is capturing into a CUDA
  // graph (a build that plans waits for its sizes, which a capture refuses). A captured build
  // reports a plan that no longer fits only through its static list's count, at each replay.
  bool reuses_plan_for(PositionsView positions, float cutoff, const Systems& systems) const;

  // Validates (finite coordinates, cutoff finite and within the supported range) and builds
  // the method's structure. Throws Error with the first bad index or the bad value, before any
  // device work.
  void build(PositionsView positions, float cutoff);
  // The same with periodic boxes, a batch or query points (Systems says what each means).
  // Throws Error(invalid_argument) for a bad box (Box's validate), bad offsets or a box count
  // that matches neither 1 nor the systems, and Error(unsupported) for a method that cannot
  // (the OptiX methods and grid-paper: no images or batches; docs/methods.md). Device sources
  // of a GPU method are checked by the image expansion's first pass instead (the same error,
  // one read-back less); that refusal leaves the engine unbuilt.
  void build(PositionsView positions, float cutoff, const Systems& systems);
  void build(PositionsView positions, float cutoff, const Box& box) {
    build(positions, cutoff, Systems::periodic(box));
  }
  // float64 positions (host memory), open or with Systems (query points stay float32). A value
  // beyond the float range is refused, naming the particle.
  void build(Float64Positions positions, float cutoff, const Systems& systems = {});

  // New positions of the same N particles, cutoff and systems unchanged: refit or rebuild per
  // the policy (with boxes or batches: a rebuild; with query points: Error(unsupported), build
  // again).
  void update(PositionsView positions);
  void update(Float64Positions positions);  // after a float64 build: rebuilds
  void set_update_policy(const UpdatePolicy& policy);

  // Computes `kernel` for every target and keeps the results in the method's memory.
  void run(Kernel kernel, const KernelOptions& options = {});
  // Copies the results of the last successful run() to the host.
  Results results() const;
  // The results of the last run() in place (no copy): what an integrator on the device reads.
  ResultsView results_view() const;
  // The results of the last run() moved out of the engine (no copy): arrays in the method's
  // memory, valid for as long as the returned owner is held, whatever the engine does next.
  // The engine keeps no results after it (results() throws until the next run(), which sizes
  // new arrays: from a stream-ordered pool on the device, so a run per call stays cheap).
  OwnedResults take_results();
  // run() then results().
  Results compute(Kernel kernel, const KernelOptions& options = {});

  // The CSR neighbour list of the built positions, where the method works (device memory for
  // GPU methods), into reusable buffers, sized exactly: on the GPU a count pass, a scan and a
  // fill pass; on the CPU one pass into rows per thread, then copied into place.
  void neighbours(NeighbourListBuffer& list, const ListOptions& options = {});
  // The same, copied to the host.
  NeighbourList neighbours(const ListOptions& options = {});
  // The pairs (i, j[, S]) as COO entries into a static capacity (`out`, in the memory where the
  // method works: Engine::space()), rows in ascending order: on the GPU the count pass, a scan
  // and the fill pass, with no read-back and no allocation that grows with the pairs (the CPU
  // lists as neighbours() does, then copies the rows up to the capacity). out.count gets the
  // true count (valid iff <= out.capacity); entries past it are padding (i = j =
  // out.pad_index, S = 0). GPU methods queue it on the engine's stream and return without
  // waiting. ListOptions: half and cutoffs (S when out.shifts is set); distances, vectors and
  // coo are refused (compute D from i, j and S; the entries are COO).
  void neighbours(const StaticPairs& out, const ListOptions& options = {});
  // The padded [N, K] matrix in one pass (PaddedOptions says what). Overflowing rows are
  // reported, never truncated silently. A matrix beyond the memory budget
  // (raycut/host_memory.hpp; on the GPU the free device memory) is Error(out_of_memory) before
  // anything is allocated.
  PaddedReport padded_neighbours(PaddedNeighbourBuffer& list, const PaddedOptions& options);

  const Timings& last_timings() const { return timings_; }
  // The number of targets (rows of lists, entries of results): N, or M with query points.
  std::size_t size() const { return size_; }
  // The number of sources: N (the positions given to build()).
  std::size_t sources() const { return sources_; }
  const Systems& systems() const { return systems_; }
  float cutoff() const { return cutoff_; }

 private:
  // Throws for list options this build cannot take (half with queries, bad per-pair cutoffs).
  void check_list_options(const ListOptions& options) const;
  friend struct detail::EngineAccess;
  friend struct detail::PairPassAccess;
  // What include/raycut/pairs.hpp and include/raycut/cuda/pairs.cuh run a user's functor
  // through (detail::PairPassAccess).
  detail::PairPass pair_pass() const;
  // update(); `checked`: the caller has checked the coordinates (raycut's own engines over
  // positions they checked), so a plain update skips its finiteness pass (one with systems
  // rebuilds, and checks as build() does).
  void update(PositionsView positions, bool checked);
  // Throws unless update() with n particles can follow the last build().
  void require_updatable(std::size_t n) const;
  // build(positions, cutoff, systems) over the points path; `float64`: the caller's positions
  // in double when `positions` are their float rounding (Float64Positions).
  void build_points(PositionsView positions, float cutoff, const Systems& systems,
                    const double* float64);
  template <class F>
  void with_positions_in_method_space(const PositionsView& positions, F&& f);
  detail::Method& impl(const char* call) const;
  // After a build that reused its plan: waits for the device's check and, if the plan no
  // longer fits, builds again from the same positions with a fresh plan. What every result but
  // a static-capacity list calls first.
  void settle_reused_plan();

  std::string method_;
  std::unique_ptr<detail::Method> impl_;
  void* stream_ = nullptr;
  std::size_t size_ = 0, sources_ = 0;
  float cutoff_ = 0;
  Systems systems_;
  // The points a method builds over with images (core/images.hpp), reused by later builds.
  std::shared_ptr<detail::ImagePoints> images_;
  // The plan of the last build with Systems (core/images.hpp), kept for the same layout.
  std::shared_ptr<const detail::ImagePlan> plan_;
  Systems plan_key_;
  std::size_t plan_sources_ = 0;
  float plan_cutoff_ = 0;
  bool plan_queries_ = false;
  bool queries_ = false;  // built with query points
  bool float64_ = false;  // built from Float64Positions
  bool built_ = false;
  bool has_run_ = false;
  bool timed_ = true;
  bool reuse_plan_ = false;
  // The last build reused its plan: its positions (and queries), for settle_reused_plan().
  bool reused_ = false;
  PositionsView reused_positions_;
  PositionsView reused_queries_;
  Timings timings_;
};

// A Verlet list: the list of every pair within cutoff + skin, rebuilt only when some particle
// has moved more than skin / 2 since the last build (then no pair within the cutoff can be
// missing from it). The displacement is checked where the positions are (on the device for GPU
// methods: one reduction and a 4-byte flag read, no copy of positions). Kernels that use the
// list filter by the cutoff themselves.
class VerletList {
 public:
  // `systems`: boxes and batches as Engine::build takes them (no query points).
  VerletList(std::string_view method, float cutoff, float skin, const ListOptions& options = {},
             const Systems& systems = {});
  // New positions (the same N after the first call); returns true when the list was rebuilt.
  bool update(PositionsView positions);
  const NeighbourListBuffer& list() const { return list_; }
  Engine& engine() { return engine_; }
  float cutoff() const { return cutoff_; }
  float skin() const { return skin_; }
  std::uint64_t rebuilds() const { return rebuilds_; }

 private:
  Engine engine_;
  float cutoff_, skin_;
  ListOptions options_;
  Systems systems_;
  NeighbourListBuffer list_;
  std::shared_ptr<void> built_;  // positions at the last build, where the method works
  std::uint64_t rebuilds_ = 0;
};

}  // namespace raycut
