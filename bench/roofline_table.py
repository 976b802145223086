#!/usr/bin/env python3
"""The roofline of the grid's traversal kernels, per workload, from Nsight Compute runs of
neighbour_bench (one run per operation: `ncu --csv --metrics ... neighbour_bench --periodic
--ops OP --modes prepared --reps 1`, then `summarise_ncu.py --launches` of each).

neighbour_bench runs its workloads in a fixed order (the periodic liquid, the 512 x 128 batch, the
64 x 4096 batch; or the uniform suite alone), so a launch's workload follows from where it falls:
the batches' builds start with origins_kernel, and the 64 x 4096 batch is the first whose pass
runs a thread per target. Warm-up and timed launches are alike; the first of each is kept. The
count that neighbour_bench runs beside a list to check its length is not the list's: left out.

Per kernel: time, DRAM bytes and their share of the card's peak, and instructions and DRAM bytes
per ordered pair within the cutoff (the pairs a full list holds), beside ncu's SM throughput,
active warps and registers. The plot is an instruction roofline: warp instructions per DRAM byte
against warp instructions per second, under the card's issue and DRAM roofs.

  roofline_table.py --periodic OP=launches.csv ... --uniform OP=launches.csv ... \
      --out roofline.csv --png roofline.png --peak-gbs 3350 --sms 132 --clock-ghz 1.98
"""
import argparse
import csv

ORDERED_PAIRS = {  # ordered pairs within the cutoff (neighbour_bench's `pairs`)
    "lj-liquid-pbc 2^20": 57917774,
    "batch-pbc 512x128": 3591090,
    "batch-pbc 64x4096": 14470422,
    "uniform 32/32": 135586514,
}
TRAVERSALS = ("grid_thread_kernel", "grid_group_kernel", "grid_emit_kernel", "grid_band_kernel")


def launches(path):
    with open(path) as f:
        for row in csv.DictReader(f):
            launch, kernel = row["kernel"].split(" ", 1)
            yield int(launch), kernel, row


def periodic_workload(rows):
    """launch id -> workload, from the order neighbour_bench runs them in."""
    ids = [(launch, kernel) for launch, kernel, _ in rows]
    origins = [launch for launch, kernel in ids if kernel.startswith("origins_kernel")]
    first_batch = origins[0] if origins else float("inf")
    thread = [launch for launch, kernel in ids
              if launch > first_batch and kernel.startswith("grid_thread_kernel")]
    second_batch = max([o for o in origins if thread and o < thread[0]], default=float("inf"))

    def of(launch):
        if launch < first_batch:
            return "lj-liquid-pbc 2^20"
        return "batch-pbc 512x128" if launch < second_batch else "batch-pbc 64x4096"
    return of


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--periodic", nargs="+", action="extend", default=[],
                    help="OP=file: the periodic workloads")
    ap.add_argument("--uniform", nargs="+", action="extend", default=[],
                    help="OP=file: uniform beta 32 p 32")
    ap.add_argument("--out", required=True)
    ap.add_argument("--png")
    ap.add_argument("--peak-gbs", type=float, default=3350.0, help="DRAM peak (H100 SXM: 3350)")
    ap.add_argument("--sms", type=int, default=132)
    ap.add_argument("--clock-ghz", type=float, default=1.98)
    args = ap.parse_args()
    table, seen = [], set()
    for suite, specs in (("periodic", args.periodic), ("uniform", args.uniform)):
        for spec in specs:
            op, path = spec.split("=", 1)
            rows = list(launches(path))
            workload = periodic_workload(rows) if suite == "periodic" else (lambda _: "uniform 32/32")
            for launch, kernel, r in rows:
                if not kernel.startswith(TRAVERSALS) or (workload(launch), op, kernel) in seen:
                    continue
                if "CountKernel" in kernel and op != "count":
                    continue  # neighbour_bench's check
                seen.add((workload(launch), op, kernel))
                pairs = ORDERED_PAIRS[workload(launch)]
                dram, inst = float(r["dram_bytes_mean"]), float(r["instructions_mean"])
                table.append({
                    "workload": workload(launch), "operation": op, "kernel": kernel,
                    "us": f"{float(r['us_mean']):.1f}", "dram_mb": f"{dram / 1e6:.1f}",
                    "dram_gbs": r["dram_gbs"], "dram_pct_of_peak": r["dram_pct_of_peak"],
                    "l2_mb": f"{float(r['l2_bytes_mean']) / 1e6:.1f}",
                    "warp_instructions_m": f"{inst / 1e6:.1f}",
                    "thread_instructions_per_pair": f"{32 * inst / pairs:.1f}",
                    "dram_bytes_per_pair": f"{dram / pairs:.2f}",
                    "sm_throughput_pct": r["sm_throughput_pct"],
                    "warps_active_pct": r["warps_active_pct"], "registers": r["registers"],
                    "ordered_pairs": pairs})
    with open(args.out, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(table[0]))
        w.writeheader()
        w.writerows(table)
    if args.png:
        try:
            import matplotlib
        except ImportError:
            raise SystemExit(f"{args.png} not written: matplotlib is missing "
                             "(Debian: apt-get install python3-matplotlib); the table is written")
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        issue = args.sms * 4 * args.clock_ghz * 1e9  # warp instructions per second: 4 per SM-clock
        fig, ax = plt.subplots(figsize=(8, 5.5))
        xs = [10 ** (k / 10) for k in range(-30, 31)]
        ax.plot(xs, [min(issue, args.peak_gbs * 1e9 * x) for x in xs], "k-", lw=1)
        ax.text(40, issue * 1.06, "issue roof (4 warp instructions per SM-clock)", ha="right")
        for t in table:
            if t["kernel"].startswith("grid_band_kernel"):
                continue  # a few thousand targets
            x = float(t["warp_instructions_m"]) / max(float(t["dram_mb"]), 1e-9)
            y = float(t["warp_instructions_m"]) * 1e6 / (float(t["us"]) * 1e-6)
            main = t["workload"].startswith(("lj-liquid", "uniform"))
            ax.scatter(x, y, s=22 if main else 10, c="C0" if main else "C7")
            if main:
                label = f"{t['workload'].split('-')[0]} {t['operation']}: {t['kernel'].split('<')[0][5:-7]}"
                ax.annotate(label, (x, y), fontsize=6.5, xytext=(4, -3), textcoords="offset points")
        ax.set_xlim(0.05, 50)
        ax.set_ylim(1e11, 2e12)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("warp instructions per DRAM byte")
        ax.set_ylabel("warp instructions per second")
        ax.set_title("Grid traversals, instruction roofline (ncu); grey: batches", fontsize=10)
        fig.tight_layout()
        fig.savefig(args.png, dpi=130)


if __name__ == "__main__":
    main()
