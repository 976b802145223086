#include "raycut/engine.hpp"

#include <chrono>
#include <cmath>
#include <vector>

#include "core/method.hpp"
#include "core/validation.hpp"
#if defined(RAYCUT_HAVE_CUDA)
#include "cuda/runtime.hpp"
#endif

namespace raycut {
namespace {

using Clock = std::chrono::steady_clock;

double elapsed_ms(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
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

// Checks coordinates where they live, before any work on them; throws naming the first bad one.
void validate_positions(const PositionsView& positions) {
  if (positions.size > 0 && positions.xyz == nullptr)
    throw Error(ErrorCode::invalid_argument, "positions pointer is null for N = " +
                                                 std::to_string(positions.size) + " particles");
  if (positions.space == MemorySpace::host) {
    const std::size_t bad = detail::first_non_finite_host(positions.xyz, positions.size);
    if (bad < positions.size) detail::throw_non_finite(bad, positions.xyz + 3 * bad);
    return;
  }
#if defined(RAYCUT_HAVE_CUDA)
  const std::size_t bad = detail::cuda::first_non_finite(positions.xyz, positions.size);
  if (bad < positions.size) {
    float xyz[3];
    detail::cuda::download(xyz, positions.xyz + 3 * bad, sizeof xyz);
    detail::throw_non_finite(bad, xyz);
  }
#else
  throw Error(ErrorCode::unsupported,
              "positions are in device memory but raycut was built without CUDA");
#endif
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
#if defined(RAYCUT_HAVE_CUDA)
  return detail::cuda::device_available();
#else
  return false;
#endif
}

std::string auto_method() {
  // Fastest available first: the measured order of bench/results (docs/benchmarks.md).
  for (const char* name : {"grid", "cell-list"}) {
    for (const auto& entry : detail::method_registry())
      if (entry.name == name && entry.why_unavailable().empty()) return name;
  }
  return "brute-force";
}

Engine::Engine(std::string_view method) {
  method_ = method == "auto" ? auto_method() : std::string(method);
  const auto& entry = find_entry(method_);
  if (std::string why = entry.why_unavailable(); !why.empty())
    throw Error(ErrorCode::unsupported, "method '" + method_ + "' is not available: " + why);
  impl_ = entry.make();
}

Engine::~Engine() = default;
MemorySpace Engine::space() const {
  return impl_->space();
}
Engine::Engine(Engine&&) noexcept = default;
Engine& Engine::operator=(Engine&&) noexcept = default;

void Engine::build(PositionsView positions, float cutoff) {
  detail::validate_cutoff(cutoff);
  validate_positions(positions);
  built_ = false;
  has_run_ = false;
  size_ = positions.size;
  cutoff_ = cutoff;
  timings_ = {};
  if (size_ == 0) {  // nothing to build; every query answers "no pairs"
    built_ = true;
    return;
  }

  with_positions_in_method_space(positions, [&](const float* xyz) {
    const auto start = Clock::now();
    impl_->build(xyz, size_, cutoff);
    impl_->synchronize();
    timings_.build_ms = elapsed_ms(start);
    timings_.device_build_ms = impl_->device_build_ms();
  });
  built_ = true;
}

void Engine::update(PositionsView positions) {
  if (!built_) throw Error(ErrorCode::invalid_argument, "Engine::update() called before build()");
  if (positions.size != size_)
    throw Error(ErrorCode::invalid_argument, "Engine::update() needs the " + std::to_string(size_) +
                                                 " particles of build(), got " +
                                                 std::to_string(positions.size));
  validate_positions(positions);
  has_run_ = false;
  timings_ = {};
  if (size_ == 0) return;
  with_positions_in_method_space(positions, [&](const float* xyz) {
    const auto start = Clock::now();
    timings_.refit = impl_->update(xyz, size_, cutoff_);
    impl_->synchronize();
    timings_.build_ms = elapsed_ms(start);
    timings_.device_build_ms = impl_->device_build_ms();
  });
}

void Engine::set_update_policy(const UpdatePolicy& policy) {
  if (!(policy.skin >= 0) || !std::isfinite(policy.skin))
    throw Error(ErrorCode::invalid_argument,
                "update skin must be finite and >= 0, got " + std::to_string(policy.skin));
  impl_->set_update_policy(policy);
}

template <class F>
void Engine::with_positions_in_method_space(const PositionsView& positions, F&& f) {
  // Move the positions to where the method works (not part of the timed phases).
  const float* xyz = positions.xyz;
  std::vector<float> host_copy;
#if defined(RAYCUT_HAVE_CUDA)
  detail::cuda::DeviceMemory device_copy;
#endif
  if (positions.space != impl_->space()) {
    const std::size_t bytes = 3 * size_ * sizeof(float);
#if defined(RAYCUT_HAVE_CUDA)
    if (impl_->space() == MemorySpace::host) {
      host_copy.resize(3 * size_);
      detail::cuda::download(host_copy.data(), xyz, bytes);
      xyz = host_copy.data();
    } else {
      device_copy = detail::cuda::upload(xyz, bytes);
      xyz = static_cast<const float*>(device_copy.get());
    }
#else
    (void)bytes;
    throw Error(ErrorCode::unsupported, "raycut was built without CUDA");
#endif
  }
  f(xyz);
}

void Engine::run(Kernel kernel, const KernelOptions& options) {
  if (!built_) throw Error(ErrorCode::invalid_argument, "Engine::run() called before build()");
  last_kernel_ = kernel;
  has_run_ = true;
  if (size_ == 0) return;
  const auto start = Clock::now();
  impl_->compute(kernel, options);
  impl_->synchronize();
  timings_.compute_ms = elapsed_ms(start);
  timings_.device_compute_ms = impl_->device_compute_ms();
}

Results Engine::results() const {
  if (!has_run_) throw Error(ErrorCode::invalid_argument, "Engine::results() called before run()");
  if (size_ > 0) return impl_->results();
  Results empty;  // N = 0: the right (empty) vectors, none missing
  return empty;
}

ResultsView Engine::results_view() const {
  if (!has_run_)
    throw Error(ErrorCode::invalid_argument, "Engine::results_view() called before run()");
  if (size_ == 0) return ResultsView{nullptr, nullptr, nullptr, impl_->space()};
  return impl_->results_view();
}

Results Engine::compute(Kernel kernel, const KernelOptions& options) {
  run(kernel, options);
  return results();
}

NeighbourList Engine::neighbours() {
  if (!built_)
    throw Error(ErrorCode::invalid_argument, "Engine::neighbours() called before build()");
  if (size_ == 0) return NeighbourList{{0}, {}};
  return impl_->neighbours();
}

}  // namespace raycut
