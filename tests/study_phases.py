#!/usr/bin/python3
"""The DBS procedure's phases as the studies cut them (tools/study_dbs.py phases,
tools/study_dbs_goal.py phase_slices), on tools.csv files written here, and
the goal study's runs from another base grid (--base).
Silent on success, one line per failure, exit 1.

 1. A whole procedure of 12 rows (step 0 … 11): outside at rows 0–3, in the
    tissue from row 4 with the depth growing to its largest at row 7, held
    to row 8, retracting from row 9: the shift ends at row 3, the target at
    row 7, the hold at row 8; the phases shift 1–3, insertion 4–6, hold
    7–8, retraction 9–11.
 2. A run that ends before the cannula touches the brain (--steps: the
    shift alone, 6 rows, depth 0 throughout): its phases are the shift
    alone, steps 1–5 (it used to be cut as a hold of every step from 0).
 3. `dbs-goal --base 12x14x11`: every SPR and goal run starts from
    tissue.grid=[12,14,11] instead of [10,12,9], with its other settings
    unchanged and a name of its own; the uniform and estimate runs are
    the study's; a malformed grid exits with a message.
"""
import os
import sys
import tempfile

SRC = os.environ.get("NH_SOURCE_DIR", os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, os.path.join(SRC, "tools"))
from study_dbs import phases  # noqa: E402
from study_dbs_goal import DBS_GOAL, adaptive_variants, phase_slices  # noqa: E402

failures = []


def write(folder, states, depths):
    with open(os.path.join(folder, "tools.csv"), "w") as f:
        f.write("step,time,name,state,depth\n")
        for i, (s, d) in enumerate(zip(states, depths)):
            f.write("%d,%g,cannula,%s,%g\n" % (i, 0.05 * i, s, d))


def check(what, states, depths, want_phases, want_slices):
    with tempfile.TemporaryDirectory() as d:
        write(d, states, depths)
        got = phases(d, "cannula")
    if tuple(got) != want_phases:
        print("FAIL: %s: phases %s, expected %s" % (what, got, want_phases), file=sys.stderr)
        failures.append(what)
        return
    r = dict(zip(("i_shift", "i_top", "i_back"), got))
    sl = [(w, s.start, s.stop - 1) for w, s in phase_slices(r, len(states))]
    if sl != want_slices:
        print("FAIL: %s: phase slices %s, expected %s" % (what, sl, want_slices), file=sys.stderr)
        failures.append(what)


check("whole procedure",
      ["outside"] * 4 + ["inserting"] * 4 + ["holding"] + ["retracting"] * 3,
      [0, 0, 0, 0, 0.002, 0.004, 0.006, 0.008, 0.008, 0.006, 0.004, 0.002],
      (3, 7, 8), [("shift", 1, 3), ("insertion", 4, 6), ("hold", 7, 8), ("retraction", 9, 11)])
check("the shift alone", ["outside"] * 6, [0.0] * 6, (5, 5, 5), [("shift", 1, 5)])

def fail(msg):
    print("FAIL: " + msg, file=sys.stderr)
    failures.append(msg)


old, new = DBS_GOAL["adaptive"], adaptive_variants("12x14x11")
if len(new) != len(old) or len({v[0] for v in new}) != len(new):
    fail("--base: %d runs (%d names), expected %d with distinct names" % (
        len(new), len({v[0] for v in new}), len(old)))
for (n0, _, s0, k0), (n1, l1, s1, k1) in zip(old, new):
    refines = k0 in ("spr", "goal")
    want = [("tissue.grid=[12,14,11]" if x == "tissue.grid=[10,12,9]" else x) for x in s0] \
        if refines else s0
    if s1 != want or k1 != k0 or (n1 != n0) != refines:
        fail("--base: %s -> %s %s, expected %s" % (n0, n1, s1, want))
    if refines and "tissue.grid=[10,12,9]" in s0 and "12×14×11" not in l1:
        fail("--base: %s's label '%s' does not name the base" % (n1, l1))
try:
    adaptive_variants("12x14")
    fail("--base 12x14: accepted")
except SystemExit as e:
    if "not NXxNYxNZ" not in str(e):
        fail("--base 12x14: '%s'" % e)
sys.exit(1 if failures else 0)
