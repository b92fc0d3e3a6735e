#!/usr/bin/python3
"""Plots of the cases in cases/ for docs/cases.md: runs the simulator, reads
its CSV outputs and writes PNGs to docs/img/.

    tools/plot_cases.py [--binary build/needlehex] [--out docs/img]

- cantilever_convergence.png: tip deflection error against Timoshenko beam
  theory versus cell size, grids 10n x n x n for n = 1, 2, 4, 8 (ν = 0,
  static tolerance 1e-10, as tests/test_cantilever.c), with a slope-2 line.
- phantom_probes.png: ux(t) of probes 1-7 of cases/phantom-tissue.yaml.
- phantom_profile.png: ux at t = 0.5 s along the probe line on the grids
  8x4x4, 16x8x8 and 32x16x16.

It also prints the numbers behind the plots as Markdown tables. Needs numpy
and matplotlib (Debian's python3-numpy, python3-matplotlib).
"""
import argparse
import math
import os
import subprocess
import sys
import tempfile

import matplotlib.ticker
import numpy as np

from outputs import read_series
from plotstyle import FIGSIZE, plt, save
from richardson import richardson

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def run(binary, case, out, sets=()):
    cmd = [binary, "run", os.path.join(ROOT, "cases", case), "--quiet", "--overwrite", "--out", out]
    for s in sets:
        cmd += ["--set", s]
    subprocess.run(cmd, check=True)


def read_probes(out):
    """{name: (t[], ux[], uy[], uz[])} from probes.csv."""
    series = read_series(out, "probes.csv", ["time", "ux", "uy", "uz"])
    return {k: tuple(v.T) for k, v in series.items()}


def timoshenko_tip():
    """Tip deflection of cases/cantilever.yaml at ν = 0: the formula of
    tests/test_cantilever.c (load P spread uniformly over x in [L-a, L])."""
    E, nu, L, b, P, a = 1.0e6, 0.0, 0.1, 0.01, 1.0e-3, 0.001
    I, A, G = b ** 4 / 12, b * b, E / (2 * (1 + nu))
    kappa = 10 * (1 + nu) / (12 + 11 * nu)
    s0, s1 = L - a, L
    bend = (L * (s1 ** 3 - s0 ** 3) - (s1 ** 4 - s0 ** 4) / 4) / (6 * E * I)
    shear = 0.5 * (s1 * s1 - s0 * s0) / (kappa * G * A)
    return P / a * (bend + shear), P / a * bend


def cantilever(binary, tmp, img):
    beam, eb = timoshenko_tip()
    ns = [1, 2, 4, 8]
    d = []
    for n in ns:
        out = os.path.join(tmp, "cantilever_%d" % n)
        run(binary, "cantilever.yaml", out,
            ["tissue.grid=[%d,%d,%d]" % (10 * n, n, n), "tissue.material.poisson=0",
             "solver.tolerance=1e-10"])
        t, ux, uy, uz = read_probes(out)["tip"]
        d.append(-uz[-1])
    d = np.array(d)
    h = 0.01 / np.array(ns)  # cell edge: 0.1 m / 10n = 0.01 m / n
    err = np.abs(d - beam) / beam
    extrap, _, p = richardson(ns[1:], d[1:])  # d(n) = d∞ − C n^(−p)

    print("Timoshenko tip deflection %.6e m (Euler-Bernoulli %.6e m)" % (beam, eb))
    print("\n| grid | cell size (mm) | tip deflection (m) | error vs Timoshenko | order from errors |"
          " order from differences |")
    print("|---|---|---|---|---|---|")
    for i, n in enumerate(ns):
        oe = "%.2f" % math.log2(err[i - 1] / err[i]) if i > 0 else "–"
        od = "%.2f" % math.log2((d[i - 1] - d[i - 2]) / (d[i] - d[i - 1])) if i > 1 else "–"
        print("| %d×%d×%d | %.3f | %.6e | %+.3f %% | %s | %s |" % (
            10 * n, n, n, 1e3 * h[i], d[i], 100 * (d[i] - beam) / beam, oe, od))
    print("\nRichardson (last three grids): order %.3f, extrapolated %.6e m (%+.3f %% vs Timoshenko)"
          % (p, extrap, 100 * (extrap - beam) / beam))

    fig, ax = plt.subplots(figsize=FIGSIZE)
    ax.loglog(1e3 * h, err, "o-", label="needlehex, tip deflection error")
    ref = err[-1] * (h / h[-1]) ** 2
    ax.loglog(1e3 * h, ref, "k--", label="slope 2 reference")
    for i, n in enumerate(ns):
        ax.annotate("%d×%d×%d" % (10 * n, n, n), (1e3 * h[i], err[i]), textcoords="offset points",
                    xytext=(6, -12), fontsize=8)
    ax.set_xticks(1e3 * h)
    ax.set_xticklabels(["%g" % v for v in 1e3 * h])
    ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax.set_xlabel("cell size h (mm)")
    ax.set_ylabel("|δ − δ_Timoshenko| / δ_Timoshenko  (–)")
    ax.set_title("cantilever: tip deflection vs Timoshenko beam theory (ν = 0)")
    ax.grid(True, which="both", alpha=0.3)
    save(fig, os.path.join(img, "cantilever_convergence.png"), legend=ax)


