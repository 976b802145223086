// The oracle on the GPU: every target against every source (the traversal:
// include/raycut/detail/cuda/brute_force_pass.cuh). O(N^2): for tests and small inputs.
#include <string>

#include "cuda/device_results.cuh"
#include "cuda/methods.hpp"
#include "raycut/detail/cuda/brute_force_pass.cuh"
#include "raycut/predicate.hpp"

namespace raycut::detail::cuda {
namespace {

class BruteForceGpu final : public CudaPairMethod<BruteForceGpu> {
 public:
  void build(const float* xyz, std::size_t n, float cutoff) override {
    build_points(Points::plain(xyz, n), cutoff);
  }

  std::string points_unsupported() const override { return {}; }
  void build_points(const Points& points, float cutoff) override {
    const std::size_t n = points.size;
    if (n >= UINT32_MAX)  // list indices are 32-bit
      throw Error(ErrorCode::invalid_argument,
                  "brute-force-gpu handles at most 2^32 - 2 points, got " + std::to_string(n));
    build_timer_.start(stream_);
    xyz_.resize(3 * n);
    RAYCUT_CUDA_CHECK(cudaMemcpyAsync(xyz_.data(), points.xyz, 3 * n * sizeof(float),
                                      cudaMemcpyDeviceToDevice, stream_));
    build_timer_.stop(stream_);
    n_ = points.targets;
    points_ = n;
    images_ = points.images;
    system_ = points.systems > 1 ? points.system : nullptr;
    cutoff_squared_ = squared_cutoff(cutoff);
  }

  std::size_t size() const { return n_; }
  PairPass pair_pass() const override {
    PairPass pass;
    pass.kind = PassKind::brute_force_gpu;
    pass.n = n_;
    pass.points = points_;
    pass.images = images_;
    pass.cutoff_squared = cutoff_squared_;
    pass.brute_force.xyz = xyz_.data();
    pass.brute_force.system = system_;
    return pass;
  }
  template <class F>
  void run(const F& f) const {
    run_without_idle_cutoffs(f, [&](const auto& g) { run_brute_force(pair_pass(), g, stream_); });
  }

 private:
  DeviceBuffer<float> xyz_;
  std::size_t n_ = 0, points_ = 0;  // targets, points
  ImageTables images_;
  const std::uint32_t* system_ = nullptr;
  float cutoff_squared_ = 0;
};

}  // namespace

std::unique_ptr<Method> make_brute_force() {
  return std::make_unique<BruteForceGpu>();
}

}  // namespace raycut::detail::cuda
