#include "cuda/images.hpp"

#include <thrust/iterator/counting_iterator.h>
#include <thrust/iterator/transform_iterator.h>
#include <cub/device/device_scan.cuh>

#include <cstring>
#include <string>
#include <vector>

#include "core/validation.hpp"
#include "cuda/device_buffer.cuh"
#include "cuda/device_results.cuh"
#include "raycut/detail/cuda/visit.cuh"

namespace raycut::detail::cuda {
namespace {

constexpr int block = 256;

// The system holding index i of a set split by offsets[0..systems] (upper bound, minus one).
__device__ __forceinline__ std::uint32_t system_of(const std::uint64_t* offsets,
                                                   std::uint32_t systems, std::uint64_t i) {
  std::uint32_t lo = 0, hi = systems;
  while (hi - lo > 1) {
    const std::uint32_t mid = (lo + hi) / 2;
    if (offsets[mid] <= i)
      lo = mid;
    else
      hi = mid;
  }
  return lo;
}

struct Plan {
  ImageFrame* frames;
  const std::uint64_t* sources;  // systems + 1
  const std::uint64_t* queries;  // systems + 1, or null
  std::uint32_t systems;
  std::uint64_t n, targets, first_image;
};

__global__ void origins_kernel(Plan plan, const float* sources, const float* queries) {
  const std::uint32_t s = blockIdx.x * blockDim.x + threadIdx.x;
  if (s >= plan.systems) return;
  if (plan.sources[s] < plan.sources[s + 1])
    system_origin(plan.frames[s], sources + 3 * plan.sources[s]);
  else if (plan.queries && plan.queries[s] < plan.queries[s + 1])
    system_origin(plan.frames[s], queries + 3 * plan.queries[s]);
}

// Images per particle; the first particle whose shift leaves int32 in bad[0], the first with a
// non-finite coordinate in bad[1] (else ~0): the engine's finiteness check, fused in this pass
// (one kernel and one read-back less per build).
__global__ void count_kernel(Plan plan, const float* sources, std::uint32_t* counts,
                             unsigned long long* bad) {
  const std::uint64_t p = blockIdx.x * std::uint64_t{block} + threadIdx.x;
  if (p >= plan.n) return;
  const float* x = sources + 3 * p;
  if (!(isfinite(x[0]) && isfinite(x[1]) && isfinite(x[2]))) {
    atomicMin(bad + 1, static_cast<unsigned long long>(p));
    counts[p] = 0;
    return;
  }
  const ImageFrame& frame = plan.frames[system_of(plan.sources, plan.systems, p)];
  const WrappedPoint w = wrap_point(frame, x);
  if (!w.ok) atomicMin(bad, static_cast<unsigned long long>(p));
  counts[p] = static_cast<std::uint32_t>(image_count(frame, w, false));
}

struct Out {
  float* xyz;
  PointImage* image;
  std::uint32_t* system;  // null: one system
  __device__ void place(std::uint64_t k, const float p[3], std::uint32_t src, std::uint32_t s,
                        const std::int32_t t[3]) const {
    for (int c = 0; c < 3; ++c) xyz[3 * k + c] = p[c];
    image[k] = PointImage{src, {t[0], t[1], t[2]}};
    if (system) system[k] = s;
  }
  __device__ void place_wrapped(std::uint64_t k, const ImageFrame& frame, const WrappedPoint& w,
                                std::uint32_t src, std::uint32_t s) const {
    float p[3];
    for (int c = 0; c < 3; ++c) p[c] = static_cast<float>(w.x[c] - frame.origin[c]);
    const std::int32_t t[3] = {-w.shift[0], -w.shift[1], -w.shift[2]};
    place(k, p, src, s, t);
  }
};

// Query points: the targets, wrapped. Bad shifts of queries go to *bad too (as index + n).
__global__ void queries_kernel(Plan plan, const float* queries, Out out, unsigned long long* bad) {
  const std::uint64_t q = blockIdx.x * std::uint64_t{block} + threadIdx.x;
  if (q >= plan.targets) return;
  const std::uint32_t s = system_of(plan.queries, plan.systems, q);
  const WrappedPoint w = wrap_point(plan.frames[s], queries + 3 * q);
  if (!w.ok) atomicMin(bad, static_cast<unsigned long long>(plan.n + q));
  out.place_wrapped(q, plan.frames[s], w, not_a_source, s);
}

// Each particle: itself wrapped (a target, or a source after the queries), then its images.
__global__ void particles_kernel(Plan plan, const float* sources, const std::uint64_t* image_offset,
                                 bool with_queries, Out out) {
  const std::uint64_t p = blockIdx.x * std::uint64_t{block} + threadIdx.x;
  if (p >= plan.n) return;
  const std::uint32_t s = system_of(plan.sources, plan.systems, p);
  const ImageFrame& frame = plan.frames[s];
  const WrappedPoint w = wrap_point(frame, sources + 3 * p);
  const auto source = static_cast<std::uint32_t>(p);
  out.place_wrapped(with_queries ? plan.targets + p : p, frame, w, source, s);
  std::uint64_t next = plan.first_image + image_offset[p];
  for_each_image(frame, w, false, [&](const int n[3], const float position[3]) {
    const std::int32_t t[3] = {n[0] - w.shift[0], n[1] - w.shift[1], n[2] - w.shift[2]};
    out.place(next++, position, source, s, t);
  });
}

struct CountOrZero {
  const std::uint32_t* counts;
  std::uint64_t n;
  __host__ __device__ std::uint64_t operator()(std::uint64_t i) const {
    return i < n ? counts[i] : 0;
  }
};

// count_kernel's findings: the first index whose shift leaves int32, the first non-finite one.
struct Bad {
  unsigned long long shift, non_finite;
};

class DeviceImagePoints final : public ImagePoints {
 public:
  MemorySpace space() const override { return MemorySpace::device; }
  void expand(const ImagePlan& plan, const float* sources, const float* queries,
              void* stream) override;

