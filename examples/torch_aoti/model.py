"""A Lennard-Jones energy whose forward pass calls pyraycut.neighbor_list (the PyTorch operator
underneath), exported with a dynamic number of atoms and compiled into an AOTInductor package
that runner.cpp loads and runs without Python.

    python examples/torch_aoti/model.py energy.pt2      # writes the package
"""
import sys

import torch

import pyraycut

CUTOFF = 2.5
SIGMA = 1.0


class Energy(torch.nn.Module):
    """The LJ energy of every pair within CUTOFF (periodic box ``cell``), float64."""

    def forward(self, x: torch.Tensor, cell: torch.Tensor) -> torch.Tensor:
        d = pyraycut.neighbor_list("d", x, CUTOFF, cell=cell)
        inv6 = (SIGMA / d) ** 6
        return 2.0 * (inv6 * inv6 - inv6).sum()


def package(path: str) -> str:
    """Exports Energy with a dynamic N and writes its AOTInductor package to ``path``."""
    x = torch.rand(64, 3, dtype=torch.float64) * 5.0
    cell = 5.0 * torch.eye(3, dtype=torch.float64)
    n = torch.export.Dim("n", min=2, max=1 << 24)
    program = torch.export.export(Energy(), (x, cell), dynamic_shapes={"x": {0: n}, "cell": None})
    return torch._inductor.aoti_compile_and_package(program, package_path=path)


if __name__ == "__main__":
    print(package(sys.argv[1] if len(sys.argv) > 1 else "energy.pt2"))
    print(f"operators: {pyraycut.load_torch_ops()}")
