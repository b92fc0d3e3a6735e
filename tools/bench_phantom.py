#!/usr/bin/python3
"""Benchmark: median ms/step of cases/phantom-tissue.yaml at 8x4x4, 16x8x8 and
32x16x16 cells, split by phase, and the ratio of the whole step to the
numeric factorisation alone. Not a test: it reports numbers.

    tools/bench_phantom.py [--binary build/needlehex] [--steps 30] [--markdown]

Reads each run's steps.csv (times per phase, seconds). The first step is left
out of the medians: it includes CHOLMOD's symbolic analysis.
"""
import argparse
import csv
import os
import statistics
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PHASES = ["t_assemble", "t_factor", "t_solve", "t_constraints", "t_adapt", "t_output", "t_step"]


def run(binary, grid, steps, out):
    cmd = [binary, "run", os.path.join(ROOT, "cases", "phantom-tissue.yaml"), "--quiet", "--overwrite",
           "--out", out, "--set", "tissue.grid=[%d,%d,%d]" % grid,
           "--set", "time.steps=%d" % steps, "--set", "output.every=0"]
    subprocess.run(cmd, check=True)
    with open(os.path.join(out, "steps.csv")) as f:
        rows = list(csv.DictReader(f))[1:]
    med = {p: 1e3 * statistics.median(float(r[p]) for r in rows) for p in PHASES}
    return int(rows[0]["dofs"]), int(rows[0]["free_dofs"]), med


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--binary", default=os.path.join(ROOT, "build", "needlehex"))
    ap.add_argument("--steps", type=int, default=30)
    ap.add_argument("--markdown", action="store_true", help="print a Markdown table")
    a = ap.parse_args()
    grids = [(8, 4, 4), (16, 8, 8), (32, 16, 16)]
    print("grid        dofs  free   assemble   factor    solve   output     step  step/factor")
    lines = []
    with tempfile.TemporaryDirectory() as tmp:
        for g in grids:
            dofs, free, m = run(a.binary, g, a.steps, os.path.join(tmp, "x".join(map(str, g))))
            ratio = m["t_step"] / m["t_factor"]
            print("%-9s %6d %5d %10.3f %8.3f %8.3f %8.3f %8.3f %8.2f" % (
                "x".join(map(str, g)), dofs, free, m["t_assemble"], m["t_factor"], m["t_solve"],
                m["t_output"], m["t_step"], ratio))
            lines.append("| %s | %d | %d | %.3f | %.3f | %.3f | %.3f | %.3f | %.2f |" % (
                "×".join(map(str, g)), dofs, free, m["t_assemble"], m["t_factor"], m["t_solve"],
                m["t_output"], m["t_step"], ratio))
    if a.markdown:
        print("\n| grid | dofs | free dofs | assemble | factor | solve | output | step | step / factor |")
        print("|---|---|---|---|---|---|---|---|---|")
        print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
