// Device helpers of the Python extension, in their own CUDA translation unit (device.cu): the
// extension's host code stays a plain C++ file.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

namespace raycut_py {

// Device memory owned by the Python arrays that wrap it (freed by their capsule).
void* device_alloc(std::size_t bytes);  // throws raycut::Error(out_of_memory)
void device_free(void* p) noexcept;
int current_device();  // the CUDA device of this thread (cudaGetDevice); throws on failure
int current_device_or_none() noexcept;  // the same, or -1 where no device is usable
// dst <- src, both device memory, queued on `stream` (synchronize() before reading dst).
void device_copy(void* dst, const void* src, std::size_t bytes, void* stream);
void synchronize(void* stream);

// A per-particle system index (int32 when !wide, else int64) in device memory, n >= 1, as
// batch= gives it: its first and last values, and the first k with index[k] > index[k + 1]
// (n - 1 when it is sorted), then index[k] and index[k + 1] (0 when sorted). One kernel, one
// read-back, on `stream`.
struct IndexSummary {
  std::int64_t first = 0, last = 0;
  std::uint64_t unsorted = 0;
  std::int64_t here = 0, after = 0;
};
IndexSummary summarise_index(const void* index, bool wide, std::size_t n, void* stream);
// Systems::offsets of a sorted index with values in [0, systems): offsets[s] = the number of
// entries below s, s = 0 .. systems, into host memory (systems + 1 values); on `stream`.
void index_offsets(const void* index, bool wide, std::size_t n, std::size_t systems,
                   std::uint64_t* host_offsets, void* stream);

// A flag the device raises and the host reads without waiting: compare() queues a comparison of
// two device arrays of `bytes` and, where they differ, writes `code` to *count (an int64 in
// device memory) and raises the flag; raised() says whether a finished comparison found a
// difference (one not yet finished counts as none) and lowers it. On a stream being captured
// into a CUDA graph, compare() only queues the comparison (a replay's verdict reaches *count
// alone) and raised() says false without asking the device.
class ChangeFlag {
 public:
  ChangeFlag();
  ~ChangeFlag();
  ChangeFlag(const ChangeFlag&) = delete;
  ChangeFlag& operator=(const ChangeFlag&) = delete;
  void compare(const void* a, const void* b, std::size_t bytes, std::int64_t* count,
               std::int64_t code, void* stream);
  bool raised(void* stream);

 private:
  int* host_ = nullptr;    // mapped pinned memory
  int* device_ = nullptr;  // the same, as the device writes it
  void* done_ = nullptr;   // the event after the last comparison
  bool pending_ = false;
};

}  // namespace raycut_py
