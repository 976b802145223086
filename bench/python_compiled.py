#!/usr/bin/env python3
"""A compiled model step against the same step in eager mode, and the operator's own cost: what a
PyTorch user pays for raycut inside ``torch.compile`` (docs/python.md, "Compiled steps").

Workload ``lj-pbc`` (bench/python_latency.py's: a periodic Lennard-Jones liquid, density 0.8442,
cutoff 2.5, float32) at each of ``--sizes``. Rows, in python_latency.py's CSV columns:

- interface ``python-torch-op``, mode ``eager``: ``torch.ops.raycut.neighbor_list`` alone with
  static capacity (``max_pairs`` = 1.25 x the count), the operator beside raycut_latency_bench's
  C++ rows of the same workload;
- interface ``python-torch-step``: an LJ step (the list with static capacity, then energy and
  forces from the pairs, summed with ``index_add_``), in mode ``eager``, ``compiled``
  (``torch.compile(fullgraph=True, dynamic=True)``: one compilation for every size) and, on CUDA,
  ``graph`` (the same with ``mode="reduce-overhead"``: Inductor replays the step as a CUDA graph,
  which a host synchronisation inside it would forbid).

Each compiled step's energy and forces are checked against eager before it is timed; the run
fails (exit 1) on a difference. Timing, warm-up and the profiler's counts as python_latency.py.

    python bench/python_compiled.py --output compiled.csv [--sizes 1000,10000,1048576]

``--device cpu`` runs the same on CPU tensors (no ``graph`` mode, no profiler counts): a check
of the script. Exit codes: 0 done, 1 failure, 2 bad arguments, 77 no CUDA device or no PyTorch.
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Optional

sys.path.insert(0, str(Path(__file__).resolve().parent))
import python_latency as latency  # noqa: E402  (the timing rule, workload, CSV and profiler)


def lj_step(torch):
    """The step as a function of (positions, cell, pbc, max_pairs): energy () and forces (N, 3)
    of LJ with epsilon = sigma = 1 over a full list; padding entries (i = N) weigh nothing."""
    def step(x, cell, pbc, max_pairs: int):
        i, j, shifts, _ = torch.ops.raycut.neighbor_list(x, latency.CUTOFF, cell, pbc, None,
                                                         False, max_pairs)
        n = x.shape[0]
        real = i < n
        i = torch.where(real, i, 0)
        j = torch.where(real, j, 0)
        r = x[j] - x[i] + shifts.to(x.dtype) @ cell
        d2 = torch.where(real, (r * r).sum(1), 1.0)
        inv6 = d2.reciprocal() ** 3
        zero = torch.zeros_like(d2)
        energy = 2.0 * torch.where(real, inv6 * inv6 - inv6, zero).sum()  # 4 x 1/2 (full list)
        magnitude = torch.where(real, 24.0 * (2.0 * inv6 * inv6 - inv6) / d2, zero)
        forces = torch.zeros_like(x).index_add_(0, i, -magnitude[:, None] * r)
        return energy, forces

    return step


def main(argv: Optional[list[str]] = None) -> list[dict]:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", type=latency.parse_sizes, default=[1000, 10000, 100000],
                        help="particles per system (default 1000,10000,100000)")
    args = latency.parse_timing_arguments(parser, argv)
    torch, sync, machine = latency.torch_on_the_device(args, "python_compiled")
    import pyraycut

    if pyraycut._torch_ops() is None:
        print("python_compiled: raycut's PyTorch operators are not built", file=sys.stderr)
        raise SystemExit(77)
    cuda = args.device == "cuda"
    print(f"lj-pbc compiled steps on torch {args.device} tensors ({machine['gpu']}, driver "
          f"{machine['driver']}, CUDA {machine['cuda']}, torch {torch.__version__}), "
          f"{args.reps} reps, loops >= {args.min_loop_ms:g} ms")

    step = lj_step(torch)
    steps = {"eager": step,
             "compiled": torch.compile(step, fullgraph=True, dynamic=True)}
    if cuda:
        steps["graph"] = torch.compile(step, fullgraph=True, dynamic=True,
                                       mode="reduce-overhead")
    generator = torch.Generator().manual_seed(args.seed)
    rows = []
    for n in args.sizes:
        x, cell, _ = latency.workload(torch, 1, n, args.device, generator)
        pbc = torch.ones(3, dtype=torch.bool, device=args.device)
        count = int(torch.ops.raycut.neighbor_list(x, latency.CUTOFF, cell, pbc, None, False,
                                                   None)[3])
        max_pairs = max(math.ceil(1.25 * count), 1)
        calls = {("python-torch-op", "eager"): lambda: torch.ops.raycut.neighbor_list(
            x, latency.CUTOFF, cell, pbc, None, False, max_pairs)}
        want_energy, want_forces = step(x, cell, pbc, max_pairs)
        for mode, function in steps.items():
            def call(function=function, graph=(mode == "graph")):
                if graph:  # each call a new step: the last one's outputs may be overwritten
                    torch.compiler.cudagraph_mark_step_begin()
                return function(x, cell, pbc, max_pairs)

            energy, forces = (t.clone() for t in call())
            scale = float(want_forces.abs().max())
            if not (math.isclose(float(energy), float(want_energy), rel_tol=1e-4) and
                    float((forces - want_forces).abs().max()) <= 1e-4 * scale):
                print(f"python_compiled: {mode} step at {n} particles differs from eager: energy "
                      f"{float(energy)!r} against {float(want_energy)!r}", file=sys.stderr)
                raise SystemExit(1)
            calls[("python-torch-step", mode)] = call
        for (interface, mode), call in calls.items():
            us = latency.median_us_per_call(call, sync, args.reps, args.min_loop_ms)
            kernels, syncs = ("", "")
            if cuda:
                kernels, syncs = latency.profile_counts(torch, call, sync, args.profile_calls)
            rows.append({"workload": "lj-pbc", "systems": 1, "n_per_system": n,
                         "interface": interface, "mode": mode, "capacity": "static",
                         "us_per_call": f"{us:.2f}", "kernels": kernels, "syncs": syncs,
                         **machine})
            print(f"lj-pbc {n:>8} {interface:<18} {mode:<9} {us:10.1f} us"
                  f"{f'  kernels {kernels} syncs {syncs}' if cuda else ''}", flush=True)
    if args.output:
        latency.write_rows(args.output, rows)
    return rows


if __name__ == "__main__":
    main()
