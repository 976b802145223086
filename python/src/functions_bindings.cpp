// pyraycut._raycut's module-level functions: the methods and kernels raycut knows, the CUDA
// device, and (with CUDA) the batch index of a CUDA tensor turned into offsets on the device.
#include <nanobind/stl/string.h>

#include <cmath>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <nanobind/stl/optional.h>

#include "arrays.hpp"
#include "bindings.hpp"
#include "errors.hpp"
#include "raycut/device_pairs.hpp"
#include "raycut/engine.hpp"

#if defined(RAYCUT_PY_CUDA)
#include "device.hpp"
#endif

namespace raycut_py {

namespace {

using HostIndices = nb::ndarray<const std::int64_t, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
template <class S>
using HostShifts =
    nb::ndarray<const S, nb::ndim<2>, nb::shape<-1, 3>, nb::c_contig, nb::device::cpu>;

// r = x_j - x_i + S . cell in float64 for P pairs (i, j, S): targets x_i, sources x_j (N, 3)
// float64, cells (C, 3, 3) with the cell of each pair (`cell_of`, P; none: cells[0]), shifts
// none (open systems). Returns (r (P, 3), |r| (P,)), |r| rounded as NumPy's
// sqrt(sum(r * r, axis=1)): ((x^2 + y^2) + z^2), no FMA. The d and D of float64 inputs in one
// pass over the pairs: NumPy's gathers, products and sums took 5 passes and their temporaries
// (60 % of a float64 list call at 10,000 atoms).
template <class S>
nb::tuple pair_vectors(const HostPositions64& targets, const HostPositions64& sources,
                       const HostIndices& i, const HostIndices& j,
                       const std::optional<HostShifts<S>>& shifts,
                       const std::optional<HostCells>& cells,
                       const std::optional<HostIndices>& cell_of) {
  const std::size_t pairs = i.shape(0), nt = targets.shape(0), ns = sources.shape(0);
  if (targets.shape(1) != 3 || sources.shape(1) != 3)
    value_error("pair_vectors: positions must have shape (N, 3)");
  if (j.shape(0) != pairs || (shifts && shifts->shape(0) != pairs) ||
      (cell_of && cell_of->shape(0) != pairs))
    value_error("pair_vectors: i, j, shifts and cell_of must have one entry per pair");
  if (shifts && (!cells || cells->shape(0) == 0 || cells->shape(1) != 3 || cells->shape(2) != 3))
    value_error("pair_vectors: shifts need cells of shape (C, 3, 3), C >= 1");
  const std::size_t cell_count = cells ? cells->shape(0) : 0;
  std::vector<double> r(3 * pairs), length(pairs);
  {
    nb::gil_scoped_release unlocked;
    const double *xt = targets.data(), *xs = sources.data();
    const std::int64_t *pi = i.data(), *pj = j.data();
    for (std::size_t p = 0; p < pairs; ++p) {
      const std::int64_t a = pi[p], b = pj[p];
      if (a < 0 || static_cast<std::size_t>(a) >= nt || b < 0 || static_cast<std::size_t>(b) >= ns)
        throw raycut::Error(raycut::ErrorCode::invalid_argument,
                            "pair_vectors: pair " + std::to_string(p) + " indexes (" +
                                std::to_string(a) + ", " + std::to_string(b) + ") outside " +
                                std::to_string(nt) + " targets and " + std::to_string(ns) +
                                " sources");
      double v[3];
      for (int c = 0; c < 3; ++c) v[c] = xs[3 * b + c] - xt[3 * a + c];
      if (shifts) {
        const std::int64_t k = cell_of ? cell_of->data()[p] : 0;
        if (k < 0 || static_cast<std::size_t>(k) >= cell_count)
          throw raycut::Error(raycut::ErrorCode::invalid_argument,
                              "pair_vectors: pair " + std::to_string(p) + " has cell " +
                                  std::to_string(k) + " of " + std::to_string(cell_count));
        const double* cell = cells->data() + 9 * k;
        const S* s = shifts->data() + 3 * p;
        for (int c = 0; c < 3; ++c)
          v[c] += static_cast<double>(s[0]) * cell[c] + static_cast<double>(s[1]) * cell[3 + c] +
                  static_cast<double>(s[2]) * cell[6 + c];
      }
      for (int c = 0; c < 3; ++c) r[3 * p + c] = v[c];
      double squares = v[0] * v[0];
      squares += v[1] * v[1];
      squares += v[2] * v[2];
      length[p] = std::sqrt(squares);
    }
  }
  return nb::make_tuple(host_array(std::move(r), {pairs, 3}),
                        host_array(std::move(length), {pairs}));
}

}  // namespace

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
  m.def("prefer_small_systems", &raycut::prefer_small_systems, nb::arg("particles"),
        nb::arg("systems"),
        "Whether the stream-ordered small-system pass serves this many particles in this many "
        "systems (raycut::prefer_small_systems).");
  m.def("pair_vectors", &pair_vectors<std::int32_t>, nb::arg("targets"), nb::arg("sources"),
        nb::arg("i"), nb::arg("j"), nb::arg("shifts").none(), nb::arg("cells").none(),
        nb::arg("cell_of").none(),
        "(r, |r|): r = x_j - x_i + S . cell in float64 for pairs (i, j, S) (int32 or int64 S).");
  m.def("pair_vectors", &pair_vectors<std::int64_t>, nb::arg("targets"), nb::arg("sources"),
        nb::arg("i"), nb::arg("j"), nb::arg("shifts").none(), nb::arg("cells").none(),
        nb::arg("cell_of").none());
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
