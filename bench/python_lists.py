#!/usr/bin/env python3
"""Neighbour lists from Python against the same C++ call, on the workloads of docs/benchmarks.md,
"Neighbour lists" (the goal: Python within 10 % of C++).

Workloads (``--tiny``: the same shapes, small enough for the CPU in a few seconds):

- ``lj-pbc-full``: LJ liquid, 2^20 particles uniform random in a periodic cube at density 0.8442,
  rc = 2.5: the full list with image shifts, ``neighbor_list("ijS", x, 2.5, cell, pbc=True)``;
- ``lj-pbc-half``: the same, ``half=True``;
- ``batch-pbc``: 512 periodic cubes of 128 particles (side 5.33 < 2 rc: several images), one
  batch, one cell for all: ``neighbor_list("ijS", x, 2.5, cell, pbc=True, batch=batch)`` (a
  CUDA batch index for CUDA input: turned into offsets on the device);
- ``uniform-open``: the paper's uniform beta = 32, p = 32 box (1M particles in [0, 1)^3, cutoff
  1/32), not periodic: ``neighbor_list("ij", x, 1/32)``.

For each, these variants take turns call by call (so that a busy machine slows them alike):

- ``cpp_list``: the C++ call of neighbour_bench's list_full_s / list_half_s / list_full,
  through the bound engine (``pyraycut._raycut.Engine``, no Python layer): ``build`` +
  ``neighbours`` into a fresh CSR buffer, one engine reused from call to call;
- ``cpp_pairs``: the same engine's ``build`` + ``pairs``: the CSR expanded to the COO
  ``i, j (, S)`` that ``neighbor_list`` returns, still without the Python layer;
- ``python``: ``pyraycut.neighbor_list`` as a user calls it (engine cache on, the default);
- ``python_csr``: ``pyraycut.Engine.build`` + ``Engine.neighbours`` (CSR, with shifts where the
  workload has them): the C++ call's own output through the Python API, against ``cpp_list``;
- ``python_nocache``: the same with ``pyraycut.set_engine_cache(False)``: a fresh engine per call,
  its structure buffers allocated and freed every call.

Timing: CUDA events on the current stream around each call for CUDA input (the library
synchronises before returning), wall clock otherwise; ``--reps`` timed calls (>= 5) after
``--warmup``; medians. Every row also carries the C++ engine's own build time of the same call
(``engine_build_ms``, ``Engine.timings``: CUDA events for GPU methods). ``--native CSV`` adds the
standalone C++ figures of neighbour_bench (its "cold" and "prepared" medians for the same
workload, operation and method) beside them.

Writes a CSV (``--out``; default bench/results/local/python_lists-<gpu or cpu>.csv, the GPU named
on every row) and a markdown table (``--md``; default: the CSV's name with .md), and prints it.

    python bench/python_lists.py                      # the full sizes (GPU)
    python bench/python_lists.py --tiny               # a few seconds on the CPU
    python bench/python_lists.py --native nb.csv      # with neighbour_bench's figures
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
from pyraycut import _arrays, _systems

DENSITY, RC = 0.8442, 2.5
GOAL = 1.10  # Python within 10 % of C++


def workloads(tiny: bool) -> list:
    """(name, N, systems, cutoff, quantities, half, periodic)."""
    lj = 1 << 12 if tiny else 1 << 20
    systems = 8 if tiny else 512
    beta, p = (8, 4) if tiny else (32, 32)
    return [
        ("lj-pbc-full", lj, 1, RC, "ijS", False, True),
        ("lj-pbc-half", lj, 1, RC, "ijS", True, True),
        ("batch-pbc", systems * 128, systems, RC, "ijS", False, True),
        ("uniform-open", p * beta ** 3, 1, 1.0 / beta, "ij", False, False),
    ]


# neighbour_bench's (suite, param, p, operation) of each workload, for --native.
NATIVE = {
    "lj-pbc-full": ("lj-liquid-pbc", "list_full_s"),
    "lj-pbc-half": ("lj-liquid-pbc", "list_half_s"),
    "batch-pbc": ("batch-pbc", "list_full_s"),
    "uniform-open": ("uniform", "list_full"),
}


class Input:
    """Positions (and batch index) of one workload, in the framework the run uses."""

    def __init__(self, name, n, systems, cutoff, quantities, half, periodic, torch, seed):
        self.name, self.n, self.systems, self.cutoff = name, n, systems, cutoff
        self.quantities, self.half, self.periodic = quantities, half, periodic
        rng = np.random.default_rng(seed)
        per_system = n // systems
        side = (per_system / DENSITY) ** (1 / 3) if periodic else 1.0
        x = (rng.random((n, 3)) * side).astype(np.float32)
        batch = np.repeat(np.arange(systems), per_system) if systems > 1 else None
        self.cell = [side] * 3 if periodic else None
        self.pbc = True if periodic else None
        self.torch = torch
        if torch is not None:
            self.x = torch.from_numpy(x).cuda()
            self.batch = None if batch is None else torch.from_numpy(batch).cuda()
        else:
            self.x, self.batch = x, batch
        # What the bound engine takes: the Python layer's own conversions, made once here.
        boxes = _systems.boxes(self.cell, self.pbc)
        b = _systems.batch(boxes, n, self.batch)
        self.cells = boxes.cells if periodic else None
        self.flags = boxes.pbc if periodic else None
        self.offsets = b.offsets


def make_variants(inp: Input, method: str) -> tuple:
    """name -> a function doing one call and returning (its outputs, the index of an array with
    one entry per pair); the bound engine; where the outputs live."""
    like = _arrays.prepare(inp.x)[1]
    stream = _arrays.stream_of(like)
    engine = pyraycut._raycut.Engine(method)
    shifts = "S" in inp.quantities

    def cpp_list():
        engine.set_stream(stream)
        engine.build(inp.x, inp.cutoff, inp.cells, inp.flags, inp.offsets)
        return engine.neighbours(inp.half, False, False, False, shifts), 1

    def cpp_pairs():
        engine.set_stream(stream)
        engine.build(inp.x, inp.cutoff, inp.cells, inp.flags, inp.offsets)
        return engine.pairs(inp.half, False, False, False, shifts), 0

    def python():
        return pyraycut.neighbor_list(inp.quantities, inp.x, inp.cutoff, cell=inp.cell,
                                    pbc=inp.pbc, batch=inp.batch, half=inp.half,
                                    method=method), 0

    py_engine = pyraycut.Engine(method)

    def python_csr():  # the C++ call's own format (CSR) through the Python API
        py_engine.build(inp.x, inp.cutoff, cell=inp.cell, pbc=inp.pbc, batch=inp.batch)
        return py_engine.neighbours(half=inp.half, shifts=shifts), 1

    # python_nocache is timed in a loop of its own (time_variants' `cache`): turning the cache
    # off drops the cached engine, which would make every `python` call a cold one.
    return ({"cpp_list": cpp_list, "cpp_pairs": cpp_pairs, "python": python,
             "python_csr": python_csr}, {
        "python_nocache": python}, engine, like)


def entries(out: tuple, k: int, like) -> int:
    """The length of out[k] (the extension's device arrays through the caller's framework:
    a zero-copy view), read after the timing."""
    return int(_arrays.output(out[k], like).shape[0])


def time_variants(variants: dict, engine, like, torch, reps: int, warmup: int,
                  cache: bool = True) -> dict:
    """name -> (times ms, wall ms, engine build ms, pair counts), with neighbor_list's engine
    cache on or off. Outputs are counted and freed outside the timing."""
    pyraycut.set_engine_cache(cache)
    out = {name: ([], [], [], []) for name in variants}
    for rep in range(warmup + reps):
        for name, fn in variants.items():
            ms, wall, build_ms, pairs = out[name]
            if torch is not None:
                start, stop = torch.cuda.Event(enable_timing=True), torch.cuda.Event(
                    enable_timing=True)
                torch.cuda.synchronize()
                t0 = time.perf_counter()
                start.record()
                result, k = fn()
                stop.record()
                stop.synchronize()
                t1 = time.perf_counter()
                elapsed = start.elapsed_time(stop)
            else:
                t0 = time.perf_counter()
                result, k = fn()
                t1 = time.perf_counter()
                elapsed = (t1 - t0) * 1e3
            count = entries(result, k, like)
            del result
            if rep < warmup:
                continue
            ms.append(elapsed)
            wall.append((t1 - t0) * 1e3)
            pairs.append(count)
            if name.startswith("cpp"):
                t = engine.timings()
                build_ms.append(t["device_build_ms"] if t["device_build_ms"] >= 0 else
                                t["build_ms"])
    pyraycut.set_engine_cache(True)
    return out


def read_native(path: str) -> dict:
    """(suite, param, operation, method, mode) -> neighbour_bench's median ms."""
    found = {}
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            key = (row["suite"], row["param"], row["p"], row["operation"], row["method"],
                   row["mode"])
            found[key] = float(row["ms"]) if row["ms"] else float("nan")
    return found


