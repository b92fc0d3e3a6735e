#!/usr/bin/python3
"""tools/study.py convergence on synthetic run folders (--reuse: nothing is
run but `needlehex check` for the box of cases/dbs/dbs.yaml, 140 × 170 × 130
mm). Silent on success, one line per failure, exit 1.

Expected values from closed forms, not from the tool:
 1. h = the longest cell edge: 130/9, 10, 130/18, 5 mm on 10×12×9, 14×17×13,
    20×24×18, 28×34×26 (and 140/17 on the failed 17×21×16).
 2. STN shift f(h) = 2 − 0.001 h² mm and cortical shift g(h) = 6 − 0.05 h mm
    written as targets.csv / probes.csv: every triple of grids (non-constant
    ratios 1.44 : 1.38, 1.38 : 1.44, 1.44 : 1.38) has the observed order 2 (STN) and 1
    (cortex) and the STN extrapolates to 2; spread (max − min)/mean and the
    largest |f − mean|/mean from the three closed-form values.
 3. A run that stopped with exit 1 ("2 of 3123 cells inverted") is a row
    "failed (inverted)", left out of the triples, and the goal is missed; a run
    (40×48×36, h = 130/36) whose steps.csv marks step 2 of 3 unsolved is a row
    "unsolved (Newton)", kept in the triples (its triple names it) and named
    in the verdict.
 5. --estimate 9 (the goal estimate on the grids with h ≥ 9 mm): runs whose STN
    moves by a_i (2 − 0.01 h) mm at step i (a_i = i/3), exactly linear in h, so
    the ladder's reference is a_i · 2 mm with a zero bar and the true error
    a_i · 0.01 h mm; error_estimate written as given multiples of it (1.5, 0.4,
    1 on 10×12×9; 3, 1, 0.5 on 14×17×13; none on the finer grids): the table
    has those six effectivities, every step judged, and the summary counts 4
    of 6 in [0.5, 2], median 1.00, range 0.40–3.00.
 4. nested(): 10×12×9 → 20×24×18 and 14×17×13 → 28×34×26 are nested (factor
    2 on every axis), 10×12×9 → 20×25×19 and 10×12×9 → 20×24×27 are not; the
    report lists those two nested pairs.
"""
import json
import os
import re
import subprocess
import sys
import tempfile

import numpy as np

