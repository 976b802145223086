#!/usr/bin/env python3
"""kNN beside the radius search of the same reach: ``pyraycut.torch.knn(x, x, k)`` and
``knn_graph(x, k)`` on uniform points in a unit cube, against ``pyraycut.torch.radius_graph(x,
r)`` whose r holds k points on average (what the kNN's first round costs at least), on PyTorch
tensors of each device given; on the CPU also SciPy's ``cKDTree(x).query(x, k)`` (the tree
built in the call, as raycut builds its cells; the same k nearest as ``knn(x, x, k)``) where
SciPy is installed.

Each call runs ``--reps`` times after one untimed call, the two calls taking turns (so that a busy
machine slows them alike); CUDA is synchronised around each call. The median and the minimum
wall time go to a CSV (``--out``) with the device, the driver and the versions, and to a table.
Checks that every row has k neighbours.

    python bench/python_knn.py [--device cuda] [--n 1000000] [--k 16] [--reps 5] [--out FILE]
"""
from __future__ import annotations

import argparse
import csv
import math
import os
import platform
import statistics
import time

import torch

import pyraycut
import pyraycut.torch as rc

try:
    from scipy.spatial import cKDTree
except ImportError:  # the peer is optional
    cKDTree = None


def device_name(device: str) -> tuple[str, str]:
    """(the device's name, the driver or the CPU's threads)."""
    if device == "cuda":
        return torch.cuda.get_device_name(), f"driver CUDA {torch.version.cuda}"
    return platform.processor() or platform.machine(), f"{torch.get_num_threads()} threads"


def timed(fn, device: str) -> float:
    if device == "cuda":
        torch.cuda.synchronize()
    start = time.perf_counter()
    fn()
    if device == "cuda":
        torch.cuda.synchronize()
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--device", action="append", choices=["cpu", "cuda"],
                        help="repeatable; default: cuda where there is one, else cpu")
    parser.add_argument("--n", type=int, action="append", help="points (repeatable)")
    parser.add_argument("--k", type=int, action="append", help="neighbours (repeatable)")
    parser.add_argument("--reps", type=int, default=5)
    parser.add_argument("--out", default=None)
    args = parser.parse_args()
    devices = args.device or (["cuda"] if torch.cuda.is_available() else ["cpu"])
    rows = []
    for device in devices:
        name, detail = device_name(device)
        for n in args.n or ([1_000_000] if device == "cuda" else [100_000]):
            x = torch.rand(n, 3, generator=torch.Generator().manual_seed(1)).to(device)
            for k in args.k or [16]:
                r = (3 * k / (4 * math.pi * n)) ** (1 / 3)  # k points on average within r
                edges = rc.knn(x, x, k)
                assert edges.shape[1] == n * k, "a row without its k neighbours"
                graph_edges = rc.radius_graph(x, r).shape[1]
                calls = {"knn": lambda: rc.knn(x, x, k),
                         "knn_graph": lambda: rc.knn_graph(x, k),
                         "radius_graph": lambda: rc.radius_graph(x, r)}
                if device == "cpu" and cKDTree is not None:
                    points = x.numpy()
                    threads = torch.get_num_threads()
                    calls["scipy_ckdtree"] = lambda: cKDTree(points).query(points, k,
                                                                           workers=threads)
                times = {name_: [] for name_ in calls}
                for _ in range(args.reps):
                    for call, fn in calls.items():
                        times[call].append(timed(fn, device))
                for call, t in times.items():
                    rows.append({
                        "device": name, "detail": detail, "n": n, "k": k, "call": call,
                        "edges": graph_edges if call == "radius_graph" else n * k,
                        "ms_median": round(1e3 * statistics.median(t), 3),
                        "ms_min": round(1e3 * min(t), 3), "reps": args.reps,
                        "torch": torch.__version__, "pyraycut": pyraycut.__version__,
                    })
    print(f"{'device':28} {'n':>9} {'k':>4} {'call':>13} {'edges':>10} {'median ms':>10} "
          f"{'min ms':>9}")
    for row in rows:
        print(f"{row['device'][:28]:28} {row['n']:>9} {row['k']:>4} {row['call']:>13} "
              f"{row['edges']:>10} {row['ms_median']:>10} {row['ms_min']:>9}")
    if args.out:
        os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
        with open(args.out, "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=list(rows[0]))
            writer.writeheader()
            writer.writerows(rows)


if __name__ == "__main__":
    main()