def native_key(inp: Input, method: str, mode: str) -> tuple:
    suite, op = NATIVE[inp.name]
    if suite == "uniform":
        beta = round(1.0 / inp.cutoff)
        return (suite, str(beta), str(inp.n // beta ** 3), op, method, mode)
    if suite == "batch-pbc":
        return (suite, str(inp.systems), str(inp.n // inp.systems), op, method, mode)
    return (suite, "1", str(inp.n), op, method, mode)


def gpu_name(torch) -> str:
    if torch is not None:
        return torch.cuda.get_device_name(0)
    return "none"


def cuda_torch():
    """torch when CUDA input can be used here (torch with CUDA and raycut's CUDA methods)."""
    try:
        import torch
    except ImportError:
        return None
    if torch.cuda.is_available() and pyraycut.cuda_available():
        return torch
    return None


def fmt(v: float, digits: int = 3) -> str:
    return "" if v != v else f"{v:.{digits}f}"


def table(rows: list, native: bool) -> str:
    """The markdown table: one line per workload."""
    by = {}
    for r in rows:
        by.setdefault(r["workload"], {})[r["variant"]] = r
    head = ["workload", "input", "method", "N", "pairs", "C++ list ms", "C++ pairs ms",
            "Python ms", "Python CSR ms", "Python no cache ms", "Python / C++ list",
            "Python / C++ pairs", "Python CSR / C++ list"]
    if native:
        head += ["native cold ms", "native prepared ms", "Python / native prepared",
                 "Python CSR / native prepared"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for name, v in by.items():
        py, cl, cp, csr = v["python"], v["cpp_list"], v["cpp_pairs"], v["python_csr"]
        cells = [name, py["input"], py["method"], str(py["n"]), str(py["pairs"]), fmt(cl["ms"]),
                 fmt(cp["ms"]), fmt(py["ms"]), fmt(csr["ms"]), fmt(v["python_nocache"]["ms"]),
                 fmt(py["ms"] / cl["ms"], 2), fmt(py["ms"] / cp["ms"], 2),
                 fmt(csr["ms"] / cl["ms"], 2)]
        if native:
            prepared = py["native_prepared_ms"]
            ratio = (lambda a: fmt(a / prepared if prepared == prepared else float("nan"), 2))
            cells += [fmt(py["native_cold_ms"]), fmt(prepared), ratio(py["ms"]),
                      ratio(csr["ms"])]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv=None) -> list:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--tiny", action="store_true", help="small inputs (the CPU, CI)")
    p.add_argument("--reps", type=int, default=None, help="timed calls (default 10; tiny 5)")
    p.add_argument("--warmup", type=int, default=2)
    p.add_argument("--method", default="auto")
    p.add_argument("--workload", action="append", help="repeatable; default: all four")
    p.add_argument("--numpy", action="store_true", help="NumPy input even where CUDA is here")
    p.add_argument("--native", default=None, help="neighbour_bench CSV of the same machine")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--out", default=None)
    p.add_argument("--md", default=None)
    args = p.parse_args(argv)
    reps = args.reps or (5 if args.tiny else 10)
    if reps < 1:
        p.error("--reps must be >= 1")
    torch = None if args.numpy else cuda_torch()
    gpu = gpu_name(torch)
    native = read_native(args.native) if args.native else None
    known = [w[0] for w in workloads(args.tiny)]
    for w in args.workload or []:
        if w not in known:
            p.error(f"unknown workload {w!r} (known: {', '.join(known)})")

    rows = []
    for spec in workloads(args.tiny):
        if args.workload and spec[0] not in args.workload:
            continue
        inp = Input(*spec, torch=torch, seed=args.seed)
        variants, uncached, engine, like = make_variants(inp, args.method)
        try:
            measured = time_variants(variants, engine, like, torch, reps, args.warmup)
            measured.update(time_variants(uncached, engine, like, torch, reps, args.warmup,
                                          cache=False))
        except (NotImplementedError, ValueError) as e:
            print(f"skipped {inp.name} on {args.method}: {e}", file=sys.stderr)
            continue
        counts = {c for _, _, _, pairs in measured.values() for c in pairs}
        for name, (ms, wall, build_ms, pairs) in measured.items():
            row = {
                "workload": inp.name, "input": "torch-cuda" if torch else "numpy",
                "method": engine.method, "n": inp.n, "systems": inp.systems,
                "cutoff": round(inp.cutoff, 6), "quantities": inp.quantities, "half": inp.half,
                "periodic": inp.periodic, "variant": name, "ms": statistics.median(ms),
                "min": min(ms), "max": max(ms), "wall_ms": statistics.median(wall),
                "engine_build_ms": statistics.median(build_ms) if build_ms else float("nan"),
                "pairs": pairs[0], "check": "ok" if len(counts) == 1 else "MISMATCH",
                "reps": len(ms), "clock": "cuda-events" if torch else "wall", "gpu": gpu,
                "cpu": f"{platform.processor() or platform.machine()} x{os.cpu_count()}",
            }
            if native is not None:
                for mode in ("cold", "prepared"):
                    row[f"native_{mode}_ms"] = native.get(native_key(inp, engine.method, mode),
                                                          float("nan"))
            rows.append(row)
        del inp, variants, engine
        pyraycut.clear_engine_cache()

    slug = "".join(c if c.isalnum() else "-" for c in gpu).lower() if torch else "cpu"
    out = args.out or os.path.join(os.path.dirname(os.path.abspath(__file__)), "results",
                                   "local", f"python_lists-{slug}{'-tiny' if args.tiny else ''}"
                                   ".csv")
    md = args.md or os.path.splitext(out)[0] + ".md"
    os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
    if rows:
        with open(out, "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=list(rows[0]))
            writer.writeheader()
            for r in rows:
                writer.writerow({k: (fmt(v, 4) if isinstance(v, float) else v)
                                 for k, v in r.items()})
    text = table(rows, native is not None) if rows else "(no rows)"
    clock = "CUDA events" if torch else "wall clock"
    title = (f"raycut neighbour lists, Python against C++ ({'tiny, ' if args.tiny else ''}"
             f"{rows[0]['input'] if rows else ''}, GPU: {gpu}; {clock}, medians of {reps} after "
             f"{args.warmup} warm-up; goal: Python / C++ list <= {GOAL:.2f})")
    with open(md, "w") as f:
        f.write(f"{title}\n\n{text}\n")
    print(title)
    print(text)
    if any(r["check"] != "ok" for r in rows):
        print("pair counts differ between variants (check = MISMATCH)", file=sys.stderr)
    print(f"wrote {out} and {md}")
    return rows


if __name__ == "__main__":
    main()
