#!/usr/bin/python3
"""The traction patch test, end to end (tests/data/traction_patch.yaml).

A block E = 5000 Pa, ν = 0, L = 0.04 m, clamped at x = 0, under a uniform
traction σ = 100 Pa on x = L ramped by the schedule [[0, 0], [2, 1]]
(static, steps at t = 1, 2: σ/2, σ). Exact solution u_x = s(t) σ x / E,
u_y = u_z = 0 (uniaxial stress; with ν = 0 the clamp adds no lateral
strain), which lies in the trilinear space: every grid must reproduce it to
round-off (tolerance 1e-9 relative to σL/E). Also as a pressure p = −σ
(traction −p n = σ e_x on that face), and a pressure p = σ: u_x = −s σ x / E.
"""
import csv
import os
import shutil
import subprocess
import sys
import tempfile

BIN, SRC = os.environ["NH_BINARY"], os.environ["NH_SOURCE_DIR"]
SCENE = os.path.join(SRC, "tests", "data", "traction_patch.yaml")
E, SIGMA, L = 5000.0, 100.0, 0.04
failures = []

def run(tmp, name, sets, sign):
    out = os.path.join(tmp, name)
    cmd = [BIN, "run", SCENE, "--quiet", "--out", out]
    for s in sets:
        cmd += ["--set", s]
    subprocess.run(cmd, check=True)
    with open(os.path.join(out, "probes.csv")) as f:
        rows = list(csv.DictReader(f))
    tol = 1e-9 * SIGMA * L / E
    for r in rows:
        t, x = float(r["time"]), float(r["x"]) - float(r["ux"])
        s = min(max(t / 2.0, 0.0), 1.0)
        want = (float(r["ux"]), float(r["uy"]), float(r["uz"]))
        exact = (sign * s * SIGMA * x / E, 0.0, 0.0)
        for k in range(3):
            if abs(want[k] - exact[k]) > tol:
                failures.append(f"{name}: probe {r['name']} at t = {t}: u[{k}] expected "
                                f"{exact[k]:.12g}, got {want[k]:.12g} (tol {tol:.3g})")
    if len(rows) != 6:
        failures.append(f"{name}: {len(rows)} probe rows, expected 6")

def main():
    tmp = tempfile.mkdtemp(prefix="nh-traction-")
    region = "box: {min: [0.04, -1, -1], max: [1, 1, 1]}, schedule: [[0, 0], [2, 1]]"
    try:
        run(tmp, "grid-4-3-2", [], 1)
        run(tmp, "grid-1-1-1", ["tissue.grid=[1,1,1]"], 1)
        run(tmp, "grid-7-5-3", ["tissue.grid=[7,5,3]"], 1)
        run(tmp, "pull-by-pressure",
            ["tissue.tractions=[{%s, pressure: %g}]" % (region, -SIGMA)], 1)
        run(tmp, "push-by-pressure",
            ["tissue.tractions=[{%s, pressure: %g}]" % (region, SIGMA)], -1)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    for f in failures:
        print("FAIL:", f, file=sys.stderr)
    return 1 if failures else 0

if __name__ == "__main__":
    sys.exit(main())
