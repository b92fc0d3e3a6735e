#!/usr/bin/python3
"""Sweeps through the execution engine (tools/study.py sweep, dask.distributed),
runs in $NH_WORK/sweep. Silent on success, one line per failure, exit 1.

 1. Four cantilever variants (Young's modulus x Poisson's ratio) on a
    LocalCluster of 2 workers give the same table as the serial engine
    (--workers 0: one needlehex after the other, no Dask): every output
    equal to the last digit (the runs are deterministic, one thread each).
    Independent check of the table: the tip deflection at E = 2 MPa is half
    that at E = 1 MPa (linear elasticity; the load is small, 0.35 % of the
    length) to 1e-3.
 2. Restart: the same sweep again skips all four (complete, same command).
 3. A worker killed (SIGKILL) while it runs a variant: the sweep still ends
    with all four variants complete (Dask reschedules the lost one on the
    restarted worker) and their values equal the serial ones, or it names
    the lost variant as failed (exit 1) and the others are complete.
"""
import csv
import os
import shutil
import signal
import subprocess
import sys
import time

BIN = os.environ["NH_BINARY"]
SRC = os.environ.get("NH_SOURCE_DIR", os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
STUDY = os.path.join(SRC, "tools", "study.py")
WORK = os.path.join(os.environ.get("NH_WORK", "."), "sweep")
failures = []


def fail(msg):
    print("FAIL:", msg, file=sys.stderr)
    failures.append(msg)


def spec(name, sets):
    path = os.path.join(WORK, name + ".yaml")
    with open(path, "w") as f:
        f.write("scene: %s\nset: %s\n" % (os.path.join(SRC, "cases", "cantilever.yaml"), sets))
        f.write("grid:\n  tissue.material.young: [1.0e+6, 2.0e+6]\n"
                "  tissue.material.poisson: [0.3, 0.45]\n"
                "outputs:\n  - {name: tip_uz, file: probes.csv, row: tip, column: uz}\n"
                "  - {name: mid_uz, file: probes.csv, row: mid, column: uz}\n")
    return path


def sweep_cmd(path, out, workers):
    return ["/usr/bin/python3", STUDY, "sweep", path, "--binary", BIN, "--out", out,
            "--workers", str(workers)]


def table(out):
    with open(os.path.join(out, "sweep.csv")) as f:
        return {r["variant"]: r for r in csv.DictReader(f)}


def run_sweep(what, path, out, workers):
    """Runs a sweep to its end: its table, or None (failure recorded)."""
    p = subprocess.run(sweep_cmd(path, out, workers), capture_output=True, text=True)
    if p.returncode != 0:
        fail("%s: exit %d: %s" % (what, p.returncode, p.stderr[-500:]))
        return None
    return table(out)


def compare(what, got, ref):
    for v in ref:
        if v not in got or got[v]["status"] != "ok":
            fail("%s: variant %s missing or failed" % (what, v))
            continue
        for k in ("tip_uz", "mid_uz"):
            if got[v][k] != ref[v][k]:
                fail("%s: %s %s = %s, serial %s (expected equal)" % (what, v, k, got[v][k],
                                                                      ref[v][k]))


def main():
    shutil.rmtree(WORK, ignore_errors=True)
    os.makedirs(WORK)
    quick = spec("quick", "[]")
    ref = run_sweep("serial sweep", quick, os.path.join(WORK, "serial"), 0)
    if ref is None:
        return 1
    # variants in grid order: v000 (1e6, 0.3), v001 (1e6, 0.45), v002 (2e6, 0.3), v003 (2e6, 0.45)
    for a, b in (("v000", "v002"), ("v001", "v003")):
        ratio = float(ref[b]["tip_uz"]) / float(ref[a]["tip_uz"])
        if not abs(ratio - 0.5) <= 1e-3:
            fail("tip deflection ratio E 2 MPa / 1 MPa (%s/%s) = %.6g, expected 0.5 +- 1e-3" % (
                b, a, ratio))

    out2 = os.path.join(WORK, "workers2")
    got = run_sweep("2-worker sweep", quick, out2, 2)
    if got is not None:
        compare("2 workers", got, ref)
        p = subprocess.run(sweep_cmd(quick, out2, 2), capture_output=True, text=True)
        if p.returncode != 0 or "4 of 4 variants already complete" not in p.stderr:
            fail("restart: expected the 4 complete variants skipped, got exit %d: %s" % (
                p.returncode, p.stderr[-300:]))

    # 3. Longer variants (a few seconds each); kill the worker running the first one seen.
    slow = spec("slow", "['tissue.grid=[80,8,8]', 'time.steps=6']")
    ref = run_sweep("serial slow sweep", slow, os.path.join(WORK, "slow-serial"), 0)
    if ref is None:
        return 1
    out3 = os.path.join(WORK, "killed")
    proc = subprocess.Popen(sweep_cmd(slow, out3, 2), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    killed, t0 = None, time.time()
    while killed is None and proc.poll() is None and time.time() - t0 < 120:
        for pid in filter(str.isdigit, os.listdir("/proc")):
            try:
                with open("/proc/%s/cmdline" % pid, "rb") as f:
                    cmd = f.read().split(b"\0")
                with open("/proc/%s/stat" % pid) as f:
                    ppid = int(f.read().rsplit(")", 1)[1].split()[1])
            except OSError:
                continue
            if BIN.encode() in cmd and any(out3.encode() in c and b".partial" in c for c in cmd):
                os.kill(ppid, signal.SIGKILL)  # the Dask worker running this variant
                killed = [c.decode() for c in cmd if out3.encode() in c][0]
                break
        time.sleep(0.2)
    stdout, stderr = proc.communicate(timeout=600)
    if killed is None:
        fail("kill: no running variant seen to kill (sweep exit %d)" % proc.returncode)
        return 1
    got = table(out3)
    lost = [v for v, r in got.items() if r["status"] != "ok"]
    if proc.returncode == 0:
        if lost:
            fail("kill: exit 0 but variants %s not ok" % lost)
        compare("after a killed worker", got, ref)
    else:
        named = [v for v in lost if ("variant %s failed" % v) in stderr]
        if not lost or named != lost:
            fail("kill: exit %d, lost variants %s, named in the report %s: %s" % (
                proc.returncode, lost, named, stderr[-500:]))
        compare("after a killed worker (complete ones)", {v: r for v, r in got.items()
                                                          if v not in lost},
                {v: r for v, r in ref.items() if v not in lost})
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
