// A caller's own pair functor through raycut::cuda::for_each_pair on every GPU method: functors
// with the built-in Lennard-Jones math give Engine::compute's results bit for bit (the same
// traversal in the same order); a functor without combine() runs where the grid would share a
// target between lanes, with the same answer; N = 0 and 1; the OptiX methods refuse; a functor
// that reads j and S in a periodic box gets every triple of the double-precision oracle, on
// whichever streams its passes run, after a build and a rebuild (the grid gathers its images on
// the first pass that reads them). Methods not available here (no GPU, no OptiX) are skipped
// with the reason.
#include <cuda_runtime.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <memory>
#include <numeric>
#include <random>
#include <string>
#include <vector>

#include "periodic_oracle.hpp"
#include "raycut/cuda/pairs.cuh"
#include "raycut/engine.hpp"
#include "raycut/tools/device_array.hpp"
#include "raycut/tools/generators.hpp"
#include "user_functors.hpp"

namespace raycut {
// Parameters print as the method's name (else as raw bytes).
inline void PrintTo(const MethodDescription& m, std::ostream* os) {
  *os << m.name;
}
}  // namespace raycut

namespace {

using raycut::Engine;
using raycut::Kernel;
using raycut::MemorySpace;

#define CHECK_CUDA(call) ASSERT_EQ((call), cudaSuccess) << #call

// n values of T in device memory.
template <class T>
struct DeviceBuffer {
  T* p = nullptr;
  std::size_t n = 0;
  explicit DeviceBuffer(std::size_t count) : n(count) {
    if (n && cudaMalloc(&p, n * sizeof(T)) != cudaSuccess) p = nullptr;
    if (p) cudaMemset(p, 0xff, n * sizeof(T));  // not what any kernel writes
  }
  DeviceBuffer(const DeviceBuffer&) = delete;
  ~DeviceBuffer() { cudaFree(p); }
  std::vector<T> to_host() const {
    std::vector<T> out(n);
    if (n) cudaMemcpy(out.data(), p, n * sizeof(T), cudaMemcpyDeviceToHost);
    return out;
  }
};

template <class T>
bool same_bits(const std::vector<T>& a, const std::vector<T>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(T)) == 0;
}

template <class T>
std::string first_difference(const std::vector<T>& a, const std::vector<T>& b) {
  if (a.size() != b.size())
    return "sizes " + std::to_string(a.size()) + " and " + std::to_string(b.size());
  for (std::size_t k = 0; k < a.size(); ++k)
    if (std::memcmp(&a[k], &b[k], sizeof(T)) != 0)
      return "index " + std::to_string(k) + ": " + std::to_string(a[k]) + " vs " +
             std::to_string(b[k]);
  return "none";
}

// sum_j |4 eps ((sigma/r)^12 - (sigma/r)^6)|: the scale of the round-off of a Lennard-Jones sum.
struct LjMagnitude : user::LjNoCombine {
  RAYCUT_HD void operator()(float& acc, std::uint32_t, std::uint32_t, raycut::Vec3,
                            float r2) const {
    const float t = 1.0f / r2, w = t * t * t;
    acc += fabsf(w * (sigma6 * w - 1.0f));
  }
  RAYCUT_HD void finish(std::uint32_t i, float& acc) const {
    energy[i] = acc * fabsf(four_epsilon_sigma6);
  }
};

bool is_optix(const std::string& name) {
  return name.rfind("optix", 0) == 0;
}

// Every method that is not a CPU one, available here or not.
std::vector<raycut::MethodDescription> gpu_methods() {
  std::vector<raycut::MethodDescription> out;
  for (const auto& m : raycut::list_methods())
    if (m.name != "brute-force" && m.name != "cell-list") out.push_back(m);
  return out;
}

class GpuFunctors : public ::testing::TestWithParam<raycut::MethodDescription> {
 protected:
  void SetUp() override {
    if (!GetParam().available)
      GTEST_SKIP() << GetParam().name << " not available here: " << GetParam().why_unavailable;
  }
  const std::string& method() const { return GetParam().name; }
};

