#!/usr/bin/python3
"""An immersed sphere under uniform external pressure, end to end (issue 25's
benchmark; docs/theory.md §5c, "The sphere under pressure").

A ball R = 30 mm, centre c = (3.11, −4.73, 2.29) mm, given as an STL
icosphere (20480 triangles, tissue.domain.surface), E = 3000 Pa, ν = 0.45,
B-bar, `tissue.cut_cells: integrated`, a pressure p = 3 Pa on its whole
surface (tissue.tractions), held by a tie (tissue.fixed) of radius
a = 1.5 mm at c, static, g³ cells over the bounding box.

Expected values, from analysis:
- Without the tie the linear field u = −p (X − c)/(3K) is exact (the
  immersed patch test, tests/test_fcm.c): any closed surface, polyhedral
  too. The tie is a foundation of modulus k = 10³ E/a² over r < a
  (docs/theory.md §5, "Fixed regions on an immersed domain"); the problem
  stays radial, u = f(r) e_r, and f has a closed form (`tied_radial`):
  inside, (λ+2μ)(f'' + 2f'/r − 2f/r²) = k f, f = C i₁(βr), β² = k/(λ+2μ)
  (i₁ the modified spherical Bessel function); outside, f = A r + B/r²;
  f and σ_rr continuous at a, σ_rr(R) = −p. That is the exact solution
  of the scene; it differs from the linear field by −2.4e-3 (relative) at
  r = 0.35 R and less further out (the tie's own perturbation).
- The discrete error at the probes (8 points at 0.35 R … 0.9 R, relative to
  |u_exact| at each, the max over probes) comes from the tie, a region
  smaller than a cell on every grid here, which the grid resolves only as
  h → a. The goal (issue 25): order ≥ 1 from the first grid on, i.e. every
  e_g ≤ e_first · g_first / g, and, on a finest grid of 24³ or more (the
  slow variant), e ≤ 1 % against both the closed form and the linear field.

With --ellipsoid: an ellipsoid of semi-axes 30, 22, 16 mm (the icosphere
scaled, then turned by 30° about (1, 2, 3)), the same centre, material, tie
and pressure; the probes at the same fractions of its radius along the same
directions. The linear field is still exact without the tie (a closed
surface under uniform pressure: the stress −p I), and the tie's
perturbation is the inclusion's in an unbounded body under that field's
strain (`tied_radial` with the remote condition f → −p r/(3K) instead of
σ_rr(R) = −p): the boundary's image of it is of relative order (a/R)³ ≈
1.3e-4 at the surface, below the errors measured. Asserted: order ≥ 1 from
the first grid (the 1 % at 24³ is the sphere's goal; the ellipsoid's
probes at 0.35 of its 16 mm semi-axis lie 5.6 mm from the tie, which a 24³
grid of its smaller box resolves with cells of 1.6-2.3 mm). Measured on
12, 14, 16, 20, 24: 3.97, 2.14, 1.85, 1.47, 1.18 % (0.93 % against the
linear field at 24³), order 1.01-1.21 from 14³ on. Not on every sequence
(docs/theory.md §5c): on 9, 10, 11, 13, 15, 18, 22 the errors are 2.39,
8.48, 2.11, 1.48, 0.47, 1.66, 1.30 %, the order-1 line from 9³ failing at
four of them; least-squares order 1.6 over all thirteen grids.

With --mask: the same body (sphere or ellipsoid) as a NIfTI label image of
0.5 mm voxels (tissue.domain.mask), label 1 where a voxel's centre is
inside. Its tissue {χ > 1/2} is a smoothed staircase within half a voxel of
the smooth surface; the linear field stays exact without the tie (a closed
surface), and the tie's perturbation and its image are the same to the
staircase's relative size (< 1e-5 at the probes): the same references and
assertions. Measured on 8 ... 24 (docs/theory.md §5c) within 3 % of the STL's
errors: the error is the tie's, not the surface's.

With --tie-refine MM: the same, with the tie's neighbourhood refined
before the first step until no cell there has an edge above MM
(tissue.fixed.0.refine). The tie then no longer falls inside one cell, and
the linear field is in the discrete space everywhere else (the patch test),
so no grid of the sequence has an error of its own: what is left is the
resolved tie's, and the finite-strain deviation of the run (corotational
cells, the pressure on the deformed surface) from the linear closed form,
of the order of the strain ε = p/(3K) = 1e-4. Asserted on every grid: the
error ≤ 10 ε = 1e-3 against the tied closed form (sphere only). Measured
(docs/theory.md §5c) with 0.5 mm on 8 ... 24 (13 grids): 2.96e-4 ...
7.87e-4, where the tie unrefined gives 0.07-9.1 %; with 0.25 mm 3.0e-4 ...
3.8e-4 on all thirteen; it scales with p (9e-5 at p/10, 3.0e-3 at 10 p on
12³ and 16³): the finite strain's, not the grid's.

Arguments: [--ellipsoid] [--mask] [--tie-refine MM] the grids (default 8 12
16). NH_VERBOSE=1 prints the table.
"""
import csv
import math
import os
import shutil
import struct
import subprocess
import sys
import tempfile

