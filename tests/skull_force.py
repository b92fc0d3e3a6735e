#!/usr/bin/python3
"""The skull's force in steps.csv (skull_contacts, skull_fx/fy/fz): a brain
resting in its skull under gravity (tissue.domain brain, no fixed region, no
buoyancy, gap 0, mass damping 4 /s, dynamic to rest) is held by the skull
alone. The elastic forces of the elements sum to zero and the damping force
vanishes at rest, so the skull's force on the tissue balances the weight:

    F_skull = -M g,   M = rho * sum_c phi_c V_c

with phi_c (`fill`) and the rest volume V_c of each cell read from the last
tissue frame (cells of a box grid and its refinements are boxes, so V_c is
the product of their edges) — an independent sum, not the code's lumped
masses. Checks (silent on success, one line per failure, exit 1):
 1. F_y = M g to 1e-3 relative (the rest of the settling: the brain comes to
    rest with time constant 1/4 s; at t = 4 s the damping force is
    below 1e-4 of the weight), F_x and F_z below 1e-6 M g (symmetry of
    the brain about the planes x = 0 and z = 0 under gravity along -y);
 2. skull_contacts > 0 at rest, and 0 with zero force in a run without
    gravity whose skull stands 1 mm off (nothing touches; with gap 0 the
    surface points touch and carry round-off multipliers, ~1e-16 N).
Arguments KEY=VALUE are scene overrides for both runs (the ctest variant
skull_force_integrated passes tissue.cut_cells=integrated: then `fill` is
the quadrature's tissue fraction and M the quadrature's mass).
"""
import os
import sys
import xml.etree.ElementTree as ET

import numpy as np
import vtk
from vtk.util.numpy_support import vtk_to_numpy

from nh_run import fail, finish, run, work

SETS = sys.argv[1:]
WORK = work("skull_force" + ("_" + "_".join(a.split("=")[1] for a in SETS) if SETS else ""))
SCENE = os.path.join(WORK, "rest.yaml")
RHO, G = 1040.0, 9.81
with open(SCENE, "w") as f:
    f.write("""name: skull-rest
time: {mode: dynamic, step: 0.05, end: 4.0}
gravity: [0, -%g, 0]
tissue:
  domain:
    brain: {size: [0.14, 0.17, 0.13], center: [0, 0, 0]}
  grid: [8, 10, 8]
  material: {young: 2509, poisson: 0.45, density: %g}
  damping: {mass: 4.0, stiffness: 0.0}
  skull: {gap: 0.0}
output:
  every: 80
""" % (G, RHO))

out = os.path.join(WORK, "rest")
r = run(SCENE, out, SETS)
if r:
    last = r["steps"][-1]
    F = np.array([float(last[c]) for c in ("skull_fx", "skull_fy", "skull_fz")])
    frames = ET.parse(os.path.join(out, "tissue.pvd")).getroot()
    vtu = os.path.join(out, list(frames.iter("DataSet"))[-1].get("file"))
    rd = vtk.vtkXMLUnstructuredGridReader()
    rd.SetFileName(vtu)
    rd.Update()
    grid = rd.GetOutput()
    X = vtk_to_numpy(grid.GetPoints().GetData()) - vtk_to_numpy(grid.GetPointData().GetArray("displacement"))
    fill = vtk_to_numpy(grid.GetCellData().GetArray("fill"))
    mass = 0.0
    for c in range(grid.GetNumberOfCells()):
        ids = grid.GetCell(c).GetPointIds()
        P = X[[ids.GetId(a) for a in range(ids.GetNumberOfIds())]]
        mass += RHO * fill[c] * np.prod(P.max(axis=0) - P.min(axis=0))
    W = mass * G
    if not abs(F[1] - W) <= 1e-3 * W:
        fail("skull_fy %.6g N at rest, expected the weight M g = %.6g N within 1e-3 (%.2e off)"
             % (F[1], W, abs(F[1] - W) / W))
    if not (abs(F[0]) <= 1e-6 * W and abs(F[2]) <= 1e-6 * W):
        fail("skull_fx, skull_fz %.3g, %.3g N, expected below 1e-6 of the weight %.4g N by symmetry"
             % (F[0], F[2], W))
    if not int(last["skull_contacts"]) > 0:
        fail("skull_contacts %s at rest, expected > 0" % last["skull_contacts"])
    print("at rest: skull force (%.3e, %.8f, %.3e) N, weight %.8f N, %s contacts"
          % (F[0], F[1], F[2], W, last["skull_contacts"]))
free = run(SCENE, os.path.join(WORK, "free"),
           ["gravity=[0,0,0]", "time.end=0.1", "tissue.skull.gap=0.001"] + SETS)
if free and any(int(s["skull_contacts"]) != 0 or float(s["skull_fy"]) != 0.0 for s in free["steps"]):
    fail("without gravity: skull_contacts/skull_fy %s, expected 0 (nothing presses)"
         % [(s["skull_contacts"], s["skull_fy"]) for s in free["steps"]])
finish()
