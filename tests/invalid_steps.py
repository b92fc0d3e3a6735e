#!/usr/bin/python3
"""Step guards: absurd physics ends with exit 1 naming the step and the
reason, and writes nothing after the last plausible step.

Each case runs needlehex on a shipped case with an absurd override (the
list of issue 16: a Young's modulus of 1e-3 Pa, a load of 1 MN on a 4 cm
block, a needle at 3 m/s with cells of 5 mm, one at 100 m/s) and checks:
- the exit status (1; 2 for a tool that crosses the whole tissue in one
  step, refused before the run) and the words of the reason;
- no tissue frame and no steps.csv row after the failing step (every frame
  on disk is listed by tissue.pvd and reads with meshio);
- with solver.on_invalid: warn, the run goes on, warns once, and steps.csv
  counts the inverted cells;
- the residual of the linearised dynamic step is reported (finite, above
  round-off on the corotational phantom), and solver.newton brings it below
  its tolerance;
- `check` warns when a tool moves more than a grid cell per step.
Silent on success; loud (case, expected, actual) on failure."""
import csv
import os
import shutil
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET

import meshio

BIN, SRC = os.environ["NH_BINARY"], os.environ["NH_SOURCE_DIR"]
failures = []


def fail(case, msg):
    failures.append(f"{case}: {msg}")


def run(case_file, sets, out):
    args = [BIN, "run", os.path.join(SRC, "cases", case_file), "--out", out, "--quiet"]
    for s in sets:
        args += ["--set", s]
    return subprocess.run(args, capture_output=True, text=True, timeout=300)


def rows(out):
    path = os.path.join(out, "steps.csv")
    return list(csv.DictReader(open(path))) if os.path.exists(path) else []


def frames(out):
    pvd = os.path.join(out, "tissue.pvd")
    listed = [d.get("file") for d in ET.parse(pvd).getroot().iter("DataSet")]
    on_disk = sorted(f for f in os.listdir(out) if f.startswith("tissue_") and f.endswith(".vtu"))
    return listed, on_disk


def expect_stop(name, case_file, sets, status, words, last_step):
    out = os.path.join(WORK, name)
    r = run(case_file, sets, out)
    if r.returncode != status:
        fail(name, f"exit {r.returncode}, expected {status}; stderr: {r.stderr}")
        return
    for w in words:
        if w not in r.stderr:
            fail(name, f"stderr lacks {w!r}: {r.stderr}")
    if status == 2:
        return
    steps = [int(x["step"]) for x in rows(out)]
    if steps and max(steps) > last_step:
        fail(name, f"steps.csv has rows up to step {max(steps)}, expected at most {last_step}")
    listed, on_disk = frames(out)
    late = [f for f in on_disk if int(f[7:13]) > last_step]
    if late:
        fail(name, f"frames after the failing step: {late}")
    if sorted(listed) != on_disk:
        fail(name, f"tissue.pvd lists {listed}, the folder holds {on_disk}")
    for f in listed:
        meshio.read(os.path.join(out, f))


def main():
    global WORK
    WORK = tempfile.mkdtemp(prefix="nh-invalid-")
    try:
        expect_stop("soft", "phantom-tissue.yaml", ["tissue.material.young=1e-3"], 1,
                    ["step 1 ", "cells inverted"], 0)
        expect_stop("load", "phantom-tissue.yaml", ["tissue.loads.0.force=[1e6,0,0]"], 1,
                    ["step 1 ", "128 of 128 cells inverted"], 0)
        expect_stop("fast", "needle-phantom.yaml", ["tools.0.motion.0.speed=3"], 1,
                    ["step 2 ", "tool 'needle' is punctured", "outside the tissue"], 1)
        expect_stop("faster", "needle-phantom.yaml", ["tools.0.motion.0.speed=100"], 2,
                    ["needle-phantom.yaml:20: tools.0:", "more than the tissue's extent"], 0)

        # warn: goes on, warns once, counts the inverted cells.
        out = os.path.join(WORK, "warn")
        r = run("phantom-tissue.yaml", ["tissue.material.young=1e-3", "solver.on_invalid=warn",
                                        "time.end=0.05"], out)
        inverted = [int(x["inverted"]) for x in rows(out)]
        if r.returncode != 0 or r.stderr.count("cells inverted") != 1:
            fail("warn", f"exit {r.returncode} (expected 0), one warning expected: {r.stderr}")
        if not inverted or max(inverted) == 0:
            fail("warn", f"steps.csv `inverted` should count cells, got {inverted}")

        # The residual of the linearised step, and Newton's.
        out = os.path.join(WORK, "residual")
        r = run("phantom-tissue.yaml", ["time.end=0.1"], out)
        res = [float(x["residual"]) for x in rows(out)]
        if r.returncode != 0 or not res or not all(0 < v < 1e-2 for v in res):
            fail("residual", f"expected finite residuals above round-off, got {res[:3]}...")
        out = os.path.join(WORK, "newton")
        r = run("phantom-tissue.yaml",
                ["time.end=0.1", "solver.newton={max_iterations: 6, tolerance: 1e-9}"], out)
        res = [float(x["residual"]) for x in rows(out)]
        its = [int(x["iterations"]) for x in rows(out)]
        if r.returncode != 0 or not res or max(res) > 1e-9 or max(its) < 2:
            fail("newton", f"residuals {res[:3]}... (tolerance 1e-9), iterations {its[:3]}...")

        # check warns about a tool that moves 1 cm per step on 5 mm cells.
        r = subprocess.run([BIN, "check", os.path.join(SRC, "cases", "needle-phantom.yaml"),
                            "--set", "time.step=0.5"], capture_output=True, text=True)
        if r.returncode != 0 or "more than a grid cell" not in r.stderr:
            fail("travel", f"exit {r.returncode}, expected 0 and a warning: {r.stderr}")
    finally:
        shutil.rmtree(WORK, ignore_errors=True)
    for f in failures:
        print(f, file=sys.stderr)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
