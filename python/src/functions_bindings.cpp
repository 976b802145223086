// pyraycut._raycut's module-level functions: the methods and kernels raycut knows, the CUDA
// device, and (with CUDA) the batch index of a CUDA tensor turned into offsets on the device.
#include <nanobind/stl/string.h>

#include <cstdint>
#include <vector>

#include "arrays.hpp"
#include "bindings.hpp"
#include "raycut/engine.hpp"

#if defined(RAYCUT_PY_CUDA)
#include "device.hpp"
#endif

namespace raycut_py {

void bind_functions(nb::module_& m) {
  m.def(
      "methods",
      [] {
        nb::list out;
        for (const auto& d : raycut::list_methods()) {
          nb::dict row;
          row["name"] = d.name;
          row["summary"] = d.summary;
          row["available"] = d.available;
          row["why"] = d.why_unavailable;
          out.append(row);
        }
        return out;
      },
      "Every method raycut knows, available here or not.");
  m.def("kernel_catalogue", &kernel_catalogue,
        "The built-in kernels: name, parameters, per-particle inputs and outputs of each.");
  m.def("auto_method", &raycut::auto_method, "What method='auto' picks on this machine.");
  m.def("cuda_device_available", &raycut::cuda_device_available);
  m.def(
      "current_device",
      [] {
#if defined(RAYCUT_PY_CUDA)
        return raycut_py::current_device_or_none();
#else
        return -1;
#endif
      },
      "The CUDA device current in this thread (where a GPU method allocates), -1 without one.");
  m.attr("has_cuda") =
#if defined(RAYCUT_PY_CUDA)
      true;
#else
      false;
#endif

#if defined(RAYCUT_PY_CUDA)
  // batch= as a CUDA tensor: checked and turned into offsets on the device (python/pyraycut/
  // _systems.py), only a summary and the offsets read back.
  m.def(
      "device_index_summary",
      [](nb::handle index, std::uintptr_t stream) {
        const DeviceIndex in = device_index(index);
        raycut_py::IndexSummary s;
        {
          nb::gil_scoped_release release;
          s = raycut_py::summarise_index(in.data, in.wide, in.n, reinterpret_cast<void*>(stream));
        }
        return nb::make_tuple(s.first, s.last, s.unsorted, s.here, s.after);
      },
      nb::arg("index"), nb::arg("stream"),
      "(first, last, k, index[k], index[k + 1]) of a 1-D int32/int64 CUDA array of N >= 1 "
      "entries: k the first place it decreases (N - 1 when sorted).");
  m.def(
      "device_index_offsets",
      [](nb::handle index, std::size_t systems, std::uintptr_t stream) {
        const DeviceIndex in = device_index(index);
        std::vector<std::uint64_t> offsets(systems + 1);
        {
          nb::gil_scoped_release release;
          raycut_py::index_offsets(in.data, in.wide, in.n, systems, offsets.data(),
                                   reinterpret_cast<void*>(stream));
        }
        return host_array(std::move(offsets), {systems + 1});
      },
      nb::arg("index"), nb::arg("systems"), nb::arg("stream"),
      "Systems offsets (S + 1, uint64) of a sorted 1-D int32/int64 CUDA index with values in "
      "[0, S).");
#endif
}

}  // namespace raycut_py
