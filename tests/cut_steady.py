#!/usr/bin/python3
"""A needle pushed at constant speed into a homogeneous gel cuts steadily:
once the tip has punctured and started cutting, every step is `cutting`
(no `punctured` step in between: the cut state does not chatter) and the
axial force is the cutting force plus the shaft's friction (issue 29;
docs/interaction.md, "Cut state and channel spacing").

Runs the binary ($NH_BINARY) on cases/steering/gel-one-bend.yaml (a
271 x 265 x 39 mm block of a 20 kPa gel, 16 x 16 x 3 cells, the needle
inserted along x at 1 cm/s, mu = 0, cutting force F_c = 0.1 N,
friction_per_length 1 N/m) for 6 s (~55 mm), one channel point per cell
edge (interaction.spacing 0), into $NH_WORK/cut_steady. Silent on
success, one line per failure, exit 1.

Derived expectations.
 1. Straight needle (bevel 0). With mu = 0 every axial bound is a constant:
    the tip's F_c, the shaft's friction_per_length x the channel length each
    point carries, summing to friction_per_length x D (D the entry point's
    distance behind the tip at the step's end: the previous step's `depth`
    + speed x step; tests/shaft_friction.py). A tip pushed forward at
    constant speed keeps its axial row on that bound every step (it cuts:
    the tissue ahead cannot follow a rigid needle's 0.5 mm per step at a
    force below F_c once it is loaded to F_c), so the state is `cutting` at
    every step after the first cut, and the axial force is
        F = F_c + friction_per_length x D.
    Tolerance 1e-4 N (0.1 % of F_c): the rows' frames follow the needle's
    tangent at each point, and the block clamped at z = 0 pushes the needle
    sideways by ~0.6 mN (tools.csv lateral_force), which projects onto the
    tip's tangent by its tilt (measured deviation 8.5e-6 N); the chatter of
    issue 29 swung the force between 0.1 and 2.9 N.
 2. Bevel 8 deg, the same insertion: the bevel bends the path towards +y
    (the tip ends above the line of insertion), and the cut state is still
    `cutting` at every step after the first cut. With half a cell's spacing
    (6.5 mm on these 13 mm cells) the same run switches between `punctured`
    and `cutting` 10 times (docs/interaction.md): that configuration is
    the issue's, not tested here.
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from nh_run import fail, finish, run, work  # noqa: E402

CASE = os.path.join(os.environ["NH_SOURCE_DIR"], "cases", "steering", "gel-one-bend.yaml")
WORK = work("cut_steady")
FC, FPL, SPEED, STEP, TOL = 0.1, 1.0, 0.01, 0.05, 1e-4
Y0 = 0.1325  # the case's line of insertion


def check(bevel):
    name = "bevel%g" % bevel
    res = run(CASE, os.path.join(WORK, name),
              ["time.end=6", "tools.0.bevel.angle=%g" % bevel, "tools.0.interaction.spacing=0",
               "output.every=0"])
    if res is None:
        return
    tools = res["tools"]
    first = next((i for i, r in enumerate(tools) if r["state"] == "cutting"), None)
    if first is None:
        fail("%s: never cutting" % name)
        return
    after = tools[first:]
    other = [r for r in after if r["state"] != "cutting"]
    if other:
        fail("%s: %d steps after the first cut (step %s) are not cutting, first: step %s %s"
             % (name, len(other), tools[first]["step"], other[0]["step"], other[0]["state"]))
    if len(after) < 100:
        fail("%s: %d cutting steps, expected >= 100" % (name, len(after)))
    if bevel == 0:
        for prev, row in zip(after, after[1:]):
            D = float(prev["depth"]) + SPEED * STEP
            F, expected = float(row["axial_force"]), FC + FPL * D
            if not abs(F - expected) <= TOL:
                fail("%s: step %s axial force %.9g N, expected F_c + friction_per_length x D = "
                     "%.9g N (D %.6g m), tolerance %g N" % (name, row["step"], F, expected, D,
                                                             TOL))
    elif not float(tools[-1]["tip_y"]) > Y0 + 1e-3:
        fail("%s: tip y %.6g m, expected above the line %g m by > 1 mm (towards the bevel)"
             % (name, float(tools[-1]["tip_y"]), Y0))


check(0)
check(8)
finish()
