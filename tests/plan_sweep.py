#!/usr/bin/python3
"""Several target-compensation plans on the study engine (tools/study.py plan,
`command: plan` in a sweep spec; docs/dbs.md, "Several plans"), runs in
$NH_WORK/plan_sweep. Silent on success, one line per failure, exit 1.

The scene: a soft block (8 x 4 x 4 cells, 4 x 2 x 2 cm) held at its x = 4 cm
face sags under gravity switched on over 0.3 s; a needle planned from an
entry on the x = 0 face to a target inside is inserted once the block has
settled and held there. Four plans (tolerance 0.01 mm):

  v000  E 20 kPa, target A      v001  E 40 kPa, target A
  v002  E 20 kPa, target B      v003  rigid block (E 1e12 Pa), no gravity

 1. A LocalCluster of 2 workers (loopback) gives the same table as the
    serial engine (--workers 0), every column to the last digit (each plan
    is deterministic, one thread).
 2. Each plan converged with miss <= the tolerance; its table row agrees with
    its folder: misses_mm ends with miss_mm, runs = the number of run_NN
    folders, and the electrode-target distance of the last row of
    final/targets.csv (written by the run, not by the planner) equals
    miss_mm to 1e-9 relative.
 3. Rigid block, no gravity: the tool goes where it is aimed and the target
    stays (m(a) = a - X, the planner's J = I is exact): one run, aim = the
    target point, miss < 1e-3 mm.
 4. Linear elasticity: the block's sag and the drag of the needle scale as
    1/E (the needle is 1e7 times stiffer), so the compensation |aim - X| at
    40 kPa is half that at 20 kPa: ratio 0.5 +- 0.02 (the corotational
    rotations, a few degrees, and the contact are the non-linear part).
 5. max_runs 1: the soft plans are `not converged` (a result, not a
    failure), the rigid one ok; the command exits 1 naming them; run again,
    the three are complete and skipped (same exit and table).
 6. The engine's LocalCluster of 2 workers listens on loopback only: every
    listening TCP socket of this process and its children (scheduler,
    nannies, workers, and their HTTP servers) is bound to 127.0.0.1 or ::1
    (/proc/net/tcp, tcp6).
"""
import csv
import math
import os
import shutil
import subprocess
import sys

import yaml

