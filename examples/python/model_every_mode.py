"""A learned pair potential in every mode: eager PyTorch, torch.compile, torch.export with
AOTInductor (and its C++ runner), and JAX, all on raycut's periodic neighbour list.

The model (``PairPotential``) is a small message-free machine-learning potential: the energy of a
periodic box is the sum over the pairs within the cutoff of a learnable function of their
distance, a two-layer MLP on Gaussian radial basis functions times a smooth cosine cutoff (0 with
its derivative at the cutoff). The forward pass calls ``pyraycut.neighbor_list("d", x, cutoff,
cell=cell)``: on CPU tensors that is the operator ``torch.ops.raycut.neighbor_list`` (integer
pairs) and distances computed in PyTorch, so forces are ``-dE/dx`` by autograd, in float64.

``main`` runs the whole tour and checks each step:

1. training: a few Adam steps on the energies and forces of a Lennard-Jones reference
   (raycut's fused ``torch.ops.raycut.lj_forces``) on jittered periodic lattices; the loss must
   fall;
2. ``torch.compile(fullgraph=True, dynamic=True)``: energy and forces equal to eager, on two
   sizes of box through one compiled graph;
3. ``torch.export`` with a dynamic number of atoms, packaged by AOTInductor
   (``aoti_compile_and_package``), loaded back and compared with eager on two sizes; the
   package has examples/torch_aoti's signature (``(x, cell) -> energy``), so that runner.cpp
   runs it from C++ (``expected_energy`` gives the value it must print);
4. JAX: the same parameters in ``jax_energy`` (``pyraycut.jax.neighbor_list`` under
   ``jax.jit``, float64), equal to PyTorch's energy.

    python examples/python/model_every_mode.py [atoms per side] [package.pt2]
"""
from __future__ import annotations

import math
import sys
import tempfile
import time
from pathlib import Path
from typing import Optional

import torch

import pyraycut

CUTOFF = 2.5
SPACING, JITTER = 1.1, 0.1  # examples/torch_aoti/runner.cpp's lattice


def lattice(side: int, seed: int, dtype: torch.dtype = torch.float64) -> tuple:
    """A simple cubic lattice of ``side``^3 atoms (spacing 1.1, each jittered by up to +-0.05)
    in its periodic cubic box: (x (N, 3), cell (3, 3)). With seed 7 it is the lattice of
    examples/torch_aoti/runner.cpp (the same generator, the same draws)."""
    generator = torch.Generator().manual_seed(seed)
    grid = torch.arange(side, dtype=torch.float64) * SPACING
    axes = torch.meshgrid(grid, grid, grid, indexing="ij")
    x = torch.stack([a.flatten() for a in axes], 1)
    x = x + JITTER * (torch.rand(side**3, 3, dtype=torch.float64, generator=generator) - 0.5)
    cell = SPACING * side * torch.eye(3, dtype=torch.float64)
    return x.to(dtype), cell.to(dtype)


class PairPotential(torch.nn.Module):
    """E = 1/2 sum over the ordered pairs (i, j, S) within the cutoff of phi(d_ij), with
    phi(d) = MLP(Gaussians(d)) * (cos(pi d / rc) + 1) / 2."""

    def __init__(self, cutoff: float = CUTOFF, basis: int = 8, hidden: int = 16,
                 inner: float = 0.7, seed: int = 0):
        super().__init__()
        torch.manual_seed(seed)
        self.cutoff = cutoff
        self.register_buffer("centres", torch.linspace(inner, cutoff, basis, dtype=torch.float64))
        self.width = (cutoff - inner) / (basis - 1)
        self.mlp = torch.nn.Sequential(torch.nn.Linear(basis, hidden), torch.nn.Tanh(),
                                       torch.nn.Linear(hidden, 1)).double()

    def pair_energy(self, d: torch.Tensor) -> torch.Tensor:
        gaussians = torch.exp(-(((d[:, None] - self.centres) / self.width) ** 2))
        envelope = 0.5 * (torch.cos(math.pi * d / self.cutoff) + 1.0)
        return self.mlp(gaussians).squeeze(-1) * envelope

    def forward(self, x: torch.Tensor, cell: torch.Tensor) -> torch.Tensor:
        d = pyraycut.neighbor_list("d", x, self.cutoff, cell=cell)  # the full list: each pair twice
        return 0.5 * self.pair_energy(d).sum()


