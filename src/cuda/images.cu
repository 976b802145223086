#include "cuda/images.hpp"

#include <cmath>
#include <cstring>
#include <string>
#include <vector>

#include "core/validation.hpp"
#include "cuda/device_buffer.cuh"
#include "cuda/device_results.cuh"
#include "cuda/runtime.hpp"
#include "cuda/scan.cuh"
#include "raycut/detail/cuda/visit.cuh"
#include "raycut/static_pairs.hpp"

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

// `Real`: the sources as given (float), or the caller's float64 positions (their float rounding
// is then only what the search reads; Engine::build(Float64Positions)).
template <class Real>
__global__ void origins_kernel(Plan plan, const Real* sources, const float* queries) {
  const std::uint32_t s = blockIdx.x * blockDim.x + threadIdx.x;
  if (s >= plan.systems) return;
  if (plan.sources[s] < plan.sources[s + 1])
    system_origin(plan.frames[s], sources + 3 * plan.sources[s]);
  else if (plan.queries && plan.queries[s] < plan.queries[s + 1])
    system_origin(plan.frames[s], queries + 3 * plan.queries[s]);
}

// What the wrap pass finds, read back once: the first particle whose shift leaves int32 (a
// query's as index + n) and the first with a non-finite coordinate, each kept as ~index by
// atomicMax (0: none, so that one memset clears all), how many particles have images (listed by
// wrap_kernel for images_kernel), and the largest |coordinate| of every point to come (the bits
// of a float >= 0, which order as unsigned; 0: 0.0f), for the float band.
struct Findings {
  unsigned long long not_shift, not_non_finite, with_images;
  unsigned extent;
};
constexpr std::uint64_t none = ~0ull;
__host__ __device__ inline std::uint64_t first_of(unsigned long long inverted) {
  return ~inverted;  // none when nothing was found
}
__device__ inline void report(unsigned long long& inverted, std::uint64_t index) {
  atomicMax(&inverted, ~static_cast<unsigned long long>(index));
}