SRC = os.environ.get("NH_SOURCE_DIR", os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BIN = os.environ.get("NH_BINARY", os.path.join(SRC, "build", "needlehex"))
sys.path.insert(0, os.path.join(SRC, "tools"))
from study_convergence import nested  # noqa: E402

failures = []


def check(what, got, want, tol):
    if not abs(got - want) <= tol:
        print("FAIL: %s = %.12g, expected %.12g (tolerance %g)" % (what, got, want, tol),
              file=sys.stderr)
        failures.append(what)


def fake_run(d, h, ok=True, unsolved=False):
    """A run folder: 3 steps, the STN moving by f(h) in −y, the probe by g(h) in +z; ok=False:
    stopped at step 1 by inverted cells; unsolved: step 2 marked unsolved (residual 0.8)."""
    os.makedirs(d)
    f, g = 1e-3 * (2 - 0.001 * h * h), 1e-3 * (6 - 0.05 * h)
    n = 3 if ok else 1
    with open(os.path.join(d, "steps.csv"), "w") as s:
        s.write("step,time,dofs,cells,t_step,inverted,residual,unsolved\n")
        for i in range(1, n + 1):
            bad = unsolved and i == 2
            s.write("%d,%g,%d,%d,0.5,%d,%g,%d\n" % (i, 0.05 * i, 1000, 200, 0 if ok else 2,
                                                   0.8 if bad else 1e-9, bad))
    with open(os.path.join(d, "targets.csv"), "w") as t, \
            open(os.path.join(d, "probes.csv"), "w") as p:
        t.write("step,time,name,x,y,z,distance\n")
        p.write("step,time,name,x,y,z,ux,uy,uz\n")
        for i in range(0, n + 1):
            a = i / n
            t.write("%d,%g,STN,0.012,%.17g,-0.01,0.09\n" % (i, 0.05 * i, -0.005 - a * f))
            p.write("%d,%g,convergence-cortex,0,0,0,0,0,%.17g\n" % (i, 0.05 * i, a * g))
    info = {"cmd": [], "wall": 1.0, "returncode": 0 if ok else 1}
    if not ok:
        info["message"] = "needlehex: step 1: 2 of 3123 cells inverted"
    with open(os.path.join(d, "run.json"), "w") as j:
        json.dump(info, j)


def fake_linear_run(d, h, ratios):
    """A run folder of 3 ok steps whose STN moves by a_i (2 − 0.01 h) mm in −y at step i
    (a_i = i/3), with error_estimate = ratios[i − 1] × the true error a_i · 0.01 h mm (no
    column without ratios)."""
    os.makedirs(d)
    with open(os.path.join(d, "steps.csv"), "w") as s:
        s.write("step,time,dofs,cells,t_step,inverted,residual,unsolved\n")
        for i in range(1, 4):
            s.write("%d,%g,1000,200,0.5,0,1e-9,0\n" % (i, 0.05 * i))
    with open(os.path.join(d, "targets.csv"), "w") as t, \
            open(os.path.join(d, "probes.csv"), "w") as p:
        t.write("step,time,name,x,y,z,distance%s\n" % (",error_estimate" if ratios else ""))
        p.write("step,time,name,x,y,z,ux,uy,uz\n")
        for i in range(0, 4):
            a = i / 3
            est = ",%.17g" % (ratios[i - 1] * a * 1e-5 * h) if ratios and i else \
                (",nan" if ratios else "")
            t.write("%d,%g,STN,0.012,%.17g,-0.01,0.09%s\n"
                    % (i, 0.05 * i, -0.005 - a * 1e-3 * (2 - 0.01 * h), est))
            p.write("%d,%g,convergence-cortex,0,0,0,0,0,%.17g\n" % (i, 0.05 * i, a * 0.006))
    with open(os.path.join(d, "run.json"), "w") as j:
        json.dump({"cmd": [], "wall": 1.0, "returncode": 0}, j)


def effectivity_block():
    """Item 5: the effectivity table and summary of --estimate 9 on synthetic runs."""
    given = {"10x12x9": (130 / 9, (1.5, 0.4, 1.0)), "14x17x13": (10.0, (3.0, 1.0, 0.5)),
             "20x24x18": (130 / 18, None), "28x34x26": (5.0, None)}
    with tempfile.TemporaryDirectory() as tmp:
        for name, (h, ratios) in given.items():
            fake_linear_run(os.path.join(tmp, name), h, ratios)
        p = subprocess.run([sys.executable, os.path.join(SRC, "tools", "study.py"),
                            "convergence", os.path.join(SRC, "cases", "dbs", "dbs.yaml"),
                            "--binary", BIN, "--grids", ",".join(given), "--out", tmp,
                            "--reuse", "--estimate", "9"], capture_output=True, text=True)
        if p.returncode != 0:
            print("FAIL: the study with --estimate exited %d: %s" % (p.returncode, p.stderr),
                  file=sys.stderr)
            failures.append("estimate")
            return
        rep = open(os.path.join(tmp, "report.md")).read()
        if not os.path.exists(os.path.join(tmp, "img", "convergence-%s-effectivity.png"
                                           % os.path.basename(tmp))):
            failures.append("effectivity plot")
            print("FAIL: no effectivity plot", file=sys.stderr)
    got = {}
    for line in rep.splitlines():
        c = [x.strip() for x in line.strip("|").split("|")]
        if len(c) == 7 and re.fullmatch(r"\d+x\d+x\d+", c[0]) and c[1].isdigit():
            got[(c[0], int(c[1]))] = c
    want = {(n, i): (ratios[i - 1], i / 3 * 0.01 * h) for n, (h, ratios) in given.items()
            if ratios for i in (1, 2, 3)}
    if set(got) != set(want):
        failures.append("effectivity rows")
        print("FAIL: effectivity rows %s, expected %s" % (sorted(got), sorted(want)),
              file=sys.stderr)
        return
    for key, (ratio, err) in want.items():
        c = got[key]
        check("%s step %d: |x − x∞| mm" % key, float(c[2]), err, 6e-5)
        check("%s step %d: bar mm" % key, float(c[3]), 0.0, 6e-5)
        check("%s step %d: effectivity" % key, float(c[5]), ratio, 0.006)
        if c[6] != "yes":
            failures.append("judged")
            print("FAIL: %s step %d not judged (zero bar)" % key, file=sys.stderr)
    summary = "median 1.00, 0.40–3.00, 4 in [0.5, 2]. Judged (true error > 3 bars): 6 " \
        "pairs, 4 of them in [0.5, 2]"
    if summary not in rep:
        failures.append("effectivity summary")
        print("FAIL: the summary does not read '%s':\n%s" % (summary, rep), file=sys.stderr)


effectivity_block()
grids = {"10x12x9": 130 / 9, "14x17x13": 10.0, "17x21x16": 140 / 17, "20x24x18": 130 / 18,
         "28x34x26": 5.0, "40x48x36": 130 / 36}
with tempfile.TemporaryDirectory() as tmp:
    for name, h in grids.items():
        fake_run(os.path.join(tmp, name), h, ok=name != "17x21x16", unsolved=name == "40x48x36")
    p = subprocess.run([sys.executable, os.path.join(SRC, "tools", "study.py"), "convergence",
                        os.path.join(SRC, "cases", "dbs", "dbs.yaml"), "--binary", BIN,
                        "--grids", ",".join(grids), "--out", tmp, "--reuse"],
                       capture_output=True, text=True)
    if p.returncode != 0:
        print("FAIL: the study exited %d: %s" % (p.returncode, p.stderr), file=sys.stderr)
        sys.exit(1)
    rep = open(os.path.join(tmp, "report.md")).read()
    png = "convergence-%s.png" % os.path.basename(tmp)  # named after the folder
    if not os.path.exists(os.path.join(tmp, "img", png)):
        failures.append("no plot")
        print("FAIL: no img/%s" % png, file=sys.stderr)

rows = {}
for line in rep.splitlines():
    cells = [c.strip() for c in line.strip("|").split("|")]
    if re.fullmatch(r"\d+x\d+x\d+", cells[0]):
        rows[cells[0]] = cells
for name, h in grids.items():
    r = rows.get(name)
    if r is None:
        failures.append(name)
        print("FAIL: no row for %s" % name, file=sys.stderr)
        continue
    check("%s: h" % name, float(r[1]), h, 0.006)
    if name == "17x21x16":
        if not r[9].startswith("failed (inverted)"):
            failures.append(name)
            print("FAIL: %s: status '%s', expected failed (inverted)" % (name, r[9]),
                  file=sys.stderr)
        continue
    want_status = "unsolved (Newton): 1 of 3 steps, the first step 2 (residual 0.80)" \
        if name == "40x48x36" else "ok"
    if r[9] != want_status:
        failures.append(name)
        print("FAIL: %s: status '%s', expected '%s'" % (name, r[9], want_status), file=sys.stderr)
    check("%s: STN shift" % name, float(r[5]), 2 - 0.001 * h * h, 6e-5)
    check("%s: cortical shift" % name, float(r[6]), 6 - 0.05 * h, 6e-4)

want = [("10x12x9", "14x17x13", "20x24x18"), ("14x17x13", "20x24x18", "28x34x26"),
        ("20x24x18", "28x34x26", "40x48x36")]
trip = [line for line in rep.splitlines() if any(line.startswith("| %s, " % w[0]) for w in want)]
if len(trip) != 3:
    failures.append("triples")
    print("FAIL: %d triples in the report, expected 3 (the failed grid left out)" % len(trip),
          file=sys.stderr)
for line, names in zip(trip, want):
    c = [x.strip() for x in line.strip("|").split("|")]
    f = np.array([2 - 0.001 * grids[n] ** 2 for n in names])
    check("%s: STN spread %%" % c[0], float(c[3].rstrip(" %")),
          100 * (f.max() - f.min()) / f.mean(), 0.006)
    check("%s: STN max deviation %%" % c[0], float(c[4].rstrip(" %")),
          100 * np.max(np.abs(f - f.mean())) / f.mean(), 0.006)
    check("%s: STN order" % c[0], float(c[5]), 2.0, 0.006)
    check("%s: STN f∞" % c[0], float(c[6]), 2.0, 6e-5)
    check("%s: cortex order" % c[0], float(c[8]), 1.0, 0.006)
    if c[2] != "no":
        failures.append(c[0])
        print("FAIL: %s: nested '%s', expected no" % (c[0], c[2]), file=sys.stderr)
    if c[9] != ("40x48x36" if "40x48x36" in names else "–"):
        failures.append(c[0])
        print("FAIL: %s: grids not ok '%s'" % (c[0], c[9]), file=sys.stderr)
if "**missed**" not in rep or "1 grid(s) failed (17x21x16)" not in rep or \
        "1 ran with steps unsolved (40x48x36)" not in rep:
    failures.append("verdict")
    print("FAIL: the verdict does not name the failed grid:\n%s" % rep, file=sys.stderr)
for pair in ("10x12x9 → 20x24x18", "14x17x13 → 28x34x26"):
    if pair not in rep:
        failures.append(pair)
        print("FAIL: the nested pair %s is not in the report" % pair, file=sys.stderr)
for a, b, want_nested in (((10, 12, 9), (20, 24, 18), True), ((14, 17, 13), (28, 34, 26), True),
                          ((10, 12, 9), (20, 25, 19), False), ((10, 12, 9), (20, 24, 27), False)):
    if nested(a, b) != want_nested:
        failures.append("nested")
        print("FAIL: nested(%s, %s) = %s" % (a, b, not want_nested), file=sys.stderr)
sys.exit(1 if failures else 0)
