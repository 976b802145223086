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
// dst <- src, both device memory, on `stream`, synchronised before returning.
void device_copy(void* dst, const void* src, std::size_t bytes, void* stream);

// COO pairs of a device CSR list: i[e] = the row of entry e, j[e] = indices[e], both int64, on
// `stream` (a cudaStream_t; null: the legacy default stream), synchronised before returning.
void csr_to_coo(const std::uint64_t* offsets, const std::uint32_t* indices, std::size_t n,
                std::uint64_t pairs, std::int64_t* i, std::int64_t* j, void* stream);

}  // namespace raycut_py
