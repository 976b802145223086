#!/usr/bin/env python3
"""Ratio table (markdown) and plot of every method against the paper's own CUDA grid.

Reads CSVs of `raycut bench`; the paper's grid rows (method paper-cudaLJ) come from the same run
with `raycut bench --paper-binary PATH`. Ratio = paper-cudaLJ total / method total (> 1: faster
than the paper), with the chosen timer for our rows (the paper's binary only has host times).

  compare_paper.py bench-uniform.csv bench-surface.csv --md ratios.md --png ratios.png
"""
import argparse
import csv
from collections import defaultdict

PAPER = "paper-cudaLJ"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("csv", nargs="+", help="CSV files of raycut bench")
    ap.add_argument("--methods", help="comma-separated methods to show (default: all)")
    ap.add_argument("--md", help="markdown ratio table to write")
    ap.add_argument("--png", help="plot to write")
    ap.add_argument("--timer", default="host", help="timer of our rows to compare (host, events)")
    args = ap.parse_args()

    rows = []
    for path in args.csv:
        with open(path) as f:
            rows += list(csv.DictReader(f))
    wanted = set(args.methods.split(",")) if args.methods else None
    paper = [r for r in rows if r["method"] == PAPER]
    ours = [r for r in rows if r["method"] != PAPER and (wanted is None or r["method"] in wanted)]
    env = {k: ours[0][k] for k in ("gpu", "driver", "cuda", "optix")} if ours else {}

    ref = {(r["suite"], int(r["param"]), int(r["p"])): float(r["total_ms"]) for r in paper}
    methods = sorted({r["method"] for r in ours})
    table = defaultdict(dict)  # (suite, param, p) -> method -> (total, build, compute)
    pairs = {}
    for r in ours:
        if r["timer"] != args.timer:
            continue
        key = (r["suite"], int(r["param"]), int(r["p"]))
        table[key][r["method"]] = (float(r["total_ms"]), float(r["build_ms"]),
                                   float(r["compute_ms"]), r["reps"])
        pairs[key] = (int(r["N"]), r["pairs"])

    lines = []
    if ours:
        lines.append(f"Measured on {env['gpu']} (driver {env['driver']}, CUDA {env['cuda']}, "
                     f"OptiX {env['optix']}); "
                     "paper-cudaLJ is the paper's own Cuda-version/cudaLJ.cu, run in the same "
                     "session.\n")
    for suite in ("uniform", "surface"):
        keys = sorted(k for k in table if k[0] == suite)
        if not keys:
            continue
        name = "beta" if suite == "uniform" else "alpha"
        lines.append(f"### {suite} suite ({args.timer} timer, medians, ms; ratio = paper-cudaLJ "
                     f"total / method total)\n")
        head = f"| {name} | p | N | paper-cudaLJ |"
        sep = "|---|---|---|---|"
        for m in methods:
            head += f" {m} (build+compute) | ratio |"
            sep += "---|---|"
        lines += [head, sep]
        for key in keys:
            n, _ = pairs[key]
            paper_ms = ref.get(key)
            row = f"| {key[1]} | {key[2]} | {n:,} | " + (f"{paper_ms:.3f} |" if paper_ms else "- |")
            for m in methods:
                if m in table[key]:
                    t, b, c, reps = table[key][m]
                    note = "" if reps in ("5", "") else f" ({reps} reps)"
                    ratio = f"{paper_ms / t:.2f}" if paper_ms else "-"
                    row += f" {t:.3f} ({b:.3f}+{c:.3f}){note} | {ratio} |"
                else:
                    row += " - | - |"
            lines.append(row)
        lines.append("")
    text = "\n".join(lines)
    if args.md:
        with open(args.md, "w") as f:
            f.write(text + "\n")
    print(text)

    if args.png:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        suites = [s for s in ("uniform", "surface") if any(k[0] == s for k in table)]
        fig, axes = plt.subplots(1, len(suites), figsize=(7 * len(suites), 5), squeeze=False)
        for ax, suite in zip(axes[0], suites):
            for m in methods:
                pts = sorted((pairs[k][0], ref[k] / table[k][m][0]) for k in table
                             if k[0] == suite and m in table[k] and k in ref)
                if pts:
                    ax.plot([x for x, _ in pts], [y for _, y in pts], "o", label=m)
            ax.axhline(1.0, color="gray", lw=0.8)
            ax.axhline(3.0, color="gray", lw=0.8, ls="--")
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_xlabel("N (particles)")
            ax.set_ylabel("paper-cudaLJ total / method total")
            ax.set_title(f"{suite} suite, {args.timer} timer")
            ax.legend()
        fig.tight_layout()
        fig.savefig(args.png, dpi=120)


if __name__ == "__main__":
    main()
