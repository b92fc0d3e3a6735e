#!/usr/bin/python3
"""refine_cells_tool (the driver of docs/dbs.md's controlled local
refinement) on the traction patch test (tests/data/traction_patch.yaml).

A block E = 5000 Pa, ν = 0, L = 0.04 m, clamped at x = 0, under a uniform
traction σ = 100 Pa on x = L ramped by [[0, 0], [2, 1]] (static, steps at
t = 1, 2). The exact field u_x = s(t) σ x / E, u_y = u_z = 0 lies in the
trilinear space of every mesh, with hanging nodes too (their interpolation
is exact for it): refining cells before either step must leave the probes'
displacements at the exact values to round-off (1e-9 relative to σL/E, the
full formulation), and the dofs must grow at the step after the refinement.
A point outside the mesh, or a refinement after the last step, is refused
with exit 2.
"""
import os
import subprocess
import sys

TOOL, SRC = sys.argv[1], os.environ["NH_SOURCE_DIR"]
SCENE = os.path.join(SRC, "tests", "data", "traction_patch.yaml")
E, SIGMA, L = 5000.0, 100.0, 0.04
SETS = ["--", "tissue.material.formulation=full", "adapt.max_level=1", "adapt.every=1000000"]
failures = []

for step in (0, 1):
    # the clamped corner cell and an interior one: hanging nodes on the
    # clamp's face and inside the block
    cmd = [TOOL, SCENE, str(step), "2", "0.005,0.003,0.002", "0.025,0.01,0.007"] + SETS
    lines = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout.split()
    rows = [lines[i:i + 6] for i in range(0, len(lines), 6)]
    if len(rows) != 2:
        failures.append("refine before step %d: %d lines, expected 2" % (step + 1, len(rows)))
        continue
    dofs = [int(r[2]) for r in rows]
    if not (step == 0 or dofs[1] > dofs[0]):
        failures.append("refine before step 2: dofs %d, %d did not grow" % tuple(dofs))
    for r in rows:
        t, u = float(r[1]), [float(v) * 1e-3 for v in r[3:6]]
        s = t / 2.0
        exact = (s * SIGMA * L / E, 0.0, 0.0)  # the probe `end` at x = L
        err = max(abs(a - b) for a, b in zip(u, exact))
        if err > 1e-9 * SIGMA * L / E:
            failures.append("refine before step %d, t = %g: u = %s, exact %s, error %.3g > %.3g"
                            % (step + 1, t, u, exact, err, 1e-9 * SIGMA * L / E))

bad = subprocess.run([TOOL, SCENE, "0", "1", "0.5,0.01,0.005"] + SETS, capture_output=True,
                     text=True)
if bad.returncode != 2 or "outside the mesh" not in bad.stderr:
    failures.append("a point outside the mesh: exit %d, %r (expected 2, 'outside the mesh')"
                    % (bad.returncode, bad.stderr.strip()))

late = subprocess.run([TOOL, SCENE, "2", "2", "0.005,0.003,0.002"] + SETS, capture_output=True,
                      text=True)
if late.returncode != 2:  # a refinement after the last step would never happen
    failures.append("refine before step 3 of 2: exit %d (expected 2)" % late.returncode)

for f in failures:
    print("FAIL:", f)
sys.exit(1 if failures else 0)
