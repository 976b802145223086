#!/usr/bin/env python3
"""Compares raycut's weakly compressible SPH runs with the reference data (docs/sph-validation.md).

Dam break: the surge front Z = x_front / a against T = t sqrt(2 g / a) of
`raycut sph --scenario dam-break --result-csv F` with Martin & Moyce's (1952) digitised points
(docs/sph-validation.md), |Z_sim - Z_exp| / Z_exp at every point (the target: <= 10 % for T <= 2.5).
Hydrostatic: p(y) of `raycut sph --scenario hydrostatic --result-csv F` against rho0 g (H - y)
(the targets: within 2 % below the top two particle layers; density within 1 %), with a
least-squares fit of p against y over those layers.

Prints markdown tables; writes docs/images/validation-dam-break.png and
validation-hydrostatic.png (matplotlib).

  python3 bench/sph_validation.py \
      --dam-break bench/results/cpu-2core/sph-dam-break-r10-2026-11-22.csv:"10 across a" \
      --dam-break bench/results/cpu-2core/sph-dam-break-r20-2026-11-22.csv:"20 across a" \
      --hydrostatic bench/results/cpu-2core/sph-hydrostatic-2026-11-22.csv --out docs/images
"""

import argparse
import bisect
import csv
import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

# Martin & Moyce (1952), digitised.
T_EXP = [0, 0.41, 0.84, 1.19, 1.43, 1.63, 1.82, 1.97, 2.20, 2.32, 2.50, 2.64, 2.82, 2.96, 3.11,
         3.33]
Z_EXP = [1.00, 1.11, 1.23, 1.44, 1.67, 1.89, 2.11, 2.33, 2.56, 2.78, 3.00, 3.22, 3.44, 3.67, 3.89,
         4.11]
T_TARGET = 2.5
RHO0, G = 1000.0, 9.81


