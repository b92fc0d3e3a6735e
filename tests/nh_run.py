"""Shared by the Python tests that run the binary: the binary ($NH_BINARY),
a work folder under $NH_WORK, failures reported one line each (expected,
actual, tolerance) and counted for the exit status, and a run that returns
the CSV tables of its output folder."""
import csv
import os
import resource
import subprocess
import sys

BIN = os.environ["NH_BINARY"]
failures = []


def work(name):
    """The test's folder $NH_WORK/name, created."""
    path = os.path.join(os.environ.get("NH_WORK", "."), name)
    os.makedirs(path, exist_ok=True)
    return path


def fail(msg):
    failures.append(msg)
    print("FAIL:", msg, file=sys.stderr)


def run_process(scene, out, sets=(), quiet=True):
    """needlehex run SCENE --out OUT (--set S for each of sets; --quiet unless
    quiet is false, which keeps the log's notes in stderr): the finished
    process (returncode, stdout, stderr) and the CPU seconds it used."""
    cmd = [BIN, "run", scene, "--out", out, "--overwrite"] + (["--quiet"] if quiet else [])
    for s in sets:
        cmd += ["--set", s]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    p = subprocess.run(cmd, capture_output=True, text=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return p, cpu


def run(scene, out, sets=(), tables=("steps", "probes", "tools")):
    """needlehex run SCENE --out OUT (--set S for each of sets); the tables
    that exist as {name: rows}, or None (a failure recorded) on a non-zero
    exit."""
    p, _ = run_process(scene, out, sets)
    if p.returncode != 0:
        fail("%s: exit %d, expected 0: %s" % (scene, p.returncode, p.stderr.strip()))
        return None
    result = {}
    for t in tables:
        path = os.path.join(out, t + ".csv")
        if os.path.exists(path):
            with open(path) as f:
                result[t] = list(csv.DictReader(f))
    return result


def finish():
    sys.exit(1 if failures else 0)
