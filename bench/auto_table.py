#!/usr/bin/env python3
"""`auto` against the fastest method on every configuration of `raycut bench` CSVs.

auto picks `grid` on a GPU (raycut::auto_method), so its time is the grid's row of the same run.
Writes a markdown table: per configuration the fastest method, its total, auto's total and
auto / best (host timer, medians). Exits 1 when auto is more than --bound (default 1.10) above
the best anywhere.

  auto_table.py bench-uniform.csv bench-surface.csv --md auto-vs-best.md
"""
import argparse
import csv
import sys

AUTO = "grid"
PAPER = "paper-cudaLJ"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("csv", nargs="+")
    ap.add_argument("--md", required=True)
    ap.add_argument("--timer", default="host")
    ap.add_argument("--bound", type=float, default=1.10)
    args = ap.parse_args()

    times = {}  # (suite, param, p) -> {method: total}
    sizes = {}
    for path in args.csv:
        with open(path) as f:
            for r in csv.DictReader(line for line in f if not line.startswith("#")):
                if r["timer"] != args.timer or r["method"] == PAPER:
                    continue
                key = (r["suite"], int(r["param"]), int(r["p"]))
                times.setdefault(key, {})[r["method"]] = float(r["total_ms"])
                sizes[key] = int(r["N"])

    lines = ["| suite | param | p | N | fastest | its ms | auto (grid) ms | auto / fastest |",
             "|---|---|---|---|---|---|---|---|"]
    worst, over = 1.0, []
    for key in sorted(times):
        row = times[key]
        if AUTO not in row:
            continue
        best = min(row, key=row.get)
        ratio = row[AUTO] / row[best]
        worst = max(worst, ratio)
        if ratio > args.bound:
            over.append(key)
        lines.append(f"| {key[0]} | {key[1]} | {key[2]} | {sizes[key]:,} | {best} | "
                     f"{row[best]:.3f} | {row[AUTO]:.3f} | {ratio:.2f} |")
    lines.append("")
    lines.append(f"{len(lines) - 3} configurations; auto is at most {worst:.2f}x the fastest "
                 f"({len(over)} above {args.bound:.2f}x).")
    with open(args.md, "w") as f:
        f.write("\n".join(lines) + "\n")
    print(lines[-1])
    return 1 if over else 0


if __name__ == "__main__":
    sys.exit(main())
