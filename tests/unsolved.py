#!/usr/bin/python3
"""unsolved.py — a run says when its steps were not solved (steps.csv
`unsolved`, docs/outputs.md).

1. cases/dbs/dbs.yaml at nu = 0.4999 (three steps of 0.05 s) with
   solver.newton.max_iterations 0 (one linearisation, strictly): it leaves
   the nearly incompressible corotational tissue a relative residual near 1
   (the issue measured 0.73-1.02); every step with residual > 0.5 has
   unsolved = 1, the run exits 0 and stderr warns at the first such step and
   counts them at the end.
1b. The same scene without solver.newton: a step left above 0.5 takes
   Newton iterations (docs/theory.md §3, "Newton iterations in the dynamic
   step") until its residual is at most solver.newton.tolerance's default
   1e-8 (at most 8): every step has iterations > 1, residual <= 1e-8,
   unsolved = 0, one factorisation per iteration at least (refactor:
   every), and no warning.
2. The same scene at its own nu = 0.45: residuals well below 0.5, unsolved
   = 0 everywhere and no warning.
3. cases/needle-retract.yaml after the needle has left (t > 1.6 s): the
   body relaxes with forces at round-off, relative residuals of round-off
   over round-off; no step is flagged (the round-off floor), no warning.
4. A rigid-like block (E 1e12 Pa) a needle enters, rests in and leaves: once
   it retracts, the forces are the round-off of K (Rᵀx − X) (relative
   residual 0.98-0.99, 140 of 290 steps flagged before the floor, whose
   rule of "1e-6 of the run's largest force" they passed at 5e-6); with
   the floor eps |x|_max ||diag K|| h no step is flagged.
5. A dynamic step whose Newton iterations leave it unsolved stops the run
   (solver.on_invalid: stop, the default; docs/outputs.md, "When a step is
   not plausible"): dbs.yaml at nu = 0.4999 with solver.newton
   {max_iterations: 1} (one iteration from the linearisation's 0.73-1.02
   cannot reach the tolerance 1e-8: the rescue above takes 2-8): exit 1
   before writing step 1, the message naming the step, the residual, the
   one iteration, the node of the largest residual entry and a likely
   cause. With solver.on_invalid: warn the run goes on: exit 0, every step
   flagged, the guard's warning once and the summary counting them from
   step 1.
The column's rule, and these expectations, follow from the definition:
unsolved = residual > 0.5 for a linearised dynamic step, unless the residual
is below the round-off level of its internal forces (docs/outputs.md).
Silent on success; exit 1 on failure.
"""
import csv
import os
import subprocess
import sys

BIN = sys.argv[1]
SRC = os.environ["NH_SOURCE_DIR"]
WORK = os.path.join(os.environ.get("NH_WORK", "."), "unsolved")
failures = []


def check(cond, msg):
    if not cond:
        failures.append(msg)
        print("FAIL:", msg, file=sys.stderr)


def run(name, scene, *sets):
    out = os.path.join(WORK, name)
    args = [BIN, "run", os.path.join(SRC, scene), "--out", out, "--overwrite", "--quiet"]
    for s in sets:
        args += ["--set", s]
    p = subprocess.run(args, capture_output=True, text=True)
    check(p.returncode == 0, "%s: exit %d: %s" % (name, p.returncode, p.stderr))
    with open(os.path.join(out, "steps.csv")) as f:
        rows = list(csv.DictReader(f))
    return rows, p.stderr


rows, err = run("stiff", "cases/dbs/dbs.yaml", "tissue.material.poisson=0.4999", "time.end=0.15",
                "solver.newton={max_iterations: 0}")
flags = [int(float(r["unsolved"])) for r in rows]
res = [float(r["residual"]) for r in rows]
check(len(rows) == 3 and all(x > 0.5 for x in res), "nu 0.4999: residuals %s, expected > 0.5" % res)
check(flags == [1 if x > 0.5 else 0 for x in res], "nu 0.4999: unsolved %s for residuals %s"
      % (flags, res))
check("step 1 " in err and "not solved" in err and "3 of 3 steps left unsolved" in err,
      "nu 0.4999: stderr lacks the warnings:\n" + err)

rows, err = run("rescued", "cases/dbs/dbs.yaml", "tissue.material.poisson=0.4999",
                "time.end=0.15", "solver.refactor=every")
