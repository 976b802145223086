#!/usr/bin/env python3
"""Call latency of ``pyraycut.neighbor_list`` on PyTorch tensors for small systems and batches:
the Python rows beside ``raycut_latency_bench``'s C++ rows (docs/benchmarks.md, "Latency of
small systems"), in the same CSV columns.

Workload ``lj-pbc``: a periodic Lennard-Jones liquid, density 0.8442, cutoff 2.5, positions
uniform random in a cube of side (n / 0.8442)^(1/3) per system, float32; single systems
(``--sizes``) and batches (``--batches SxN``: S systems of N particles, each its own cube, one
cell per system, ``batch`` the sorted int64 system index). Each workload is measured so:

- capacity ``exact``: ``neighbor_list("ijS", x, 2.5, cell=..., pbc=True, batch=...)``;
- capacity ``static``: ``neighbor_list("ijSc", ..., max_pairs=K)``, K = 1.25 x the true count
  (found once): the count comes back as a tensor for the caller to check, so the call reads
  nothing back (the static-capacity contract);
- capacity ``static-checked``: ``"ijS"`` with the same ``max_pairs``: the package checks the
  count itself, which reads it back (one wait a call);
- mode ``graph``, capacity ``static``: the ``static`` call captured once in a CUDA graph
  (``torch.cuda.graph``) and replayed (CUDA only; a row only where the capture succeeds, which
  proves the call does not synchronise; the calls that plan on the host cannot be captured);
- interface ``python-torch-op``, capacity ``exact``: the operator ``torch.ops.raycut``'s Python
  wrapper called directly in eager mode (where its CUDA kernel is built), against the package's
  zero-copy path above: which of the two eager CUDA calls should take;
- interface ``python-torch-op``, capacity ``static``: ``torch.ops.raycut.neighbor_list.default``
  itself with the ``static`` call's arguments made once: the operator's own cost (PyTorch's
  dispatch, the output tensors, the launches), and so, subtracted from ``static``, the Python
  wrapper's;
- interface ``python-torch-verlet-update``: ``VerletList(2.5, skin=0.3, shifts=True, ...)``'s
  ``update(x)`` with the positions it was built from, so that nothing rebuilds: the cost of a
  step loop's check (its answer, True or False, is read on the host).

Timing as the C++ bench: after warm-up, ``--reps`` repetitions of a loop of K calls (K doubled
until a loop takes ``--min-loop-ms``), synchronised (``torch.cuda.synchronize``) only around each
loop; ``us_per_call`` the median of loop time / K. ``kernels`` and ``syncs`` per call come from
``torch.profiler`` over ``--profile-calls`` calls: kernels executed on the device (memcpy and
memset activities not counted), and synchronisations (the runtime calls cudaDeviceSynchronize
and cudaStreamSynchronize, plus each device-to-host copy).

    python bench/python_latency.py --output latency-python.csv [--crossover]

Appends to ``--output`` when it holds rows of the same columns, else writes it. ``--device cpu``
runs the same on PyTorch CPU tensors (no profiler counts): a check of the script itself.
Exit codes: 0 done, 1 failure, 2 bad arguments, 77 no CUDA device or no PyTorch.
"""
from __future__ import annotations

import argparse
import csv
import math
import os
import statistics
import sys
import time
from typing import Callable, Iterable, Optional

DENSITY = 0.8442
CUTOFF = 2.5
VERLET_SKIN = 0.3
COLUMNS = ["workload", "systems", "n_per_system", "interface", "mode", "capacity", "us_per_call",
           "kernels", "syncs", "gpu", "driver", "cuda"]
CROSSOVER_SIZES = (2000, 4000, 8000)
# Runtime calls that make the host wait for the device.
SYNC_CALLS = ("cudaDeviceSynchronize", "cudaStreamSynchronize", "cudaEventSynchronize")


def parse_batches(text: str) -> list[tuple[int, int]]:
    """``"32x100,256x100"`` -> [(32, 100), (256, 100)]; ``"none"`` -> []."""
    if text == "none":
        return []
    batches = []
    for part in text.split(","):
        pieces = part.split("x")
        if len(pieces) != 2 or not all(p.isdigit() and int(p) > 0 for p in pieces):
            raise argparse.ArgumentTypeError(
                f"--batches: {part!r} is not SxN (systems x particles, whole numbers >= 1, "
                f"e.g. 32x100), or 'none'")
        batches.append((int(pieces[0]), int(pieces[1])))
    return batches


