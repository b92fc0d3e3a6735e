#!/usr/bin/python3
"""Convergence table of a DBS procedure on uniform meshes (docs/dbs.md).

    tools/dbs_convergence.py RUN_DIR:H RUN_DIR:H RUN_DIR:H [--target STN] [--cannula cannula]

Each RUN_DIR is the output of one `needlehex run` of the whole procedure on
a uniform mesh of cell size H (mm). Per run: the dofs, the STN shift
|x(t_s) − X| (t_s the last step before the cannula touches the brain, as in
tools/study.py dbs: study_dbs.phases) and the final electrode–STN distance
(targets.csv, last step). For three runs, the observed order p of each
quantity from f(h) = f∞ − C h^p through the three (h, f) (tools/richardson.py,
bisection on p in (0.05, 6): the spacings need not have a constant ratio)
and the extrapolated f∞; no order when the differences change sign (not in
the asymptotic range).
"""
import argparse
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from outputs import read_points, read_steps  # noqa: E402
from richardson import observed  # noqa: E402
from study_dbs import phases  # noqa: E402


def measure(d, target, cannula):
    pos = read_points(d, "targets.csv")[0]
    tgt = pos[target]
    i_shift = phases(d, cannula)[0]
    st = read_steps(d)
    return {"dofs": int(st["dofs"].max()), "steps": len(st["dofs"]),
            "shift": 1e3 * float(np.linalg.norm(tgt[i_shift, :3] - tgt[0, :3])),
            "final": 1e3 * float(tgt[-1, 3]), "cpu": float(st["t_step"].sum())}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("runs", nargs="+", help="RUN_DIR:H (H the cell size in mm), coarse first")
    ap.add_argument("--target", default="STN")
    ap.add_argument("--cannula", default="cannula")
    a = ap.parse_args()
    rows = []
    for spec in a.runs:
        d, h = spec.rsplit(":", 1)
        r = measure(d, a.target, a.cannula)
        r["h"], r["dir"] = float(h), d
        rows.append(r)
    rows.sort(key=lambda r: -r["h"])
    print("| mesh (run) | h mm | dofs | steps | STN shift mm | final electrode–STN mm | step s |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        print("| %s | %g | %d | %d | %.3f | %.3f | %.0f |" % (
            os.path.basename(r["dir"].rstrip("/")), r["h"], r["dofs"], r["steps"], r["shift"],
            r["final"], r["cpu"]))
    if len(rows) >= 3:
        last = rows[-3:]
        h = [r["h"] for r in last]
        cells = []
        for key in ("shift", "final"):
            f = [r[key] for r in last]
            p, f_inf = None, None
            if (f[1] - f[0]) * (f[2] - f[1]) > 0:  # monotone: an order can be observed
                p, f_inf = observed(h, f)  # f(h) = f∞ − C h^p
            cells.append("**%.3f** (observed order %.2f)" % (f_inf, p) if p is not None else
                         "no order (differences %+.3f, %+.3f)" % (f[1] - f[0], f[2] - f[1]))
        print("| Richardson (h = %s) | | | | %s | %s | |" % (
            ", ".join("%g" % v for v in h), cells[0], cells[1]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