its = [int(float(r["iterations"])) for r in rows]
res = [float(r["residual"]) for r in rows]
fac = [int(float(r["factorised"])) for r in rows]
check(len(rows) == 3 and all(1 < i <= 9 for i in its) and all(x <= 1e-8 for x in res)
      and all(f >= i for f, i in zip(fac, its))
      and all(int(float(r["unsolved"])) == 0 for r in rows) and "unsolved" not in err,
      "nu 0.4999, Newton: iterations %s, residuals %s, factorised %s, stderr %s"
      % (its, res, fac, err))

rows, err = run("soft", "cases/dbs/dbs.yaml", "time.end=0.15")
check(all(float(r["residual"]) < 0.5 and int(float(r["unsolved"])) == 0 for r in rows)
      and "unsolved" not in err, "nu 0.45: %s %s" % ([(r["residual"], r["unsolved"]) for r in rows],
                                                     err))

rows, err = run("retract", "cases/needle-retract.yaml")
check(sum(int(float(r["unsolved"])) for r in rows) == 0 and "unsolved" not in err,
      "needle-retract: %d steps flagged" % sum(int(float(r["unsolved"])) for r in rows))
RIGID = """name: rigid
time: {step: 0.01, end: 2.9}
tissue:
  domain:
    box: {min: [0, 0, 0], max: [0.04, 0.02, 0.02]}
  grid: [8, 4, 4]
  material: {young: 1.0e12, poisson: 0.4, density: 1000}
  fixed:
    - {box: {min: [0.0399, -1, -1], max: [1, 1, 1]}}
tools:
  - name: needle
    length: 0.04
    radius: 0.0005
    elements: 16
    material: {young: 2.0e11, poisson: 0.3, density: 7800}
    damping: {mass: 0.0, stiffness: 0.001}
    trajectory: {entry: [0.0, 0.01, 0.01], target: T, standoff: 0.004}
    motion:
      - {until: target, speed: 0.02}
      - {until: 1.5, speed: 0}
      - {until: start, speed: -0.02}
    interaction: {puncture_force: 0.01, cutting_force: 0.01, friction: 0.05}
targets:
  - {name: T, point: [0.02, 0.01, 0.01], tool: needle}
output:
  every: 0
"""
os.makedirs(WORK, exist_ok=True)
with open(os.path.join(WORK, "rigid.yaml"), "w") as f:
    f.write(RIGID)
rows, err = run("rigid", os.path.join(WORK, "rigid.yaml"))
flagged = [r["step"] for r in rows if int(float(r["unsolved"]))]
check(len(rows) == 290 and not flagged and "unsolved" not in err,
      "rigid block: %d rows, steps flagged %s" % (len(rows), flagged[:10]))

out = os.path.join(WORK, "one_iteration")
p = subprocess.run([BIN, "run", os.path.join(SRC, "cases/dbs/dbs.yaml"), "--out", out, "--overwrite",
                    "--quiet", "--set", "tissue.material.poisson=0.4999", "--set", "time.end=0.15",
                    "--set", "solver.newton={max_iterations: 1}"], capture_output=True, text=True)
with open(os.path.join(out, "steps.csv")) as f:
    written = list(csv.DictReader(f))
check(p.returncode == 1 and not written
      and "step 1 (t = 0.05 s): the step's equations are not solved" in p.stderr
      and "after 1 Newton iteration (at most 1 by solver.newton.max_iterations" in p.stderr
      and "the largest residual entry is at node" in p.stderr and "Likely cause" in p.stderr,
      "one Newton iteration: exit %d, %d rows written, stderr:\n%s"
      % (p.returncode, len(written), p.stderr))
rows, err = run("one_iteration_warn", "cases/dbs/dbs.yaml", "tissue.material.poisson=0.4999",
                "time.end=0.15", "solver.newton={max_iterations: 1}", "solver.on_invalid=warn")
flags = [int(float(r["unsolved"])) for r in rows]
check(flags == [1, 1, 1] and err.count("are not solved") == 1
      and "3 of 3 steps left unsolved (relative residual above its bound; the first: step 1)"
      in err, "one Newton iteration, warn: unsolved %s, stderr:\n%s" % (flags, err))
sys.exit(1 if failures else 0)