const char* const families[] = {
    "uniform",         "sphere-surface", "lattice-k2",       "lattice-shifted-k3",
    "near-coincident", "axis-aligned",   "gaussian-outlier", "offset-1e3"};

// Calls body(engine, options) for every family and size, the engine built on device positions.
template <class Body>
void for_each_case(const std::string& method, std::initializer_list<std::size_t> sizes,
                   Body&& body) {
  raycut::KernelOptions options;
  options.lj_epsilon = 1.5f;
  options.lj_sigma = 0.35f;
  for (const char* family : families)
    for (std::size_t n : sizes) {
      const float cutoff = 0.5f;
      const raycut::PointCloud cloud = raycut::make_family(family, n, cutoff, 7 + n);
      SCOPED_TRACE(method + " " + family + " n=" + std::to_string(cloud.size()));
      Engine engine(method);
      if (cloud.size() == 0) {
        engine.build({nullptr, 0, MemorySpace::host}, cutoff);
      } else {
        const raycut::DeviceArray xyz(cloud.xyz);
        try {
          engine.build(xyz.view(), cutoff);
        } catch (const raycut::Error& e) {
          // The paper's dense grid cannot hold a box 1e3 cutoffs wide and x 0.5 C cells: its
          // clear out-of-memory refusal is its correct answer (as in the conformance suite).
          if (method == "grid-paper" && e.code() == raycut::ErrorCode::out_of_memory) continue;
          throw;
        }
      }
      body(engine, options);
    }
}

TEST_P(GpuFunctors, UserLennardJonesEqualsBuiltInBitForBit) {
  if (is_optix(method())) GTEST_SKIP() << "OptiX methods refuse functors (OptixRefuses)";
  for_each_case(method(), {2, 257, 3000, 40000}, [&](Engine& engine, const auto& options) {
    const raycut::Results want = engine.compute(Kernel::lj, options);
    DeviceBuffer<float> energy(engine.size());
    raycut::cuda::for_each_pair(engine, user::Lj{user::lj_parameters(options, energy.p)});
    CHECK_CUDA(cudaDeviceSynchronize());
    const std::vector<float> got = energy.to_host();
    EXPECT_TRUE(same_bits(got, want.energy)) << first_difference(got, want.energy);
  });
}

TEST_P(GpuFunctors, UserLennardJonesForcesEqualBuiltInBitForBit) {
  if (is_optix(method())) GTEST_SKIP() << "OptiX methods refuse functors (OptixRefuses)";
  for_each_case(method(), {2, 257, 3000, 40000}, [&](Engine& engine, const auto& options) {
    const raycut::Results want = engine.compute(Kernel::lj_forces, options);
    const std::size_t n = engine.size();
    DeviceBuffer<float> energy(n), force(3 * n), virial(6 * n);
    raycut::cuda::for_each_pair(
        engine, user::LjForces{options.lj_sigma * options.lj_sigma, 4.0f * options.lj_epsilon,
                               energy.p, force.p, virial.p});
    CHECK_CUDA(cudaDeviceSynchronize());
    const auto e = energy.to_host(), f = force.to_host(), v = virial.to_host();
    EXPECT_TRUE(same_bits(e, want.energy)) << first_difference(e, want.energy);
    EXPECT_TRUE(same_bits(f, want.force)) << first_difference(f, want.force);
    EXPECT_TRUE(same_bits(v, want.virial)) << first_difference(v, want.virial);
  });
}