def parse_sizes(text: str) -> list[int]:
    sizes = []
    for part in text.split(","):
        if not part.isdigit() or int(part) < 1:
            raise argparse.ArgumentTypeError(f"--sizes: {part!r} is not a whole number >= 1")
        sizes.append(int(part))
    return sizes


def positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"{text!r} is not a positive number")
    return value


def count_profile(events: Iterable[tuple[str, bool]]) -> tuple[int, int]:
    """(kernels, syncs) among profiler events given as (name, on_device): device events that
    are neither copies nor memsets (nor CUPTI's synchronisation records) are kernels; the
    runtime's waits (device, stream and event synchronisations) and device-to-host copies into
    pageable memory, which block the host, are synchronisations. A copy into pinned memory is
    not: the host goes on, and a wait for it, if any, is one of those calls."""
    kernels = syncs = 0
    for name, on_device in events:
        if on_device:
            if name.startswith("Memcpy DtoH") and "Pageable" in name:
                syncs += 1
            elif not name.startswith(("Memcpy", "Memset")) and "Sync" not in name:
                kernels += 1
        elif name.startswith(SYNC_CALLS):
            syncs += 1
    return kernels, syncs


def nvidia_driver_version() -> str:
    """The first dotted number of the kernel module's version line, as raycut's system_info."""
    try:
        with open("/proc/driver/nvidia/version") as f:
            for word in f.read().split():
                if word[:1].isdigit() and "." in word:
                    return word
    except OSError:
        pass
    return "unknown"


def median_us_per_call(call: Callable[[], object], sync: Callable[[], None], reps: int,
                       min_loop_ms: float) -> float:
    """The timing rule: K calls per loop, K doubled until a loop lasts min_loop_ms (those loops
    are the warm-up), then `reps` loops; the median of loop time / K, in microseconds."""
    def loop(k: int) -> float:
        sync()
        start = time.perf_counter()
        for _ in range(k):
            call()
        sync()
        return (time.perf_counter() - start) * 1e6

    loop(1)  # first call: the engine, the operator's caches, the allocator's pool
    k = 1
    while loop(k) < 1e3 * min_loop_ms and k < 1 << 24:
        k *= 2
    return statistics.median(loop(k) / k for _ in range(reps))


def workload(torch, systems: int, per_system: int, device: str, generator):
    """Positions (n, 3) float32, cells (3, 3) or (systems, 3, 3), batch (n,) int64 or None."""
    side = (per_system / DENSITY) ** (1.0 / 3.0)
    n = systems * per_system
    x = (torch.rand((n, 3), generator=generator, dtype=torch.float64) * side).to(torch.float32)
    cell = torch.eye(3, dtype=torch.float32) * side
    batch = None
    if systems > 1:
        cell = cell.expand(systems, 3, 3).contiguous()
        batch = torch.arange(systems, dtype=torch.int64).repeat_interleave(per_system)
        batch = batch.to(device)
    return x.to(device), cell.to(device), batch


def captured(torch, call: Callable[[], object]) -> tuple[Optional[Callable[[], object]], object]:
    """`call` captured in a CUDA graph (after one warm-up call on a side stream, as PyTorch asks):
    a function that replays it, and the captured call's outputs (what each replay writes); None
    when the capture fails: the call synchronises or allocates outside the graph's pool (printed,
    so the missing row is explained)."""
    stream = torch.cuda.Stream()
    stream.wait_stream(torch.cuda.current_stream())
    with torch.cuda.stream(stream):
        call()
    torch.cuda.current_stream().wait_stream(stream)
    graph = torch.cuda.CUDAGraph()
    try:
        with torch.cuda.graph(graph):
            outputs = call()
    except Exception as e:  # noqa: BLE001 - any failure means no graph row, said why
        print(f"  no CUDA graph: the capture failed ({type(e).__name__}: {str(e)[:120]})",
              flush=True)
        torch.cuda.synchronize()
        return None, None
    return graph.replay, outputs


def profile_counts(torch, call: Callable[[], object], sync: Callable[[], None],
                   calls: int, table: Optional[str] = None) -> tuple[str, str]:
    """kernels and syncs per call (as text for the CSV) over `calls` profiled calls; `table`: a
    file that gets the profiler's table of where the host time went (CUDA runtime calls
    included)."""
    from torch.profiler import ProfilerActivity, profile

    sync()
    with profile(activities=[ProfilerActivity.CPU, ProfilerActivity.CUDA]) as prof:
        for _ in range(calls):
            call()
        sync()
    cuda = torch.autograd.DeviceType.CUDA
    events = ((e.name(), e.device_type() == cuda) for e in prof.profiler.kineto_results.events())
    kernels, syncs = count_profile(events)
    # The profiled window ends with the loop's own synchronisation: not the calls'.
    syncs = max(syncs - 1, 0)
    if table:
        with open(table, "w") as f:
            f.write(prof.key_averages().table(sort_by="self_cpu_time_total", row_limit=40))
    return f"{kernels / calls:g}", f"{syncs / calls:g}"


