#!/usr/bin/python3
"""The steps.csv counters count what a step did (docs/outputs.md, steps.csv;
issue 31). Silent on success, one line per failure, exit 1.

 1. cases/phantom-tissue.yaml, dynamic, with Newton corrections
    (solver.newton, tolerance 1e-14 so that every step takes its 3) and
    solver.refactor: every: the step factorises its A once and each
    correction factorises the A its residual assembled, so at every step
    factorised = iterations (= 1 + corrections). With the default reuse
    (solver.refactor: auto) the step's own factorisation may be skipped:
    iterations − 1 <= factorised <= iterations.
 2. cases/cantilever.yaml, static: every Newton iteration assembles the
    tangent at a new state, where the loaded cells have rotated, so
    tangent_updates >= iterations > 0 (main wrote 0: the load steps' counts
    were not summed), and factorised >= 1.
 3. cases/dbs/dbs-skull-static.yaml on 6 x 7 x 6 cells, static with skull
    contact (the coupled quasi-static Newton): each iteration is one coupled
    solve whose exact-path assembly rebuilds the tangent of every leaf that
    moved; the brain sags as a whole, so tangent_updates >= iterations (and
    <= iterations x cells), factorised >= iterations (main wrote 0 for both
    tangent_updates and the re-solves' counters: the iterations' counts
    were not summed).
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from nh_run import fail, finish, run, work  # noqa: E402

SRC = os.environ.get("NH_SOURCE_DIR", os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
W = work("counters")
NEWTON = "solver.newton={max_iterations: 3, tolerance: 1.0e-14}"

for refactor in ("every", "auto"):
    t = run(os.path.join(SRC, "cases", "phantom-tissue.yaml"), os.path.join(W, refactor),
            [NEWTON, "solver.refactor=" + refactor, "time.end=0.1"])
    if t is None:
        continue
    for r in t["steps"]:
        it, fa = int(r["iterations"]), int(r["factorised"])
        lo = it if refactor == "every" else it - 1
        if not (it == 4 and lo <= fa <= it):
            fail("phantom-tissue, refactor %s, step %s: iterations %d, factorised %d; expected "
                 "4 iterations and %d <= factorised <= %d" % (refactor, r["step"], it, fa, lo, it))

t = run(os.path.join(SRC, "cases", "cantilever.yaml"), os.path.join(W, "static"))
if t is not None:
    for r in t["steps"]:
        it, tu, fa = int(r["iterations"]), int(r["tangent_updates"]), int(r["factorised"])
        if not (it > 0 and tu >= it and fa >= 1):
            fail("cantilever, step %s: iterations %d, tangent_updates %d, factorised %d; expected "
                 "tangent_updates >= iterations > 0 and factorised >= 1" % (r["step"], it, tu, fa))
t = run(os.path.join(SRC, "cases", "dbs", "dbs-skull-static.yaml"), os.path.join(W, "skull"),
        ["tissue.grid=[6,7,6]", "time.steps=2"])
if t is not None:
    for r in t["steps"]:
        it, tu, fa = int(r["iterations"]), int(r["tangent_updates"]), int(r["factorised"])
        cells = int(r["cells"])
        if not (it > 0 and it <= tu <= it * cells and fa >= it):
            fail("dbs-skull-static, step %s: iterations %d, tangent_updates %d, factorised %d, "
                 "cells %d; expected iterations <= tangent_updates <= iterations x cells and "
                 "factorised >= iterations" % (r["step"], it, tu, fa, cells))
finish()