def energy_and_forces(model, x: torch.Tensor, cell: torch.Tensor,
                      create_graph: bool = False) -> tuple:
    """(E, F = -dE/dx); ``create_graph`` keeps F differentiable (training on forces)."""
    x = x.detach().requires_grad_(True)
    energy = model(x, cell)
    (grad,) = torch.autograd.grad(energy, x, create_graph=create_graph)
    return (energy, -grad) if create_graph else (energy.detach(), -grad)


def reference(x: torch.Tensor, cell: torch.Tensor) -> tuple:
    """The Lennard-Jones energy and forces (epsilon = sigma = 1, cut at the model's cutoff),
    from raycut's fused pass (float32), as float64 tensors."""
    energy, force, _ = torch.ops.raycut.lj_forces(x, CUTOFF, cell=cell)
    return energy.sum().double(), force.double()


def train(model: PairPotential, configurations: list, steps: int, lr: float = 0.02) -> list:
    """Adam on the energy per atom and the forces (mean squared errors, summed over the
    configurations); returns the loss before each step."""
    targets = [reference(x, cell) for x, cell in configurations]
    optimiser = torch.optim.Adam(model.parameters(), lr=lr)
    losses = []
    for _ in range(steps):
        optimiser.zero_grad()
        loss = torch.zeros((), dtype=torch.float64)
        for (x, cell), (e_ref, f_ref) in zip(configurations, targets):
            e, f = energy_and_forces(model, x, cell, create_graph=True)
            loss = loss + ((e - e_ref) / len(x)) ** 2 + ((f - f_ref) ** 2).mean()
        loss.backward()
        optimiser.step()
        losses.append(float(loss.detach()))
    return losses


def package(model: PairPotential, path: str, side: int = 3) -> str:
    """Exports ``model`` with a dynamic number of atoms and writes its AOTInductor package."""
    x, cell = lattice(side, 1)
    n = torch.export.Dim("n", min=2, max=1 << 24)
    program = torch.export.export(model, (x, cell), dynamic_shapes={"x": {0: n}, "cell": None})
    return torch._inductor.aoti_compile_and_package(program, package_path=path)


def expected_energy(model: PairPotential, side: int) -> float:
    """The energy that examples/torch_aoti/runner.cpp must print for this model's package run on
    its own lattice of ``side``^3 atoms (``torch_aoti_runner package ops side expected``)."""
    with torch.no_grad():
        return float(model(*lattice(side, 7)))


def jax_energy(model: PairPotential, max_pairs: int):
    """The model's energy as a jitted JAX function of (x, cell), float64, with the model's
    current parameters: pyraycut.jax.neighbor_list (static capacity ``max_pairs``; padding
    entries have d = 0 and are masked out). Returns (function, jax module)."""
    import jax
    import jax.numpy as jnp

    import pyraycut.jax as rj

    first, _, last = model.mlp
    w1, b1 = (p.detach().numpy() for p in (first.weight, first.bias))
    w2, b2 = (p.detach().numpy() for p in (last.weight, last.bias))
    centres, width, cutoff = model.centres.numpy(), model.width, model.cutoff

    @jax.jit
    def energy(x, cell):
        i, j, shifts, count = rj.neighbor_list(x, cutoff, cell=cell, max_pairs=max_pairs)
        d = jnp.linalg.norm(rj.vectors(x, i, j, shifts, cell), axis=1)
        real = jnp.arange(max_pairs) < count
        gaussians = jnp.exp(-(((d[:, None] - centres) / width) ** 2))
        phi = (jnp.tanh(gaussians @ w1.T + b1) @ w2.T + b2)[:, 0]
        phi = phi * 0.5 * (jnp.cos(jnp.pi * d / cutoff) + 1.0)
        return 0.5 * jnp.sum(jnp.where(real, phi, 0.0)), count

    return energy, jax


