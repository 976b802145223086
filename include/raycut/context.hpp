// An execution context: the CUDA stream a call queues its work on, and the memory resource it
// allocates its temporaries from. Stream-ordered entry points (raycut/device_pairs.hpp) take one
// on every call and never wait on the host, as CUB's do; a CUDA graph can capture them.
// Host-only header: no CUDA types.
#pragma once

#include <cstddef>

namespace raycut {

// Where a call's device temporaries come from. Memory is stream-ordered: allocate() returns
// memory usable by work queued on `stream` from now on; deallocate() hands it back once the work
// queued on `stream` so far is done, without waiting. PyTorch's caching allocator, CuPy's pool
// and cudaMallocAsync all fit this contract. Implementations throw on failure.
class MemoryResource {
 public:
  virtual ~MemoryResource() = default;
  virtual void* allocate(std::size_t bytes, void* cuda_stream) = 0;
  virtual void deallocate(void* p, std::size_t bytes, void* cuda_stream) noexcept = 0;
};

struct Context {
  // A cudaStream_t; null: the legacy default stream. It must outlive what was allocated through
  // the context (a StaticPairBuffer frees on it when it goes).
  void* stream = nullptr;
  // Null: stream-ordered allocations on `stream` from raycut's own pool of the device, which keeps
  // freed blocks for the next call (capturable in a CUDA graph as allocation nodes).
  MemoryResource* memory = nullptr;
};

}  // namespace raycut
