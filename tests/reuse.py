#!/usr/bin/python3
"""Reuse of factorisations (solver.refactor: auto) against a factorisation at
every step (solver.refactor: every), through the binary ($NH_BINARY), runs in
$NH_WORK/reuse. Silent on success, one line per failure, exit 1.

Each solve with a reused factor stops at a relative error `solver.tolerance`
(tol, 1e-8 by default), and the constraint forces' outer correction at a
relative change tol. Backward Euler does not amplify a perturbation of the
state (docs/theory.md §3), so after N steps the two runs differ by at most
about N · tol relative to the largest value compared: the bound checked
for every probe / target / tool tip displacement and tool force, over all
steps. The auto run must have reused (fewer factorisations than steps),
else the comparison says nothing.

Cases: the needle phantom (cases/phantom/phantom.yaml) uniform 8×4×4 and
adaptive (hex2), 40 steps of the insertion; a shortened DBS procedure
(cases/dbs/dbs.yaml: steps of 0.1 s, the shift ramped over 0.5 s, the
cannula inserted at 6 cm/s from 0.5 s), 25 steps; the brain sinking onto
the skull (cases/dbs/dbs-skull.yaml on a 10×12×9 grid, uniform, 30 steps:
up to ~180 skull rows), where the auto run must also have made steps with
several outer corrections (the renewal rule counts their constraint solves);
the phantom goal-oriented (hex2, 2 levels, the estimate every 4 steps), 40
steps, whose duals take a factorisation of A at the step's solution
(nh_system_solve_rows), which the next step reuses: there the estimates
(probes.csv error_estimate) are compared too, relative to their largest.
That factorisation renews the factor's cycle, so a step estimated with the
goal estimator solves with its mesh's own factor even when the renewal rule
asks for a factorisation at its start (reuse.c): each estimated step that
was not re-solved makes at most one factorisation (main's rule made two at
steps 32 and 36 of this case, the renewal's and the duals'; an estimated
step that starts on an inherited factor may still make two, which this
case's do not: its mesh changes follow estimates, 4 steps apart).

    reuse.py [CASE ...]   the named cases only (default: all)
"""
import csv
import os
import subprocess
import sys

import numpy as np

BIN = os.environ["NH_BINARY"]
SRC = os.environ.get("NH_SOURCE_DIR", os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
WORK = os.path.join(os.environ.get("NH_WORK", "."), "reuse")
TOL = 1e-8
failures = []


def fail(msg):
    failures.append(msg)
    print("FAIL:", msg, file=sys.stderr)


def read(out, name):
    path = os.path.join(out, name + ".csv")
    if not os.path.exists(path):
        return []
    with open(path) as f:
        return list(csv.DictReader(f))


def run_both(case, scene, sets):
    """Runs the case with solver.refactor every, then auto: their folders (None if one failed)."""
    outs = []
    for mode in ("every", "auto"):
        outs.append(os.path.join(WORK, "%s-%s" % (case, mode)))
        args = [BIN, "run", scene, "--quiet", "--overwrite", "--out", outs[-1],
                "--set", "solver.refactor=" + mode]
        p = subprocess.run(args + [w for s in sets for w in ("--set", s)], capture_output=True,
                           text=True)
        if p.returncode != 0:
            fail("%s (%s): exit %d, expected 0: %s" % (case, mode, p.returncode, p.stderr.strip()))
            return None, None
    return outs


def series(out):
    """{quantity: array over steps}: probe and target positions, tool tips and forces."""
    s = {}
    for fname, cols in (("probes", ["x", "y", "z"]), ("targets", ["x", "y", "z"]),
                        ("tools", ["tip_x", "tip_y", "tip_z"]),
                        ("tools", ["axial_force", "lateral_force"])):
        for r in read(out, fname):
            key = "%s %s %s" % (fname, r["name"], cols[0])
            s.setdefault(key, []).append([float(r[c]) for c in cols])
            if fname == "probes" and r.get("error_estimate", "") not in ("", "nan"):
                s.setdefault("probes %s error_estimate" % r["name"], []).append(
                    [float(r["error_estimate"])])
    return {k: np.array(v) for k, v in s.items()}


def compare(case, scene, sets, corrections=0):
    """corrections: the auto run must have made a step with at least this many."""
    every, auto = run_both(case, scene, sets)
    if not every:
        return
    steps = read(auto, "steps")
    if "adapt.estimator=goal" in sets:
        estimated = [r for r in steps if r["eta"] != "nan" and int(float(r["resolves"])) == 0]
        if not estimated:
            fail("%s: no step was estimated without a re-solve" % case)
        for r in estimated:
            if int(float(r["factorised"])) > 1:
                fail("%s: step %s, estimated, factorised %s times, expected at most once (the "
                     "duals' factorisation renews the cycle)" % (case, r["step"], r["factorised"]))
    most = max((int(float(r["corrections"])) for r in steps), default=0)
    if most < corrections:
        fail("%s: the auto run made at most %d outer corrections in a step, expected >= %d"
             % (case, most, corrections))
    n = len(steps)
    fact = sum(int(float(r["factorised"])) for r in steps)
    if not fact < n:
        fail("%s: the auto run factorised at %d of %d steps: nothing was reused" % (case, fact, n))
    # (a goal run's every also factorises for the duals at the step's solution)
    if sum(int(float(r["factorised"])) for r in read(every, "steps")) < n:
        fail("%s: the every run did not factorise at every step" % case)
    a, e = series(auto), series(every)
    if set(a) != set(e) or not a:
        fail("%s: the runs report different quantities (%s vs %s)" % (case, sorted(a), sorted(e)))
        return
    for k in sorted(e):
        if a[k].shape != e[k].shape:
            fail("%s: %s has %s values with auto, %s with every" % (case, k, a[k].shape, e[k].shape))
            continue
        # displacements: relative to the motion since step 0; forces and estimates: to their
        # largest value
        base = e[k] - e[k][0] if "force" not in k and "estimate" not in k else e[k]
        scale = np.abs(base).max()
        diff = np.abs(a[k] - e[k]).max()
        bound = n * TOL * scale
        if not diff <= bound:
            fail("%s: %s differs by %.3g between auto and every, bound %.3g (= %d steps x %g x "
                 "largest %.3g)" % (case, k, diff, bound, n, TOL, scale))


def main():
    phantom = os.path.join(SRC, "cases", "phantom", "phantom.yaml")
    dbs = os.path.join(SRC, "cases", "dbs")
    cases = {
        "phantom-uniform": (phantom, ["time.steps=40"], 0),
        "phantom-adaptive": (phantom, ["time.steps=40", "adapt.template=hex2",
                                       "adapt.max_level=1"], 0),
        "dbs-short": (os.path.join(dbs, "dbs.yaml"),
                      ["time.step=0.1", "time.end=2.5",
                       "tissue.buoyancy.schedule=[[0, 0], [0.5, 1]]",
                       "tools.0.motion=[{until: 0.5, speed: 0}, {until: target, speed: 0.06}]"], 0),
        "dbs-skull": (os.path.join(dbs, "dbs-skull.yaml"),
                      ["tissue.grid=[10,12,9]", "adapt.every=1000000", "time.end=1.5"], 2),
        "phantom-goal": (phantom, ["time.steps=40", "adapt.estimator=goal", "adapt.template=hex2",
                                   "adapt.max_level=2", "adapt.every=4"], 0),
    }
    for name in sys.argv[1:] or list(cases):
        if name not in cases:
            fail("no case %s (cases: %s)" % (name, ", ".join(cases)))
            continue
        scene, sets, corrections = cases[name]
        compare(name, scene, sets, corrections)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
