// Runs the AOTInductor package of model.py (a Lennard-Jones energy that calls raycut's PyTorch
// operator) from C++, without Python, and checks it against the same energy computed here by
// calling torch.ops.raycut.neighbor_list through the dispatcher.
//
//   torch_aoti_runner energy.pt2 path/to/pyraycut/_torch_ops.so [atoms per side [expected]]
//
// Loading _torch_ops.so registers the operators with the dispatcher, where the package's code
// finds them. Prints the energies and pair count; exits 1 when they disagree. Any package of a
// model `(x, cell) -> energy` runs here; for one that is not model.py's Lennard-Jones energy (a
// learned potential: examples/python/model_every_mode.py), pass the energy it must give on this
// lattice as `expected`, which then replaces the direct Lennard-Jones value in the check.
#include <ATen/ATen.h>
#include <ATen/core/dispatch/Dispatcher.h>
#include <dlfcn.h>
#include <torch/csrc/inductor/aoti_package/model_package_loader.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <optional>
#include <string>
#include <tuple>

namespace {

constexpr double cutoff = 2.5, sigma = 1.0;  // model.py's

using Pairs = std::tuple<at::Tensor, at::Tensor, at::Tensor, at::Tensor>;
using NeighborList = Pairs(const at::Tensor&, double, const std::optional<at::Tensor>&,
                           const std::optional<at::Tensor>&, const std::optional<at::Tensor>&, bool,
                           std::optional<std::int64_t>);

}  // namespace

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr, "usage: %s energy.pt2 _torch_ops.so [atoms per side [expected]]\n",
                 argv[0]);
    return 2;
  }
  if (dlopen(argv[2], RTLD_NOW | RTLD_GLOBAL) == nullptr) {
    std::fprintf(stderr, "error: cannot load %s: %s\n", argv[2], dlerror());
    return 2;
  }
  const int side = argc > 3 ? std::atoi(argv[3]) : 6;
  if (side < 2) {
    std::fprintf(stderr, "error: atoms per side must be >= 2, got %s\n", argv[3]);
    return 2;
  }
  std::optional<double> expected;
  if (argc > 4) {
    char* end = nullptr;
    expected = std::strtod(argv[4], &end);
    if (end == argv[4] || *end != '\0' || !std::isfinite(*expected)) {
      std::fprintf(stderr, "error: expected energy must be a finite number, got %s\n", argv[4]);
      return 2;
    }
  }
  // A jittered simple cubic lattice of spacing 1.1 in its periodic box.
  const double spacing = 1.1, edge = spacing * side;
  at::manual_seed(7);
  const at::Tensor grid = at::arange(side, at::kDouble) * spacing;
  const std::vector<at::Tensor> axes = at::meshgrid({grid, grid, grid}, "ij");
  const at::Tensor x = at::stack({axes[0].flatten(), axes[1].flatten(), axes[2].flatten()}, 1) +
                       0.1 * (at::rand({side * side * side, 3}, at::kDouble) - 0.5);
  const at::Tensor cell = edge * at::eye(3, at::kDouble);

  torch::inductor::AOTIModelPackageLoader loader(argv[1]);
  const double packaged = loader.run({x, cell})[0].item<double>();

  const auto neighbor_list = c10::Dispatcher::singleton()
                                 .findSchemaOrThrow("raycut::neighbor_list", "")
                                 .typed<NeighborList>();
  const auto [i, j, shifts, count] =
      neighbor_list.call(x, cutoff, cell, std::nullopt, std::nullopt, false, std::nullopt);
  const at::Tensor r =
      x.index_select(0, j) - x.index_select(0, i) + shifts.to(at::kDouble).matmul(cell);
  const at::Tensor inv6 = (sigma / r.norm(2, {1})).pow(6);
  const double direct = expected.value_or((2.0 * (inv6 * inv6 - inv6).sum()).item<double>());

  const bool agree = std::abs(packaged - direct) <= 1e-9 * std::max(1.0, std::abs(direct));
  std::printf("atoms %lld pairs %lld packaged %.12g %s %.12g %s\n",
              static_cast<long long>(x.size(0)), static_cast<long long>(count.item<std::int64_t>()),
              packaged, expected ? "expected" : "direct", direct, agree ? "ok" : "DISAGREE");
  return agree ? 0 : 1;
}
