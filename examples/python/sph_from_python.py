"""SPH density from Python: pyraycut.Engine.compute("sph_density", sph_mass=m) on a block of
particles, checked against a NumPy evaluation of the poly6 kernel,

    density_i = sum_{j != i, |r_ij| < h} m 315 / (64 pi h^9) (h^2 - |r_ij|^2)^3,   h = cutoff

(raycut's SphDensityKernel: the particle's own term, j = i, is not included).

    python examples/python/sph_from_python.py [N]
"""
from __future__ import annotations

import sys
import time

import numpy as np

import pyraycut


def block(size: int, spacing: float, seed: int) -> np.ndarray:
    """About `size` particles on a jittered cubic lattice (a block of fluid at rest)."""
    side = max(1, round(size ** (1 / 3)))
    g = np.arange(side) * spacing
    x = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    x = x + np.random.default_rng(seed).normal(0, 0.05 * spacing, x.shape)
    return x.astype(np.float32)


def density_numpy(x: np.ndarray, mass: float, h: float) -> np.ndarray:
    """The poly6 density in float64, by blocks of rows (brute force, O(N^2))."""
    x64 = x.astype(np.float64)
    poly6 = mass * 315.0 / (64.0 * np.pi * h ** 9)
    out = np.empty(len(x))
    for start in range(0, len(x), 512):
        r2 = np.sum((x64[None, :, :] - x64[start:start + 512, None, :]) ** 2, axis=-1)
        w = np.clip(h * h - r2, 0.0, None) ** 3
        w[np.arange(len(w)), np.arange(start, start + len(w))] = 0.0  # j != i
        out[start:start + 512] = poly6 * w.sum(axis=1)
    return out


def main(size: int = 8_000, spacing: float = 0.01, smoothing: float = 2.0,
         rest_density: float = 1000.0, seed: int = 0, method: str = "auto") -> dict:
    x = block(size, spacing, seed)
    h = smoothing * spacing
    mass = rest_density * spacing ** 3  # one lattice cell of fluid per particle

    engine = pyraycut.Engine(method)
    start = time.perf_counter()
    engine.build(x, cutoff=h)
    rho = engine.compute("sph_density", sph_mass=mass)["density"]
    elapsed = time.perf_counter() - start

    reference = density_numpy(x, mass, h)
    # float32 sums of terms that are all >= 0: a relative error of a few ulps per term.
    scale = np.maximum(reference, reference.max() * 1e-3)
    max_rel = float(np.max(np.abs(rho - reference) / scale)) if len(x) else 0.0
    ok = rho.dtype == np.float32 and rho.shape == (len(x),) and max_rel < 1e-4
    interior = rho[np.all((x > 3 * h) & (x < x.max(axis=0) - 3 * h), axis=1)]

    result = {"size": len(x), "h": h, "mass": mass, "seconds": elapsed,
              "max_relative_error": max_rel,
              "interior_density": float(interior.mean()) if len(interior) else float("nan"),
              "ok": bool(ok)}
    print(f"SPH density: {len(x)} particles, h = {h:g}, m = {mass:g}, {engine.method}, "
          f"{elapsed * 1e3:.2f} ms (build + kernel)")
    print(f"interior density {result['interior_density']:.1f} (rest {rest_density:g}, without "
          f"the self term); largest relative error vs NumPy {max_rel:.2e}: "
          f"{'OK' if ok else 'FAILED'}")
    return result


if __name__ == "__main__":
    result = main(int(sys.argv[1]) if len(sys.argv) > 1 else 8_000)
    sys.exit(0 if result["ok"] else 1)