// Small inputs, where the grid lets several lanes share a target (GridKernel::lanes*): a functor
// without combine() falls back to a thread per target and gives the same answer. Counts are exact
// whatever the order; Lennard-Jones sums agree to round-off.
TEST_P(GpuFunctors, WithoutCombineSameAnswerAtSmallN) {
  if (is_optix(method())) GTEST_SKIP() << "OptiX methods refuse functors (OptixRefuses)";
  bool lanes_seen = false;
  for_each_case(method(), {2, 100, 1000}, [&](Engine& engine, const auto& options) {
    const std::size_t n = engine.size();
    if (method() == "grid" && n > 0) {
      const raycut::detail::GridKernel k = raycut::detail::PairPassAccess::of(engine).grid.kernel;
      lanes_seen |= k != raycut::detail::GridKernel::thread &&
                    k != raycut::detail::GridKernel::thread_many_registers;
    }
    const raycut::Results count = engine.compute(Kernel::count);
    const raycut::Results lj = engine.compute(Kernel::lj, options);
    DeviceBuffer<std::uint32_t> c1(n), c2(n);
    DeviceBuffer<float> e1(n), e2(n);
    raycut::cuda::for_each_pair(engine, user::CountFromInit{1000, c1.p});
    raycut::cuda::for_each_pair(engine, user::CountFromInitCombine{{1000, c2.p}});
    raycut::cuda::for_each_pair(engine, user::lj_parameters(options, e1.p));
    raycut::cuda::for_each_pair(engine, user::Lj{user::lj_parameters(options, e2.p)});
    DeviceBuffer<float> scale(n);
    raycut::cuda::for_each_pair(engine, LjMagnitude{user::lj_parameters(options, scale.p)});
    CHECK_CUDA(cudaDeviceSynchronize());
    const auto got1 = c1.to_host(), got2 = c2.to_host();
    const auto lj1 = e1.to_host(), lj2 = e2.to_host(), lj_scale = scale.to_host();
    EXPECT_TRUE(same_bits(lj2, lj.energy)) << first_difference(lj2, lj.energy);
    for (std::size_t i = 0; i < n; ++i) {
      ASSERT_EQ(got1[i], count.count[i] + 1000 + i % 5) << "without combine, target " << i;
      ASSERT_EQ(got2[i], count.count[i] + 1000 + i % 5) << "with combine, target " << i;
      if (std::isfinite(lj_scale[i]))
        ASSERT_NEAR(lj1[i], lj.energy[i], 1e-5 * lj_scale[i]) << "target " << i;
    }
  });
  if (method() == "grid")
    EXPECT_TRUE(lanes_seen) << "the grid shared no target between lanes at these sizes: the "
                               "test no longer covers what it is for";
}

TEST_P(GpuFunctors, EmptyAndSingleParticle) {
  if (is_optix(method())) GTEST_SKIP() << "OptiX methods refuse functors (OptixRefuses)";
  Engine empty(method());
  empty.build({nullptr, 0, MemorySpace::host}, 1.0f);
  raycut::cuda::for_each_pair(empty, user::Lj{user::lj_parameters({}, nullptr)});  // nothing runs

  const float xyz[3] = {0.25f, -1.0f, 3.0f};
  Engine one(method());
  one.build({xyz, 1, MemorySpace::host}, 1.0f);
  DeviceBuffer<float> energy(1), force(3), virial(6);
  raycut::cuda::for_each_pair(one, user::LjForces{1, 4, energy.p, force.p, virial.p});
  CHECK_CUDA(cudaDeviceSynchronize());
  EXPECT_EQ(energy.to_host(), std::vector<float>(1, 0.0f));
  EXPECT_EQ(force.to_host(), std::vector<float>(3, 0.0f));
  EXPECT_EQ(virial.to_host(), std::vector<float>(6, 0.0f));
}

