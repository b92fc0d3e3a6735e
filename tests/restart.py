#!/usr/bin/python3
"""Checkpoint, restart, signals and atomic outputs (issue: results that last).

1. A run killed with SIGKILL mid-way (after at least 13 of 30 steps) leaves
   a tissue.pvd whose every frame VTK reads, and a readable checkpoint.
2. `--restart DIR` continues it; at the last step the probes and the last
   frame's displacements equal an uninterrupted run's to 1e-12 relative.
3. SIGTERM stops a run after the current step: exit status 1, a message
   naming the step, a final frame and a checkpoint; restarting finishes it
   with the same result.
4. A corrupted, a foreign and another scene's checkpoint are refused with
   exit status 2 and one message.
"""
import csv
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET

import numpy as np
import vtk
from vtk.util.numpy_support import vtk_to_numpy

BIN = os.environ["NH_BINARY"]
SRC = os.environ["NH_SOURCE_DIR"]
SCENE = os.path.join(SRC, "tests", "data", "restart.yaml")
failures = []


def fail(msg):
    failures.append(msg)
    print("FAIL:", msg, file=sys.stderr)


def read_vtu(path):
    r = vtk.vtkXMLUnstructuredGridReader()
    r.SetFileName(path)
    r.Update()
    g = r.GetOutput()
    if g is None or g.GetNumberOfPoints() == 0:
        raise RuntimeError("VTK cannot read " + path)
    return vtk_to_numpy(g.GetPointData().GetArray("displacement"))


def frames(d):
    root = ET.parse(os.path.join(d, "tissue.pvd")).getroot()
    return [(float(e.get("timestep")), e.get("file")) for e in root.iter("DataSet")]


def last_probes(d):
    with open(os.path.join(d, "probes.csv")) as f:
        rows = list(csv.DictReader(f))
    last = max(int(r["step"]) for r in rows)
    return last, np.array([[float(r[k]) for k in ("ux", "uy", "uz")] for r in rows if int(r["step"]) == last])


def run(out, *extra, check=True):
    p = subprocess.run([BIN, "run", SCENE, "--quiet", "--out", out, *extra], capture_output=True, text=True)
    if check and p.returncode != 0:
        raise RuntimeError("run failed (%d): %s" % (p.returncode, p.stderr))
    return p


def compare(ref, got, what):
    s_ref, p_ref = last_probes(ref)
    s_got, p_got = last_probes(got)
    if s_ref != s_got:
        fail("%s: last step %d, expected %d" % (what, s_got, s_ref))
        return
    scale = np.abs(p_ref).max()
    if not np.allclose(p_got, p_ref, rtol=0, atol=1e-12 * scale):
        fail("%s: probes differ by %g (scale %g)" % (what, np.abs(p_got - p_ref).max(), scale))
    f_ref, f_got = frames(ref)[-1][1], frames(got)[-1][1]
    if f_ref != f_got:
        fail("%s: last frame %s, expected %s" % (what, f_got, f_ref))
        return
    u_ref, u_got = read_vtu(os.path.join(ref, f_ref)), read_vtu(os.path.join(got, f_got))
    if u_ref.shape != u_got.shape or not np.allclose(u_got, u_ref, rtol=0, atol=1e-12 * np.abs(u_ref).max()):
        fail("%s: last frame displacements differ" % what)


def main():
    tmp = tempfile.mkdtemp(prefix="nh-restart-")
    try:
        ref = os.path.join(tmp, "ref")
        run(ref)

        # 1-2: SIGKILL mid-way, then restart.
        killed = os.path.join(tmp, "killed")
        p = subprocess.Popen([BIN, "run", SCENE, "--quiet", "--out", killed], stderr=subprocess.PIPE)
        steps = os.path.join(killed, "steps.csv")
        deadline = time.time() + 600
        while time.time() < deadline and p.poll() is None:
            try:
                with open(steps) as f:
                    if sum(1 for _ in f) >= 14:  # header + 13 rows
                        break
            except FileNotFoundError:
                pass
            time.sleep(0.002)
        if p.poll() is not None:
            fail("the run finished before it could be killed: the test needs a slower scene")
            return 1
        p.send_signal(signal.SIGKILL)
        p.wait()
        for t, name in frames(killed):
            try:
                read_vtu(os.path.join(killed, name))
            except Exception as e:  # noqa: BLE001
                fail("after SIGKILL, frame %s of the PVD is unreadable: %s" % (name, e))
        if not os.path.exists(os.path.join(killed, "checkpoint.nhc")):
            fail("no checkpoint after 13 steps with output.checkpoint = 5")
        run(killed, "--restart", killed)
        compare(ref, killed, "kill + restart")

        # 3: SIGTERM.
        term = os.path.join(tmp, "term")
        p = subprocess.Popen([BIN, "run", SCENE, "--quiet", "--out", term], stderr=subprocess.PIPE, text=True)
        steps = os.path.join(term, "steps.csv")
        while p.poll() is None:
            try:
                with open(steps) as f:
                    if sum(1 for _ in f) >= 8:
                        break
            except FileNotFoundError:
                pass
            time.sleep(0.002)
        p.send_signal(signal.SIGTERM)
        _, err = p.communicate()
        if p.returncode != 1 or "stopped by signal" not in err or err.count("\n") != 1:
            fail("SIGTERM: expected exit 1 and one 'stopped by signal' line, got %d: %r" % (p.returncode, err))
        with open(steps) as f:
            done = sum(1 for _ in f) - 1
        if not any(name == "tissue_%06d.vtu" % done for _, name in frames(term)):
            fail("SIGTERM: no final frame for step %d" % done)
        run(term, "--restart", term)
        compare(ref, term, "SIGTERM + restart")

        # 4: bad checkpoints.
        bad = os.path.join(tmp, "bad")
        shutil.copytree(ref, bad)
        ck = os.path.join(bad, "checkpoint.nhc")
        data = bytearray(open(ck, "rb").read())
        cases = []
        corrupt = bytearray(data)
        corrupt[len(corrupt) // 2] ^= 0x40
        cases.append(("corrupted", bytes(corrupt), "corrupted"))
        cases.append(("truncated", bytes(data[: len(data) // 3]), "corrupted"))
        cases.append(("foreign", open(os.path.join(ref, "tissue.pvd"), "rb").read(), "not a needlehex checkpoint"))
        for what, content, phrase in cases:
            with open(ck, "wb") as f:
                f.write(content)
            p = run(bad, "--restart", bad, check=False)
            if p.returncode != 2 or phrase not in p.stderr or p.stderr.count("\n") != 1:
                fail("%s checkpoint: expected exit 2 and '%s', got %d: %r" % (what, phrase, p.returncode, p.stderr))
        with open(ck, "wb") as f:
            f.write(data)
        p = run(bad, "--restart", bad, "--set", "tissue.material.young=2e7", check=False)
        if p.returncode != 2 or "another scene" not in p.stderr:
            fail("other scene: expected exit 2 and 'another scene', got %d: %r" % (p.returncode, p.stderr))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
