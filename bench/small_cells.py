#!/usr/bin/env python3
"""Neighbour lists of the small periodic cells that machine-learned potentials are trained on (a
data loader lists every structure of a dataset, one at a time, on the CPU): ASE's
``neighbor_list("ijS", atoms, cutoff)`` as computed by ``pyraycut.ase``, vesin
(``vesin.ase_neighbor_list``), matscipy (``matscipy.neighbours.neighbour_list``) and, with
``--ase``, ASE itself, each where installed.

The structures are rattled (0.05 A) bulk cells from a primitive 1-atom cell to 256 atoms, a slab
with vacuum and a molecule (open, in a box), at cutoffs of 5 and 6 A. Each call runs after one
untimed call, the libraries taking turns in every round (a busy machine slows them alike); the
best of the rounds (each the mean over ``--calls`` calls) and the median go to a CSV (``--out``)
with the machine and the versions, and to a table of times relative to pyraycut's. Checks that
every library gives the same pairs (i, j, S). Set OMP_NUM_THREADS=1 to compare with the
single-threaded peers.

    OMP_NUM_THREADS=1 python bench/small_cells.py [--rounds 7] [--calls 200] [--ase] [--out FILE]
                                                  [--png FILE]
    python bench/small_cells.py --plot FILE.csv --png FILE.png    (the figure of a CSV)
"""
from __future__ import annotations

import argparse
import csv
import os
import platform
import statistics
import time

import numpy as np
from ase.build import bulk, fcc111, molecule

import pyraycut
import pyraycut.ase


def structures() -> list[tuple[str, object, float]]:
    """(name, Atoms, cutoff): what an MLIP dataset holds, smallest first."""
    cases = [
        ("Cu fcc primitive (1)", bulk("Cu", "fcc", a=3.6), 5.0),
        ("Cu fcc cubic (4)", bulk("Cu", "fcc", a=3.6, cubic=True), 6.0),
        ("Si diamond (8)", bulk("Si", "diamond", a=5.43, cubic=True), 5.0),
        ("NaCl rocksalt (8)", bulk("NaCl", "rocksalt", a=5.64, cubic=True), 6.0),
        ("Si diamond 2x2x2 (64)", bulk("Si", "diamond", a=5.43, cubic=True).repeat(2), 5.0),
        ("Cu fcc 4x4x4 (256)", bulk("Cu", "fcc", a=3.6, cubic=True).repeat(4), 5.0),
        ("Cu(111) slab 3x3x4 (36)", fcc111("Cu", (3, 3, 4), vacuum=10.0), 5.0),
        ("ethanol, open (9)", molecule("CH3CH2OH"), 5.0),
    ]
    cases[-1][1].center(vacuum=6.0)  # a box for the libraries that need a cell; pbc stays False
    for _, atoms, _ in cases:
        atoms.rattle(0.05, seed=1)
    return cases


def libraries(with_ase: bool) -> dict:
    found = {"pyraycut": lambda atoms, c: pyraycut.ase.neighbor_list("ijS", atoms, c)}
    try:
        import vesin

        found["vesin"] = lambda atoms, c: vesin.ase_neighbor_list("ijS", atoms, c)
    except ImportError:
        pass
    try:
        from matscipy.neighbours import neighbour_list

        found["matscipy"] = lambda atoms, c: neighbour_list("ijS", atoms, c)
    except ImportError:
        pass
    if with_ase:
        from ase.neighborlist import neighbor_list

        found["ase"] = lambda atoms, c: neighbor_list("ijS", atoms, c)
    return found


def pair_set(result) -> set:
    i, j, s = result
    return set(zip(np.asarray(i).tolist(), np.asarray(j).tolist(),
                   map(tuple, np.asarray(s).tolist())))


def versions() -> str:
    out = [f"pyraycut {getattr(pyraycut, '__version__', '?')}", f"numpy {np.__version__}"]
    for name in ("vesin", "matscipy", "ase"):
        try:
            out.append(f"{name} {__import__(name).__version__}")
        except ImportError:
            pass
    return "; ".join(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--calls", type=int, default=200)
    parser.add_argument("--ase", action="store_true", help="ASE's own list too (slow)")
    parser.add_argument("--out", help="CSV file")
    parser.add_argument("--png", help="a bar chart of the best times (matplotlib)")
    parser.add_argument("--plot", help="draw --png from this CSV instead of measuring")
    args = parser.parse_args()
    if args.plot:
        with open(args.plot, newline="") as f:
            plot(list(csv.DictReader(f)), args.png)
        return
    libs = libraries(args.ase)
    machine = f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores"
    threads = os.environ.get("OMP_NUM_THREADS", "all")
    rows = []
    for name, atoms, cutoff in structures():
        results = {lib: f(atoms, cutoff) for lib, f in libs.items()}
        reference = pair_set(results["pyraycut"])
        for lib, result in results.items():
            if pair_set(result) != reference:
                raise SystemExit(f"{name}: {lib} gives other pairs than pyraycut")
        means = {lib: [] for lib in libs}
        for _ in range(args.rounds):
            for lib, f in libs.items():
                calls = max(1, args.calls // (20 if lib == "ase" else 1))
                start = time.perf_counter()
                for _ in range(calls):
                    f(atoms, cutoff)
                means[lib].append((time.perf_counter() - start) / calls * 1e6)
        for lib in libs:
            rows.append({"structure": name, "atoms": len(atoms), "cutoff": cutoff,
                         "pairs": len(reference), "library": lib,
                         "best_us": round(min(means[lib]), 2),
                         "median_us": round(statistics.median(means[lib]), 2),
                         "threads": threads, "machine": machine, "versions": versions()})
    print(f"{'structure':26s} {'pairs':>6s} " + " ".join(f"{lib:>16s}" for lib in libs))
    for name, _, _ in structures():
        mine = {r["library"]: r for r in rows if r["structure"] == name}
        base = mine["pyraycut"]["best_us"]
        print(f"{name:26s} {mine['pyraycut']['pairs']:6d} " + " ".join(
            f"{mine[lib]['best_us']:8.1f} ({mine[lib]['best_us'] / base:4.2f}x)" for lib in libs))
    if args.out:
        with open(args.out, "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=list(rows[0]))
            writer.writeheader()
            writer.writerows(rows)
    if args.png:
        plot(rows, args.png)


def plot(rows: list[dict], png: str) -> None:
    """Best time per call of each library, per structure (log scale)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(dict.fromkeys(r["structure"] for r in rows))
    libs = list(dict.fromkeys(r["library"] for r in rows))
    best = {(r["structure"], r["library"]): float(r["best_us"]) for r in rows}
    fig, ax = plt.subplots(figsize=(10, 4.5))
    width = 0.8 / len(libs)
    for k, lib in enumerate(libs):
        ax.bar([s + k * width for s in range(len(names))],
               [best.get((name, lib), float("nan")) for name in names], width, label=lib)
    ax.set_xticks([s + 0.4 - width / 2 for s in range(len(names))])
    ax.set_xticklabels(names, rotation=30, ha="right", fontsize=8)
    ax.set_yscale("log")
    ax.set_ylabel("us per call (best round)")
    first = rows[0]
    ax.set_title(f"neighbor_list('ijS') of small cells, {first['machine']}, "
                 f"threads {first['threads']}", fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(png, dpi=120)


if __name__ == "__main__":
    main()
