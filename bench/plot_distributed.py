#!/usr/bin/env python3
"""Scaling tables (and a plot) of `raycut bench --distributed` runs, against the scaling goals (docs/distributed.md).

Reads the CSVs that `mpirun -np K raycut bench --distributed` writes (one per rank count; rows
of the same method, rows scheme, periodic images, positions and transport are compared with
each other). Weak
scaling (rows with scaling = weak): the step at K ranks over the step at the fewest ranks of the
same N_per_rank, goal <= --weak-goal. Strong scaling (scaling = strong): the step at the fewest
ranks over the step at K ranks of the same N (the speed-up), goal >= --strong-goal at --strong-at
ranks. One-rank device rows with plain_step_ms: the step over the plain engine's (goal <= 1.05).

  plot_distributed.py weak-np1.csv weak-np2.csv strong-np1.csv strong-np2.csv \
      --md scaling.md [--png scaling.png] [--weak-goal 1.15] [--strong-goal 1.7] [--strong-at 2]
"""
import argparse
import csv
from collections import defaultdict


def read_rows(paths):
    rows = []
    for path in paths:
        with open(path, newline="") as f:
            rows.extend(csv.DictReader(f))
    return rows


def key(row):
    # "images" (in CSVs that have the column): local (single-domain periodic axes imaged by the local engine) or
    # halos (--halo-images: every periodic axis by halos).
    return (row["method"], row["rows"], row.get("images", "local"), row.get("positions", "host"),
            row.get("transport", "mpi-host"))


def scaling_tables(rows, weak_goal, strong_goal, strong_at):
    """(markdown lines, {(scaling, key, size): [(ranks, value)]}) of the weak and strong rows."""
    groups = defaultdict(list)
    for row in rows:
        size = row["N_per_rank"] if row["scaling"] == "weak" else row["N"]
        groups[(row["scaling"], key(row), int(size))].append(row)
    lines, curves = [], {}
    for scaling, title in (("weak", "Weak scaling"), ("strong", "Strong scaling")):
        chosen = sorted(g for g in groups if g[0] == scaling)
        if not chosen:
            continue
        size_name = "N per rank" if scaling == "weak" else "N"
        measure = "step / fewest ranks' step" if scaling == "weak" else "speed-up"
        lines += [f"### {title}", "",
                  f"| method | rows | images | positions | transport | {size_name} | ranks | dims "
                  f"| halos | refresh ms | lj_forces ms | step ms | {measure} | goal |",
                  "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for group in chosen:
            by_ranks = sorted(groups[group], key=lambda r: int(r["ranks"]))
            base = float(by_ranks[0]["step_ms"])
            curve = []
            for r in by_ranks:
                ranks, step = int(r["ranks"]), float(r["step_ms"])
                value = step / base if scaling == "weak" else base / step
                curve.append((ranks, value))
                if ranks == int(by_ranks[0]["ranks"]):
                    goal = "reference"
                elif scaling == "weak":
                    goal = f"<= {weak_goal}: {'met' if value <= weak_goal else 'MISSED'}"
                elif ranks == strong_at:
                    goal = f">= {strong_goal}: {'met' if value >= strong_goal else 'MISSED'}"
                else:
                    goal = ""
                method, rows_scheme, images, positions, transport = group[1]
                lines.append(f"| {method} | {rows_scheme} | {images} | {positions} | {transport} | "
                             f"{group[2]} | {ranks} | {r['dims']} | {r['halos']} | "
                             f"{float(r['refresh_ms']):.3f} | {float(r['compute_ms']):.3f} | "
                             f"{step:.3f} | {value:.3f} | {goal} |")
            curves[group] = curve
        lines.append("")
    return lines, curves


def plain_table(rows):
    """The one-rank rows with the plain engine beside them."""
    chosen = [r for r in rows if r.get("plain_step_ms") and int(r["ranks"]) == 1]
    if not chosen:
        return []
    lines = ["### One rank against the plain engine (same run)", "",
             "| method | images | positions | transport | N | steps per exchange | step ms "
             "| plain build + lj_forces ms | step / plain | goal <= 1.05 "
             "| update / halos / local build ms |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in sorted(chosen, key=lambda r: (r["method"], int(r["N"]), int(r.get("steps") or 1))):
        ratio = float(r["step_ms"]) / float(r["plain_step_ms"])
        parts = ("update_ms", "halo_refresh_ms", "local_build_ms")  # in CSVs from 2026-12-02 on
        breakdown = (" / ".join(f"{float(r[p]):.3f}" for p in parts)
                     if all(r.get(p) for p in parts) else "")
        lines.append(f"| {r['method']} | {r.get('images', 'local')} | {r.get('positions', 'host')} | "
                     f"{r.get('transport', 'mpi-host')} | {r['N']} | "
                     f"{r.get('steps') or 1} | {float(r['step_ms']):.3f} | "
                     f"{float(r['plain_step_ms']):.3f} | {ratio:.3f} | "
                     f"{'met' if ratio <= 1.05 else 'MISSED'} | {breakdown} |")
    return lines + [""]


def plot(curves, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for (scaling, k, size), curve in sorted(curves.items()):
        ax = axes[0 if scaling == "weak" else 1]
        ax.plot([c[0] for c in curve], [c[1] for c in curve], marker="o",
                label=f"{k[0]} {k[2]} {k[3]} {k[4]} {size}")
    axes[0].set(title="Weak scaling", xlabel="ranks (GPUs)", ylabel="step / fewest ranks' step")
    axes[1].set(title="Strong scaling", xlabel="ranks (GPUs)", ylabel="speed-up")
    for ax in axes:
        ax.grid(True, alpha=0.3)
        if ax.lines:
            ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("csv", nargs="+")
    parser.add_argument("--md", required=True)
    parser.add_argument("--png")
    parser.add_argument("--weak-goal", type=float, default=1.15)
    parser.add_argument("--strong-goal", type=float, default=1.7)
    parser.add_argument("--strong-at", type=int, default=2)
    args = parser.parse_args()
    rows = read_rows(args.csv)
    gpus = sorted({r["gpu"] for r in rows})
    lines = [f"raycut bench --distributed ({', '.join(gpus)}; MPI_Wtime, the slowest rank per "
             f"phase, medians)", ""]
    lines += plain_table(rows)
    tables, curves = scaling_tables(rows, args.weak_goal, args.strong_goal, args.strong_at)
    lines += tables
    with open(args.md, "w") as f:
        f.write("\n".join(lines) + "\n")
    if args.png and curves:
        plot(curves, args.png)


if __name__ == "__main__":
    main()
