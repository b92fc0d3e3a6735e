#!/usr/bin/python3
"""A full disk during a run: exit 1 with the OS reason, no temporary file
left, and every file written so far readable.

usage: disk_full.py TRIALS

Each trial mounts a tmpfs of a size drawn at random (fixed seed) below what
the run needs (cases/needle-phantom.yaml, 30 steps, a frame and results.h5
every step: about 2.4 MB), runs needlehex into it and checks:
- exit status 1, and stderr names "No space left on device" and the step;
- no "*.tmp" file is left;
- every VTU each PVD lists reads with meshio; every CSV has whole lines of
  as many fields as its header;
- results.h5 (when written) opens with h5py, and every frame it links and
  every frame results.xdmf lists reads back (meshio's XDMF reader).
Mounting needs root (CAP_SYS_ADMIN); without it the test is skipped (77).
Silent on success; loud (trial, size, what failed) on failure."""
import csv
import contextlib
import glob
import io
import os
import random
import shutil
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET

import h5py
import meshio

BIN, SRC = os.environ["NH_BINARY"], os.environ["NH_SOURCE_DIR"]
SCENE = os.path.join(SRC, "cases", "needle-phantom.yaml")
ARGS = ["--set", "time.end=0.3", "--set", "output.hdf5=true", "--set", "output.every=1", "--quiet"]
failures = []


def fail(trial, msg):
    failures.append(f"trial {trial}: {msg}")


def mount(point, kib):
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={kib}k", "tmpfs", point],
                       capture_output=True, text=True)
    return r.returncode == 0


def check_folder(trial, out):
    tmp = glob.glob(os.path.join(out, "*.tmp"))
    if tmp:
        fail(trial, f"temporary files left: {sorted(os.path.basename(t) for t in tmp)}")
    for pvd in glob.glob(os.path.join(out, "*.pvd")):
        try:
            files = [d.get("file") for d in ET.parse(pvd).getroot().iter("DataSet")]
        except ET.ParseError as e:
            fail(trial, f"{os.path.basename(pvd)} does not parse: {e}")
            continue
        for f in files:
            try:
                with contextlib.redirect_stderr(io.StringIO()):  # meshio's note on poly-lines
                    meshio.vtu.read(os.path.join(out, f))
            except Exception as e:  # noqa: BLE001 - any failure to read is the finding
                fail(trial, f"{f} listed by {os.path.basename(pvd)} does not read: {e!r}")
    for path in glob.glob(os.path.join(out, "*.csv")):
        with open(path, newline="") as fh:
            text = fh.read()
        if text and not text.endswith("\n"):
            fail(trial, f"{os.path.basename(path)} ends in half a line")
        rows = list(csv.reader(text.splitlines()))
        bad = [i for i, r in enumerate(rows) if len(r) != len(rows[0])]
        if bad:
            fail(trial, f"{os.path.basename(path)}: line {bad[0] + 1} has {len(rows[bad[0]])} "
                 f"fields, the header {len(rows[0])}")
    h5 = os.path.join(out, "results.h5")
    if os.path.exists(h5):
        try:
            with h5py.File(h5, "r") as f:
                f["steps"][()]
                for name in f["frames"]:
                    f["frames"][name]["points"][()]
                    f["frames"][name]["connectivity"][()]
        except Exception as e:  # noqa: BLE001
            fail(trial, f"results.h5 does not read: {e!r}")
    xdmf = os.path.join(out, "results.xdmf")
    if os.path.exists(xdmf) and ET.parse(xdmf).getroot().find(".//Grid/Grid") is not None:
        try:
            with meshio.xdmf.TimeSeriesReader(xdmf) as reader:
                reader.read_points_cells()
                for k in range(reader.num_steps):
                    reader.read_data(k)
        except Exception as e:  # noqa: BLE001
            fail(trial, f"results.xdmf series does not read: {e!r}")


def main():
    trials = int(sys.argv[1]) if len(sys.argv) > 1 else 20
    work = tempfile.mkdtemp(prefix="nh-full-")
    point = os.path.join(work, "mnt")
    os.makedirs(point)
    if os.geteuid() != 0 or not mount(point, 64):
        shutil.rmtree(work, ignore_errors=True)
        print("skipped: cannot mount a tmpfs (needs root)")
        return 77
    subprocess.run(["umount", point], check=True)
    rng = random.Random(16)
    try:
        for trial in range(trials):
            kib = rng.randint(16, 2300)
            mount(point, kib)
            try:
                out = os.path.join(point, "run")
                r = subprocess.run([BIN, "run", SCENE, "--out", out] + ARGS, capture_output=True,
                                   text=True, timeout=120)
                if r.returncode != 1:
                    fail(trial, f"{kib} KiB: exit {r.returncode}, expected 1; stderr: {r.stderr}")
                elif "No space left on device" not in r.stderr:
                    fail(trial, f"{kib} KiB: stderr lacks the OS reason: {r.stderr}")
                elif os.path.isdir(out) and "step" not in r.stderr:
                    fail(trial, f"{kib} KiB: stderr does not name the step: {r.stderr}")
                if "Segmentation" in r.stderr or "HDF5-DIAG" in r.stderr:
                    fail(trial, f"{kib} KiB: HDF5 diagnostics or a crash: {r.stderr}")
                if os.path.isdir(out):
                    check_folder(f"{trial} ({kib} KiB)", out)
            finally:
                subprocess.run(["umount", point], check=True)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    for f in failures:
        print(f, file=sys.stderr)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
