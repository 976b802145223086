"""Lennard-Jones molecular dynamics with PyTorch autograd forces and raycut neighbour lists.

An open cluster of a few hundred LJ atoms (reduced units: sigma = epsilon = mass = 1), velocity
Verlet. The half neighbour list (each pair once, i < j) comes from pyraycut.neighbor_list("ijD")
with the cutoff plus a skin, rebuilt every `rebuild_every` steps (sooner when an atom has moved
more than skin / 2 since the last build); between builds the pair vectors are x[j] - x[i] of the
same pairs, in PyTorch. Pairs beyond the cutoff are masked in PyTorch; the energy is the sum of the
shifted LJ potential over the list and the forces are -dE/dx by autograd (the positions require
grad: raycut then returns D computed in PyTorch from the pairs, so gradients flow).

Runs on CUDA when torch.cuda.is_available() (and raycut has its CUDA methods), else on the CPU;
prints a line and exits 0 when PyTorch is not installed. Checks that the total energy is
conserved (loosely: float32, a few hundred steps) and prints it.

    python examples/python/lj_md_torch.py [N]
"""
from __future__ import annotations

import math
import sys
import time

import numpy as np

import pyraycut

try:
    import torch
except ImportError:  # the example needs PyTorch; everything else of raycut does not
    torch = None


def fcc_cluster(size: int, seed: int) -> np.ndarray:
    """The `size` sites of an FCC lattice (nearest neighbours at the LJ minimum, 2^(1/6)) nearest
    to its centre: a roughly spherical cluster, slightly jittered."""
    a = 2 ** (1 / 6) * math.sqrt(2)  # lattice constant
    cells = math.ceil((size / 4) ** (1 / 3)) + 2
    g = np.arange(cells)
    corners = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 1, 3)
    basis = np.array([[0, 0, 0], [0.5, 0.5, 0], [0.5, 0, 0.5], [0, 0.5, 0.5]])
    sites = ((corners + basis) * a).reshape(-1, 3)
    sites -= sites.mean(axis=0)
    sites = sites[np.argsort(np.linalg.norm(sites, axis=1), kind="stable")[:size]]
    sites += np.random.default_rng(seed).normal(0, 0.01, sites.shape)
    return sites.astype(np.float32)


def lj_energy(D: "torch.Tensor", cutoff: float) -> "torch.Tensor":
    """The shifted LJ energy 4 (r^-12 - r^-6) - (the same at the cutoff), summed over the pairs of
    the half list within the cutoff (the skin's pairs beyond it contribute nothing)."""
    r2 = (D * D).sum(dim=1)
    inside = r2 < cutoff * cutoff
    inv6 = torch.where(inside, r2, torch.ones_like(r2)).reciprocal() ** 3
    shift = 4.0 * (cutoff ** -12 - cutoff ** -6)
    pair = 4.0 * (inv6 * inv6 - inv6) - shift
    return torch.where(inside, pair, torch.zeros_like(pair)).sum()


class NeighbourList:
    """A half list of the pairs within cutoff + skin, kept while no atom moved more than skin / 2
    since it was built (and at most `rebuild_every` steps)."""

    def __init__(self, cutoff: float, skin: float, rebuild_every: int, method: str):
        self.cutoff, self.skin, self.rebuild_every, self.method = cutoff, skin, rebuild_every, method
        self.i = self.j = self.built_at = None
        self.age = 0
        self.builds = 0

    def vectors(self, x: "torch.Tensor") -> "torch.Tensor":
        """Pair vectors x[j] - x[i] (autograd flows to x), rebuilding the list when due."""
        moved = 0.0
        if self.built_at is not None:
            moved = float((x.detach() - self.built_at).norm(dim=1).max()) if len(x) else 0.0
        if self.i is None or self.age + 1 >= self.rebuild_every or moved > self.skin / 2:
            self.i, self.j, D = pyraycut.neighbor_list("ijD", x, self.cutoff + self.skin,
                                                     half=True, method=self.method)
            self.built_at = x.detach().clone()
            self.age = 0
            self.builds += 1
            return D
        self.age += 1
        return x.index_select(0, self.j) - x.index_select(0, self.i)


def main(size: int = 256, steps: int = 200, dt: float = 0.002, temperature: float = 0.1,
         cutoff: float = 2.5, skin: float = 0.3, rebuild_every: int = 10, seed: int = 0,
         device: str | None = None, tolerance: float = 1e-3) -> dict:
    if torch is None:
        print("lj_md_torch: PyTorch is not installed, skipping")
        return {"skipped": True, "ok": True}
    if device is None:
        device = "cuda" if torch.cuda.is_available() and pyraycut.cuda_available() else "cpu"
    method = "auto" if device != "cpu" else "cell-list"
    torch.manual_seed(seed)

    x = torch.from_numpy(fcc_cluster(size, seed)).to(device)
    v = torch.randn(size, 3, device=device) * math.sqrt(temperature)
    v -= v.mean(dim=0)  # no drift of the cluster
    nlist = NeighbourList(cutoff, skin, rebuild_every, method)

    def forces(x: "torch.Tensor") -> tuple:
        x = x.detach().requires_grad_(True)
        energy = lj_energy(nlist.vectors(x), cutoff)
        (grad,) = torch.autograd.grad(energy, x)
        return energy.detach(), -grad

    potential, f = forces(x)
    energies = []
    start = time.perf_counter()
    for step in range(steps + 1):
        if step > 0:  # velocity Verlet, unit masses
            v = v + 0.5 * dt * f
            x = x + dt * v
            potential, f = forces(x)
            v = v + 0.5 * dt * f
        kinetic = 0.5 * (v * v).sum()
        energies.append((float(potential), float(kinetic)))
    if device != "cpu":
        torch.cuda.synchronize()
    elapsed = time.perf_counter() - start

    e = np.array([p + k for p, k in energies])
    drift = float(np.max(np.abs(e - e[0])) / abs(e[0]))
    ok = bool(np.all(np.isfinite(e))) and drift < tolerance
    result = {"size": size, "steps": steps, "device": device, "method": method,
              "builds": nlist.builds, "e0": float(e[0]), "e_end": float(e[-1]),
              "max_relative_drift": drift, "seconds": elapsed, "skipped": False, "ok": ok}
    print(f"LJ MD: {size} atoms, {steps} steps of {dt:g} on {device} ({method}), cutoff "
          f"{cutoff:g} + skin {skin:g}: {nlist.builds} list builds, "
          f"{elapsed / max(steps, 1) * 1e3:.2f} ms/step")
    for step in sorted({0, steps // 4, steps // 2, 3 * steps // 4, steps}):
        p, k = energies[step]
        print(f"  step {step:5d}  potential {p / size:9.5f}  kinetic {k / size:8.5f}  "
              f"total {(p + k) / size:9.5f}  (per atom)")
    print(f"energy conservation: largest |E - E0| / |E0| = {drift:.2e} (tolerance "
          f"{tolerance:g}): {'OK' if ok else 'FAILED'}")
    return result


if __name__ == "__main__":
    result = main(int(sys.argv[1]) if len(sys.argv) > 1 else 256)
    sys.exit(0 if result["ok"] else 1)
