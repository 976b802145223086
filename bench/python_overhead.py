#!/usr/bin/env python3
"""The overhead of raycut's Python API over the same C++ work, at 1,000 particles (the
target: <= 30 us a call).

For each input (NumPy on the host; PyTorch CUDA tensors when torch and a GPU build are there) and
each API call it times many calls, one at a time (median and minimum of the per-call wall times;
a CUDA input is synchronised after each call, and the library synchronises each phase anyway):

- ``count``: ``Engine.compute("count")`` on a built engine, against the extension's own calls
  (``run`` + ``results`` of ``pyraycut._raycut.Engine``, no Python wrapper) and against the C++
  phase time the engine reports (``Engine.timings["compute_ms"]``, wall, synchronised);
- ``build+count``: ``Engine.build`` + ``Engine.compute("count")``, against the extension's
  ``build`` + ``run`` + ``results`` and ``build_ms + compute_ms``;
- ``neighbor_list``: ``pyraycut.neighbor_list("ij", x, cutoff)`` (a new engine, a build, the COO
  pairs), against the extension's ``Engine`` + ``build`` + ``pairs`` (the C++ phases time only
  the build: the pair extraction is not in ``timings``).

``wrapper_us`` = API - extension calls: what the Python layer adds;
``over_cpp_us`` = API - C++ phases: that plus nanobind, argument checks and output wrapping (for
``neighbor_list``: plus the untimed pair extraction); ``over_cpp_loop_us`` = API - the same
engine calls in a C++ loop (``Engine._cpp_loop_us``: [build +] run + results_view, wall per call,
no Python): the issue's overhead "of a Python call over the same C++ call", what
``meets_target`` checks (for ``neighbor_list``, which has no C++ loop: ``wrapper_us``). Writes a CSV (``--out``, default
bench/results/local/python_overhead-<gpu or cpu>.csv, the GPU named in it) and prints a table.

    python bench/python_overhead.py [--n 1000] [--calls 2000] [--method auto] [--out FILE]
"""
from __future__ import annotations

import argparse
import csv
import os
import platform
import statistics
import sys
import time

import numpy as np

import pyraycut
from pyraycut import _arrays

TARGET_US = 30.0


def per_call_us(fns, calls: int, warmup: int, sync=None) -> list:
    """Wall microseconds of each of `calls` calls of each function of fns (after `warmup`
    untimed ones), the functions taking turns call by call (so that a busy machine slows them
    alike): one list of times per function."""
    for _ in range(warmup):
        for fn in fns:
            fn()
    if sync:
        sync()
    times = [[] for _ in fns]
    clock = time.perf_counter_ns
    for _ in range(calls):
        for fn, t in zip(fns, times):
            start = clock()
            fn()
            if sync:
                sync()
            t.append((clock() - start) / 1e3)
    return times


def gpu_name() -> str:
    try:
        import torch

        if torch.cuda.is_available():
            return torch.cuda.get_device_name(0)
    except ImportError:
        pass
    if pyraycut.cuda_available():
        return "CUDA GPU"
    return ""


def inputs(n: int, seed: int) -> list:
    """(label, positions, sync) for each input kind available here."""
    x = np.random.default_rng(seed).random((n, 3)).astype(np.float32)
    out = [("numpy", x, None)]
    try:
        import torch
    except ImportError:
        return out
    if torch.cuda.is_available() and pyraycut.cuda_available():
        out.append(("torch-cuda", torch.from_numpy(x).cuda(), torch.cuda.synchronize))
    return out