def appends_to(path: str) -> bool:
    """Whether --output already holds rows of these columns (then rows are appended to it).
    Exits naming the file when it holds other columns."""
    if not (os.path.exists(path) and os.path.getsize(path) > 0):
        return False
    with open(path, newline="") as f:
        header = next(csv.reader(f), [])
    if header != COLUMNS:
        raise SystemExit(f"--output: {path!r} holds other columns ({','.join(header)}); "
                         f"expected {','.join(COLUMNS)}")
    return True


def write_rows(path: str, rows: list[dict]) -> None:
    append = appends_to(path)
    with open(path, "a" if append else "w", newline="") as f:
        writer = csv.DictWriter(f, COLUMNS)
        if not append:
            writer.writeheader()
        writer.writerows(rows)


def parse_timing_arguments(parser: argparse.ArgumentParser,
                           argv: Optional[list[str]]) -> argparse.Namespace:
    """Adds the options every latency script shares (--output, --reps, --min-loop-ms,
    --profile-calls, --device, --seed) to ``parser`` and parses ``argv``; refuses a bad count or
    an --output of other columns before anything is measured."""
    parser.add_argument("--output", help="CSV file (appended to when it has the same columns)")
    parser.add_argument("--reps", type=int, default=30, help="timed loops (default 30)")
    parser.add_argument("--min-loop-ms", type=positive, default=2.0,
                        help="a timed loop lasts at least this long (default 2)")
    parser.add_argument("--profile-calls", type=int, default=20,
                        help="calls profiled for kernels and syncs (default 20)")
    parser.add_argument("--device", choices=["cuda", "cpu"], default="cuda",
                        help="where the tensors live (cpu: a check of the script, no counts)")
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args(argv)
    if args.reps < 1:
        parser.error(f"--reps must be >= 1, got {args.reps}")
    if args.profile_calls < 1:
        parser.error(f"--profile-calls must be >= 1, got {args.profile_calls}")
    if args.output:
        appends_to(args.output)  # refused before measuring, not after
    return args


def torch_on_the_device(args: argparse.Namespace, script: str) -> tuple:
    """(torch, sync, machine) for --device; exits 77 without PyTorch or without a CUDA device.
    ``machine``: the CSV's gpu, driver and cuda columns."""
    try:
        import torch
    except ImportError:
        print(f"{script}: PyTorch is not installed: nothing to measure", file=sys.stderr)
        raise SystemExit(77)
    cuda = args.device == "cuda"
    if cuda and not torch.cuda.is_available():
        print(f"{script}: no CUDA device (torch.cuda.is_available() is False): nothing to "
              "measure (--device cpu checks the script on the CPU)", file=sys.stderr)
        raise SystemExit(77)
    sync = torch.cuda.synchronize if cuda else (lambda: None)
    machine = {"gpu": torch.cuda.get_device_name() if cuda else "none",
               "driver": nvidia_driver_version() if cuda else "none",
               "cuda": (torch.version.cuda or "none") if cuda else "none"}
    return torch, sync, machine