import nibabel as nib
import numpy as np

BIN = os.environ["NH_BINARY"]
VERBOSE = bool(os.environ.get("NH_VERBOSE"))
C = np.array([3.11, -4.73, 2.29]) * 1e-3
R, A_TIE, E, NU, P = 0.03, 0.0015, 3000.0, 0.45, 3.0
DIRS = [(1, 0, 0), (0, -1, 0), (0, 0, 1), (1, 1, 1), (-1, 2, -1), (2, -1, -2), (-1, -1, 1),
        (0, 1, -1)]
RADII = [0.9, 0.75, 0.6, 0.45, 0.8, 0.35, 0.65, 0.5]
failures = []
AXES = np.array([0.030, 0.022, 0.016])


def turn():
    """The rotation by 30° about (1, 2, 3) (Rodrigues)."""
    k = np.array([1.0, 2.0, 3.0]) / math.sqrt(14.0)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    t = math.radians(30.0)
    return np.eye(3) + math.sin(t) * K + (1 - math.cos(t)) * K @ K


def shape(v, ellipsoid):
    """Unit-sphere points to the body's surface (offsets from C, m)."""
    return (turn() @ (AXES * v).T).T if ellipsoid else R * v


def icosphere(levels):
    t = (1 + 5 ** 0.5) / 2
    v = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t),
         (0, 1, -t), (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    v = [np.array(p) / np.linalg.norm(p) for p in v]
    f = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4),
         (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9),
         (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    for _ in range(levels):
        mids, g = {}, []

        def mid(i, j):
            key = (min(i, j), max(i, j))
            if key not in mids:
                m = v[i] + v[j]
                v.append(m / np.linalg.norm(m))
                mids[key] = len(v) - 1
            return mids[key]

        for a, b, c in f:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            g += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        f = g
    return np.array(v), f


def write_stl(path, ellipsoid):
    v, f = icosphere(5)
    x = (C + shape(v, ellipsoid)) * 1e3  # mm
    with open(path, "wb") as out:
        out.write(b"\0" * 80 + struct.pack("<I", len(f)))
        for tri in f:
            out.write(struct.pack("<12fH", 0, 0, 0, *x[tri[0]], *x[tri[1]], *x[tri[2]], 0))


def write_mask(path, ellipsoid, voxel=0.5e-3):
    """The body as a NIfTI label image (nibabel): label 1 where the voxel's
    centre is inside, `voxel` spacing, the sform placing the body at C. The
    tissue is then {χ > 1/2}, χ the trilinear interpolation of the indicator
    (a smoothed staircase, within half a voxel of the smooth surface)."""
    half = (AXES.max() if ellipsoid else R) + 4 * voxel
    n = int(math.ceil(2 * half / voxel))
    lo = C - 0.5 * (n - 1) * voxel
    ax = [lo[k] + np.arange(n) * voxel - C[k] for k in range(3)]
    X = np.stack(np.meshgrid(*ax, indexing="ij"), axis=-1)
    if ellipsoid:  # body frame: turn back, then scale to the unit ball
        X = X @ turn() / AXES
    else:
        X = X / R
    data = (np.einsum("...k,...k", X, X) < 1.0).astype(np.uint8)
    affine = np.diag([voxel * 1e3] * 3 + [1.0])
    affine[:3, 3] = lo * 1e3
    img = nib.Nifti1Image(data, affine)
    img.set_sform(affine, 1)
    img.set_qform(affine, 1)
    img.header.set_xyzt_units("mm")
    nib.save(img, path)


def lame():
    mu = E / (2 * (1 + NU))
    lam = E * NU / ((1 + NU) * (1 - 2 * NU))
    return lam, mu


def tied_radial(r, unbounded=False):
    """f(r) of the ball with the foundation k = 10³ E/a² over r < a (unbounded:
    of an unbounded body whose remote field is the linear one)."""
    lam, mu = lame()
    M, K, k = lam + 2 * mu, lam + 2 * mu / 3, 1e3 * E / A_TIE ** 2
    b = math.sqrt(k / M)
    i1 = lambda x: (x * math.cosh(x) - math.sinh(x)) / x ** 2
    di1 = lambda x: math.sinh(x) / x - 2 * i1(x) / x
    x = b * A_TIE
    mat = np.array([[i1(x), -A_TIE, -1 / A_TIE ** 2],
                    [M * b * di1(x) + 2 * lam * i1(x) / A_TIE, -3 * K, 4 * mu / A_TIE ** 3],
                    [0, 3 * K, -4 * mu / R ** 3] if not unbounded else [0, 1, 0]])
    cc, a, bb = np.linalg.solve(mat, [0, 0, -P if not unbounded else -P / (3 * K)])
    return cc * i1(b * r) if r < A_TIE else a * r + bb / r ** 2


def scene(tmp, ellipsoid, mask):
    probes = []
    for i, (d, s) in enumerate(zip(DIRS, RADII)):
        d = np.array(d, float) / np.linalg.norm(d)
        probes.append("  - {name: p%d, point: [%.12g, %.12g, %.12g]}"
                      % (i, *(C + s * shape(d, ellipsoid))))
    path = os.path.join(tmp, "sphere.yaml")
    with open(path, "w") as out:
        domain = ("mask: {file: sphere.nii.gz, labels: [1]}" if mask
                  else "surface: {file: sphere.stl}")
        out.write(f"""name: sphere-pressure
time: {{mode: static, step: 1.0, steps: 1}}
tissue:
  domain:
    {domain}
  grid: [8, 8, 8]
  cut_cells: integrated
  material: {{young: {E}, poisson: {NU}, density: 1000}}
  fixed:
    - {{sphere: {{center: [{C[0]:.12g}, {C[1]:.12g}, {C[2]:.12g}], radius: {A_TIE}}}}}
  tractions:
    - {{box: {{min: [-1, -1, -1], max: [1, 1, 1]}}, pressure: {P}}}
adapt: {{max_level: 0}}
probes:
""" + "\n".join(probes) + "\n")
    return path


def errors(out, ellipsoid):
    """max over probes of |u_h − u|/|u|: against the tied closed form and
    against the linear field."""
    lam, mu = lame()
    K = lam + 2 * mu / 3
    with open(os.path.join(out, "probes.csv")) as f:
        rows = [r for r in csv.DictReader(f) if r["step"] == "1"]
    if len(rows) != len(DIRS):
        failures.append(f"{out}: {len(rows)} probe rows at step 1, expected {len(DIRS)}")
        return math.nan, math.nan
    tied = lin = 0.0
    for r in rows:
        u = np.array([float(r[k]) for k in ("ux", "uy", "uz")])
        X = np.array([float(r[k]) for k in "xyz"]) - u
        d = X - C
        rr = np.linalg.norm(d)
        exact, linear = tied_radial(rr, ellipsoid) * d / rr, -P * d / (3 * K)
        tied = max(tied, np.linalg.norm(u - exact) / np.linalg.norm(exact))
        lin = max(lin, np.linalg.norm(u - linear) / np.linalg.norm(linear))
    return tied, lin


def main():
    args = sys.argv[1:]
    refine = None
    if "--tie-refine" in args:
        i = args.index("--tie-refine")
        try:
            refine = float(args[i + 1]) * 1e-3
        except (IndexError, ValueError):
            refine = None
        del args[i:i + 2]
    flags = [a for a in args if a.startswith("--")]
    if set(flags) - {"--ellipsoid", "--mask"} or (refine is not None and not refine > 0) or \
            ("--tie-refine" in sys.argv and refine is None):
        print(f"usage: {sys.argv[0]} [--ellipsoid] [--mask] [--tie-refine MM] [GRID ...]",
              file=sys.stderr)
        return 2
    ellipsoid, mask = "--ellipsoid" in flags, "--mask" in flags
    grids = [int(g) for g in args if g not in flags] or [8, 12, 16]
    sets = ["--set", f"tissue.fixed.0.refine={refine!r}"] if refine else []
    tmp = tempfile.mkdtemp(prefix="nh-sphere-")
    try:
        if mask:
            write_mask(os.path.join(tmp, "sphere.nii.gz"), ellipsoid)
        else:
            write_stl(os.path.join(tmp, "sphere.stl"), ellipsoid)
        path = scene(tmp, ellipsoid, mask)
        table = []
        for g in grids:
            out = os.path.join(tmp, f"g{g}")
            subprocess.run([BIN, "run", path, "--quiet", "--overwrite", "--out", out, "--set",
                            f"tissue.grid=[{g},{g},{g}]"] + sets, check=True)
            table.append((g,) + errors(out, ellipsoid))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    g0, e0, _ = table[0]
    for g, tied, lin in table if refine else []:
        if not ellipsoid and not tied <= 10 * P / (3 * (lame()[0] + 2 * lame()[1] / 3)):
            failures.append(f"{g}³, the tie refined to {1e3 * refine:g} mm: error {tied:.3e} "
                            f"against the tied closed form above 10 ε = 1e-3")
    for g, tied, lin in table[1:] if not refine else []:
        if not tied <= e0 * g0 / g:
            failures.append(f"{g}³: error {tied:.3e} against the tied closed form above the "
                            f"order-1 line {e0 * g0 / g:.3e} from {g0}³")
    g, tied, lin = table[-1]
    if g >= 24 and not ellipsoid and not tied <= 0.01:
        failures.append(f"{g}³ (finest): error {tied:.3e} against the tied closed form > 1 %")
    if g >= 24 and not ellipsoid and not lin <= 0.01:
        failures.append(f"{g}³: error {lin:.3e} against the linear field > 1 %")
    if VERBOSE:
        print("grid  error vs tied closed form  vs linear field")
        for g, tied, lin in table:
            print(f"{g:4d}  {tied:.3e}  {lin:.3e}")
        for (ga, ta, la), (gb, tb, lb) in zip(table, table[1:]):
            print(f"order {ga}->{gb}: tied {math.log(ta / tb) / math.log(gb / ga):.2f}, "
                  f"linear {math.log(la / lb) / math.log(gb / ga):.2f}")
        print("tie offset (closed form / linear − 1) at r/R = 0.35, 0.5, 0.9:",
              [f"{tied_radial(s * R) / (-P * s * R / (3 * (lame()[0] + 2 * lame()[1] / 3))) - 1:.2e}"
               for s in (0.35, 0.5, 0.9)])
    for f in failures:
        print("FAIL:", f, file=sys.stderr)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
