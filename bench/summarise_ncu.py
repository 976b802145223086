#!/usr/bin/env python3
"""Per-kernel roofline numbers from Nsight Compute's CSV (scripts/device_run.sh roofline).

Reads `ncu --csv --metrics ...` output (one row per kernel launch and metric) and writes one row
per kernel: launches, mean time, DRAM and L2 bytes, instructions, the achieved DRAM bandwidth and
its share of the card's peak, and ncu's own SM and memory throughput percentages.

  summarise_ncu.py ncu-periodic.csv --peak-gbs 3350 --out roofline.csv

With --launches, one row per launch instead (in launch order, its ID first), for runs whose
kernels of one name serve several workloads; --min-us drops the launches shorter than that.
"""
import argparse
import csv
import re
from collections import defaultdict


def short(name):
    name = re.sub(r"raycut::(detail::)?(cuda::)?", "", name)
    name = re.sub(r"\(.*$", "", name)  # the parameter list
    return name.replace("<unnamed>::", "").replace("void ", "").strip()


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("ncu_csv")
    ap.add_argument("--peak-gbs", type=float, default=3350.0,
                    help="the card's DRAM peak in GB/s (H100 SXM 80GB: 3350; H200: 4800)")
    ap.add_argument("--out", required=True)
    ap.add_argument("--launches", action="store_true", help="one row per launch, not per kernel")
    ap.add_argument("--min-us", type=float, default=0.0,
                    help="leave out rows whose mean time is below this (microseconds)")
    args = ap.parse_args()
    with open(args.ncu_csv) as f:
        lines = f.readlines()
    start = next(k for k, line in enumerate(lines) if line.startswith('"ID"'))
    metrics = defaultdict(lambda: defaultdict(list))
    device = {}
    order = []
    for row in csv.DictReader(lines[start:]):
        kernel = short(row["Kernel Name"])
        if args.launches:
            kernel = f'{row["ID"]} {kernel}'
        if kernel not in metrics:
            order.append(kernel)
        device[kernel] = row.get("Device Name", "")
        value = row["Metric Value"].replace(",", "")
        metrics[kernel][row["Metric Name"]].append(float(value) if value else 0.0)

    def mean(m, key):
        v = m.get(key, [])
        return sum(v) / len(v) if v else 0.0

    with open(args.out, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["kernel", "launches", "us_mean", "dram_bytes_mean", "l2_bytes_mean",
                    "instructions_mean", "dram_gbs", "dram_pct_of_peak", "sm_throughput_pct",
                    "memory_throughput_pct", "warps_active_pct", "registers", "device"])
        for kernel in order:
            m = metrics[kernel]
            ns = mean(m, "gpu__time_duration.sum")
            if ns < 1000 * args.min_us:
                continue
            dram = mean(m, "dram__bytes_read.sum") + mean(m, "dram__bytes_write.sum")
            gbs = dram / ns if ns else 0.0  # bytes per ns = GB/s
            w.writerow([kernel, len(m["gpu__time_duration.sum"]), f"{ns / 1000:.2f}",
                        f"{dram:.0f}", f"{mean(m, 'lts__t_bytes.sum'):.0f}",
                        f"{mean(m, 'sm__inst_executed.sum'):.0f}", f"{gbs:.1f}",
                        f"{100 * gbs / args.peak_gbs:.1f}",
                        f"{mean(m, 'sm__throughput.avg.pct_of_peak_sustained_elapsed'):.1f}",
                        f"{mean(m, 'gpu__compute_memory_throughput.avg.pct_of_peak_sustained_elapsed'):.1f}",
                        f"{mean(m, 'sm__warps_active.avg.pct_of_peak_sustained_active'):.1f}",
                        f"{mean(m, 'launch__registers_per_thread'):.0f}", device[kernel]])


if __name__ == "__main__":
    main()
