#!/usr/bin/env python3
"""Before/after table (markdown) of neighbour_bench CSVs from one device run.

Rows are matched on (suite, param, p, method, operation, mode); each side may have several CSVs
(alternated rounds of the same run). Shows every round's median and the ratio after / before of
the best and of the worst round (< 1: faster after).

  compare_runs.py --before base-1.csv base-2.csv --after new-1.csv new-2.csv --mode prepared \
      --md before-after.md --png before-after.png
"""
import argparse
import csv
from collections import defaultdict

KEY = ("suite", "param", "p", "method", "operation", "mode")


def read(paths):
    runs = defaultdict(list)  # key -> [ms per CSV]
    order = []
    machine = set()
    for path in paths:
        with open(path) as f:
            for row in csv.DictReader(f):
                machine.add(f"{row['gpu']} (driver {row['driver']}, CUDA {row['cuda']})")
                key = tuple(row[k] for k in KEY)
                if key not in runs:
                    order.append(key)
                runs[key].append(float(row["ms"]))
    return runs, order, machine


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", nargs="+", required=True, help="CSVs of the reference build")
    ap.add_argument("--after", nargs="+", required=True, help="CSVs of the changed build")
    ap.add_argument("--mode", default="prepared", help="cold or prepared (default prepared)")
    ap.add_argument("--md", help="markdown file to write (default: print)")
    ap.add_argument("--png", help="bar plot of after / before per row (matplotlib)")
    args = ap.parse_args()

    before, order, machine = read(args.before)
    after, _, machine_after = read(args.after)
    shown = []  # (label, worst and best after / before)
    lines = [
        f"{args.mode}, medians (ms) per round on {', '.join(sorted(machine | machine_after))}: "
        f"before {' '.join(args.before)}; after {' '.join(args.after)}",
        "",
        "| suite | systems x per system | method | operation | before ms | after ms | after / before |",
        "|---|---|---|---|---|---|---|",
    ]
    for key in order:
        if key[5] != args.mode or key not in after:
            continue
        b, a = before[key], after[key]
        fmt = lambda v: " / ".join(f"{x:.3f}" for x in v)
        lo, hi = sorted((min(a) / min(b), max(a) / max(b)))
        ratio = f"{lo:.3f}" if f"{lo:.3f}" == f"{hi:.3f}" else f"{lo:.3f}-{hi:.3f}"
        lines.append(
            f"| {key[0]} | {key[1]} x {int(key[2]):,} | {key[3]} | {key[4]} | {fmt(b)} | {fmt(a)} "
            f"| {ratio} |"
        )
        shown.append((f"{key[0]} {key[1]}x{int(key[2]):,} {key[3]} {key[4]}", lo, hi))
    text = "\n".join(lines) + "\n"
    if args.md:
        with open(args.md, "w") as f:
            f.write(text)
    else:
        print(text, end="")
    if args.png:
        machines = ", ".join(sorted(machine | machine_after))
        plot(shown, f"{args.mode}: after / before on {machines}, same run", args.png)


def plot(shown, title, path):
    try:
        import matplotlib
    except ImportError:
        raise SystemExit(f"{path} not written: matplotlib is missing "
                         "(Debian: apt-get install python3-matplotlib); the table is written")
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(9, 0.32 * len(shown) + 1.5))
    y = range(len(shown))
    ax.barh(y, [hi for _, _, hi in shown], color="C1", label="worst round")
    ax.barh(y, [lo for _, lo, _ in shown], color="C0", label="best round")
    ax.axvline(1.0, color="k", lw=0.8)
    ax.set_yticks(list(y), [label for label, _, _ in shown], fontsize=7)
    ax.invert_yaxis()
    ax.set_xlabel("after / before (< 1: faster after)")
    ax.set_xlim(0.5, 1.1)
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    fig.savefig(path, dpi=120)


if __name__ == "__main__":
    main()
