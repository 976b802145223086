// The few CUDA runtime services the host-only engine needs, behind a plain C++ interface.
// Defined in runtime.cu; only compiled in (and only called) when RAYCUT_HAVE_CUDA is defined.
#pragma once

#include <cstddef>
#include <memory>
#include <string>

namespace raycut::detail::cuda {

// True when at least one CUDA device is usable by this process.
bool device_available();

// Index of the first particle with a non-finite coordinate in device memory, or n if none; on
// `stream` (a cudaStream_t), which it synchronises.
std::size_t first_non_finite(const float* device_xyz, std::size_t n, void* stream);

// Copies `bytes` (at most 64) of device memory to `host` through a pinned block of this host
// thread (no pinned allocation per call), after the work queued on `stream` (a cudaStream_t),
// which it synchronises.
void read_back(void* host, const void* device, std::size_t bytes, void* stream);

struct DeviceFree {
  void operator()(void* p) const noexcept;
};
using DeviceMemory = std::unique_ptr<void, DeviceFree>;

// Allocates and copies host -> device, synchronously; throws Error(out_of_memory) when it does
// not fit, saying how much was asked and how much is free.
DeviceMemory upload(const void* host, std::size_t bytes);
void download(void* host, const void* device, std::size_t bytes);
// `bytes` between any two of host and device memory (the direction from the pointers),
// synchronously; nothing when bytes is 0.
void copy(void* to, const void* from, std::size_t bytes);
// A device-to-device copy into new memory, queued on `stream` (a cudaStream_t).
DeviceMemory copy_on_device(const void* device, std::size_t bytes, void* stream);

// True when some particle of `now` is more than `distance` away from its place in `then`, or has
// a non-finite coordinate ((n, 3) device positions): one reduction on `stream`, one flag read
// back.
bool moved_beyond(const float* now, const float* then, std::size_t n, float distance, void* stream);

// Whether `stream` (a cudaStream_t) is being captured into a CUDA graph: work that would tell
// the host something (an event to query, a copy to read) is left out of a capture, whose replays
// report through device memory alone.
bool capturing(void* stream);

// Name of the current device and the CUDA runtime version ("13.0").
std::string device_name();
std::string runtime_version();

}  // namespace raycut::detail::cuda
