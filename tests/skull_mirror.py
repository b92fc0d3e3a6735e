#!/usr/bin/python3
"""Mirror symmetry of the brain shift in a skull on a grid with an odd cell
count across (contact/skull.c, docs/theory.md §5c "Points on a crease";
docs/dbs.md). cases/dbs/dbs-skull.yaml on 11 x 13 x 10 cells, uniform, the
drainage of its first second (20 steps; the tools still): the brain, the
grid (centred on the brain's mid-plane x = 0), the brainstem tie, gravity
and the drainage are mirror symmetric in x, so the exact discrete solution
is too: u_x(-x, y, z) = -u_x(x, y, z), u_y and u_z even. The solves are not
exact: the constraint forces are solved to 1e-10 (relative) by sweeps in row
order, which is not mirror symmetric, and solver.tolerance is 1e-8; a stable
step carries such an error, it does not grow it. Checked at the last step:

    max over nodes |u(X) - M u(M X)| <= 1e-6 max |u|    (M: x -> -x)

100 times the largest solve tolerance (measured: 1e-10 max |u|). Before the
skull points were kept off the creases of F, a point on the mid-plane sat on
the hemispheres' crease (or faced it 1 mm out, beside the brainstem), its
row direction flipped with round-off and pushed it further that way: the
antisymmetric part grew ~1e3-fold per step to 2 % of max |u| by t = 1 s.
The skull's rows are mirror symmetric too (each row's mirror image is a
row, with the mirrored impulse), so the net contact force has no x part:

    |F_x| <= 1e-6 |F|  at every step with contact (skull_fx, skull_fy, skull_fz)

Also: every node has a mirror node (the grid is centred), and the run is
clean. Extra arguments are --set strings (skull_mirror_mortar:
tissue.skull.rows=mortar, the weighted-gap rows, docs/theory.md §5c).
Silent on success.
"""
import os
import sys
import xml.etree.ElementTree as ET

import numpy as np
import vtk
from vtk.util.numpy_support import vtk_to_numpy

from nh_run import fail, finish, run, work

SCENE = os.path.join(os.environ["NH_SOURCE_DIR"], "cases", "dbs", "dbs-skull.yaml")
OUT = os.path.join(work("skull_mirror" + "".join("_" + a.split("=")[-1] for a in sys.argv[1:])),
                   "run")
SETS = ["tissue.grid=[11,13,10]", "adapt.every=1000000", "time.end=1.0", "output.every=0"]
SETS += sys.argv[1:]

r = run(SCENE, OUT, SETS)
if r:
    unsolved = [s["step"] for s in r["steps"] if s.get("unsolved", "0") not in ("0", "")]
    if unsolved:
        fail("steps left unsolved: %s (expected none)" % unsolved)
    for st in r["steps"]:
        f = np.array([float(st[k]) for k in ("skull_fx", "skull_fy", "skull_fz")])
        if not abs(f[0]) <= 1e-6 * np.linalg.norm(f):
            fail("step %s: net skull force x part %.3g N of |F| = %.3g N, expected <= 1e-6 |F| "
                 "(mirror-symmetric rows)" % (st["step"], f[0], np.linalg.norm(f)))
    last = list(ET.parse(os.path.join(OUT, "tissue.pvd")).getroot().iter("DataSet"))[-1].get("file")
    rd = vtk.vtkXMLUnstructuredGridReader()
    rd.SetFileName(os.path.join(OUT, last))
    rd.Update()
    g = rd.GetOutput()
    x = vtk_to_numpy(g.GetPoints().GetData()).astype(float)
    u = vtk_to_numpy(g.GetPointData().GetArray("displacement")).astype(float)
    X = x - u  # the frame's points are the deformed ones
    scale = np.abs(X).max()
    key = {tuple(np.round(p / scale * 1e9).astype(np.int64)): i for i, p in enumerate(X)}
    mirror = np.array([key.get(tuple(np.round(np.array([-p[0], p[1], p[2]]) / scale * 1e9)
                                     .astype(np.int64)), -1) for p in X])
    if (mirror < 0).any():
        fail("%d of %d nodes without a mirror node (expected 0: the grid is centred on x = 0)"
             % ((mirror < 0).sum(), len(X)))
    else:
        um = u[mirror] * np.array([-1.0, 1.0, 1.0])
        asym = np.abs(u - um).max()
        umax = np.abs(u).max()
        if not asym <= 1e-6 * umax:
            i = int(np.argmax(np.abs(u - um).max(axis=1)))
            fail("max |u - M u(M X)| = %.3g m at X = (%.2f, %.2f, %.2f) mm, expected <= 1e-6 max|u| "
                 "= %.3g m (a mirror-symmetric problem)" % (asym, *(1e3 * X[i]), 1e-6 * umax))
finish()
