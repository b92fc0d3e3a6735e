#!/usr/bin/python3
"""tools/study.py --set: a scene override for every run of any study, and the
options of one study refused by the others. Runs in $NH_WORK/study_set.
Silent on success, one line per failure, exit 1.

 1. A sweep of the cantilever over ν (two variants, E = 1 MPa in the spec)
    run again with `--set tissue.material.young=2.0e+6`: every variant's
    tip deflection halves (linear elasticity, the load 0.35 % of the length:
    the same check as tests/sweep.py) to 1e-3, and each run's command
    (run.json) ends with the override.
 2. The engine's variants (study_engine.run_variants, what phantom, dbs,
    dbs-shift, dbs-goal and cube run through): two cantilever variants
    (E = 1 and 2 MPa) with the same override E = 4 MPa give the same
    deflection, a quarter of the first's without it (to 1e-3): the override
    comes after each variant's own sets.
 3. The default folder of a study run with overrides carries their values
    (out/study/dbs-goal-mortar), so runs with and without them never share
    one.
 4. A convergence option given to another study (`dbs-goal --end 3`,
    `sweep SPEC --grids 10x12x9`) exits 2 naming the option and the study,
    before it looks for the binary.
"""
import argparse
import contextlib
import csv
import io
import json
import os
import shutil
import subprocess
import sys

BIN = os.environ["NH_BINARY"]
SRC = os.environ.get("NH_SOURCE_DIR", os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
STUDY = os.path.join(SRC, "tools", "study.py")
WORK = os.path.join(os.environ.get("NH_WORK", "."), "study_set")
CANTILEVER = os.path.join(SRC, "cases", "cantilever.yaml")
sys.path.insert(0, os.path.join(SRC, "tools"))
import study_engine as engine  # noqa: E402

failures = []


def fail(msg):
    print("FAIL:", msg, file=sys.stderr)
    failures.append(msg)


def tip_uz(run):
    with open(os.path.join(run, "probes.csv")) as f:
        rows = [r for r in csv.DictReader(f) if r["name"] == "tip"]
    return float(rows[-1]["uz"])


def close(what, got, want, tol=1e-3):
    if not abs(got / want - 1.0) <= tol:
        fail("%s = %.6g, expected %.6g (relative tolerance %g)" % (what, got, want, tol))


def sweep(out, extra):
    spec = os.path.join(WORK, "nu.yaml")
    with open(spec, "w") as f:
        f.write("scene: %s\nset: ['tissue.material.young=1.0e+6']\n" % CANTILEVER)
        f.write("grid:\n  tissue.material.poisson: [0.3, 0.45]\n"
                "outputs:\n  - {name: tip_uz, file: probes.csv, row: tip, column: uz}\n")
    p = subprocess.run(["/usr/bin/python3", STUDY, "sweep", spec, "--binary", BIN, "--out", out,
                        "--workers", "0"] + extra, capture_output=True, text=True)
    if p.returncode != 0:
        fail("sweep %s: exit %d: %s" % (extra, p.returncode, p.stderr[-400:]))
        return None
    return spec


def main():
    shutil.rmtree(WORK, ignore_errors=True)
    os.makedirs(WORK)

    # 1. sweep
    plain, stiff = os.path.join(WORK, "plain"), os.path.join(WORK, "stiff")
    spec = sweep(plain, [])
    if spec and sweep(stiff, ["--set", "tissue.material.young=2.0e+6"]):
        for v in ("v000", "v001"):
            close("sweep %s: tip deflection with E 2 MPa / without" % v,
                  tip_uz(os.path.join(stiff, v)) / tip_uz(os.path.join(plain, v)), 0.5)
            with open(os.path.join(stiff, v, "run.json")) as f:
                cmd = json.load(f)["cmd"]
            if cmd[-2:] != ["--set", "tissue.material.young=2.0e+6"]:
                fail("sweep %s: the command does not end with the override: %s" % (v, cmd))

    # 2. the engine's variants
    def args(sets):
        return argparse.Namespace(sets=sets, steps=None, workers=0, scheduler=None, reuse=False,
                                  restart=False, threads=1, out=None)
    variants = [("e1", ["tissue.material.young=1.0e+6"]), ("e2", ["tissue.material.young=2.0e+6"])]
    out = os.path.join(WORK, "variants")
    with contextlib.redirect_stderr(io.StringIO()):  # the engine's progress lines
        done = engine.run_variants(args([]), BIN, CANTILEVER, os.path.join(out, "plain"),
                                   variants)
        done4 = engine.run_variants(args(["tissue.material.young=4.0e+6"]), BIN, CANTILEVER,
                                    os.path.join(out, "set"), variants)
    if sorted(done) != ["e1", "e2"] or sorted(done4) != ["e1", "e2"]:
        fail("run_variants: complete %s and %s, expected e1, e2 in both" % (sorted(done),
                                                                           sorted(done4)))
    else:
        u1 = tip_uz(os.path.join(out, "plain", "e1"))
        close("run_variants: e2 without the override / e1", tip_uz(os.path.join(out, "plain",
                                                                                "e2")) / u1, 0.5)
        for v in ("e1", "e2"):
            close("run_variants: %s with E 4 MPa / e1 without" % v,
                  tip_uz(os.path.join(out, "set", v)) / u1, 0.25)

    # 3. the default folder
    got = engine.out_dir(args(["tissue.skull.rows=mortar"]), "dbs-goal")
    if got != os.path.join(engine.ROOT, "out", "study", "dbs-goal-mortar"):
        fail("out_dir with an override: %s, expected out/study/dbs-goal-mortar" % got)
    if engine.out_dir(args([]), "dbs-goal") != os.path.join(engine.ROOT, "out", "study",
                                                             "dbs-goal"):
        fail("out_dir without overrides: %s" % engine.out_dir(args([]), "dbs-goal"))

    # 4. another study's option
    for cmd, opt, study in ((["dbs-goal", "--end", "3"], "--end", "dbs-goal"),
                            (["sweep", spec or CANTILEVER, "--grids", "10x12x9"], "--grids",
                             "sweep")):
        # a binary that does not exist: should the refusal fail, the study stops at once
        # instead of running
        p = subprocess.run(["/usr/bin/python3", STUDY] + cmd + [
            "--binary", os.path.join(WORK, "no-such-needlehex"), "--out",
            os.path.join(WORK, "refused")], capture_output=True, text=True)
        want = "%s: not an option of the %s study" % (opt, study)
        if p.returncode != 2 or want not in p.stderr:
            fail("%s: exit %d, expected 2 with '%s': %s" % (" ".join(cmd), p.returncode, want,
                                                            p.stderr[-300:]))
        if os.path.exists(os.path.join(WORK, "refused")):
            fail("%s: refused, but its folder was created" % " ".join(cmd))
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
