#include "cpu/host_method.hpp"

namespace raycut::detail {
namespace {
template <class T>
T* sized(std::vector<T>& v, std::size_t count, bool wanted) {
  if (!wanted) return nullptr;
  v.assign(count, T{});
  return v.data();
}
}  // namespace

KernelOutputs prepare_host_results(Results& r, Kernel kernel, std::size_t n) {
  const KernelProduces p = produces(kernel);
  return {sized(r.count, n, p.count), sized(r.energy, n, p.energy), sized(r.force, 3 * n, p.force),
          sized(r.virial, 6 * n, p.virial), sized(r.density, n, p.density)};
}

ResultsView view_of(const Results& r) {
  return {data_or_null(r.count),  data_or_null(r.energy),  data_or_null(r.force),
          data_or_null(r.virial), data_or_null(r.density), MemorySpace::host};
}

}  // namespace raycut::detail