def read(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def interpolate(xs, ys, x):
    k = min(max(bisect.bisect_left(xs, x), 1), len(xs) - 1)
    return ys[k - 1] + (ys[k] - ys[k - 1]) * (x - xs[k - 1]) / (xs[k] - xs[k - 1])


def dam_break(runs, out):
    fig, ax = plt.subplots(figsize=(6.4, 4.6))
    ax.plot(T_EXP, Z_EXP, "ko", label="Martin & Moyce 1952 (digitised)")
    table = []
    for path, label in runs:
        rows = read(path)
        t = [float(r["T"]) for r in rows]
        z = [float(r["Z"]) for r in rows]
        ax.plot(t, z, "-", label=f"raycut WCSPH, {label}")
        errors = []
        for te, ze in zip(T_EXP, Z_EXP):
            if te > t[-1]:
                break
            zs = interpolate(t, z, te)
            errors.append((te, ze, zs, (zs - ze) / ze))
        table.append((label, errors))
    ax.axvline(T_TARGET, color="grey", lw=0.8, ls=":")
    ax.set_xlabel(r"$T = t\,\sqrt{2g/a}$")
    ax.set_ylabel(r"$Z = x_{front}/a$")
    ax.set_title("Dam break (a = 0.1 m, column a x 2a x a)")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    path = os.path.join(out, "validation-dam-break.png")
    fig.savefig(path, dpi=120)
    print(f"wrote {path}\n")

    labels = [label for label, _ in table]
    print("| T | Z exp | " + " | ".join(f"Z ({l}) | error" for l in labels) + " |")
    print("|---|---|" + "---|---|" * len(labels))
    for k, (te, ze) in enumerate(zip(T_EXP, Z_EXP)):
        cells = []
        for _, errors in table:
            if k < len(errors):
                cells.append(f"{errors[k][2]:.3f} | {100 * errors[k][3]:+.1f} %")
            else:
                cells.append("- | -")
        print(f"| {te:.2f} | {ze:.2f} | " + " | ".join(cells) + " |")
    print()
    for label, errors in table:
        within = [e for e in errors if e[0] <= T_TARGET]
        worst = max(within, key=lambda e: abs(e[3]))
        mean = sum(e[3] for e in within) / len(within)
        allmax = max(abs(e[3]) for e in errors)
        print(f"{label}: T <= {T_TARGET}: max |Z_sim - Z_exp| / Z_exp = {100 * abs(worst[3]):.1f} % "
              f"(at T = {worst[0]}), mean signed {100 * mean:+.1f} %; all T: max "
              f"{100 * allmax:.1f} %")


def hydrostatic(path_csv, out):
    rows = read(path_csv)
    y = [float(r["y"]) for r in rows]
    p = [float(r["p_mean"]) for r in rows]
    ph = [float(r["p_hydrostatic"]) for r in rows]
    rho = [float(r["rho_mean"]) for r in rows]
    layers = len(rows)
    # The layers below the top two (the CSV may hold a partial layer above the top: drop it).
    full = [k for k in range(layers) if float(r_count(rows[k])) > 0.5 * max(
        float(r_count(r)) for r in rows)]
    top = max(full)
    below = [k for k in full if k <= top - 2]
    height = ph[0] / (RHO0 * G) + y[0]
    n = len(below)
    sy = sum(y[k] for k in below)
    sp = sum(p[k] for k in below)
    syy = sum(y[k] ** 2 for k in below)
    syp = sum(y[k] * p[k] for k in below)
    slope = (n * syp - sy * sp) / (n * syy - sy * sy)
    intercept = (sp - slope * sy) / n
    fit_height = -intercept / slope
    errs = [(p[k] - ph[k]) / ph[k] for k in below]
    devs = [rho[k] / RHO0 - 1 for k in below]

    fig, (a1, a2) = plt.subplots(1, 2, figsize=(9.6, 4.4))
    depth = [height - v for v in y]
    a1.plot([0, height], [0, RHO0 * G * height], "k-", label=r"$\rho_0 g (H - y)$")
    a1.plot(depth, p, "o", ms=4, label="raycut WCSPH (layer means)")
    a1.set_xlabel("depth H - y [m]")
    a1.set_ylabel("pressure [Pa]")
    a1.grid(alpha=0.3)
    a1.legend()
    a1.set_title(f"Hydrostatic column, H = {height:.2f} m")
    a2.plot([depth[k] for k in below], [100 * e for e in errs], "o-", ms=4,
            label="pressure error")
    a2.plot([depth[k] for k in below], [100 * d for d in devs], "s-", ms=4,
            label=r"$\rho/\rho_0 - 1$")
    for v in (-2, 2):
        a2.axhline(v, color="grey", lw=0.8, ls=":")
    a2.set_xlabel("depth H - y [m]")
    a2.set_ylabel("%")
    a2.grid(alpha=0.3)
    a2.legend()
    a2.set_title("below the top two layers")
    fig.tight_layout()
    path = os.path.join(out, "validation-hydrostatic.png")
    fig.savefig(path, dpi=120)
    print(f"\nwrote {path}\n")

    print("| layer | depth [m] | p [Pa] | rho0 g (H - y) [Pa] | error | rho / rho0 - 1 |")
    print("|---|---|---|---|---|---|")
    for k in full:
        mark = "" if k in below else " (top two)"
        print(f"| {k}{mark} | {height - y[k]:.4f} | {p[k]:.1f} | {ph[k]:.1f} | "
              f"{100 * (p[k] - ph[k]) / ph[k]:+.2f} % | {100 * (rho[k] / RHO0 - 1):+.3f} % |")
    print(f"\nbelow the top two layers ({len(below)} layers): max |error| "
          f"{100 * max(map(abs, errs)):.2f} %, mean |error| "
          f"{100 * sum(map(abs, errs)) / len(errs):.2f} %, max |rho/rho0 - 1| "
          f"{100 * max(map(abs, devs)):.3f} %; fit dp/dy = {slope:.1f} Pa/m = "
          f"{-slope / (RHO0 * G):.4f} rho0 g, p = 0 at y = {fit_height:.4f} m (H = {height:.4f})")


def r_count(row):
    return row["count"]


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--dam-break", action="append", default=[],
                    help="PATH[:LABEL] of a dam-break --result-csv (repeatable)")
    ap.add_argument("--hydrostatic", help="PATH of a hydrostatic --result-csv")
    ap.add_argument("--out", default="docs/images", help="folder for the PNGs")
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    if args.dam_break:
        runs = []
        for spec in args.dam_break:
            path, _, label = spec.partition(":")
            runs.append((path, label or os.path.basename(path)))
        dam_break(runs, args.out)
    if args.hydrostatic:
        hydrostatic(args.hydrostatic, args.out)


if __name__ == "__main__":
    main()
