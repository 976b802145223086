#!/usr/bin/env python3
"""Draw the paper's Figures 9 (uniform) and 10 (surface) from pyraycut bench CSVs.

One panel per beta (or alpha); in each, one group of bars per N (one bar per method), every bar
stacked build (light) + compute (dark), log scale, and above each bar its speedup over the
paper's own grid (method paper-cudaLJ, same run) when that row exists. Host-clock rows are
used, as the paper's binary only has those.

  plot_figures.py merged.csv [more.csv ...] --out-dir bench/results/h100
"""
import argparse
import csv
import math
import os
from collections import defaultdict

import matplotlib
import matplotlib.patches

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

PAPER = "paper-cudaLJ"


def load(paths, timer):
    rows = []
    for path in paths:
        with open(path) as f:
            rows += [r for r in csv.DictReader(f) if r["timer"] == timer]
    return rows


def method_order(methods):
    # The paper's grid first, then ours in a stable order.
    return sorted(methods, key=lambda m: (m != PAPER, m != "grid-paper", m))


def draw_suite(rows, suite, out_dir):
    rows = [r for r in rows if r["suite"] == suite]
    if not rows:
        return None
    by_param = defaultdict(list)
    for r in rows:
        by_param[int(r["param"])].append(r)
    methods = method_order({r["method"] for r in rows})
    colours = {m: plt.cm.tab10(i % 10) for i, m in enumerate(methods)}
    # Panels where some method of ours ran (the paper's binary runs sizes we may skip).
    params = sorted(q for q in by_param if any(r["method"] != PAPER for r in by_param[q]))
    fig, axes = plt.subplots(len(params), 1, figsize=(max(8, 1.6 * len(methods) + 4),
                                                       3.2 * len(params)), squeeze=False)
    gpu = rows[0]["gpu"]
    for ax, param in zip(axes[:, 0], params):
        table = {(r["method"], int(r["N"])): r for r in by_param[param]}
        sizes = sorted({int(r["N"]) for r in by_param[param]})
        width = 0.8 / len(methods)
        for k, method in enumerate(methods):
            for x, n in enumerate(sizes):
                r = table.get((method, n))
                if r is None:
                    continue
                build, compute = float(r["build_ms"]), float(r["compute_ms"])
                pos = x + (k - (len(methods) - 1) / 2) * width
                ax.bar(pos, build, width, color=colours[method], alpha=0.45)
                ax.bar(pos, compute, width, bottom=build, color=colours[method])
                paper = table.get((PAPER, n))
                if paper is not None and method != PAPER:
                    speedup = float(paper["total_ms"]) / (build + compute)
                    ax.text(pos, (build + compute) * 1.08, f"{speedup:.2g}", ha="center",
                            va="bottom", fontsize=6, rotation=90)
        ax.set_yscale("log")
        ax.set_xticks(range(len(sizes)))
        ax.set_xticklabels([f"{n:,}" for n in sizes], fontsize=7)
        name = "beta" if suite == "uniform" else "alpha"
        ax.set_title(f"{suite}, {name} = {param}: build (light) + compute (dark), "
                     "speedup over the paper's grid above", fontsize=9)
        ax.set_ylabel("ms (median)")
        ax.grid(axis="y", which="both", alpha=0.3)
    handles = [matplotlib.patches.Patch(color=colours[m], label=m) for m in methods]
    axes[0, 0].legend(handles=handles, fontsize=7, ncol=min(4, len(methods)), loc="upper left")
    axes[-1, 0].set_xlabel(f"N (particles) -- {gpu}, host clock")
    fig.tight_layout()
    path = os.path.join(out_dir, f"figure-{suite}.png")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("csv", nargs="+")
    ap.add_argument("--out-dir", default=".")
    ap.add_argument("--timer", default="host")
    args = ap.parse_args()
    rows = load(args.csv, args.timer)
    for suite in ("uniform", "surface"):
        path = draw_suite(rows, suite, args.out_dir)
        if path:
            print(path)


if __name__ == "__main__":
    main()
