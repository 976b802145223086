#!/usr/bin/env python3
"""Plot the call latency of small-system neighbour lists (docs/benchmarks.md, "Latency of small
systems"): the rows of raycut_latency_bench and bench/python_latency.py (one or more CSVs of
the columns workload,systems,n_per_system,interface,mode,capacity,us_per_call,kernels,syncs,
gpu,driver,cuda), us_per_call against total particles (systems x n_per_system), log-log, one
line per (interface, mode, capacity), single systems (circles) and batches (squares) as
separate markers of the same line's colour.

    python bench/plot_latency.py latency-cpp.csv latency-python.csv --png latency.png

--labels names each CSV's lines (one label per CSV, added to their names): the same calls
measured two ways, side by side (e.g. --labels planned reused).
"""
from __future__ import annotations

import argparse
import csv
from collections import defaultdict
from typing import Optional

COLUMNS = ["workload", "systems", "n_per_system", "interface", "mode", "capacity", "us_per_call",
           "kernels", "syncs", "gpu", "driver", "cuda"]


def read_rows(paths: list[str], labels: Optional[list[str]] = None) -> list[dict]:
    """Every row of every CSV, with systems, n_per_system and us_per_call as numbers, and the
    label of its CSV (empty without labels). Raises ValueError naming the file for missing
    columns or values that are not numbers."""
    rows = []
    for k, path in enumerate(paths):
        with open(path, newline="") as f:
            reader = csv.DictReader(f)
            missing = [c for c in COLUMNS if c not in (reader.fieldnames or [])]
            if missing:
                raise ValueError(f"{path}: missing columns {', '.join(missing)} (expected "
                                 f"{','.join(COLUMNS)})")
            for line, row in enumerate(reader, start=2):
                try:
                    row["systems"] = int(row["systems"])
                    row["n_per_system"] = int(row["n_per_system"])
                    row["us_per_call"] = float(row["us_per_call"])
                except ValueError as e:
                    raise ValueError(f"{path}, line {line}: {e}") from None
                row["particles"] = row["systems"] * row["n_per_system"]
                row["label"] = labels[k] if labels else ""
                rows.append(row)
    return rows


def series(rows: list[dict]) -> dict:
    """{(interface, mode, capacity[, label]): {"single": [(particles, us)], "batch": [...]}},
    each list sorted by particles."""
    lines: dict = defaultdict(lambda: {"single": [], "batch": []})
    for r in rows:
        kind = "single" if r["systems"] == 1 else "batch"
        key = (r["interface"], r["mode"], r["capacity"]) + ((r["label"],) if r.get("label") else ())
        lines[key][kind].append((r["particles"], r["us_per_call"]))
    for points in lines.values():
        for kind in points:
            points[kind].sort()
    return dict(lines)


def title(rows: list[dict]) -> str:
    """The machines the rows were measured on: GPU, driver and CUDA of each distinct one."""
    machines = sorted({(r["gpu"], r["driver"], r["cuda"]) for r in rows})
    where = "; ".join(f"{g}, driver {d}, CUDA {c}" for g, d, c in machines)
    return f"Neighbour-list call latency, lj-pbc ({where})"


def plot(rows: list[dict], png: str) -> None:
    try:
        import matplotlib
    except ImportError:
        raise SystemExit(f"{png} not written: matplotlib is missing "
                         "(Debian: apt-get install python3-matplotlib)") from None
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(11, 5.5))
    colours = plt.get_cmap("tab20").colors  # 20 distinct colours: a line each, none repeated

    for n, (key, points) in enumerate(sorted(series(rows).items())):
        colour = colours[n % len(colours)]
        label = "/".join(key)
        for kind, marker in (("single", "o"), ("batch", "s")):
            if not points[kind]:
                continue
            x, y = zip(*points[kind])
            ax.plot(x, y, marker=marker, color=colour, linestyle="-" if kind == "single" else ":",
                    label=f"{label} ({'single systems' if kind == 'single' else 'batches'})")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("particles in the call (systems x particles per system)")
    ax.set_ylabel("microseconds per call")
    ax.set_title(title(rows), fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))  # beside the lines
    fig.tight_layout()
    fig.savefig(png, dpi=120)
    plt.close(fig)


def main(argv: Optional[list[str]] = None) -> list[dict]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("csv", nargs="+", help="CSV files of latency rows")
    parser.add_argument("--png", required=True, help="the plot to write")
    parser.add_argument("--labels", nargs="+", help="a label per CSV, added to its lines' names")
    args = parser.parse_args(argv)
    if args.labels and len(args.labels) != len(args.csv):
        raise SystemExit(f"plot_latency: {len(args.labels)} labels for {len(args.csv)} CSVs")
    try:
        rows = read_rows(args.csv, args.labels)
    except (OSError, ValueError) as e:
        raise SystemExit(f"plot_latency: {e}") from None
    if not rows:
        raise SystemExit(f"plot_latency: no rows in {', '.join(args.csv)}")
    plot(rows, args.png)
    print(f"wrote {args.png} ({len(rows)} rows, {len(series(rows))} lines)")
    return rows


if __name__ == "__main__":
    main()
