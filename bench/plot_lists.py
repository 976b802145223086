#!/usr/bin/env python3
"""Markdown tables (targets with PASS/MISS, every configuration) and a plot of neighbour_bench.

Reads the CSV of bench/neighbour_bench (CUDA-event medians, ms). Targets (the neighbour-list
issue, uniform suite, beta 32): at p = 32 (1,048,576 particles) build + full list <= 2.0 ms and
<= 3x build + count, build + half list <= 1.2 ms, build + lj_forces <= 0.75 ms, build + lj
<= 0.6 ms, the user functor within 5 % of the built-in lj; at p = 8 build + full list <= 0.4 ms.
Targets are judged on --mode (default prepared: reused buffers) for every method in the CSV.
Rows of the periodic workloads (neighbour_bench --periodic: suites ending in -pbc, param =
systems, p = particles per system) get a table of their own.

  plot_lists.py lists.csv --md lists.md --png lists.png [--mode prepared]
"""
import argparse
import csv
import math
from collections import defaultdict

OPS = ["build", "count", "list_full", "list_only_full", "list_half", "list_full_dv", "padded",
       "lj", "lj_forces", "functor_lj", "list_full_s", "list_half_s", "lj_forces_only"]


def periodic(suite):
    return suite.endswith("-pbc")

# (description, operation, beta, p, kind, limit): kind "ms" compares the median with the limit;
# "ratio:OP" compares median / median of OP with the limit.
TARGETS = [
    ("build + full list, 1,048,576 particles", "list_full", 32, 32, "ms", 2.0),
    ("build + full list vs build + count, 1,048,576 particles", "list_full", 32, 32,
     "ratio:count", 3.0),
    ("build + half list, 1,048,576 particles", "list_half", 32, 32, "ms", 1.2),
    ("build + full list, 262,144 particles (p 8)", "list_full", 32, 8, "ms", 0.4),
    ("build + lj_forces, 1,048,576 particles", "lj_forces", 32, 32, "ms", 0.75),
    ("build + lj, 1,048,576 particles", "lj", 32, 32, "ms", 0.6),
    ("build + user functor vs build + lj, 1,048,576 particles", "functor_lj", 32, 32, "ratio:lj",
     1.05),
]


def load(paths):
    rows = []
    for path in paths:
        with open(path) as f:
            rows += list(csv.DictReader(f))
    return rows


def fnum(s):
    try:
        return float(s)
    except (TypeError, ValueError):
        return math.nan


def row_values(ops):
    """N, pairs and the median ms by operation (NaN when absent) of one configuration's rows."""
    any_row = next(iter(ops.values()))
    return (int(any_row["N"]), fnum(any_row["pairs"]),
            lambda op: fnum(ops[op]["ms"]) if op in ops else math.nan)


