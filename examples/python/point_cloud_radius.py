"""Radius search on a random point cloud with NumPy: every neighbour within a radius of every
point, as pyraycut.neighbor_list returns it on the host, checked against a brute force on a subset
of the points.

    python examples/python/point_cloud_radius.py [N]
"""
from __future__ import annotations

import sys
import time

import numpy as np

import pyraycut


def brute_force_rows(x: np.ndarray, queries: np.ndarray, radius: float, band: float) -> tuple:
    """For each query point: the sure neighbours (further than `band` inside the radius) and the
    ambiguous ones (within `band` of the radius, where float32 rounding may decide either way)."""
    x64 = x.astype(np.float64)
    sure, ambiguous = [], []
    for q in queries:
        r = np.linalg.norm(x64 - x64[q], axis=1)
        r[q] = np.inf  # no self pair
        sure.append(set(np.flatnonzero(r < radius * (1 - band)).tolist()))
        ambiguous.append(set(np.flatnonzero(np.abs(r - radius) <= radius * band).tolist()))
    return sure, ambiguous


def main(size: int = 20_000, radius: float | None = None, subset: int = 200, seed: int = 0,
         method: str = "auto") -> dict:
    rng = np.random.default_rng(seed)
    # A point cloud: a noisy sphere shell plus uniform clutter, in a unit box.
    n_shell = size * 3 // 4
    directions = rng.normal(size=(n_shell, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    shell = 0.5 + 0.35 * directions + rng.normal(0, 0.01, (n_shell, 3))
    clutter = rng.random((size - n_shell, 3))
    x = np.concatenate([shell, clutter]).astype(np.float32)
    if radius is None:
        radius = 1.0 / size ** (1 / 3)  # a few tens of neighbours on the shell

    start = time.perf_counter()
    i, j, d = pyraycut.neighbor_list("ijd", x, radius, method=method)
    elapsed = time.perf_counter() - start
    counts = np.bincount(i, minlength=size)
    offsets = np.concatenate([[0], np.cumsum(counts)])  # i is sorted: rows are contiguous

    queries = rng.choice(size, size=min(subset, size), replace=False)
    band = 1e-5
    sure, ambiguous = brute_force_rows(x, queries, radius, band)
    mismatches = 0
    for q, want, maybe in zip(queries, sure, ambiguous):
        got = set(j[offsets[q]:offsets[q + 1]].tolist())
        if not (want <= got and got <= want | maybe):
            mismatches += 1
    # Distances: |x_j - x_i| of the pairs, in float32.
    d_ref = np.linalg.norm(x[j].astype(np.float64) - x[i].astype(np.float64), axis=1)
    max_d_error = float(np.max(np.abs(d - d_ref))) if len(d) else 0.0
    ok = mismatches == 0 and max_d_error < 1e-5 * max(radius, 1.0) and bool(np.all(d < radius))

    result = {"size": size, "radius": radius, "pairs": int(len(i)),
              "mean_neighbours": float(counts.mean()) if size else 0.0,
              "max_neighbours": int(counts.max()) if size else 0, "seconds": elapsed,
              "checked": int(len(queries)), "mismatches": mismatches,
              "max_distance_error": max_d_error, "ok": ok}
    print(f"point cloud: {size} points, radius {radius:.4g}, {len(i)} ordered pairs "
          f"(mean {result['mean_neighbours']:.1f}, max {result['max_neighbours']} neighbours) "
          f"in {elapsed * 1e3:.2f} ms ({pyraycut.auto_method() if method == 'auto' else method})")
    print(f"brute force on {len(queries)} points: {mismatches} mismatching rows, "
          f"largest distance error {max_d_error:.2e}: {'OK' if ok else 'FAILED'}")
    return result


if __name__ == "__main__":
    result = main(int(sys.argv[1]) if len(sys.argv) > 1 else 20_000)
    sys.exit(0 if result["ok"] else 1)
