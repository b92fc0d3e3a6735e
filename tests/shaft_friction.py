#!/usr/bin/python3
"""The shaft's friction is the line integral of friction_per_length over the
inserted length (docs/interaction.md, "The line integral").

Runs the binary ($NH_BINARY) on cases/needle-retract.yaml (4 x 2 x 2 cm
block, needle inserted 15 mm at 2 cm/s, held 0.1 s, withdrawn) with --set
overrides, into $NH_WORK/shaft_friction, on two grids (8 x 4 x 4, cells of
5 mm; 16 x 8 x 8, 2.5 mm) and two channel spacings (the default, one cell
edge; an explicit 3.5 mm, which divides neither cell). Silent on success,
one line per failure (expected, actual, tolerance), exit 1.

Derived expectations. The needle is straight and the lateral forces are
~1e-9 N (docs/interaction.md, "Measured: the two needle cases"), so the
Coulomb part mu |lambda_lat| of every axial bound is below 1e-10 N and the
axial force is the sum of the constant parts of the bounds of the rows that
slide. Dynamic rows are written at the start of a step, where the entry
point's distance behind the tip along the needle is the previous step's
tools.csv `depth` (L - s of the entry point); the bounds take it at the
step's end, + the tool's prescribed travel over the step (+-0.2 mm here):
D. The constant parts sum to friction_per_length x D (the tip's row
carrying the first half spacing until the entry point is tied), so:
 1. every cutting step (tip row on its bound: the cutting force F_c; every
    shaft row sliding): axial force = F_c + friction_per_length x D, to
    1e-9 N, on both grids and both spacings. The staircase of one constant
    part friction_per_length x spacing per tied point (before the line
    integral) misses this by up to friction_per_length x spacing / 2
    (12.5 mN at 5 mm).
 2. every retracting step (no tip rows, every shaft row sliding back):
    axial force = -friction_per_length x D, to 1e-9 N.
 3. continuity: between consecutive cutting steps the force changes by
    friction_per_length x the change of D, to 2e-9 N (no step in depth).
 4. no friction row sticks while cutting (steps.csv `stick` = 0), the
    premise of 1; while withdrawing at most one: the deepest tied point,
    within half a spacing of the tip, carries no length (bound 0, force 0,
    counted as sticking).
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from nh_run import fail, finish, run, work  # noqa: E402

CASE = os.path.join(os.environ["NH_SOURCE_DIR"], "cases", "needle-retract.yaml")
WORK = work("shaft_friction")
FPL, FC, TOL = 5.0, 0.2, 1e-9
TRAVEL = 0.02 * 0.01  # the case's speed x step


def check(grid, spacing):
    name = "grid%s-spacing%g" % ("x".join(map(str, grid)), spacing)
    res = run(CASE, os.path.join(WORK, name),
              ["tissue.grid=[%s]" % ",".join(map(str, grid)),
               "tools.0.interaction.spacing=%r" % spacing, "output.every=0"])
    if res is None:
        return
    tools, steps = res["tools"], {r["step"]: r for r in res["steps"]}
    seen = {"cutting": 0, "retracting": 0}
    last = None  # (force, depth) of the last cutting step
    for prev, row in zip(tools, tools[1:]):
        state, step = row["state"], row["step"]
        if state not in seen:
            last = None
            continue
        F = float(row["axial_force"])
        t = float(row["time"])  # the step ends at t: in until 0.75 s, held until 0.85 s, out
        D = float(prev["depth"]) + (TRAVEL if t <= 0.75 + 1e-9 else 0.0 if t <= 0.85 + 1e-9
                                    else -TRAVEL)
        D = max(D, 0.0)  # the tip leaves the tissue within the step
        expected = FC + FPL * D if state == "cutting" else -FPL * D
        seen[state] += 1
        if not abs(F - expected) <= TOL:
            fail("%s: step %s (%s) axial force %.12g N, expected %s friction_per_length x depth "
                 "%.12g N (D %.9g m), tolerance %g N" % (
                     name, step, state, F, "F_c +" if state == "cutting" else "-", expected, D,
                     TOL))
        allowed = 0 if state == "cutting" else 1
        if int(steps[step]["stick"]) > allowed:
            fail("%s: step %s (%s): %s friction rows stick, expected <= %d"
                 % (name, step, state, steps[step]["stick"], allowed))
        if state == "cutting":
            if last is not None:
                jump = (F - last[0]) - FPL * (D - last[1])
                if not abs(jump) <= 2 * TOL:
                    fail("%s: step %s force change %.6g N beyond friction_per_length x depth "
                         "change: a step in depth, tolerance %g N" % (name, step, jump, 2 * TOL))
            last = (F, D)
        else:
            last = None
    # 15 mm at 0.2 mm per step: ~70 cutting steps; the withdrawal ~70 steps
    for state, n in seen.items():
        if n < 50:
            fail("%s: %d %s steps, expected >= 50" % (name, n, state))


for grid in ((8, 4, 4), (16, 8, 8)):
    for spacing in (0.0, 0.0035):
        check(grid, spacing)
finish()
