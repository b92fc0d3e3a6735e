#!/usr/bin/python3
"""Checkpoint, restart, signals and atomic outputs (issue: results that last).

1. A run killed with SIGKILL mid-way (after at least 13 of 30 steps) leaves
   a tissue.pvd whose every frame VTK reads, and a readable checkpoint.
2. `--restart DIR` continues it; at the last step the probes and the last
   frame's displacements equal an uninterrupted run's to 1e-12 relative.
3. SIGTERM stops a run after the current step: exit status 1, a message
   naming the step, a final frame and a checkpoint; the command the message
   prints ("continue with: needlehex run DIR/scene.yaml --restart DIR"),
   run as printed, finishes it with the same result.
4. A corrupted, a foreign, an older format's and another scene's checkpoint are refused with
   exit status 2 and one message.
5. HDF5 (output.hdf5 on in every run of cases 1-3, the reference included,
   since it is part of the scene): after each restart results.h5 has exactly
   one /steps row per step 1..30, equal to steps.csv, and its probe series
   equals the reference run's to 1e-12 relative.
6. SIGTERM inside a long step (a `lagrange` W build and solve of seconds) stops the
   run within 2.5 x step 1's own time (1 s on a quiet machine), exit 1, with
   the last complete step checkpointed.
"""
import csv
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET

import h5py
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


HDF5 = ("--set", "output.hdf5=true")


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


def compare_h5(ref, got, what):
    """results.h5 of a restarted run: one /steps row per step, equal to its
    steps.csv; probe series equal to the reference run's; the frames of its
    tissue.pvd."""
    with open(os.path.join(got, "steps.csv")) as f:
        reader = csv.reader(f)
        header = next(reader)
        csv_rows = np.array([[float(x) for x in r] for r in reader])
    try:
        h_got = h5py.File(os.path.join(got, "results.h5"), "r")
        h_ref = h5py.File(os.path.join(ref, "results.h5"), "r")
    except OSError as e:
        fail("%s: results.h5 does not open: %s" % (what, e))
        return
    with h_got, h_ref:
        steps = h_got["steps"]
        if list(steps.attrs["columns"]) != header:
            fail("%s: /steps columns %s, steps.csv has %s" % (what, list(steps.attrs["columns"]), header))
            return
        got_steps = steps[:, 0].astype(int).tolist()
        if got_steps != list(range(1, 31)):
            fail("%s: /steps has the steps %s, expected 1..30 once each" % (what, got_steps))
            return
        # Counts and solver values to the digits steps.csv prints; the
        # timings (columns t_*), eta and eta_rel with 7 digits, residual with 6.
        if csv_rows.shape != steps.shape or not np.allclose(steps[()], csv_rows, rtol=1e-5, atol=0, equal_nan=True):
            fail("%s: /steps differs from steps.csv" % what)
        exact = [j for j, c in enumerate(header) if not c.startswith("t_") and c not in ("eta", "eta_rel", "residual")]
        if not np.array_equal(steps[:, exact], csv_rows[:, exact], equal_nan=True):
            fail("%s: /steps columns %s differ from steps.csv" % (what, [header[j] for j in exact]))
        p_got, p_ref = h_got["probes"], h_ref["probes"]
        for name in ("step", "time"):
            if not np.array_equal(p_got[name][()], p_ref[name][()]):
                fail("%s: /probes/%s differs from the reference run's" % (what, name))
        v_got, v_ref = p_got["values"][()], p_ref["values"][()]
        if v_got.shape != v_ref.shape:
            fail("%s: /probes/values has shape %s, reference %s" % (what, v_got.shape, v_ref.shape))
            return
        scale = np.abs(v_ref).max()
        if not np.allclose(v_got, v_ref, rtol=0, atol=1e-12 * scale):
            fail("%s: /probes/values differ by %g (scale %g)" % (what, np.abs(v_got - v_ref).max(), scale))
        # The frames of the run's own tissue.pvd (SIGTERM adds one at the stop).
        pvd = sorted(name[len("tissue_"):-len(".vtu")] for _, name in frames(got))
        if sorted(h_got["frames"]) != pvd:
            fail("%s: /frames %s, tissue.pvd has %s" % (what, sorted(h_got["frames"]), pvd))