def phantom(binary, tmp, img):
    out = os.path.join(tmp, "phantom")
    run(binary, "phantom-tissue.yaml", out)
    pr = read_probes(out)
    names = [str(i) for i in range(1, 8)]
    fig, ax = plt.subplots(figsize=FIGSIZE)
    cmap = plt.get_cmap("viridis")
    for i, nm in enumerate(names):
        t, ux, uy, uz = pr[nm]
        ax.plot(t, 1e6 * ux, "-", color=cmap(i / 6), label="probe %s (x = %d mm)" % (nm, 5 * (i + 1)))
    ax.axvline(0.1, color="grey", ls=":", lw=1)
    ax.text(0.103, 0.03, "end of load ramp", color="grey", fontsize=8,
            transform=ax.get_xaxis_transform())
    ax.set_xlabel("time t (s)")
    ax.set_ylabel("displacement uₓ (µm)")
    ax.set_title("phantom-tissue (8×4×4): probe displacement along the axis")
    ax.grid(True, alpha=0.3)
    save(fig, os.path.join(img, "phantom_probes.png"), legend=ax)

    print("\n| probe | x (mm) | ux at t = 0.1 s (µm) | ux at t = 0.5 s (µm) |")
    print("|---|---|---|---|")
    for i, nm in enumerate(names):
        t, ux, uy, uz = pr[nm]
        k = int(np.argmin(np.abs(t - 0.1)))
        print("| %s | %d | %.4f | %.4f |" % (nm, 5 * (i + 1), 1e6 * ux[k], 1e6 * ux[-1]))

    # Final profile along the probe line on three grids.
    grids = [(8, 4, 4), (16, 8, 8), (32, 16, 16)]
    fig, ax = plt.subplots(figsize=FIGSIZE)
    rows = []
    for g, mk in zip(grids, "os^"):
        o = os.path.join(tmp, "phantom_%d" % g[0])
        run(binary, "phantom-tissue.yaml", o, ["tissue.grid=[%d,%d,%d]" % g, "output.every=0"])
        p = read_probes(o)
        x = np.array([5 * (i + 1) for i in range(7)])
        ux = np.array([p[nm][1][-1] for nm in names])
        rows.append(ux)
        ax.plot(x, 1e6 * ux, mk + "-", label="grid %d×%d×%d" % g)
    ax.set_xlabel("probe position x (mm), on the axis y = z = 10 mm")
    ax.set_ylabel("displacement uₓ at t = 0.5 s (µm)")
    ax.set_title("phantom-tissue: axial displacement profile by grid")
    ax.grid(True, alpha=0.3)
    save(fig, os.path.join(img, "phantom_profile.png"), legend=ax)

    print("\n| probe | x (mm) | " + " | ".join("ux %d×%d×%d (µm)" % g for g in grids) + " |")
    print("|---|---|" + "---|" * len(grids))
    for i, nm in enumerate(names):
        print("| %s | %d | " % (nm, 5 * (i + 1)) + " | ".join("%.4f" % (1e6 * r[i]) for r in rows)
              + " |")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--binary", default=os.path.join(ROOT, "build", "needlehex"))
    ap.add_argument("--out", default=os.path.join(ROOT, "docs", "img"), help="folder for the PNGs")
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        cantilever(a.binary, tmp, a.out)
        phantom(a.binary, tmp, a.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