def bench_input(label, x, sync, method: str, cutoff: float, calls: int, warmup: int) -> list:
    rows = []
    engine = pyraycut.Engine(method)
    engine.build(x, cutoff)
    like = engine._like
    raw = engine._engine
    host = like.host
    space = engine.space
    pairs = int(np.asarray(_arrays.to_host(engine.compute("count")["count"])).sum())

    def ext_input():  # what the wrapper hands the extension (NumPy: already float32, contiguous)
        return _arrays.prepare(x)[0]

    x_ext = ext_input()

    # In the caller's CUDA device context and stream, as the wrapper sets them; the extension
    # calls timed below run in it too (set once, outside the timed calls).
    with _arrays.device_context(like):
        raw.set_stream(_arrays.stream_of(like))

        def api_count():
            return engine.compute("count")

        def ext_count():
            return raw.compute("count", to_host=host)

        def api_build_count():
            engine.build(x, cutoff)
            return engine.compute("count")

        def ext_build_count():
            raw.build(x_ext, cutoff)
            return raw.compute("count", to_host=host)

        def api_list():
            return pyraycut.neighbor_list("ij", x, cutoff, method=method)

        def ext_list():
            e = pyraycut._raycut.Engine(method)
            e.set_stream(_arrays.stream_of(like))
            e.build(x_ext, cutoff)
            return e.pairs(False, False, False, host)

        cases = [("count", api_count, ext_count, ("compute_ms",)),
                 ("build+count", api_build_count, ext_build_count, ("build_ms", "compute_ms")),
                 ("neighbor_list", api_list, ext_list, ("build_ms",))]
        for name, api, ext, phases in cases:
            cpp_t = []
            if name != "neighbor_list":  # the engine's own C++ phase times, call by call

                def timed(ext=ext):
                    ext()
                    t = raw.timings()
                    cpp_t.append(sum(t[p] for p in phases) * 1e3)
            else:
                e = pyraycut._raycut.Engine(method)

                def timed(e=e):  # the build of neighbor_list, timed by an engine of its own
                    e.set_stream(_arrays.stream_of(like))
                    e.build(x_ext, cutoff)
                    e.pairs(False, False, False, host)
                    cpp_t.append(e.timings()["build_ms"] * 1e3)
            api_t, ext_t, _ = per_call_us((api, ext, timed), calls, warmup, sync)
            cpp_t = cpp_t[warmup:]
            api_med, ext_med = statistics.median(api_t), statistics.median(ext_t)
            cpp_med = statistics.median(cpp_t)
            loop_med = float("nan")
            if name != "neighbor_list":  # the same calls in a C++ loop: no Python at all
                loop = raw._cpp_loop_us(x_ext, cutoff, "count", name == "build+count",
                                        warmup + calls)
                loop_med = statistics.median(loop[warmup:])
            rows.append({
                "input": label, "method": engine.method, "space": space, "api": name,
                "n": len(x_ext), "cutoff": cutoff, "pairs": pairs, "calls": calls,
                "api_us_median": round(api_med, 2), "api_us_min": round(min(api_t), 2),
                "ext_us_median": round(ext_med, 2), "ext_us_min": round(min(ext_t), 2),
                "cpp_us_median": round(cpp_med, 2), "cpp_phases": "+".join(phases),
                "wrapper_us": round(api_med - ext_med, 2),
                "over_cpp_us": round(api_med - cpp_med, 2),
                "cpp_loop_us_median": round(loop_med, 2),
                "over_cpp_loop_us": round(api_med - loop_med, 2),
                "target_us": TARGET_US,
                # Against the C++ loop where there is one (the "same C++ call"), else
                # against the extension's calls.
                "meets_target": (api_med - (loop_med if loop_med == loop_med else ext_med)
                                 <= TARGET_US),
            })
    return rows


def main(argv=None) -> list:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--n", type=int, default=1000)
    p.add_argument("--cutoff", type=float, default=None,
                   help="default: about 30 neighbours each in the unit box")
    p.add_argument("--calls", type=int, default=2000)
    p.add_argument("--warmup", type=int, default=50)
    p.add_argument("--method", action="append",
                   help="repeatable; default: auto (and cell-list on a GPU build, for NumPy)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default=None)
    args = p.parse_args(argv)
    cutoff = args.cutoff or (30 / (4 / 3 * np.pi * args.n)) ** (1 / 3)
    gpu = gpu_name()
    rows = []
    for label, x, sync in inputs(args.n, args.seed):
        methods = args.method or ["auto"]
        if not args.method and label == "numpy" and pyraycut.auto_method() != "cell-list":
            methods = ["auto", "cell-list"]  # NumPy on the GPU (copies) and on the CPU
        for method in methods:
            try:
                rows += bench_input(label, x, sync, method, cutoff, args.calls, args.warmup)
            except (NotImplementedError, ValueError) as e:
                print(f"skipped {label} on {method}: {e}", file=sys.stderr)
    for row in rows:
        row["gpu"] = gpu
        row["cpu"] = platform.processor() or platform.machine()
        row["threads"] = os.cpu_count()

    out = args.out or os.path.join(os.path.dirname(os.path.abspath(__file__)), "results",
                                   "local", "python_overhead-" +
                                   ("".join(c if c.isalnum() else "-" for c in gpu).lower()
                                    if gpu else "cpu") + ".csv")
    os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
    if rows:
        with open(out, "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=list(rows[0]))
            writer.writeheader()
            writer.writerows(rows)

    print(f"raycut Python overhead, N = {args.n}, cutoff {cutoff:.4g}, {args.calls} calls each, "
          f"{gpu or 'no GPU'} (target: API - C++ loop <= {TARGET_US:g} us)")
    header = (f"{'input':<11} {'method':<11} {'api':<14} {'api us':>9} {'ext us':>9} "
              f"{'C++ us':>9} {'C++ loop':>9} {'wrapper':>8} {'over loop':>9}  ok")
    print(header)
    print("-" * len(header))
    for r in rows:
        print(f"{r['input']:<11} {r['method']:<11} {r['api']:<14} {r['api_us_median']:>9.1f} "
              f"{r['ext_us_median']:>9.1f} {r['cpp_us_median']:>9.1f} "
              f"{r['cpp_loop_us_median']:>9.1f} {r['wrapper_us']:>8.1f} "
              f"{r['over_cpp_loop_us']:>9.1f}  {'yes' if r['meets_target'] else 'NO'}")
    print("api: the Python call; ext: the same extension calls without the wrapper; C++: the "
          "engine's phase times (neighbor_list: the build only); C++ loop: build + run + "
          "results_view in a C++ loop, wall per call (the target's reference). Medians.")
    print(f"wrote {out}")
    return rows


if __name__ == "__main__":
    main()
