#!/usr/bin/python3
"""End to end: a run with output.hdf5 writes results.h5 and results.xdmf
that agree with its CSV files and VTU frames.

An adaptive dynamic run (tests/data/restart.yaml, 12 steps, hdf5 on):
- h5py: /steps has one row per step, equal to steps.csv (same columns);
  /probes has one sample per step plus the initial one, equal to probes.csv;
- /frames holds exactly the frames of tissue.pvd, at the same times;
- meshio reads every frame of the XDMF series on its own mesh (the mesh is
  refined during the run) and its points and displacements equal the VTU's.
"""
import csv
import os
import shutil
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET

import h5py
import meshio
import numpy as np

BIN, SRC = os.environ["NH_BINARY"], os.environ["NH_SOURCE_DIR"]
failures = []


def check(cond, msg):
    if not cond:
        failures.append(msg)
        print("FAIL:", msg, file=sys.stderr)


def main():
    tmp = tempfile.mkdtemp(prefix="nh-h5-")
    try:
        out = os.path.join(tmp, "run")
        subprocess.run([BIN, "run", os.path.join(SRC, "tests", "data", "restart.yaml"), "--quiet",
                        "--out", out, "--set", "time.steps=12", "--set", "output.hdf5=true",
                        "--set", "output.every=3"], check=True)
        with open(os.path.join(out, "steps.csv")) as f:
            rows = list(csv.reader(f))
        header, rows = rows[0], np.array([[float(x) for x in r] for r in rows[1:]])
        with open(os.path.join(out, "probes.csv")) as f:
            probes = list(csv.DictReader(f))
        h = h5py.File(os.path.join(out, "results.h5"), "r")
        steps = h["steps"][...]
        check(steps.shape == rows.shape, "steps: shape %s, csv %s" % (steps.shape, rows.shape))
        if steps.shape == rows.shape:
            diff = np.abs(steps - rows) / np.maximum(np.abs(rows), 1e-300)
            ok = np.isnan(rows) == np.isnan(steps)
            check(ok.all() and np.nanmax(np.where(np.isnan(rows), 0, diff)) < 1e-6,
                  "steps differ from steps.csv (printed with 7 digits)")
        vals = h["probes/values"][...]
        n_samples = len({int(p["step"]) for p in probes})
        check(vals.shape[0] == n_samples == 13, "probes: %d samples, csv %d, want 13" % (vals.shape[0], n_samples))
        for p in probes:
            k, i = int(p["step"]), ["1", "4"].index(p["name"])
            want = [float(p[c]) for c in ("x", "y", "z", "ux", "uy", "uz")]
            check(np.allclose(vals[k, i], want, rtol=1e-14, atol=1e-300), "probe %s step %d" % (p["name"], k))
        pvd = [(float(e.get("timestep")), e.get("file"))
               for e in ET.parse(os.path.join(out, "tissue.pvd")).getroot().iter("DataSet")]
        names = sorted(h["frames"].keys())
        check(len(names) == len(pvd), "frames: %d in HDF5, %d in the PVD" % (len(names), len(pvd)))
        reader = meshio.xdmf.TimeSeriesReader(os.path.join(out, "results.xdmf"))
        check(reader.num_steps == len(pvd), "XDMF lists %d frames, PVD %d" % (reader.num_steps, len(pvd)))
        sizes = set()
        for k, (t, name) in enumerate(pvd):
            reader.mesh_grid = reader.collection[k]  # each frame on its own mesh
            pts, cells = reader.read_points_cells()
            tt, pdata, _ = reader.read_data(k)
            vtu = meshio.read(os.path.join(out, name))
            sizes.add(len(pts))
            check(abs(tt - t) <= 1e-12, "frame %d: XDMF time %g, PVD %g" % (k, tt, t))
            check(pts.shape == vtu.points.shape and np.array_equal(pts, vtu.points), "frame %d: points differ" % k)
            check(np.array_equal(pdata["displacement"], vtu.point_data["displacement"]),
                  "frame %d: displacement differs" % k)
        check(len(sizes) > 1, "the mesh never changed: the test does not cover refined frames")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