// Each target's triples (i, j, S) at its row of a CSR list sized by a count pass: reads j and S,
// so a periodic pass takes the image tables. end[i] is where the row stopped.
struct FillTriples {
  using Accumulator = std::uint32_t;
  using options = raycut::functor_options<raycut::option::init>;
  const std::uint32_t* offsets;
  std::uint32_t capacity;
  std::uint32_t *i_out, *j_out, *end;
  std::int32_t* s_out;
  RAYCUT_HD Accumulator init(std::uint32_t i) const { return offsets[i]; }
  RAYCUT_HD void operator()(Accumulator& at, std::uint32_t i, std::uint32_t j, raycut::Vec3, float,
                            const raycut::Shift& s) const {
    if (at < capacity) {
      i_out[at] = i;
      j_out[at] = j;
      s_out[3 * at] = s.a;
      s_out[3 * at + 1] = s.b;
      s_out[3 * at + 2] = s.c;
    }
    ++at;
  }
  RAYCUT_HD void finish(std::uint32_t i, Accumulator& at) const { end[i] = at; }
};

// nvcc once took every functor with the shifted pair call for one with accepts(), so FillTriples
// did not compile.
static_assert(!raycut::has_accepts<FillTriples>::value && raycut::takes_shift<FillTriples>::value);

// A periodic build's triples through a caller's functor, in rows sized by the built-in count
// (which reads no images: the open traversal).
class Triples {
 public:
  explicit Triples(Engine& engine)
      : count_(engine.compute(Kernel::count).count),
        offsets_(count_.size() + 1, 0),
        offsets_d_(offsets_.size()),
        end_d_(count_.size()) {
    std::partial_sum(count_.begin(), count_.end(), offsets_.begin() + 1);
    const std::uint32_t total = offsets_.back();
    i_d_ = std::make_unique<DeviceBuffer<std::uint32_t>>(total);
    j_d_ = std::make_unique<DeviceBuffer<std::uint32_t>>(total);
    s_d_ = std::make_unique<DeviceBuffer<std::int32_t>>(3 * std::size_t{total});
    cudaMemcpy(offsets_d_.p, offsets_.data(), offsets_.size() * sizeof(std::uint32_t),
               cudaMemcpyHostToDevice);
    // A copy from pageable memory may still be in flight when cudaMemcpy returns, ordered only
    // with blocking streams: a pass on a non-blocking stream could read the offsets before they
    // land (seen on an H100: row 0 began at 0xFFFFFFFF, left in the fresh allocation).
    EXPECT_EQ(cudaDeviceSynchronize(), cudaSuccess);
  }
  // Queued on `stream`; nothing waits.
  void launch(const Engine& engine, cudaStream_t stream) const {
    raycut::cuda::for_each_pair(
        engine, FillTriples{offsets_d_.p, offsets_.back(), i_d_->p, j_d_->p, end_d_.p, s_d_->p},
        stream);
  }
  // After the launch's stream: every row full, every triple of the oracle once.
  void expect_oracle(const std::vector<float>& xyz, const raycut::Box& box, float cutoff) const {
    ASSERT_EQ(cudaDeviceSynchronize(), cudaSuccess);
    const std::vector<std::uint32_t> end = end_d_.to_host();
    for (std::size_t i = 0; i < count_.size(); ++i)
      ASSERT_EQ(end[i], offsets_[i + 1]) << "row " << i << " ended elsewhere than its count";
    const raycut_test::PeriodicCheck check =
        raycut_test::check_periodic_pairs(raycut_test::make_periodic_oracle(xyz, box, cutoff),
                                          i_d_->to_host(), j_d_->to_host(), s_d_->to_host(), false);
    EXPECT_TRUE(check.ok) << check.problems;
    EXPECT_GT(check.listed, count_.size()) << "too few pairs for the test to mean anything";
  }

 private:
  std::vector<std::uint32_t> count_, offsets_;
  DeviceBuffer<std::uint32_t> offsets_d_, end_d_;
  std::unique_ptr<DeviceBuffer<std::uint32_t>> i_d_, j_d_;
  std::unique_ptr<DeviceBuffer<std::int32_t>> s_d_;
};

