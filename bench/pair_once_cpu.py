#!/usr/bin/env python3
"""Each pair once against each pair from both sides on the CPU cell list (option::mirror,
docs/pair-pass.md, "Each pair once"): ``bench/periodic_cpu`` with a kernel (``lj_forces``,
``count``) and with the same kernel's functor less the option (``lj_forces-each-side``,
``count-each-side``), alternated, on one and two threads, several times. The minimum and the
median of each (variant, kernel, threads) over every round of every repeat go to a CSV with the
machine; ``--png`` draws the speed-up.

    python3 bench/pair_once_cpu.py [--binary build/bench/periodic_cpu] [--particles 100000]
                                   [--rounds 3] [--repeats 3] --out FILE.csv [--png FILE.png]
    python3 bench/pair_once_cpu.py --plot FILE.csv --png FILE.png
"""
from __future__ import annotations

import argparse
import csv
import os
import platform
import statistics
import subprocess

KERNELS = ["lj_forces", "count"]
VARIANTS = ["periodic", "open"]  # the periodic liquid; its particles and images as an open cloud


def run(binary: str, particles: int, rounds: int, kernel: str, threads: int) -> dict:
    """kernel ms per round (min, median as periodic_cpu prints them) of each variant."""
    env = dict(os.environ, OMP_NUM_THREADS=str(threads))
    out = subprocess.run([binary, str(particles), str(rounds), "cell-list", kernel], env=env,
                         check=True, capture_output=True, text=True).stdout
    rows = [line for line in out.splitlines() if line and not line.startswith("#")]
    header = rows[0].split(",")
    result = {}
    for line in rows[1:]:
        row = dict(zip(header, line.split(",")))
        if row["variant"] in VARIANTS:
            result[row["variant"]] = (float(row["kernel_ms_min"]), float(row["kernel_ms_median"]),
                                      int(row["pairs"]))
    return result


def measure(args) -> None:
    samples: dict[tuple, list] = {}
    for _ in range(args.repeats):
        for threads in (1, 2):
            for kernel in KERNELS:
                for form in ("each-side", "once"):
                    name = kernel + "-each-side" if form == "each-side" else kernel
                    for variant, (low, mid, pairs) in run(args.binary, args.particles, args.rounds,
                                                          name, threads).items():
                        samples.setdefault((kernel, threads, variant, form), []).append(
                            (low, mid, pairs))
    cpu = "unknown"
    if os.path.exists("/proc/cpuinfo"):
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    with open(args.out, "w", newline="") as f:
        f.write(f"# bench/pair_once_cpu.py: bench/periodic_cpu {args.particles} {args.rounds} "
                f"cell-list, {args.repeats} repeats alternated; {cpu}, {os.cpu_count()} cores, "
                f"{platform.platform()}\n")
        f.write("# each_side: the kernel's functor less option::mirror through for_each_pair; "
                "once: the kernel (each pair once, added to both). ms: minimum and median over "
                "the repeats' per-run minimum and median\n")
        w = csv.writer(f)
        w.writerow(["kernel", "threads", "variant", "pairs", "each_side_ms_min",
                    "each_side_ms_median", "once_ms_min", "once_ms_median", "speedup_min",
                    "speedup_median"])
        for kernel in KERNELS:
            for threads in (1, 2):
                for variant in VARIANTS:
                    each = samples[(kernel, threads, variant, "each-side")]
                    once = samples[(kernel, threads, variant, "once")]
                    e_min, o_min = min(s[0] for s in each), min(s[0] for s in once)
                    e_med = statistics.median(s[1] for s in each)
                    o_med = statistics.median(s[1] for s in once)
                    w.writerow([kernel, threads, variant, each[0][2], f"{e_min:.2f}",
                                f"{e_med:.2f}", f"{o_min:.2f}", f"{o_med:.2f}",
                                f"{e_min / o_min:.3f}", f"{e_med / o_med:.3f}"])
    print(open(args.out).read())


def plot(csv_path: str, png: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    rows = list(csv.DictReader(line for line in open(csv_path) if not line.startswith("#")))
    labels = [f"{r['kernel']}\n{r['variant']}, {r['threads']}t" for r in rows]
    fig, ax = plt.subplots(figsize=(9, 4))
    x = range(len(rows))
    ax.bar([i - 0.2 for i in x], [float(r["speedup_min"]) for r in rows], 0.4, label="minimum")
    ax.bar([i + 0.2 for i in x], [float(r["speedup_median"]) for r in rows], 0.4, label="median")
    ax.axhline(1.0, color="black", linewidth=0.8)
    ax.set_xticks(list(x))
    ax.set_xticklabels(labels, fontsize=7)
    ax.set_ylabel("each side / once (higher: once is faster)")
    ax.set_title("CPU cell list, 100,000-particle LJ liquid: each pair once (option::mirror)")
    ax.legend()
    fig.tight_layout()
    fig.savefig(png, dpi=120)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--binary", default="build/bench/periodic_cpu")
    p.add_argument("--particles", type=int, default=100000)
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--out")
    p.add_argument("--plot", help="draw the figure of this CSV instead of measuring")
    p.add_argument("--png")
    args = p.parse_args()
    if args.plot:
        plot(args.plot, args.png)
        return
    if not args.out:
        p.error("--out FILE.csv is needed to measure")
    measure(args)
    if args.png:
        plot(args.out, args.png)


if __name__ == "__main__":
    main()
