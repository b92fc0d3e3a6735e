#!/usr/bin/python3
"""Lazy element tangents in whole runs (solver.lazy_rotation), through the
binary ($NH_BINARY), runs in $NH_WORK/lazy_run. Silent on success, one line
per failure, exit 1.

The needle phantom (cases/phantom/phantom.yaml) at 16×8×8 (128 cells per
colour: the assembly runs in parallel), 30 steps of the insertion, with
τ = 0 (exact) and τ = 1e-3, each with solver.threads 1 and 2: the outputs
(probes.csv, tools.csv, and steps.csv but for its times) must be identical
byte for byte, since every sum of the assembly is done in colour order
whatever the thread count (docs/theory.md §4). With τ = 1e-3 fewer tangents
must have been rebuilt than with τ = 0 (else the laziness did not act and
the comparison says nothing new).
"""
import csv
import os
import subprocess
import sys

BIN = os.environ["NH_BINARY"]
SRC = os.environ.get("NH_SOURCE_DIR", os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
WORK = os.path.join(os.environ.get("NH_WORK", "."), "lazy_run")
failures = []


def fail(msg):
    failures.append(msg)
    print("FAIL:", msg, file=sys.stderr)


def run(tau, threads):
    out = os.path.join(WORK, "tau%g-t%d" % (tau, threads))
    args = [BIN, "run", os.path.join(SRC, "cases", "phantom", "phantom.yaml"), "--quiet",
            "--overwrite", "--out", out, "--set", "tissue.grid=[16,8,8]", "--set",
            "time.steps=30", "--set", "output.every=0", "--set", "solver.threads=%d" % threads,
            "--set", "solver.lazy_rotation=%g" % tau]
    p = subprocess.run(args, capture_output=True, text=True)
    if p.returncode != 0:
        fail("tau %g, %d threads: exit %d, expected 0: %s" % (tau, threads, p.returncode,
                                                               p.stderr.strip()))
        return None
    return out


def steps_without_times(out):
    with open(os.path.join(out, "steps.csv")) as f:
        rows = list(csv.DictReader(f))
    return [{k: v for k, v in r.items() if not k.startswith("t_")} for r in rows]


def main():
    os.makedirs(WORK, exist_ok=True)
    rebuilt = {}
    for tau in (0.0, 1e-3):
        outs = [run(tau, t) for t in (1, 2)]
        if None in outs:
            continue
        for name in ("probes.csv", "tools.csv"):
            a, b = (open(os.path.join(o, name)).read() for o in outs)
            if a != b:
                fail("tau %g: %s differs between 1 and 2 threads" % (tau, name))
        s1, s2 = (steps_without_times(o) for o in outs)
        if s1 != s2:
            fail("tau %g: steps.csv (times aside) differs between 1 and 2 threads" % tau)
        rebuilt[tau] = sum(int(float(r["tangent_updates"])) for r in s1[1:])
    if len(rebuilt) == 2 and not 0 < rebuilt[1e-3] < rebuilt[0.0]:
        fail("tangents rebuilt: %d with tau 1e-3, %d with tau 0: expected 0 < lazy < exact"
             % (rebuilt[1e-3], rebuilt[0.0]))
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
