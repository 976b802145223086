#include "raycut/engine.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <new>
#include <string>
#include <vector>

#include "core/device_services.hpp"
#include "core/images.hpp"
#include "core/list_storage.hpp"
#include "core/method.hpp"
#include "core/validation.hpp"
#include "raycut/host_memory.hpp"

namespace raycut {
namespace {

Error half_with_queries() {
  return Error(ErrorCode::invalid_argument,
               "half lists need one point set: with query points every (query, source) pair is "
               "a pair of its own (ask for the full list)");
}

// Refuses a CPU method's build over `points` points beyond the host memory budget, before it
// allocates (device methods check the free device memory themselves).
void require_build_memory(const detail::Method& m, const std::string& method, std::size_t points) {
  if (m.space() != MemorySpace::host) return;
  require_host_memory(detail::host_build_bytes_per_point * static_cast<double>(points), [&] {
    return "method '" + method + "' over " + std::to_string(points) + " points (~" +
           detail::number(detail::host_build_bytes_per_point) + " B each)";
  });
}

using Clock = std::chrono::steady_clock;

double elapsed_ms(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

// The end of a build begun at `start`: timed, it waits for the method's work and records the
// host clock's and the method's device time; untimed, neither (both -1).
void end_build(detail::Method& m, bool timed, Clock::time_point start, Timings& timings) {
  if (!timed) {
    timings.build_ms = timings.device_build_ms = -1;
    return;
  }
  m.synchronize();
  timings.build_ms = elapsed_ms(start);
  timings.device_build_ms = m.device_build_ms();
}

const detail::MethodEntry& find_entry(std::string_view name) {
  std::string known;
  for (const auto& entry : detail::method_registry()) {
    if (entry.name == name) return entry;
    known += (known.empty() ? "" : ", ") + entry.name;
  }
  throw Error(ErrorCode::invalid_argument,
              "unknown method '" + std::string(name) + "' (known: auto, " + known + ")");
}

// The same systems, boxes and batch layout (the query count included, not their pointer).
bool same_layout(const Systems& a, const Systems& b) {
  return a.box == b.box && a.boxes == b.boxes && a.offsets == b.offsets &&
         a.query_offsets == b.query_offsets && a.queries.size == b.queries.size;
}

// Checks coordinates where they live, before any work on them (device ones on `stream`); throws
// naming the first bad one. `values` false: the pointer and the device only (a pass that reads
// every coordinate anyway checks them).
void validate_positions(const PositionsView& positions, void* stream, bool values = true,
                        const char* what = "particle") {
  if (positions.size > 0 && positions.xyz == nullptr)
    throw Error(ErrorCode::invalid_argument, "positions pointer is null for N = " +
                                                 std::to_string(positions.size) + " particles");
  if (positions.space == MemorySpace::host) {
    if (!values) return;
    const std::size_t bad = detail::first_non_finite_host(positions.xyz, positions.size);
    if (bad < positions.size) detail::throw_non_finite(bad, positions.xyz + 3 * bad, what);
    return;
  }
  const detail::DeviceServices* device = detail::device_services();
  if (!device)
    throw Error(ErrorCode::unsupported,
                "positions are in device memory but raycut was built without CUDA");
  if (!device->available())
    throw Error(ErrorCode::unsupported,
                "positions are in device memory but no CUDA device is usable in this process");
  if (!values) return;
  const std::size_t bad = device->first_non_finite(positions.xyz, positions.size, stream);
  if (bad < positions.size) {
    float xyz[3];
    device->download(xyz, positions.xyz + 3 * bad, sizeof xyz);
    detail::throw_non_finite(bad, xyz, what);
  }
}

}  // namespace

std::vector<MethodDescription> list_methods() {
  std::vector<MethodDescription> out;
  for (const auto& entry : detail::method_registry()) {
    std::string why = entry.why_unavailable();
    out.push_back({entry.name, entry.summary, why.empty(), why});
  }
  return out;
}

bool cuda_device_available() {
  const detail::DeviceServices* device = detail::device_services();
  return device && device->available();
}

std::string auto_method() {
  // Fastest available first: the measured order of bench/results (docs/benchmarks.md).
  for (const char* name : {"grid", "cell-list"}) {
    for (const auto& entry : detail::method_registry())
      if (entry.name == name && entry.why_unavailable().empty()) return name;
  }
  return "brute-force";
}

MethodCapabilities method_capabilities(std::string_view method) {
  return find_entry(method == "auto" ? std::string_view(auto_method()) : method).capabilities;
}

Engine::Engine(std::string_view method) {
  method_ = method == "auto" ? auto_method() : std::string(method);
  const auto& entry = find_entry(method_);
  if (std::string why = entry.why_unavailable(); !why.empty())
    throw Error(ErrorCode::unsupported, "method '" + method_ + "' is not available: " + why);
  impl_ = entry.make();
}

Engine::~Engine() = default;
Engine::Engine(Engine&&) noexcept = default;
Engine& Engine::operator=(Engine&&) noexcept = default;

detail::Method& Engine::impl(const char* call) const {
  if (!impl_)
    throw Error(ErrorCode::invalid_argument,
                std::string("Engine::") + call + "() called on a moved-from Engine");
  return *impl_;
}

MemorySpace Engine::space() const {
  return impl("space").space();
}

void Engine::set_stream(void* cuda_stream) {
  impl("set_stream").set_stream(cuda_stream);
  stream_ = cuda_stream;
}

void Engine::build(PositionsView positions, float cutoff) {
  detail::Method& m = impl("build");
  detail::validate_cutoff(cutoff);
  validate_positions(positions, stream_);
  require_build_memory(m, method_, positions.size);
  float64_ = false;
  built_ = false;
  has_run_ = false;
  reused_ = false;
  size_ = sources_ = positions.size;
  cutoff_ = cutoff;
  systems_ = {};
  queries_ = false;
  images_.reset();
  timings_ = {};
  if (size_ == 0) {  // nothing to build; every query answers "no pairs"
    built_ = true;
    return;
  }

  with_positions_in_method_space(positions, [&](const float* xyz) {
    const auto start = Clock::now();
    m.build(xyz, size_, cutoff);
    end_build(m, timed_, start, timings_);
  });
  built_ = true;
}

void Engine::build(PositionsView positions, float cutoff, const Systems& systems) {
  if (systems.plain()) {
    build(positions, cutoff);
    return;
  }
  build_points(positions, cutoff, systems, nullptr);
}

void Engine::build(Float64Positions positions, float cutoff, const Systems& systems) {
  if (positions.size > 0 && positions.xyz == nullptr)
    throw Error(ErrorCode::invalid_argument, "float64 positions pointer is null for N = " +
                                                 std::to_string(positions.size) + " particles");
  // Rounded to float for the search; the doubles decide what that rounding could (images.cpp).
  std::vector<float> rounded;
  try {
    rounded.resize(3 * positions.size);
  } catch (const std::bad_alloc&) {
    throw Error(ErrorCode::out_of_memory, "not enough host memory for the float copy of " +
                                              std::to_string(positions.size) +
                                              " float64 positions");
  }
  for (std::size_t k = 0; k < 3 * positions.size; ++k) {
    const double v = positions.xyz[k];
    if (!std::isfinite(v) || std::fabs(v) > std::numeric_limits<float>::max())
      throw Error(
          ErrorCode::invalid_input,
          std::string(std::isfinite(v) ? "coordinate beyond the float range (|x| <= " +
                                             std::to_string(std::numeric_limits<float>::max()) + ")"
                                       : "non-finite coordinate") +
              " at particle index " + std::to_string(k / 3) + ": " + std::to_string(v));
    rounded[k] = static_cast<float>(v);
  }
  const PositionsView view{rounded.data(), positions.size, MemorySpace::host};
  // A method without the points path (OptiX, grid-paper) searches the rounded positions.
  if (systems.plain() && !impl("build").points_unsupported().empty()) {
    build(view, cutoff);
  } else {
    build_points(view, cutoff, systems, positions.xyz);
  }
  float64_ = true;
}

void Engine::update(Float64Positions positions) {
  require_updatable(positions.size);
  if (!float64_)
    throw Error(ErrorCode::invalid_argument,
                "Engine::update() with float64 positions after a float32 build: build() again");
  const Systems systems = systems_;
  build(positions, cutoff_, systems);
}

void Engine::build_points(PositionsView positions, float cutoff, const Systems& systems,
                          const double* float64) {
  detail::Method& m = impl("build");
  float64_ = false;
  detail::validate_cutoff(cutoff);
  // Device sources of a device method: the device expansion's first pass checks their values
  // (src/cuda/images.cu), one kernel and one read-back less per build.
  validate_positions(positions, stream_,
                     !(positions.space == MemorySpace::device && m.space() == MemorySpace::device));
  if (systems.has_queries()) {
    if (systems.queries.space != positions.space)
      throw Error(ErrorCode::invalid_argument,
                  "query points and sources must be in the same memory space (host or device)");
    validate_positions(systems.queries, stream_, true, "query point");
  }
  if (const std::string why = m.points_unsupported(); !why.empty())
    throw Error(ErrorCode::unsupported, "method '" + method_ +
                                            "' does not take periodic boxes, batches or query "
                                            "points: " +
                                            why);
  require_build_memory(m, method_,
                       positions.size + (systems.has_queries() ? systems.queries.size : 0));
  // A step loop builds the same systems again: their plan (validation, frames) is kept.
  bool same_plan = true;
  if (!plan_ || plan_queries_ != systems.has_queries() || !same_layout(systems, plan_key_) ||
      positions.size != plan_sources_ || cutoff != plan_cutoff_) {
    same_plan = false;
    plan_.reset();
    plan_ = std::make_shared<const detail::ImagePlan>(
        detail::plan_images(systems, positions.size, cutoff));
    plan_key_ = systems;
    plan_key_.queries.xyz = nullptr;  // not kept beyond build(); same_layout reads the size
    plan_queries_ = systems.has_queries();
    plan_sources_ = positions.size;
    plan_cutoff_ = cutoff;
  }
  const detail::ImagePlan& plan = *plan_;
  built_ = false;
  has_run_ = false;
  size_ = plan.target_count();
  sources_ = positions.size;
  cutoff_ = cutoff;
  systems_ = systems;
  systems_.queries = {};  // the pointer is not kept beyond build()
  queries_ = systems.has_queries();
  timings_ = {};
  if (size_ == 0) {  // no targets: every query answers "no pairs"
    built_ = true;
    return;
  }
  const auto start = Clock::now();
  with_positions_in_method_space(positions, [&](const float* sources) {
    with_positions_in_method_space(systems.queries, [&](const float* queries) {
      if (!images_ || images_->space() != m.space()) {
        images_.reset();
        if (m.space() == MemorySpace::host) {
          images_ = detail::make_host_image_points();
        } else {
          // A method on the device exists only where the CUDA backend is built.
          images_ = detail::device_services()->make_image_points();
        }
      }
      images_->set_float64_sources(float64);
      // Engine::set_reuse_plan: device positions of a method that can, float32.
      const bool may_reuse = reuse_plan_ && m.reuses_plans() && float64 == nullptr &&
                             positions.space == MemorySpace::device;
      reused_ = may_reuse && same_plan && images_->recorded() &&
                !images_->reused_plan_outgrown(stream_, /*wait=*/false);
      if (reused_) {
        images_->expand_reusing(plan, sources, queries, stream_);
        m.build_points(images_->points(), cutoff);
        images_->finish_reusing(stream_);
        reused_positions_ = positions;
        reused_queries_ = systems.queries;
      } else {
        images_->set_recording(may_reuse);  // forgets the last recorded plan
        images_->expand(plan, sources, queries, stream_);
        m.build_points(images_->points(), cutoff);
        detail::ParkingPlace parking;
        if (may_reuse && m.parking(parking)) images_->set_parking(parking);
      }
      // Within the positions' scope: a device copy of host positions is alive until it ends.
      end_build(m, timed_, start, timings_);
    });
  });
  built_ = true;
}

bool Engine::reuses_plan_for(PositionsView positions, float cutoff, const Systems& systems) const {
  if (!reuse_plan_ || !impl_ || !impl_->reuses_plans() || positions.space != MemorySpace::device ||
      !plan_ || !images_ || !images_->recorded())
    return false;
  return plan_queries_ == systems.has_queries() && same_layout(systems, plan_key_) &&
         positions.size == plan_sources_ && cutoff == plan_cutoff_;
}

void Engine::settle_reused_plan() {
  if (!reused_) return;
  reused_ = false;
  if (!images_->reused_plan_outgrown(stream_, /*wait=*/true)) return;  // else forgotten
  Systems systems = systems_;
  systems.queries = reused_queries_;
  build_points(reused_positions_, cutoff_, systems, nullptr);
}

void Engine::update(PositionsView positions) {
  update(positions, false);
}

void Engine::require_updatable(std::size_t n) const {
  if (!built_) throw Error(ErrorCode::invalid_argument, "Engine::update() called before build()");
  if (n != sources_)
    throw Error(ErrorCode::invalid_argument, "Engine::update() needs the " +
                                                 std::to_string(sources_) +
                                                 " particles of build(), got " + std::to_string(n));
  // Query points are not kept beyond build(): there is nothing to rebuild them from. Checked
  // before the systems: systems_ has dropped them, so an open build with queries looks plain.
  if (queries_)
    throw Error(ErrorCode::unsupported,
                "Engine::update() with query points: call build() with the new positions");
}

void Engine::update(PositionsView positions, bool checked) {
  detail::Method& m = impl("update");
  require_updatable(positions.size);
  float64_ = false;  // float32 positions from here on
  if (!systems_.plain()) {
    const Systems systems = systems_;
    build(positions, cutoff_, systems);
    return;
  }
  validate_positions(positions, stream_, !checked);
  has_run_ = false;
  timings_ = {};
  if (size_ == 0) return;
  built_ = false;  // until the method has its new structure
  with_positions_in_method_space(positions, [&](const float* xyz) {
    const auto start = Clock::now();
    timings_.refit = m.update(xyz, size_, cutoff_);
    end_build(m, timed_, start, timings_);
  });
  built_ = true;
}

void Engine::set_update_policy(const UpdatePolicy& policy) {
  detail::Method& m = impl("set_update_policy");
  if (!(policy.skin >= 0) || !std::isfinite(policy.skin))
    throw Error(ErrorCode::invalid_argument,
                "update skin must be finite and >= 0, got " + std::to_string(policy.skin));
  m.set_update_policy(policy);
}

template <class F>
void Engine::with_positions_in_method_space(const PositionsView& positions, F&& f) {
  // Move the positions to where the method works (not part of the timed phases).
  const float* xyz = positions.xyz;
  std::vector<float> host_copy;
  detail::DeviceBytes device_copy;
  if (positions.space != impl_->space() && positions.size > 0) {
    const std::size_t bytes = 3 * positions.size * sizeof(float);
    const detail::DeviceServices* device = detail::device_services();
    if (!device) throw Error(ErrorCode::unsupported, "raycut was built without CUDA");
    if (impl_->space() == MemorySpace::host) {
      host_copy.resize(3 * positions.size);
      device->download(host_copy.data(), xyz, bytes);
      xyz = host_copy.data();
    } else {
      device_copy = device->upload(xyz, bytes);
      xyz = static_cast<const float*>(device_copy.get());
    }
  }
  f(xyz);
}

void Engine::run(Kernel kernel, const KernelOptions& options) {
  detail::Method& m = impl("run");
  if (!built_) throw Error(ErrorCode::invalid_argument, "Engine::run() called before build()");
  has_run_ = false;  // a run that throws leaves no results behind
  validate_kernel_range(kernel, options, cutoff_);
  validate_kernel_inputs(kernel, options, queries_);
  if (size_ > 0) {
    settle_reused_plan();
    const auto start = Clock::now();
    m.compute(kernel, options);
    m.synchronize();  // run() is always timed: results() reads what it wrote
    timings_.compute_ms = elapsed_ms(start);
    timings_.device_compute_ms = m.device_compute_ms();
  }
  has_run_ = true;
}

Results Engine::results() const {
  const detail::Method& m = impl("results");
  if (!has_run_)
    throw Error(ErrorCode::invalid_argument, "Engine::results() called before a successful run()");
  if (size_ > 0) return m.results();
  Results empty;  // N = 0: the kernel's vectors, empty
  return empty;
}

ResultsView Engine::results_view() const {
  const detail::Method& m = impl("results_view");
  if (!has_run_)
    throw Error(ErrorCode::invalid_argument,
                "Engine::results_view() called before a successful run()");
  if (size_ == 0) return ResultsView{nullptr, nullptr, nullptr, nullptr, nullptr, m.space()};
  return m.results_view();
}

OwnedResults Engine::take_results() {
  detail::Method& m = impl("take_results");
  if (!has_run_)
    throw Error(ErrorCode::invalid_argument,
                "Engine::take_results() called before a successful run()");
  has_run_ = false;  // the results leave the engine
  if (size_ == 0) return {ResultsView{nullptr, nullptr, nullptr, nullptr, nullptr, m.space()}, {}};
  return m.take_results();
}

Results Engine::compute(Kernel kernel, const KernelOptions& options) {
  run(kernel, options);
  return results();
}

void Engine::neighbours(NeighbourListBuffer& list, const ListOptions& options) {
  detail::Method& m = impl("neighbours");
  if (!built_)
    throw Error(ErrorCode::invalid_argument, "Engine::neighbours() called before build()");
  if (!list.storage_ || list.storage_->space() != m.space()) list.storage_ = m.make_list_storage();
  check_list_options(options);
  if (size_ == 0) {
    list.storage_->set_empty(options);
    return;
  }
  settle_reused_plan();
  m.neighbours(*list.storage_, options);
  m.synchronize();
}

void Engine::check_list_options(const ListOptions& options) const {
  if (options.half && queries_) throw half_with_queries();
  if (options.cutoffs && options.cutoffs->active()) {
    if (queries_)
      throw Error(ErrorCode::invalid_argument,
                  "per-pair cutoffs: not with query points (they pair particles with each other)");
    detail::validate_pair_cutoffs(*options.cutoffs, size_, cutoff_);
  }
}

void Engine::neighbours(const StaticPairs& out, const ListOptions& options) {
  detail::Method& m = impl("neighbours");
  if (!built_)
    throw Error(ErrorCode::invalid_argument, "Engine::neighbours() called before build()");
  if (options.distances || options.vectors || options.coo)
    throw Error(ErrorCode::invalid_argument,
                "a static-capacity list holds i, j and S as COO entries: distances, vectors and "
                "coo are not options of it (compute D = x_j - x_i + S . cell from them)");
  if (!out.count || (out.capacity > 0 && (!out.i || !out.j)))
    throw Error(ErrorCode::invalid_argument,
                "a static-capacity list needs its count, and its i and j arrays unless the "
                "capacity is 0 (null given)");
  check_list_options(options);
  m.static_neighbours(out, options, size_);
}

NeighbourList Engine::neighbours(const ListOptions& options) {
  NeighbourListBuffer list;
  neighbours(list, options);
  return list.to_host();
}

PaddedReport Engine::padded_neighbours(PaddedNeighbourBuffer& list, const PaddedOptions& options) {
  detail::Method& m = impl("padded_neighbours");
  if (!built_)
    throw Error(ErrorCode::invalid_argument, "Engine::padded_neighbours() called before build()");
  const std::uint32_t k = options.k;
  const bool shifts = options.shifts;
  if (options.half && queries_) throw half_with_queries();
  if (options.nearest && m.space() != MemorySpace::host)
    throw Error(ErrorCode::unsupported,
                "padded neighbour list: the K nearest (PaddedOptions::nearest) run on the CPU "
                "methods, not on '" +
                    method_ + "'");
  if (!list.storage_ || list.storage_->space() != m.space())
    list.storage_ = m.make_padded_storage();
  if (k == 0 && size_ > 0)
    throw Error(ErrorCode::invalid_argument, "padded neighbour list: K must be >= 1");
  if (size_ == 0) {
    list.storage_->n = 0;
    list.storage_->k = k;
    list.storage_->shifts = nullptr;
    list.storage_->report = {};
    return {};
  }
  list.storage_->padding = static_cast<std::uint32_t>(sources_);
  // No row holds more entries than there are candidate points (each source once per image):
  // a K above that only adds padding. A matrix that does not fit is refused before it is
  // allocated, the message saying which K is enough.
  const std::uint64_t candidates =
      images_ ? images_->points().size - (queries_ ? images_->points().targets : 0) : sources_;
  const double bytes =
      4.0 * static_cast<double>(size_) * ((shifts ? 4.0 : 1.0) * static_cast<double>(k) + 1);
  const std::string what = "the padded neighbour list [N = " + std::to_string(size_) +
                           ", K = " + std::to_string(k) + "]" + (shifts ? " with shifts" : "");
  const std::string bound =
      "; no row can hold more than " + std::to_string(candidates) + " neighbours here (" +
      std::to_string(sources_) + " particles" + (images_ ? " and their images" : "") +
      "), so K = " + std::to_string(std::max<std::uint64_t>(candidates, 1)) + " is always enough";
  settle_reused_plan();
  try {
    if (m.space() == MemorySpace::host) require_host_memory(bytes, what);
    if (options.nearest)
      m.padded_nearest(*list.storage_, k, options.half, shifts);
    else
      m.padded_neighbours(*list.storage_, k, options.half, shifts);
  } catch (const Error& e) {
    if (e.code() != ErrorCode::out_of_memory || k <= candidates) throw;
    throw Error(ErrorCode::out_of_memory, e.what() + bound);
  }
  m.synchronize();
  detail::report_padded(*list.storage_, options.throw_on_overflow);
  return list.storage_->report;
}

detail::PairPass Engine::pair_pass() const {
  const detail::Method& m = impl("pair_pass");
  if (!built_)
    throw Error(ErrorCode::invalid_argument, "for_each_pair() called before Engine::build()");
  if (size_ == 0) return {};
  // A functor's pass waits for the check of a reused plan (it may build again: pair_pass() is
  // const to its callers, the rebuild is not a change they see).
  const_cast<Engine*>(this)->settle_reused_plan();
  detail::PairPass pass = m.pair_pass();
  if (pass.kind == detail::PassKind::none)
    throw Error(ErrorCode::unsupported,
                "method '" + method_ +
                    "' runs only its built-in kernels (OptiX programs are compiled ahead): use "
                    "grid, grid-paper, brute-force-gpu or a CPU method for your functor");
  pass.method = method_.c_str();
  return pass;
}

detail::PairPass detail::PairPassAccess::of(const Engine& engine) {
  return engine.pair_pass();
}

// ---- list buffers ------------------------------------------------------------------------------

NeighbourListBuffer::NeighbourListBuffer() = default;
NeighbourListBuffer::~NeighbourListBuffer() = default;
NeighbourListBuffer::NeighbourListBuffer(NeighbourListBuffer&&) noexcept = default;
NeighbourListBuffer& NeighbourListBuffer::operator=(NeighbourListBuffer&&) noexcept = default;

namespace {
const detail::ListStorage& filled(const std::unique_ptr<detail::ListStorage>& s) {
  if (!s)
    throw Error(ErrorCode::invalid_argument,
                "NeighbourListBuffer read before Engine::neighbours() filled it");
  return *s;
}
const detail::PaddedStorage& filled(const std::unique_ptr<detail::PaddedStorage>& s) {
  if (!s)
    throw Error(ErrorCode::invalid_argument,
                "PaddedNeighbourBuffer read before Engine::padded_neighbours() filled it");
  return *s;
}
}  // namespace

std::size_t NeighbourListBuffer::size() const {
  return filled(storage_).n;
}
std::uint64_t NeighbourListBuffer::pairs() const {
  return filled(storage_).pairs;
}
const std::uint64_t* NeighbourListBuffer::offsets() const {
  return filled(storage_).offsets;
}
const std::uint32_t* NeighbourListBuffer::indices() const {
  return filled(storage_).indices;
}
const std::int64_t* NeighbourListBuffer::rows() const {
  return filled(storage_).rows;
}
const std::int64_t* NeighbourListBuffer::columns() const {
  return filled(storage_).columns;
}
const float* NeighbourListBuffer::distances() const {
  return filled(storage_).distances;
}
const float* NeighbourListBuffer::vectors() const {
  return filled(storage_).vectors;
}
const std::int32_t* NeighbourListBuffer::shifts() const {
  return filled(storage_).shifts;
}
MemorySpace NeighbourListBuffer::space() const {
  return filled(storage_).space();
}
const ListOptions& NeighbourListBuffer::options() const {
  return filled(storage_).options;
}
std::size_t NeighbourListBuffer::bytes() const {
  return storage_ ? storage_->bytes() : 0;
}
NeighbourList NeighbourListBuffer::to_host() const {
  return filled(storage_).to_host();
}

PaddedNeighbourBuffer::PaddedNeighbourBuffer() = default;
PaddedNeighbourBuffer::~PaddedNeighbourBuffer() = default;
PaddedNeighbourBuffer::PaddedNeighbourBuffer(PaddedNeighbourBuffer&&) noexcept = default;
PaddedNeighbourBuffer& PaddedNeighbourBuffer::operator=(PaddedNeighbourBuffer&&) noexcept = default;

std::size_t PaddedNeighbourBuffer::size() const {
  return filled(storage_).n;
}
std::uint32_t PaddedNeighbourBuffer::width() const {
  return filled(storage_).k;
}
const std::uint32_t* PaddedNeighbourBuffer::indices() const {
  return filled(storage_).indices;
}
const std::uint32_t* PaddedNeighbourBuffer::counts() const {
  return filled(storage_).counts;
}
MemorySpace PaddedNeighbourBuffer::space() const {
  return filled(storage_).space();
}
const PaddedReport& PaddedNeighbourBuffer::report() const {
  return filled(storage_).report;
}
std::vector<std::uint32_t> PaddedNeighbourBuffer::indices_to_host() const {
  return filled(storage_).n ? filled(storage_).indices_to_host() : std::vector<std::uint32_t>{};
}
const std::int32_t* PaddedNeighbourBuffer::shifts() const {
  return filled(storage_).shifts;
}
std::vector<std::int32_t> PaddedNeighbourBuffer::shifts_to_host() const {
  return filled(storage_).n ? filled(storage_).shifts_to_host() : std::vector<std::int32_t>{};
}
std::vector<std::uint32_t> PaddedNeighbourBuffer::counts_to_host() const {
  return filled(storage_).n ? filled(storage_).counts_to_host() : std::vector<std::uint32_t>{};
}

// ---- Verlet list -------------------------------------------------------------------------------

namespace {

// Positions at the last build, in the caller's memory space.
struct KeptPositions {
  PositionsView view;
  std::vector<float> host;
  detail::DeviceBytes device;
};

std::shared_ptr<void> keep_positions(const PositionsView& p, void* stream) {
  auto kept = std::make_shared<KeptPositions>();
  kept->view = p;
  if (p.space == MemorySpace::host) {
    kept->host.assign(p.xyz, p.xyz + 3 * p.size);
    kept->view.xyz = kept->host.data();
  } else if (const detail::DeviceServices* device = detail::device_services()) {
    kept->device = device->copy_on_device(p.xyz, 3 * p.size * sizeof(float), stream);
    kept->view.xyz = static_cast<const float*>(kept->device.get());
  }
  return kept;
}

// True when some particle of `now` is more than `distance` from where `then` has it, or has a
// non-finite coordinate: on the device for device positions (a reduction, one flag read back),
// on the host otherwise.
bool moved_beyond(const PositionsView& now, const KeptPositions& then, float distance,
                  void* stream) {
  const double limit = static_cast<double>(distance) * distance;
  if (now.space == MemorySpace::host && then.view.space == MemorySpace::host) {
    for (std::size_t k = 0; k < now.size; ++k) {
      double d2 = 0;
      for (int a = 0; a < 3; ++a) {
        const double d = static_cast<double>(now.xyz[3 * k + a]) - then.view.xyz[3 * k + a];
        d2 += d * d;
      }
      if (!(d2 <= limit)) return true;  // NaN too: the rebuild reports it
    }
    return false;
  }
  const detail::DeviceServices* device = detail::device_services();
  if (device && now.space == MemorySpace::device && then.view.space == MemorySpace::device)
    return device->moved_beyond(now.xyz, then.view.xyz, now.size, distance, stream);
  return true;  // the caller moved its positions to another memory space: rebuild
}

}  // namespace

VerletList::VerletList(std::string_view method, float cutoff, float skin,
                       const ListOptions& options, const Systems& systems)
    : engine_(method), cutoff_(cutoff), skin_(skin), options_(options), systems_(systems) {
  if (systems.has_queries())
    throw Error(ErrorCode::invalid_argument, "VerletList: query points are not supported");
  detail::validate_cutoff(cutoff);
  if (!(skin >= 0) || !std::isfinite(skin))
    throw Error(ErrorCode::invalid_argument,
                "Verlet skin must be finite and >= 0, got " + std::to_string(skin));
  detail::validate_cutoff(cutoff + skin);
}

bool VerletList::update(PositionsView positions) {
  const bool first = !built_;
  if (!first) {
    if (positions.size != engine_.sources())
      throw Error(ErrorCode::invalid_argument,
                  "VerletList::update() needs the " + std::to_string(engine_.sources()) +
                      " particles of its first call, got " + std::to_string(positions.size));
    // Values unchecked here: a non-finite coordinate fails the distance test, and the rebuild
    // that follows names it. On the device that is one kernel and one wait a step, not two.
    validate_positions(positions, engine_.stream(), /*values=*/false);
    if (!moved_beyond(positions, *static_cast<const KeptPositions*>(built_.get()),
                      0.5f * skin_ * (1.0f - 1e-5f), engine_.stream()))
      return false;
  }
  engine_.build(positions, cutoff_ + skin_, systems_);
  engine_.neighbours(list_, options_);
  built_ = keep_positions(positions, engine_.stream());
  ++rebuilds_;
  return true;
}

}  // namespace raycut