 private:
  DeviceBuffer<float> xyz_;
  DeviceBuffer<PointImage> image_;
  DeviceBuffer<std::uint32_t> system_, counts_;
  DeviceBuffer<ImageFrame> frames_;
  DeviceBuffer<std::uint64_t> source_offsets_, query_offsets_, image_offset_;
  DeviceBuffer<unsigned long long> bad_;  // atomics to mapped host memory are not portable
  DeviceBuffer<unsigned char> temp_;
  MappedValue<Bad> bad_host_;
  MappedValue<std::uint64_t> total_;
  // What frames_ and the offsets hold: a step loop's next expansion uploads nothing.
  std::vector<ImageFrame> uploaded_frames_;
  std::vector<std::uint64_t> uploaded_sources_, uploaded_queries_;
};

bool same_frames(const std::vector<ImageFrame>& a, const std::vector<ImageFrame>& b) {
  return a.size() == b.size() &&
         (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(ImageFrame)) == 0);
}

template <class T>
void upload_async(DeviceBuffer<T>& buffer, const std::vector<T>& host, cudaStream_t stream) {
  buffer.resize(std::max<std::size_t>(host.size(), 1));
  if (!host.empty())
    RAYCUT_CUDA_CHECK(cudaMemcpyAsync(buffer.data(), host.data(), host.size() * sizeof(T),
                                      cudaMemcpyHostToDevice, stream));
}

void DeviceImagePoints::expand(const ImagePlan& plan, const float* sources, const float* queries,
                               void* stream_ptr) {
  const auto stream = static_cast<cudaStream_t>(stream_ptr);
  const std::uint32_t systems = plan.systems();
  const std::uint64_t n = plan.source_count(), targets = plan.target_count();
  const bool with_queries = plan.has_queries();
  if (!same_frames(plan.frames, uploaded_frames_)) {
    upload_async(frames_, plan.frames, stream);
    uploaded_frames_ = plan.frames;
  }
  if (plan.sources != uploaded_sources_) {
    upload_async(source_offsets_, plan.sources, stream);
    uploaded_sources_ = plan.sources;
  }
  if (with_queries && plan.queries != uploaded_queries_) {
    upload_async(query_offsets_, plan.queries, stream);
    uploaded_queries_ = plan.queries;
  }
  Plan p{frames_.data(),
         source_offsets_.data(),
         with_queries ? query_offsets_.data() : nullptr,
         systems,
         n,
         targets,
         0};
  if (plan.own_frames) {
    origins_kernel<<<blocks_for(systems, block), block, 0, stream>>>(p, sources, queries);
    RAYCUT_CUDA_CHECK_LAUNCH();
  }

  // Count, scan (the total lands at image_offset[n]), read the total and any bad point back.
  bad_.resize(2);
  RAYCUT_CUDA_CHECK(cudaMemsetAsync(bad_.data(), 0xFF, sizeof(Bad), stream));
  counts_.resize(std::max<std::uint64_t>(n, 1));
  image_offset_.resize(n + 1);
  if (n > 0) {
    count_kernel<<<blocks_for(n, block), block, 0, stream>>>(p, sources, counts_.data(),
                                                             bad_.data());
    RAYCUT_CUDA_CHECK_LAUNCH();
  }
  const auto input = thrust::make_transform_iterator(thrust::counting_iterator<std::uint64_t>(0),
                                                     CountOrZero{counts_.data(), n});
  std::size_t temp_bytes = 0;
  RAYCUT_CUDA_CHECK(cub::DeviceScan::ExclusiveSum(nullptr, temp_bytes, input, image_offset_.data(),
                                                  n + 1, stream));
  temp_.resize(std::max<std::size_t>(temp_bytes, 1));
  RAYCUT_CUDA_CHECK(cub::DeviceScan::ExclusiveSum(temp_.data(), temp_bytes, input,
                                                  image_offset_.data(), n + 1, stream));
  RAYCUT_CUDA_CHECK(cudaMemcpyAsync(total_.device(), image_offset_.data() + n,
                                    sizeof(std::uint64_t), cudaMemcpyDeviceToDevice, stream));
  RAYCUT_CUDA_CHECK(cudaMemcpyAsync(bad_host_.device(), bad_.data(), sizeof(Bad),
                                    cudaMemcpyDeviceToDevice, stream));
  RAYCUT_CUDA_CHECK(cudaStreamSynchronize(stream));
  const Bad bad = bad_host_.host();
  if (bad.non_finite != ~0ull || bad.shift != ~0ull) {
    const unsigned long long first = bad.non_finite != ~0ull ? bad.non_finite : bad.shift;
    float x[3];
    RAYCUT_CUDA_CHECK(cudaMemcpy(x, sources + 3 * first, sizeof x, cudaMemcpyDeviceToHost));
    if (bad.non_finite != ~0ull) throw_non_finite(first, x);
    throw Error(ErrorCode::invalid_argument,
                "particle " + std::to_string(first) + " at (" + std::to_string(x[0]) + ", " +
                    std::to_string(x[1]) + ", " + std::to_string(x[2]) +
                    ") lies more than 2^31 boxes away: its image shift leaves the int32 range");
  }
  p.first_image = targets + (with_queries ? n : 0);
  const std::uint64_t points = p.first_image + total_.host();
  if (std::string why = too_many_points(points, targets); !why.empty())
    throw Error(ErrorCode::invalid_argument, why);

  const double held =
      static_cast<double>(xyz_.bytes() + image_.bytes() + (systems > 1 ? system_.bytes() : 0));
  const double need = (12.0 + 16.0 + (systems > 1 ? 4.0 : 0.0)) * static_cast<double>(points);
  if (need > held)
    require_device_memory(static_cast<std::size_t>(need - held), "points with periodic images");
  xyz_.resize(3 * points);
  image_.resize(points);
  if (systems > 1) system_.resize(points);
  const Out out{xyz_.data(), image_.data(), systems > 1 ? system_.data() : nullptr};
  if (with_queries && targets > 0) {
    queries_kernel<<<blocks_for(targets, block), block, 0, stream>>>(p, queries, out, bad_.data());
    RAYCUT_CUDA_CHECK_LAUNCH();
    RAYCUT_CUDA_CHECK(cudaMemcpyAsync(bad_host_.device(), bad_.data(), sizeof(Bad),
                                      cudaMemcpyDeviceToDevice, stream));
    RAYCUT_CUDA_CHECK(cudaStreamSynchronize(stream));
    if (bad_host_.host().shift != ~0ull)
      throw Error(ErrorCode::invalid_argument,
                  "query point " + std::to_string(bad_host_.host().shift - n) +
                      " lies more than 2^31 boxes away: its image shift leaves the int32 range");
  }
  if (n > 0) {
    particles_kernel<<<blocks_for(n, block), block, 0, stream>>>(p, sources, image_offset_.data(),
                                                                 with_queries, out);
    RAYCUT_CUDA_CHECK_LAUNCH();
  }

  publish(plan, xyz_.data(), points, image_.data(), system_.data());
}

}  // namespace

std::unique_ptr<ImagePoints> make_device_image_points() {
  return std::make_unique<DeviceImagePoints>();
}

}  // namespace raycut::detail::cuda