// The largest extent of the block's threads into found->extent: a warp maximum, one shared
// atomic per warp, one global atomic per block (contended atomics are what wrap_kernel's time
// is sensitive to, below). Every thread of the block calls it.
__device__ void report_extent(double extent, Findings* found) {
  __shared__ unsigned block_extent;
  if (threadIdx.x == 0) block_extent = 0;
  __syncthreads();
  unsigned bits = __float_as_uint(__double2float_ru(extent));  // rounded up: still a bound
  for (int offset = 16; offset > 0; offset /= 2)
    bits = max(bits, __shfl_xor_sync(0xffffffffu, bits, offset));
  if (threadIdx.x % 32 == 0) atomicMax(&block_extent, bits);
  __syncthreads();
  if (threadIdx.x == 0 && block_extent > 0) atomicMax(&found->extent, block_extent);
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

// Particle p wrapped and placed as a point of its own (a target, or a source after the queries:
// its place needs no scan), its images counted; whether it has any. `extent`: the largest
// |coordinate| of its point and its images.
template <class Real>
__device__ bool wrap_one(const Plan& plan, const Real* sources, bool with_queries, const Out& out,
                         std::uint32_t* counts, Findings* found, std::uint64_t p, double& extent) {
  const Real* x = sources + 3 * p;
  if (!(isfinite(x[0]) && isfinite(x[1]) && isfinite(x[2]))) {
    report(found->not_non_finite, p);
    counts[p] = 0;
    return false;
  }
  const std::uint32_t s = system_of(plan.sources, plan.systems, p);
  const ImageFrame& frame = plan.frames[s];
  const WrappedPoint w = wrap_point(frame, x);
  if (!w.ok) report(found->not_shift, p);
  out.place_wrapped(with_queries ? plan.targets + p : p, frame, w, static_cast<std::uint32_t>(p),
                    s);
  extent = image_extent(frame, w);
  const auto count = static_cast<std::uint32_t>(image_count(frame, w, false));
  counts[p] = count;
  return count > 0;
}

// Every particle through wrap_one, and those with images listed (in any order: the scan of the
// counts places their images). The engine's finiteness check is fused here (one kernel and one
// read-back less per build). Only ~5 % of a liquid's particles have images, spread over every
// warp: images_kernel over the list keeps its warps full (docs/periodic.md). One list atomic
// per block: one per warp contended enough to double this kernel's time (ncu on the H200,
// 2026-12-02).
template <class Real>
__global__ void wrap_kernel(Plan plan, const Real* sources, bool with_queries, Out out,
                            std::uint32_t* counts, std::uint32_t* with_images, Findings* found) {
  __shared__ std::uint32_t listed;
  __shared__ unsigned long long first;
  if (threadIdx.x == 0) listed = 0;
  __syncthreads();
  const std::uint64_t p = blockIdx.x * std::uint64_t{block} + threadIdx.x;
  double extent = 0;
  const bool has =
      p < plan.n && wrap_one(plan, sources, with_queries, out, counts, found, p, extent);
  report_extent(extent, found);
  const std::uint32_t rank = has ? atomicAdd(&listed, 1u) : 0;
  __syncthreads();
  if (threadIdx.x == 0 && listed > 0) first = atomicAdd(&found->with_images, listed);
  __syncthreads();
  if (has) with_images[first + rank] = static_cast<std::uint32_t>(p);
}

// Query points: the targets, wrapped.
__global__ void queries_kernel(Plan plan, const float* queries, Out out, Findings* found) {
  const std::uint64_t q = blockIdx.x * std::uint64_t{block} + threadIdx.x;
  double extent = 0;
  if (q < plan.targets) {
    const std::uint32_t s = system_of(plan.queries, plan.systems, q);
    const ImageFrame& frame = plan.frames[s];
    const WrappedPoint w = wrap_point(frame, queries + 3 * q);
    if (!w.ok) report(found->not_shift, plan.n + q);
    out.place_wrapped(q, frame, w, not_a_source, s);
    for (int c = 0; c < 3; ++c) extent = fmax(extent, fabs(w.x[c] - frame.origin[c]));
  }
  report_extent(extent, found);
}

// The images of each listed particle, at the places the scan of the counts gave them; image
// slots from `slots` on are not written (a reused plan with too few: park_kernel reports it).
// `listed_on_device`: the count of listed particles where the host has not read it (a reused
// plan launches over every particle).
template <class Real>
__global__ void images_kernel(Plan plan, const Real* sources, const std::uint32_t* with_images,
                              std::uint64_t listed, const unsigned long long* listed_on_device,
                              const std::uint64_t* image_offset, Out out, std::uint64_t slots) {
  const std::uint64_t k = blockIdx.x * std::uint64_t{block} + threadIdx.x;
  if (k >= (listed_on_device ? *listed_on_device : listed)) return;
  const std::uint64_t p = with_images[k];
  const std::uint32_t s = system_of(plan.sources, plan.systems, p);
  const ImageFrame& frame = plan.frames[s];
  const WrappedPoint w = wrap_point(frame, sources + 3 * p);
  const auto source = static_cast<std::uint32_t>(p);
  std::uint64_t next = image_offset[p];
  for_each_image(frame, w, false, [&](const int n[3], const float position[3]) {
    const std::int32_t t[3] = {n[0] - w.shift[0], n[1] - w.shift[1], n[2] - w.shift[2]};
    if (next < slots) out.place(plan.first_image + next, position, source, s, t);
    ++next;
  });
}

// A reused plan (Engine::set_reuse_plan): its image slots, the float band's extent (float
// bits) and where spare slots park (a lattice of side x side places on the sheet, in each
// system's layer of the grid); the device word that says what no longer fits.
struct Reuse {
  std::uint64_t slots = 0;
  unsigned extent = 0;
  ParkingPlace parking;
  std::uint32_t side = 1;
  int* misfit = nullptr;
};

// After the images of a reused plan: slot k, when the images left it empty, gets a place of the
// parking lattice in system k % systems (no search reaches it: the slots spread over every
// system's cells of the sheet), and thread 0 writes the verdict, the first word of this build's
// misfit.
__global__ void park_kernel(Plan plan, const std::uint64_t* images, const Findings* found,
                            Reuse reuse, Out out) {
  const std::uint64_t k = blockIdx.x * std::uint64_t{block} + threadIdx.x;
  const std::uint64_t real = *images;
  if (k == 0) {
    int code = 0;
    if (first_of(found->not_non_finite) != none)
      code = static_cast<int>(count_non_finite_position);
    else if (real > reuse.slots || found->extent > reuse.extent ||
             first_of(found->not_shift) != none)
      code = static_cast<int>(count_plan_outgrown);
    *reuse.misfit = code;
  }
  if (k >= real && k < reuse.slots) {
    const ParkingPlace& at = reuse.parking;
    const std::uint64_t lattice = k / plan.systems;
    const float y = (static_cast<float>(lattice % reuse.side) + 0.5f) /
                    static_cast<float>(reuse.side),
                z = (static_cast<float>(lattice / reuse.side) + 0.5f) /
                    static_cast<float>(reuse.side);
    const float place[3] = {at.x, at.lo[0] + y * (at.hi[0] - at.lo[0]),
                            at.lo[1] + z * (at.hi[1] - at.lo[1])};
    const std::int32_t none_shifted[3] = {0, 0, 0};
    out.place(plan.first_image + k, place, 0, static_cast<std::uint32_t>(k % plan.systems),
              none_shifted);
  }
}

class DeviceImagePoints final : public ImagePoints {
 public:
  ~DeviceImagePoints() override {
    if (misfit_seen_) cudaEventDestroy(misfit_seen_);
  }
  MemorySpace space() const override { return MemorySpace::device; }
  void expand(const ImagePlan& plan, const float* sources, const float* queries,
              void* stream) override {
    expand_into(plan, sources, queries, static_cast<cudaStream_t>(stream), false);
  }

  void set_recording(bool on) override {
    recording_ = on;
    parked_ = recorded_slots_ = misfit_pending_ = false;
    reuse_.slots = 0;
  }
  void set_parking(const ParkingPlace& place) override {
    reuse_.parking = place;
    parked_ = recorded_slots_;
  }
  bool recorded() const override { return parked_; }
  void expand_reusing(const ImagePlan& plan, const float* sources, const float* queries,
                      void* stream) override {
    expand_into(plan, sources, queries, static_cast<cudaStream_t>(stream), true);
  }
  void finish_reusing(void* stream) override;
  bool reused_plan_outgrown(void* stream, bool wait) override;

 private:
  void expand_into(const ImagePlan& plan, const float* sources, const float* queries,
                   cudaStream_t stream, bool reusing);
  Out reserve(std::uint64_t points, std::uint64_t keep, bool systems, cudaStream_t stream);
  DeviceBuffer<float> xyz_;
  DeviceBuffer<PointImage> image_;
  DeviceBuffer<std::uint32_t> system_, counts_, with_images_;
  DeviceBuffer<ImageFrame> frames_;
  DeviceBuffer<std::uint64_t> source_offsets_, query_offsets_, image_offset_;
  DeviceBuffer<Findings> found_;  // atomics to mapped host memory are not portable
  DeviceBuffer<unsigned char> temp_;
  // What decides the band's pairs in double (ExactImages): the caller's positions, kept while
  // the build lives (the engine's device copy of host positions is not), and the cells.
  DeviceBuffer<float> sources_, queries_;
  DeviceBuffer<double> sources64_, cells_;
  ExactImages exact_;
  MappedValue<Findings> found_host_;
  MappedValue<std::uint64_t> total_;
  // What frames_ and the offsets hold: a step loop's next expansion uploads nothing.
  std::vector<ImageFrame> uploaded_frames_;
  std::vector<std::uint64_t> uploaded_sources_, uploaded_queries_;
  bool origins_written_ = false;  // frames_ holds origins of an earlier expansion
  // Engine::set_reuse_plan: the recorded sizes and parking place, the misfit word, and its copy
  // on the host with the event after it.
  bool recording_ = false, recorded_slots_ = false, parked_ = false, misfit_pending_ = false;
  Reuse reuse_;
  DeviceBuffer<int> misfit_;
  MappedValue<int> misfit_host_;
  cudaEvent_t misfit_seen_ = nullptr;
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

// xyz_, image_ and system_ hold at least `points`, their first `keep` kept; refused up front
// (out_of_memory, saying how much) when the device cannot hold them.
Out DeviceImagePoints::reserve(std::uint64_t points, std::uint64_t keep, bool systems,
                               cudaStream_t stream) {
  const double held = static_cast<double>(xyz_.capacity_bytes() + image_.capacity_bytes() +
                                          (systems ? system_.capacity_bytes() : 0));
  const double need = (12.0 + 16.0 + (systems ? 4.0 : 0.0)) * static_cast<double>(points);
  if (need > held)
    require_device_memory(static_cast<std::size_t>(need - held), "points with periodic images");
  xyz_.resize_keeping(3 * points, 3 * keep, stream);
  image_.resize_keeping(points, keep, stream);
  if (systems) system_.resize_keeping(points, keep, stream);
  return {xyz_.data(), image_.data(), systems ? system_.data() : nullptr};
}

// A captured build's verdict reaches the caller as its list's count at each replay, not the
// host, which may not query events meanwhile.
void DeviceImagePoints::finish_reusing(void* stream_ptr) {
  const auto stream = static_cast<cudaStream_t>(stream_ptr);
  if (capturing(stream)) return;
  RAYCUT_CUDA_CHECK(cudaMemcpyAsync(misfit_host_.device(), misfit_.data(), sizeof(int),
                                    cudaMemcpyDeviceToDevice, stream));
  if (!misfit_seen_)
    RAYCUT_CUDA_CHECK(cudaEventCreateWithFlags(&misfit_seen_, cudaEventDisableTiming));
  RAYCUT_CUDA_CHECK(cudaEventRecord(misfit_seen_, stream));
  misfit_pending_ = true;
}

bool DeviceImagePoints::reused_plan_outgrown(void* stream, bool wait) {
  if (!misfit_pending_ || capturing(stream)) return false;
  if (wait) {
    RAYCUT_CUDA_CHECK(cudaEventSynchronize(misfit_seen_));
  } else {
    const cudaError_t status = cudaEventQuery(misfit_seen_);
    if (status == cudaErrorNotReady) return false;  // not known yet: the device reports it
    RAYCUT_CUDA_CHECK(status);
  }
  misfit_pending_ = false;
  if (misfit_host_.host() == 0) return false;
  parked_ = false;  // forgotten: the next build plans afresh
  return true;
}

void DeviceImagePoints::expand_into(const ImagePlan& plan, const float* sources,
                                    const float* queries, cudaStream_t stream, bool reusing) {
  const std::uint32_t systems = plan.systems();
  const std::uint64_t n = plan.source_count(), targets = plan.target_count();
  const bool with_queries = plan.has_queries();
  // Batches: each system in its own frame; float64 sources too (one system as well), so that
  // their float points span the system rather than its distance from the origin and the band
  // stays narrow (core/images.cpp does the same). origins_kernel writes the origins into
  // frames_: a build without them uploads the frames afresh.
  const bool own_frames = plan.own_frames || float64_sources_ != nullptr;
  if (!same_frames(plan.frames, uploaded_frames_) || (origins_written_ && !own_frames)) {
    upload_async(frames_, plan.frames, stream);
    uploaded_frames_ = plan.frames;
    std::vector<double> cells(9 * std::size_t{systems});
    for (std::uint32_t s = 0; s < systems; ++s)
      for (int k = 0; k < 3; ++k)
        for (int c = 0; c < 3; ++c) cells[9 * s + 3 * k + c] = plan.frames[s].cell[k][c];
    upload_async(cells_, cells, stream);
  }
  // float64 sources (host memory): wrapped from the doubles, as the host expansion does, so
  // that the float points are within the rounding the band assumes of the caller's positions.
  const double* float64 = nullptr;
  if (float64_sources_) {
    sources64_.resize(std::max<std::uint64_t>(3 * n, 1));
    if (n > 0)
      RAYCUT_CUDA_CHECK(cudaMemcpyAsync(sources64_.data(), float64_sources_, 3 * n * sizeof(double),
                                        cudaMemcpyHostToDevice, stream));
    float64 = sources64_.data();
  }
  // The kernels that read the sources, on the doubles when given.
  const auto on_sources = [&](auto&& launch) {
    if (float64)
      launch(float64);
    else
      launch(sources);
  };
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
  origins_written_ = own_frames;
  if (own_frames) {
    on_sources([&](const auto* x) {
      origins_kernel<<<blocks_for(systems, block), block, 0, stream>>>(p, x, queries);
    });
    RAYCUT_CUDA_CHECK_LAUNCH();
  }

  // Every particle (and query) in its place and its images counted, the scan (the total lands
  // at image_offset[n]), then the total and any bad point read back at once; a reused plan
  // reads nothing back (its slots were reserved up front, and park_kernel judges).
  p.first_image = targets + (with_queries ? n : 0);
  if (std::string why = too_many_points(p.first_image, targets); !why.empty())
    throw Error(ErrorCode::invalid_argument, why);
  const bool batch = systems > 1;
  Out out = reserve(p.first_image + (reusing ? reuse_.slots : 0), 0, batch, stream);
  found_.resize(1);
  RAYCUT_CUDA_CHECK(cudaMemsetAsync(found_.data(), 0, sizeof(Findings), stream));
  counts_.resize(std::max<std::uint64_t>(n, 1));
  with_images_.resize(std::max<std::uint64_t>(n, 1));
  image_offset_.resize(n + 1);
  if (n > 0) {
    on_sources([&](const auto* x) {
      wrap_kernel<<<blocks_for(n, block), block, 0, stream>>>(
          p, x, with_queries, out, counts_.data(), with_images_.data(), found_.data());
    });
    RAYCUT_CUDA_CHECK_LAUNCH();
  }
  if (with_queries && targets > 0) {
    queries_kernel<<<blocks_for(targets, block), block, 0, stream>>>(p, queries, out,
                                                                     found_.data());
    RAYCUT_CUDA_CHECK_LAUNCH();
  }
  exclusive_sum(counts_.data(), n, image_offset_.data(), temp_, stream);
  std::uint64_t points = 0;
  float extent = 0;
  Points::PlanReuse reused;
  if (reusing) {
    misfit_.resize(1);
    if (n > 0) {
      on_sources([&](const auto* x) {
        images_kernel<<<blocks_for(n, block), block, 0, stream>>>(
            p, x, with_images_.data(), 0, &found_.data()->with_images, image_offset_.data(), out,
            reuse_.slots);
      });
      RAYCUT_CUDA_CHECK_LAUNCH();
    }
    Reuse r = reuse_;
    r.misfit = misfit_.data();
    const std::uint64_t per_system = (reuse_.slots + systems - 1) / systems;
    while (std::uint64_t{r.side} * r.side < per_system) ++r.side;
    park_kernel<<<blocks_for(std::max<std::uint64_t>(reuse_.slots, 1), block), block, 0, stream>>>(
        p, image_offset_.data() + n, found_.data(), r, out);
    RAYCUT_CUDA_CHECK_LAUNCH();
    points = p.first_image + reuse_.slots;
    std::memcpy(&extent, &reuse_.extent, sizeof extent);
    reused.misfit = misfit_.data();
  } else {
    RAYCUT_CUDA_CHECK(cudaMemcpyAsync(total_.device(), image_offset_.data() + n,
                                      sizeof(std::uint64_t), cudaMemcpyDeviceToDevice, stream));
    RAYCUT_CUDA_CHECK(cudaMemcpyAsync(found_host_.device(), found_.data(), sizeof(Findings),
                                      cudaMemcpyDeviceToDevice, stream));
    RAYCUT_CUDA_CHECK(cudaStreamSynchronize(stream));
    const Findings found = found_host_.host();
    const std::uint64_t non_finite = first_of(found.not_non_finite),
                        shift = first_of(found.not_shift);
    if (non_finite != none) {
      float x[3];
      RAYCUT_CUDA_CHECK(cudaMemcpy(x, sources + 3 * non_finite, sizeof x, cudaMemcpyDeviceToHost));
      throw_non_finite(non_finite, x);
    }
    if (shift != none && shift >= n)
      throw Error(ErrorCode::invalid_argument,
                  "query point " + std::to_string(shift - n) +
                      " lies more than 2^31 boxes away: its image shift leaves the int32 range");
    if (shift != none) {
      float x[3];
      RAYCUT_CUDA_CHECK(cudaMemcpy(x, sources + 3 * shift, sizeof x, cudaMemcpyDeviceToHost));
      throw Error(ErrorCode::invalid_argument,
                  "particle " + std::to_string(shift) + " at (" + std::to_string(x[0]) + ", " +
                      std::to_string(x[1]) + ", " + std::to_string(x[2]) +
                      ") lies more than 2^31 boxes away: its image shift leaves the int32 range");
    }
    const std::uint64_t images = total_.host();
    points = p.first_image + images;
    if (std::string why = too_many_points(points, targets); !why.empty())
      throw Error(ErrorCode::invalid_argument, why);

    out = reserve(points, p.first_image, batch, stream);
    if (found.with_images > 0) {
      on_sources([&](const auto* x) {
        images_kernel<<<blocks_for(found.with_images, block), block, 0, stream>>>(
            p, x, with_images_.data(), found.with_images, nullptr, image_offset_.data(), out,
            images);
      });
      RAYCUT_CUDA_CHECK_LAUNCH();
    }
    std::memcpy(&extent, &found.extent, sizeof extent);
    parked_ = recorded_slots_ = false;
    if (recording_ && !float64) {
      // What the next builds reuse: 1/8 more image slots (a step loop's particles cross into
      // and out of the faces' reach), the extent a 1/16 wider (the band with it).
      reuse_.slots = images + images / 8 + 64;
      extent = std::nextafter(extent * 1.0625f, INFINITY);
      std::memcpy(&reuse_.extent, &extent, sizeof extent);
      recorded_slots_ = true;
      reused.record = true;
      reused.planned_size = p.first_image + reuse_.slots;
      if (std::string why = too_many_points(reused.planned_size, targets); !why.empty())
        throw Error(ErrorCode::invalid_argument, why);
    }
  }

  // The caller's positions, kept for the band's decisions (ExactImages): the float64 ones when
  // given (uploaded above), else the float sources.
  if (!float64) {
    sources_.resize(std::max<std::uint64_t>(3 * n, 1));
    if (n > 0)
      RAYCUT_CUDA_CHECK(cudaMemcpyAsync(sources_.data(), sources, 3 * n * sizeof(float),
                                        cudaMemcpyDeviceToDevice, stream));
  }
  if (with_queries) {
    queries_.resize(std::max<std::uint64_t>(3 * targets, 1));
    if (targets > 0)
      RAYCUT_CUDA_CHECK(cudaMemcpyAsync(queries_.data(), queries, 3 * targets * sizeof(float),
                                        cudaMemcpyDeviceToDevice, stream));
  }
  exact_ = {};
  exact_.sources = float64 ? nullptr : sources_.data();
  exact_.sources64 = float64;
  exact_.queries = with_queries ? queries_.data() : nullptr;
  exact_.image = image_.data();
  exact_.system = batch ? system_.data() : nullptr;
  exact_.cells = cells_.data();
  set_float_band(exact_, plan.cutoff, rounding_bound(extent));
  publish(plan, xyz_.data(), points, image_.data(), system_.data(), &exact_, counts_.data(),
          reused);
}

}  // namespace

std::unique_ptr<ImagePoints> make_device_image_points() {
  return std::make_unique<DeviceImagePoints>();
}

}  // namespace raycut::detail::cuda