def main(argv: Optional[list[str]] = None) -> list[dict]:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", type=parse_sizes, default=[128, 1000, 10000, 100000],
                        help="single systems, particles each (default 128,1000,10000,100000)")
    parser.add_argument("--batches", type=parse_batches,
                        default=[(32, 100), (256, 100), (512, 128)],
                        help="batches SxN, comma-separated, or 'none' "
                             "(default 32x100,256x100,512x128)")
    parser.add_argument("--crossover", action="store_true",
                        help="also single systems of 2000, 4000 and 8000 particles")
    parser.add_argument("--profile-tables", metavar="DIR",
                        help="write the profiler's table of each profiled case there "
                             "(profile-SxN-interface-capacity.txt)")
    args = parse_timing_arguments(parser, argv)
    torch, sync, machine = torch_on_the_device(args, "python_latency")
    import pyraycut

    cuda = args.device == "cuda"
    print(f"lj-pbc latency, pyraycut.neighbor_list on torch {args.device} tensors "
          f"({machine['gpu']}, driver {machine['driver']}, CUDA {machine['cuda']}), "
          f"{args.reps} reps, loops >= {args.min_loop_ms:g} ms")

    cases = [(1, n) for n in args.sizes]
    if args.crossover:
        cases += [(1, n) for n in CROSSOVER_SIZES]
    cases += args.batches
    generator = torch.Generator().manual_seed(args.seed)
    ops = pyraycut._torch_ops()  # the operators' Python wrapper, None where they are not built
    rows = []
    for systems, per_system in cases:
        x, cell, batch = workload(torch, systems, per_system, args.device, generator)

        def exact():
            return pyraycut.neighbor_list("ijS", x, CUTOFF, cell=cell, pbc=True, batch=batch)

        count = len(exact()[0])
        max_pairs = max(math.ceil(1.25 * count), 1)

        def static():
            return pyraycut.neighbor_list("ijSc", x, CUTOFF, cell=cell, pbc=True, batch=batch,
                                          max_pairs=max_pairs)

        def static_checked():
            return pyraycut.neighbor_list("ijS", x, CUTOFF, cell=cell, pbc=True, batch=batch,
                                          max_pairs=max_pairs)

        try:
            entries = len(static_checked()[0])
        except ValueError as e:  # max_pairs needs the operators (built with torch)
            raise SystemExit(f"python_latency: max_pairs on {args.device} tensors: {e}") from None
        if entries != max_pairs:
            raise SystemExit(f"python_latency: max_pairs={max_pairs} gave {entries} entries, "
                             f"not the static size")
        def operator():
            return ops.neighbor_list("ijS", x, CUTOFF, cell, True, batch, False, None)

        # The operator itself, its arguments made once: what the Python wrapper adds is the
        # difference from "static".
        flags = torch.ones(3, dtype=torch.bool, device=x.device)

        def bare_operator():
            return torch.ops.raycut.neighbor_list.default(x, CUTOFF, cell, flags, batch, False,
                                                          max_pairs)

        # A step that rebuilds nothing: the positions have not moved since the list was built.
        verlet = pyraycut.VerletList(CUTOFF, VERLET_SKIN, shifts=True, cell=cell, pbc=True,
                                     batch=batch)
        verlet.update(x)

        def verlet_update():
            if verlet.update(x):
                raise SystemExit("python_latency: VerletList.update rebuilt unmoved positions")

        calls = [("python-torch", "eager", "static", static),
                 ("python-torch", "eager", "static-checked", static_checked),
                 ("python-torch", "eager", "exact", exact)]
        if cuda:
            replay, replayed = captured(torch, static)
            if replay is not None:
                calls.append(("python-torch", "graph", "static", replay))
        calls.append(("python-torch-verlet-update", "eager", "exact", verlet_update))
        if cuda and ops is not None and ops._CUDA_KERNEL:
            calls.append(("python-torch-op", "eager", "exact", operator))
            calls.append(("python-torch-op", "eager", "static", bare_operator))
        for interface, mode, capacity, call in calls:
            us = median_us_per_call(call, sync, args.reps, args.min_loop_ms)
            table = (os.path.join(args.profile_tables, f"profile-{systems}x{per_system}-"
                                  f"{interface}-{mode}-{capacity}.txt")
                     if args.profile_tables else None)
            kernels, syncs = (profile_counts(torch, call, sync, args.profile_calls, table)
                              if cuda else ("", ""))
            row = {"workload": "lj-pbc", "systems": systems, "n_per_system": per_system,
                   "interface": interface, "mode": mode, "capacity": capacity,
                   "us_per_call": f"{us:.3f}", "kernels": kernels, "syncs": syncs, **machine}
            rows.append(row)
            print(f"lj-pbc {systems:>4} x {per_system:<6} {interface:<26} {mode:<5} "
                  f"{capacity:<14} "
                  f"{us:10.2f} us  "
                  f"kernels {kernels or '-':>5}  syncs {syncs or '-':>5}  ({count} pairs)",
                  flush=True)
        # What the replays listed: the true count (a graph whose count says overflow, bad input
        # or a plan that no longer fits timed nothing worth a row).
        if cuda and replay is not None:
            sync()
            if int(replayed[-1]) != count:
                raise SystemExit(f"python_latency: the CUDA graph of {systems} x {per_system} "
                                 f"replays a count of {int(replayed[-1])}, not {count}")
    if args.output:
        write_rows(args.output, rows)
        print(f"wrote {len(rows)} rows to {args.output}")
    return rows


if __name__ == "__main__":
    main()