BIN = os.environ["NH_BINARY"]
SRC = os.environ.get("NH_SOURCE_DIR", os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
STUDY = os.path.join(SRC, "tools", "study.py")
WORK = os.path.join(os.environ.get("NH_WORK", "."), "plan_sweep")
TOL = 1e-5  # m
TARGET_A = [0.02, 0.0105, 0.009]
TARGET_B = [0.026, 0.0095, 0.012]
failures = []

SCENE = """name: block-plan
time: {mode: dynamic, step: 0.02, end: 1.6}
gravity: {vector: [0, 0, -9.81], schedule: [[0, 0], [0.3, 1]]}
tissue:
  domain:
    box: {min: [0, 0, 0], max: [0.04, 0.02, 0.02]}
  grid: [8, 4, 4]
  material: {young: 20000, poisson: 0.4, density: 1000}
  damping: {mass: 10.0, stiffness: 0.0}
  fixed:
    - {box: {min: [0.0399, -1, -1], max: [1, 1, 1]}}
tools:
  - name: needle
    length: 0.04
    radius: 0.0005
    elements: 16
    material: {young: 2.0e11, poisson: 0.3, density: 7800}
    trajectory: {entry: [0.0, 0.01, 0.011], target: T, standoff: 0.004}
    motion:
      - {until: 0.5, speed: 0}
      - {until: target, speed: 0.04}
      - {until: 1.6, speed: 0}
    interaction: {puncture_force: 0.01, cutting_force: 0.01, friction: 0.05}
targets:
  - {name: T, point: %s, tool: needle}
output:
  every: 0
""" % TARGET_A


def fail(msg):
    print("FAIL:", msg, file=sys.stderr)
    failures.append(msg)


def spec(name, max_runs):
    scene = os.path.join(WORK, "block.yaml")
    with open(scene, "w") as f:
        f.write(SCENE)
    path = os.path.join(WORK, name + ".yaml")
    with open(path, "w") as f:
        f.write("scene: block.yaml\ncommand: plan\nplan: {tolerance: %r, max_runs: %d}\n"
                "combinations:\n"
                "  - {tissue.material.young: 20000}\n"
                "  - {tissue.material.young: 40000}\n"
                "  - {tissue.material.young: 20000, targets.0.point: %s}\n"
                "  - {tissue.material.young: 1.0e+12, gravity: [0, 0, 0]}\n"
                "outputs:\n"
                "  - {name: distance_mm, file: targets.csv, row: T, column: distance, "
                "scale: 1000}\n" % (TOL, max_runs, TARGET_B))
    return path


def plan(path, out, workers):
    """tools/study.py plan: (exit status, stderr, {variant: row} or None)."""
    p = subprocess.run(["/usr/bin/python3", STUDY, "plan", path, "--binary", BIN, "--out", out,
                        "--workers", str(workers)], capture_output=True, text=True)
    rows = None
    if os.path.exists(os.path.join(out, "sweep.csv")):
        with open(os.path.join(out, "sweep.csv")) as f:
            rows = {r["variant"]: r for r in csv.DictReader(f)}
    return p.returncode, p.stderr, rows


def vec(text):
    return [float(x) for x in yaml.safe_load(text)]


def check_converged(rows, out):
    for v, r in sorted(rows.items()):
        if r["status"] != "ok" or r["converged"] != "true":
            fail("%s: status %s, converged %s; expected ok, true" % (v, r["status"],
                                                                  r["converged"]))
            continue
        miss = float(r["miss_mm"])
        if not miss <= 1e3 * TOL:
            fail("%s: miss %.6g mm > tolerance %g mm" % (v, miss, 1e3 * TOL))
        misses = vec(r["misses_mm"])
        if len(misses) != int(r["runs"]) or abs(misses[-1] - miss) > 1e-3 * miss + 1e-12:
            fail("%s: misses_mm %s, runs %s, miss_mm %s: expected runs values ending with miss"
                 % (v, r["misses_mm"], r["runs"], r["miss_mm"]))
        folders = [d for d in os.listdir(os.path.join(out, v)) if d.startswith("run_")]
        if len(folders) != int(r["runs"]):
            fail("%s: %d run folders %s, runs %s" % (v, len(folders), sorted(folders), r["runs"]))
        d = float(r["distance_mm"])
        if not abs(d - miss) <= 1e-9 * miss:
            fail("%s: final/targets.csv distance %.12g mm, plan.yaml miss %.12g mm (1e-9 rel)"
                 % (v, d, miss))


def listening(pids):
    """[(pid, address)] of the listening TCP sockets of the processes `pids` (hex from /proc)."""
    inodes = {}
    for pid in pids:
        try:
            for fd in os.listdir("/proc/%d/fd" % pid):
                link = os.readlink("/proc/%d/fd/%s" % (pid, fd))
                if link.startswith("socket:["):
                    inodes[link[8:-1]] = pid
        except OSError:
            continue
    out = []
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        with open(table) as f:
            for line in f.readlines()[1:]:
                col = line.split()
                if col[3] == "0A" and col[9] in inodes:  # state LISTEN
                    out.append((inodes[col[9]], col[1].split(":")[0]))
    return out


def descendants(root):
    children = {}
    for p in filter(str.isdigit, os.listdir("/proc")):
        try:
            with open("/proc/%s/stat" % p) as f:
                children.setdefault(int(f.read().rsplit(")", 1)[1].split()[1]), []).append(int(p))
        except OSError:
            continue
    todo, seen = [root], []
    while todo:
        p = todo.pop()
        seen.append(p)
        todo += children.get(p, [])
    return seen


def check_loopback():
    sys.path.insert(0, os.path.join(SRC, "tools"))
    import study_engine
    client, cluster = study_engine._client(2, None)
    try:
        client.wait_for_workers(2, timeout=120)
        socks = listening(descendants(os.getpid()))
    finally:
        client.close()
        cluster.close()
    loopback = ("0100007F", "00000000000000000000000001000000", "0000000000000000FFFF00000100007F")
    if len(socks) < 3:
        fail("loopback: %d listening sockets found, expected the scheduler's and 2 workers'" %
             len(socks))
    for pid, addr in socks:
        if addr not in loopback:
            fail("loopback: process %d listens on %s (hex, /proc/net), expected 127.0.0.1 or ::1"
                 % (pid, addr))


def main():
    shutil.rmtree(WORK, ignore_errors=True)
    os.makedirs(WORK)
    check_loopback()
    path = spec("plans", 8)
    rc, err, ref = plan(path, os.path.join(WORK, "serial"), 0)
    if rc != 0 or ref is None:
        fail("serial plans: exit %d, expected 0: %s" % (rc, err[-800:]))
        return 1
    check_converged(ref, os.path.join(WORK, "serial"))

    rc, err, got = plan(path, os.path.join(WORK, "workers2"), 2)
    if rc != 0 or got is None:
        fail("plans on 2 workers: exit %d, expected 0: %s" % (rc, err[-800:]))
    else:
        for v in ref:
            diff = {k: (got[v].get(k), ref[v][k]) for k in ref[v]
                    if k != "time_s" and got[v].get(k) != ref[v][k]}
            if diff:
                fail("2 workers: %s differs from the serial engine (got, serial): %s" % (v, diff))

    rigid = ref["v003"]
    if rigid["runs"] != "1" or not float(rigid["miss_mm"]) < 1e-3:
        fail("rigid: %s runs, miss %s mm; expected 1 run, < 1e-3 mm" % (rigid["runs"],
                                                                       rigid["miss_mm"]))
    aim = vec(rigid["aim_mm"])
    if max(abs(a - 1e3 * x) for a, x in zip(aim, TARGET_A)) > 1e-3:  # printed to 1e-3 mm
        fail("rigid: aim %s mm, expected the target %s mm" % (aim, [1e3 * x for x in TARGET_A]))

    comp = [math.dist(vec(ref[v]["aim_mm"]), [1e3 * x for x in TARGET_A]) for v in ("v000", "v001")]
    ratio = comp[1] / comp[0]
    if not abs(ratio - 0.5) <= 0.02:
        fail("compensation |aim - X| at 40 kPa / 20 kPa = %.4f / %.4f mm = %.4f, expected "
             "0.5 +- 0.02 (linear elasticity)" % (comp[1], comp[0], ratio))
    if os.environ.get("NH_TEST_VERBOSE"):
        print("compensations %s mm, ratio %.4f; runs %s" % (comp, ratio,
                                                          [ref[v]["runs"] for v in sorted(ref)]))

    one = spec("one-run", 1)
    out = os.path.join(WORK, "one-run")
    for attempt in ("first", "restart"):
        rc, err, rows = plan(one, out, 2)
        status = {v: r["status"] for v, r in (rows or {}).items()}
        expect = {"v000": "not converged", "v001": "not converged", "v002": "not converged",
                  "v003": "ok"}
        if rc != 1 or status != expect:
            fail("max_runs 1 (%s): exit %d, statuses %s; expected exit 1, %s: %s" % (
                attempt, rc, status, expect, err[-500:]))
        for v in ("v000", "v001", "v002"):
            if ("variant %s: not converged" % v) not in err:
                fail("max_runs 1 (%s): %s not named as not converged: %s" % (attempt, v,
                                                                             err[-500:]))
        if attempt == "restart" and "4 of 4 variants already complete" not in err:
            fail("max_runs 1, restart: expected the 4 complete plans skipped: %s" % err[-500:])
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