def main(side: int = 4, configurations: int = 3, steps: int = 20,
         package_path: Optional[str] = None, sides: tuple = (3, 4)) -> dict:
    """Trains on ``configurations`` boxes of ``side``^3 atoms, then compares the modes on boxes
    of each of ``sides``^3 atoms; the AOTInductor package is kept at ``package_path`` if given.
    Returns the losses, each mode's largest difference from eager, the seconds of each stage
    and ``ok``."""
    timings = {}
    start = time.perf_counter()
    model = PairPotential()
    data = [lattice(side, seed) for seed in range(100, 100 + configurations)]
    losses = train(model, data, steps)
    timings["train"] = time.perf_counter() - start
    trained = losses[-1] < 0.5 * losses[0]
    print(f"training: {configurations} boxes of {side ** 3} atoms, {steps} Adam steps: loss "
          f"{losses[0]:.4g} -> {losses[-1]:.4g}")

    # The same model in each mode, on boxes of every size in `sides` (one graph for all).
    boxes = [lattice(s, 200 + s) for s in sides]
    eager = [energy_and_forces(model, x, cell) for x, cell in boxes]
    result = {"losses": losses, "trained": trained}

    start = time.perf_counter()
    compiled_model = torch.compile(model, fullgraph=True, dynamic=True)
    compiled = [energy_and_forces(compiled_model, x, cell) for x, cell in boxes]
    result["compiled_energy_error"] = max(abs(float(c[0] - e[0])) for c, e in zip(compiled, eager))
    result["compiled_force_error"] = max(float((c[1] - e[1]).abs().max())
                                         for c, e in zip(compiled, eager))
    timings["compile"] = time.perf_counter() - start
    print(f"torch.compile(fullgraph, dynamic): largest |E - E_eager| "
          f"{result['compiled_energy_error']:.2e}, |F - F_eager| "
          f"{result['compiled_force_error']:.2e}")

    start = time.perf_counter()
    with tempfile.TemporaryDirectory() as scratch:
        path = package(model, package_path or str(Path(scratch) / "model.pt2"))
        loaded = torch._inductor.aoti_load_package(path)
        packaged = [float(loaded(x, cell)) for x, cell in boxes]
    result["aoti_energy_error"] = max(abs(p - float(e[0])) for p, e in zip(packaged, eager))
    timings["aoti"] = time.perf_counter() - start
    print(f"torch.export + AOTInductor package: largest |E - E_eager| "
          f"{result['aoti_energy_error']:.2e}")

    start = time.perf_counter()
    max_pairs = 60 * max(sides) ** 3  # ~50 neighbours an atom within 2.5 at this density
    energy, jax = jax_energy(model, max_pairs)
    errors = []
    with jax.enable_x64(True):
        for (x, cell), e in zip(boxes, eager):
            value, count = energy(jax.numpy.asarray(x.numpy()), jax.numpy.asarray(cell.numpy()))
            if int(count) > max_pairs:  # the list was cut: its energy means nothing
                raise RuntimeError(f"max_pairs = {max_pairs} is short of the {int(count)} pairs")
            errors.append(abs(float(value) - float(e[0])))
    result["jax_energy_error"] = max(errors)
    timings["jax"] = time.perf_counter() - start
    print(f"JAX (jit, float64): largest |E - E_torch| {result['jax_energy_error']:.2e}")

    scale = max(abs(float(e[0])) for e in eager)
    tolerance = 1e-9 * max(scale, 1.0)
    result["energies"] = [float(e[0]) for e in eager]
    result["timings"] = timings
    result["ok"] = bool(trained and result["compiled_energy_error"] <= tolerance
                        and result["compiled_force_error"] <= 1e-9
                        and result["aoti_energy_error"] <= tolerance
                        and result["jax_energy_error"] <= tolerance)
    print(f"seconds: {', '.join(f'{k} {v:.1f}' for k, v in timings.items())}; "
          f"{'OK' if result['ok'] else 'FAILED'}")
    return result


if __name__ == "__main__":
    out = main(int(sys.argv[1]) if len(sys.argv) > 1 else 4,
               package_path=sys.argv[2] if len(sys.argv) > 2 else None)
    sys.exit(0 if out["ok"] else 1)