def fmt(v, digits=3):
    return "" if v is None or math.isnan(v) else f"{v:.{digits}f}"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("csv", nargs="+", help="CSV files of neighbour_bench")
    ap.add_argument("--md", help="markdown to write (default: stdout)")
    ap.add_argument("--png", help="plot to write (matplotlib)")
    ap.add_argument("--mode", default="prepared", help="mode the targets are judged on")
    args = ap.parse_args()

    rows = load(args.csv)
    if not rows:
        raise SystemExit("no rows in " + ", ".join(args.csv))
    # (suite, param, p, method, mode) -> op -> row
    table = defaultdict(dict)
    for r in rows:
        key = (r["suite"], int(r["param"]), int(r["p"]), r["method"], r["mode"])
        table[key][r["operation"]] = r
    methods = sorted({r["method"] for r in rows})
    modes = [m for m in ("prepared", "cold") if any(r["mode"] == m for r in rows)]

    def ms(suite, beta, p, method, mode, op):
        r = table.get((suite, beta, p, method, mode), {}).get(op)
        return fnum(r["ms"]) if r else math.nan

    def value(t, method, mode):
        _, op, beta, p, kind, _ = t
        v = ms("uniform", beta, p, method, mode, op)
        if kind.startswith("ratio:"):
            v = v / ms("uniform", beta, p, method, mode, kind[6:])
        return v

    env = rows[0]
    out = [f"Measured on {env['gpu']} (driver {env['driver']}, CUDA {env['cuda']}) by "
           "bench/neighbour_bench: CUDA events from device positions to a complete device "
           f"result, medians of {env['reps']} after a warm-up. prepared: one Engine and its "
           "buffers reused; cold: a fresh Engine and fresh buffers, every allocation timed.\n"]

    has_uniform = any(k[0] == "uniform" for k in table)
    if has_uniform:
        out.append(f"### Targets (uniform suite, beta 32; judged on {args.mode})\n")
        head = "| target | limit | method | " + " | ".join(modes) + " | result |"
        out += [head, "|" + "---|" * (4 + len(modes))]
    for t in TARGETS if has_uniform else []:
        desc, _, _, _, kind, limit = t
        unit = "x" if kind.startswith("ratio:") else " ms"
        for method in methods:
            vals = {m: value(t, method, m) for m in modes}
            v = vals.get(args.mode, math.nan)
            result = "n/a" if math.isnan(v) else ("PASS" if v <= limit else "MISS")
            cells = " | ".join(fmt(vals[m]) + (unit if not math.isnan(vals[m]) else "")
                               for m in modes)
            out.append(f"| {desc} | <= {limit:g}{unit} | {method} | {cells} | {result} |")
    if has_uniform:
        out.append("")

    for mode in modes if any(not periodic(k[0]) for k in table) else []:
        out.append(f"### Every configuration ({mode}, ms; list/count = build + full list over "
                   "build + count; functor/lj = build + user functor over build + lj)\n")
        cols = ["suite", "beta", "p", "N", "method", "neighbours", "build", "count", "list_full",
                "list/count", "list only", "half", "full+d+v", "padded (K, overflow)", "lj",
                "lj_forces", "functor", "functor/lj", "list MB"]
        out += ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
        for key in sorted(k for k in table if k[4] == mode and not periodic(k[0])):
            suite, beta, p, method, _ = key
            ops = table[key]
            n, pairs, get = row_values(ops)
            padded = ""
            if "padded" in ops:
                pr = ops["padded"]
                padded = f"{fmt(get('padded'))} (K {pr['k']}, {pr['overflowed_rows']} rows)"
            mb = fnum(ops["list_full"]["bytes"]) / 2**20 if "list_full" in ops else math.nan
            cells = [suite, str(beta) if suite == "uniform" else "-",
                     str(p) if suite == "uniform" else "-", f"{n:,}", method,
                     fmt(pairs / n if n else math.nan, 1), fmt(get("build")), fmt(get("count")),
                     fmt(get("list_full")), fmt(get("list_full") / get("count"), 2),
                     fmt(get("list_only_full")), fmt(get("list_half")), fmt(get("list_full_dv")),
                     padded, fmt(get("lj")), fmt(get("lj_forces")), fmt(get("functor_lj")),
                     fmt(get("functor_lj") / get("lj"), 3), fmt(mb, 1)]
            out.append("| " + " | ".join(cells) + " |")
        out.append("")

    for mode in modes:
        keys = sorted((k for k in table if k[4] == mode and periodic(k[0])),
                      key=lambda k: (k[0], k[1] * k[2], k[3]))
        if not keys:
            continue
        out.append(f"### Periodic workloads ({mode}, ms; density 0.8442, rc 2.5; lists with image "
                   "shifts; full/count = build + full list over build + count; lj_forces alone: "
                   "the compute on a built engine)\n")
        cols = ["suite", "systems", "per system", "N", "method", "pairs", "neighbours", "build",
                "count", "full list", "full/count", "half list", "lj_forces", "lj_forces alone",
                "list MB"]
        out += ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
        for key in keys:
            suite, systems, per_system, method, _ = key
            ops = table[key]
            n, pairs, get = row_values(ops)
            mb = fnum(ops["list_full_s"]["bytes"]) / 2**20 if "list_full_s" in ops else math.nan
            cells = [suite, str(systems), f"{per_system:,}", f"{n:,}", method,
                     "" if math.isnan(pairs) else f"{int(pairs):,}",
                     fmt(pairs / n if n else math.nan, 1), fmt(get("build")), fmt(get("count")),
                     fmt(get("list_full_s")), fmt(get("list_full_s") / get("count"), 2),
                     fmt(get("list_half_s")), fmt(get("lj_forces")), fmt(get("lj_forces_only")),
                     fmt(mb, 1)]
            out.append("| " + " | ".join(cells) + " |")
        out.append("")

    bad = [r for r in rows if r["check"] not in ("ok", "bitwise", "close", "-")]
    if bad:
        out.append("**Result checks that failed:** " + ", ".join(
            f"{r['method']} {r['operation']} {r['mode']} N={r['N']}: {r['check']}" for r in bad))
        out.append("")

    text = "\n".join(out)
    if args.md:
        with open(args.md, "w") as f:
            f.write(text)
    else:
        print(text)

    if args.png and not has_uniform:
        print(f"{args.png} not written: no uniform-suite rows to plot")
    elif args.png:
        try:
            import matplotlib
        except ImportError:
            raise SystemExit(f"{args.png} not written: matplotlib is missing "
                             "(Debian: apt-get install python3-matplotlib); the tables are written")
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        mode = args.mode
        fig, (left, right) = plt.subplots(1, 2, figsize=(13, 5))
        shown = ["count", "list_full", "list_half", "list_only_full", "lj", "lj_forces",
                 "functor_lj"]
        styles = {m: s for m, s in zip(methods, ["-", "--", ":", "-."] * 4)}
        for method in methods:
            for op in shown:
                pts = sorted((int(next(iter(table[k].values()))["N"]), fnum(table[k][op]["ms"]))
                             for k in table
                             if k[0] == "uniform" and k[1] == 32 and k[3] == method
                             and k[4] == mode and op in table[k])
                if pts:
                    left.plot([x for x, _ in pts], [y for _, y in pts], styles[method],
                              color=f"C{shown.index(op)}", marker="o", ms=3,
                              label=f"{method} {op}")
            for beta in sorted({k[1] for k in table if k[0] == "uniform"}):
                pts = []
                for k in table:
                    if (k[0], k[1], k[3], k[4]) == ("uniform", beta, method, mode) and \
                            "list_full" in table[k] and "count" in table[k]:
                        pts.append((int(table[k]["count"]["N"]),
                                    fnum(table[k]["list_full"]["ms"]) /
                                    fnum(table[k]["count"]["ms"])))
                pts.sort()
                if pts:
                    right.plot([x for x, _ in pts], [y for _, y in pts], styles[method],
                               color="C0" if beta == 32 else "C1", marker="o",
                               label=f"{method} beta {beta}")
        left.set_xscale("log")
        left.set_yscale("log")
        left.set_xlabel("particles (uniform suite, beta 32)")
        left.set_ylabel(f"ms (CUDA events, median, {mode})")
        left.axhline(2.0, color="grey", lw=0.5)
        left.legend(fontsize=6, ncol=2)
        right.set_xscale("log")
        right.axhline(3.0, color="red", lw=0.8, label="target 3x")
        right.set_xlabel("particles (uniform suite)")
        right.set_ylabel("(build + full list) / (build + count)")
        right.legend(fontsize=7)
        fig.suptitle(f"Neighbour lists vs fused count, {env['gpu']}")
        fig.tight_layout()
        fig.savefig(args.png, dpi=120)


if __name__ == "__main__":
    main()
