#!/usr/bin/python3
"""The channel points' default spacing, one cell edge (docs/interaction.md,
"Why one point per cell"), on cases/phantom/phantom.yaml.

usage: channel_spacing.py [--lock]

Without arguments (label verify), on the case's 8 x 4 x 4 grid (5 mm cells)
for 0.3 s: an explicit `interaction.spacing` finer than the cell (2.5 mm)
warns exactly once ("finer than the cell"); the default and a spacing of one
cell edge (5 mm) do not warn.

--lock (label slow): the first 40 steps on 48 x 24 x 24 with the default
spacing. At half a cell edge (the default until issue 26) the rows per unit
length along the needle, 1/s = 2.4 per mm, exceed the values the tissue
(1/h = 1.2) and the needle (2/L_e = 1, a value and a slope per node of its
2 mm elements) can take, and the run locked at step 32: the tip stopped
cutting and the axial force reached 4.9 N. Expected from the laws alone
(docs/interaction.md, "Tip" and "Shaft"): every step's constraint solve
within the accepted residual and no step unsolved, the tip cutting at every
step from step 5 (the case's puncture is at step 3), and the axial force
while cutting at most the cutting force plus friction_per_length times the
covered channel, at most depth + one spacing long (the needle is straight
on the axis of symmetry: the Coulomb parts μ|λ_lat| are round-off, allowed
1e-6 N). Silent on success; one line per failure (expected, actual,
tolerance)."""
import os
import sys

from nh_run import fail, finish, run_process, work, run

SCENE = os.path.join(os.environ["NH_SOURCE_DIR"], "cases", "phantom", "phantom.yaml")
FC, FPL = 0.2, 5.0          # the case's cutting force (N) and friction_per_length (N/m)
WARNING = "finer than the cell"


def warnings():
    out = work("channel_spacing")
    for label, sets, expected in [("default", [], 0),
                                  ("one cell edge", ["tools.0.interaction.spacing=0.005"], 0),
                                  ("half a cell edge", ["tools.0.interaction.spacing=0.0025"], 1)]:
        p, _ = run_process(SCENE, os.path.join(out, label.replace(" ", "-")),
                           ["time.end=0.3"] + sets)
        if p.returncode != 0:
            fail("%s: exit %d, expected 0: %s" % (label, p.returncode, p.stderr.strip()))
            continue
        n = p.stderr.count(WARNING)
        if n != expected:
            fail("%s: %d warnings '%s', expected %d; stderr: %s"
                 % (label, n, WARNING, expected, p.stderr.strip()))


def lock():
    h = 0.02 / 24
    res = run(SCENE, work("channel_spacing_lock"), ["tissue.grid=[48,24,24]", "time.end=0.4"])
    if res is None:
        return
    steps, tools = res["steps"], res["tools"]
    if len(steps) != 40:
        fail("48x24x24: %d steps, expected 40" % len(steps))
    for r in steps:
        if int(float(r["unsolved"])) != 0 or not float(r["constraint_residual"]) <= 1e-5:
            fail("48x24x24: step %s unsolved %s, constraint residual %s (accepted: 1e-5)"
                 % (r["step"], r["unsolved"], r["constraint_residual"]))
    for r in tools:
        step = int(r["step"])
        if step < 5:
            continue
        if r["state"] != "cutting":
            fail("48x24x24: step %d state %s, expected cutting" % (step, r["state"]))
        F, d = float(r["axial_force"]), float(r["depth"])
        bound = FC + FPL * (d + h) + 1e-6
        if not F <= bound:
            fail("48x24x24: step %d axial force %.6g N > cutting + shaft friction %.6g N "
                 "(depth %.4g m)" % (step, F, bound, d))


if __name__ == "__main__":
    lock() if "--lock" in sys.argv[1:] else warnings()
    finish()