// The first pass that reads images runs on stream a, the next at once on stream b (non-blocking:
// only the gather's event orders it), then one on the engine's own; a rebuild over moved
// positions gathers again. A box thinner than the cutoff along x gives self-images.
TEST_P(GpuFunctors, PeriodicFunctorReadsImagesOnAnyStream) {
  if (is_optix(method())) GTEST_SKIP() << "OptiX methods refuse functors (OptixRefuses)";
  const raycut::Box boxes[] = {raycut::Box::orthorhombic(3.0, 3.5, 4.0),
                               raycut::Box::orthorhombic(0.9, 2.6, 3.1)};
  const float cutoff = 1.2f;
  cudaStream_t a = nullptr, b = nullptr;
  CHECK_CUDA(cudaStreamCreateWithFlags(&a, cudaStreamNonBlocking));
  CHECK_CUDA(cudaStreamCreateWithFlags(&b, cudaStreamNonBlocking));
  std::mt19937 rng(11);
  for (const raycut::Box& box : boxes) {
    SCOPED_TRACE("box " + std::to_string(box.cell[0][0]));
    std::uniform_real_distribution<float> u(-0.5f, 1.5f);  // unwrapped, up to half a box out
    std::vector<float> xyz(3 * 300);
    for (std::size_t k = 0; k < xyz.size(); ++k)
      xyz[k] = u(rng) * static_cast<float>(box.cell[k % 3][k % 3]);
    Engine engine(method());
    raycut::DeviceArray positions(xyz);
    try {
      engine.build(positions.view(), cutoff, box);
    } catch (const raycut::Error& e) {
      if (e.code() != raycut::ErrorCode::unsupported) throw;
      GTEST_SKIP() << method() << " refuses periodic boxes: " << e.what();
    }
    {
      const Triples on_a(engine), on_b(engine), on_engine(engine);
      on_a.launch(engine, a);
      on_b.launch(engine, b);
      on_engine.launch(engine, nullptr);
      on_a.expect_oracle(xyz, box, cutoff);
      on_b.expect_oracle(xyz, box, cutoff);
      on_engine.expect_oracle(xyz, box, cutoff);
    }
    for (float& v : xyz) v += 0.37f * u(rng);  // a rebuild: new slots, the table again
    positions = raycut::DeviceArray(xyz);
    engine.update(positions.view());
    const Triples on_b(engine), on_a(engine);
    on_b.launch(engine, b);
    on_a.launch(engine, a);
    on_b.expect_oracle(xyz, box, cutoff);
    on_a.expect_oracle(xyz, box, cutoff);
  }
  CHECK_CUDA(cudaStreamDestroy(a));
  CHECK_CUDA(cudaStreamDestroy(b));
}

// The OptiX methods run programs compiled ahead: a caller's functor is refused, by both entry
// points, with Error(unsupported).
TEST_P(GpuFunctors, OptixRefuses) {
  if (!is_optix(method())) GTEST_SKIP() << "not an OptiX method: the other tests run it";
  const std::vector<float> xyz = {0, 0, 0, 0.5f, 0, 0, 0, 0.5f, 0};
  Engine engine(method());
  engine.build({xyz.data(), 3, MemorySpace::host}, 1.0f);
  DeviceBuffer<float> energy(3);
  const user::Lj f{user::lj_parameters({}, energy.p)};
  try {
    raycut::cuda::for_each_pair(engine, f);
    ADD_FAILURE() << "raycut::cuda::for_each_pair: no exception";
  } catch (const raycut::Error& e) {
    EXPECT_EQ(e.code(), raycut::ErrorCode::unsupported) << e.what();
  }
  try {
    raycut::for_each_pair(engine, f);
    ADD_FAILURE() << "raycut::for_each_pair: no exception";
  } catch (const raycut::Error& e) {
    EXPECT_EQ(e.code(), raycut::ErrorCode::unsupported) << e.what();
  }
}

INSTANTIATE_TEST_SUITE_P(Methods, GpuFunctors, ::testing::ValuesIn(gpu_methods()),
                         [](const auto& info) {
                           std::string name = info.param.name;
                           for (char& c : name)
                             if (c == '-') c = '_';
                           return name;
                         });

}  // namespace