def main():
    tmp = tempfile.mkdtemp(prefix="nh-restart-")
    try:
        ref = os.path.join(tmp, "ref")
        run(ref, *HDF5)

        # 1-2: SIGKILL mid-way, then restart.
        killed = os.path.join(tmp, "killed")
        p = subprocess.Popen([BIN, "run", SCENE, "--quiet", "--out", killed, *HDF5], stderr=subprocess.PIPE)
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
        run(killed, "--restart", killed, *HDF5)
        compare(ref, killed, "kill + restart")
        compare_h5(ref, killed, "kill + restart")

        # 3: SIGTERM.
        term = os.path.join(tmp, "term")
        p = subprocess.Popen([BIN, "run", SCENE, "--quiet", "--out", term, *HDF5], stderr=subprocess.PIPE, text=True)
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
        # The printed command, exactly as printed (the scene as run: DIR/scene.yaml).
        printed = err.split("continue with: ")[-1].strip().split()
        if printed[:2] != ["needlehex", "run"] or "--restart" not in printed:
            fail("SIGTERM: no 'continue with: needlehex run ...' command in %r" % err)
        else:
            p = subprocess.run([BIN] + printed[1:] + ["--quiet"], capture_output=True, text=True)
            if p.returncode != 0:
                fail("SIGTERM: the printed command %r failed (%d): %s" % (printed, p.returncode, p.stderr))
        compare(ref, term, "SIGTERM + restart")
        compare_h5(ref, term, "SIGTERM + restart")

        # 6: SIGTERM inside a long step (step 2 refines 24x12x12 to 40410
        # dofs with `lagrange` hanging rows: 4.9 s of step, 3.7 s of it the
        # constraint rows' W and solve, on a quiet machine since W is built by
        # supernodes): the run stops soon after the signal (BOUND below),
        # exit 1, with the last complete step checkpointed.
        # The signal is aimed into step 2's constraint rows, past its
        # refinement, METIS ordering and factorisation (about 1.2 s, 3 x step
        # 1's 0.41 s on a quiet machine), which are library calls that cannot
        # stop inside (up to 1.8 s, docs/outputs.md). The delay scales with
        # step 1's own time, so a loaded or sanitized run aims at about the
        # same phase; but the load can change between steps, and the
        # sanitizers slow our W build more than the libraries, so the aim is
        # tried up to three times (4.5, 3.6 and 6 x step 1). Step 3 (the same
        # 40410-dof mesh, its W built again) is as long a step: a signal in it
        # counts too. Each try must stop with exit 1 and the checkpoint (or end
        # before the signal came: a miss), and one must stop within
        # BOUND x step 1's t_step of the signal. The bound is relative to the
        # run's own step 1, not a wall time, so that load and sanitizers,
        # which slow both alike, do not fail it (a fixed 1 s failed at 1.42 -
        # 4.55 s under ASan at load 8): 2.5 x step 1 is the 1 s of a quiet
        # machine (step 1 0.41 s), above the 0.1 - 0.2 s from a signal in the
        # W build and the up to 1.8 s (4.4 x) of a signal caught inside the
        # ordering (a try that lands there misses; the next aims elsewhere),
        # and below the 3.7 s (9 x) of a W build and solve that ignored the
        # stop request until its end.
        BOUND = 2.5
        latencies = []
        for aim in (4.5, 3.6, 6.0):
            long_dir = os.path.join(tmp, "long-%g" % aim)
            p = subprocess.Popen([BIN, "run", SCENE, "--quiet", "--out", long_dir, "--set",
                                  "adapt.hanging=lagrange", "--set", "tissue.grid=[24,12,12]", "--set",
                                  "adapt.marking.theta=0.05", "--set", "adapt.max_level=1", "--set",
                                  "time.steps=3"], stderr=subprocess.PIPE, text=True)
            steps = os.path.join(long_dir, "steps.csv")
            while p.poll() is None:
                try:
                    with open(steps) as f:
                        if sum(1 for _ in f) >= 2:  # step 1 done; step 2 is the long one
                            break
                except FileNotFoundError:
                    pass
                time.sleep(0.01)
            with open(steps) as f:
                step1 = float(next(csv.DictReader(f))["t_step"])
            time.sleep(aim * step1)
            t0 = time.monotonic()
            p.send_signal(signal.SIGTERM)
            _, err = p.communicate()
            latency = time.monotonic() - t0
            if p.returncode == 0:
                print("SIGTERM in a long step: aim %g x step 1 came after the run's end" % aim)
                continue
            if p.returncode != 1 or not re.search(r"during step [23], after step [12] of 3", err):
                fail("SIGTERM in a long step: expected exit 1 and 'during step 2 (or 3), after step 1 "
                     "(or 2)', got %d: %r" % (p.returncode, err))
                continue
            if not os.path.exists(os.path.join(long_dir, "checkpoint.nhc")):
                fail("SIGTERM in a long step: no checkpoint")
            latencies.append(latency / step1)
            if latency <= BOUND * step1:
                break
        if not latencies or min(latencies) > BOUND:
            fail("SIGTERM in a long step: stopped %s x step 1's time after the signal, expected "
                 "within %g x" % (", ".join("%.2f" % t for t in latencies) or "never (every aim missed)",
                                  BOUND))

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
        older = bytearray(data)
        older[8:12] = (7).to_bytes(4, "little")  # format 7: before the goal estimate's state
        cases.append(("older", bytes(older), "written by an older needlehex"))
        for what, content, phrase in cases:
            with open(ck, "wb") as f:
                f.write(content)
            p = run(bad, "--restart", bad, *HDF5, check=False)
            if p.returncode != 2 or phrase not in p.stderr or p.stderr.count("\n") != 1:
                fail("%s checkpoint: expected exit 2 and '%s', got %d: %r" % (what, phrase, p.returncode, p.stderr))
        with open(ck, "wb") as f:
            f.write(data)
        p = run(bad, "--restart", bad, *HDF5, "--set", "tissue.material.young=2e7", check=False)
        if p.returncode != 2 or "another scene" not in p.stderr:
            fail("other scene: expected exit 2 and 'another scene', got %d: %r" % (p.returncode, p.stderr))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
