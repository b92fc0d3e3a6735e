#!/usr/bin/python3
"""`needlehex check` notes each fixed region of an immersed domain that its
cells do not resolve (docs/theory.md §5c, "With the tie resolved"): a leaf
meeting the region has an edge above 1/8 of the region's smallest size,
and the note proposes tissue.fixed.N.refine at that 1/8.

Expected values from the scene, not from the tool: cases/dbs/dbs.yaml on
its 10 x 12 x 8 grid over the 140 x 170 x 130 mm box (cells of 14, 14.17,
16.25 mm): the brainstem, a cylinder of radius 15 mm and length 20 mm, is
20 mm across at its smallest (refine 2.5 mm); the two spheres of radius 8
mm are 16 mm across (refine 2 mm); every region meets cells of 16.25 mm.
With tissue.fixed.0.refine = 0.0025 the brainstem's note goes, its line
in the summary says it is refined to 0.0025 m, and the spheres' notes stay; with all three refined there is none; a box domain's
fixed regions (cases/cantilever.yaml) get none (its nodes are tied, not
a cut cell's sub-region).
"""
import os
import re
import subprocess

from nh_run import BIN, fail, finish

SRC = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DBS = os.path.join(SRC, "cases", "dbs", "dbs.yaml")
NOTE = re.compile(r"^note: tissue\.fixed\.(\d+), ([0-9.e+-]+) m across at its smallest, meets "
                  r"cells of edges up to ([0-9.e+-]+) m: .* tissue\.fixed\.(\d+)\.refine: "
                  r"([0-9.e+-]+) \(1/8 of its size\)", re.M)
SIZE = {0: 0.020, 1: 0.016, 2: 0.016}
EDGE = max(0.14 / 10, 0.17 / 12, 0.13 / 8)


def notes(scene, sets=()):
    cmd = [BIN, "check", scene]
    for s in sets:
        cmd += ["--set", s]
    p = subprocess.run(cmd, capture_output=True, text=True)
    if p.returncode != 0:
        fail("check %s %s: exit %d: %s" % (scene, " ".join(sets), p.returncode, p.stderr))
        return {}
    if "tissue.fixed.0.refine=0.0025" in sets and \
            "radius 0.015 m, its cells refined to edges <= 0.0025 m before" not in p.stdout:
        fail("check with %s: the brainstem's line does not say it is refined" % " ".join(sets))
    return {int(m.group(1)): m for m in NOTE.finditer(p.stdout)}


for sets, want in (((), {0, 1, 2}), (("tissue.fixed.0.refine=0.0025",), {1, 2}),
                   (("tissue.fixed.0.refine=0.0025", "tissue.fixed.1.refine=0.002",
                     "tissue.fixed.2.refine=0.002"), set())):
    got = notes(DBS, sets)
    if set(got) != want:
        fail("dbs.yaml %s: notes for regions %s, expected %s" % (" ".join(sets) or "as shipped",
                                                                sorted(got), sorted(want)))
        continue
    for r, m in got.items():
        size, edge, key, refine = float(m.group(2)), float(m.group(3)), int(m.group(4)), \
            float(m.group(5))
        if key != r or abs(size - SIZE[r]) > 1e-9 or abs(refine - SIZE[r] / 8) > 1e-9 or \
                abs(edge - EDGE) > 1e-3 * EDGE:
            fail("dbs.yaml region %d: size %g, edge %g, refine key %d at %g; expected %g, %g, "
                 "%d at %g" % (r, size, edge, key, refine, SIZE[r], EDGE, r, SIZE[r] / 8))
if notes(os.path.join(SRC, "cases", "cantilever.yaml")):
    fail("cases/cantilever.yaml (a box domain): a note on its fixed region")
finish()
