#!/usr/bin/python3
"""nifti_field.py — the displacement field on the patient's image as ITK,
ANTs and elastix read it (src/io/nifti.c, src/mesh/sample.c;
docs/anatomy.md, "Displacement fields and shifted images").

A displacement of closed form, u(X) = t + eps exp(-|X - c|^2 / sigma^2) e
(RAS, metres: a rigid translation of 2.6 mm and a bump of 0.8 mm), is given
at the nodes of a box mesh (2 mm cells, its first cell refined once: hanging
nodes), sampled by the library on a reference image's voxel centres (1 mm)
and written by tests/nifti_field_tool. Checks:

1. Header, read with nibabel: intent code 1007, shape (nx, ny, nz, 1, 3),
   float32, sform and qform (matrices and codes) and pixdim equal to the
   reference's, units mm; the mask: uint8, same geometry, 1 exactly at the
   voxel centres in the mesh's box.
2. Values: at voxel centres on mesh nodes the field is the closed form in
   LPS mm, (-u_x, -u_y, u_z) * 1000, to float32 round-off; at the other
   centres outside the refined cell it is the trilinear interpolant of the
   nodal values, computed here independently, to round-off; 0 outside the
   mesh.
3. The same grid stored flipped along i (negative x spacing in the sform, as
   nibabel's anatomical.nii), rotated (oblique, sform code 2 and qform code
   1) and in metres (xyz_units m) gives the same physical field.
4. Round trip with an independent resampler, following ITK's convention (for
   an output point p in physical LPS the input is sampled at p + d(p)): a
   ball of label 1 (radius 5 mm), resampled with scipy.ndimage.map_coordinates
   (linear) on nibabel's affines, has its intensity centroid moved as the
   closed form moves it: the centroid of {p : |p + u(p) - b| < R} minus b
   (b, R the ball's centre and radius; on a 0.1 mm grid), about -u; to a
   tenth of a voxel (0.1 mm; half a voxel would let an error of half a voxel
   in the grid's origin through). The same with the flipped
   grid (to 1e-9 mm of the first), the oblique one, and with elastix's transformix
   (DeformationFieldTransform, the parameter file written by
   tools/transformix_params.py): the image, and points, which transformix maps
   p -> p + d(p) (to 1e-3 mm at mesh nodes).
5. The scalar writer keeps the reference's type and scaling (int16 with
   scl_slope 2, scl_inter 10: the same values) or writes float32; a write
   into a missing folder, or on a reference whose file changed since it was
   read, fails with NH_ERR_IO and the path named, nothing on stderr (libnifti2
   silent), no file left behind.
Silent on success; one line per failure, exit 1.
"""
import os
import re
import shutil
import subprocess
import sys

import nibabel as nib
import numpy as np
from scipy import ndimage

TOOL = sys.argv[1]
PARAMS = os.path.join(os.environ["NH_SOURCE_DIR"], "tools", "transformix_params.py")
WORK = os.path.join(os.environ.get("NH_WORK", "."), "nifti_field")
failures = []


def check(cond, msg):
    if not cond:
        failures.append(msg)
        print("FAIL:", msg, file=sys.stderr)


# the closed form (RAS, metres) and the mesh
T = np.array([1.3e-3, -2.1e-3, 0.9e-3])  # not half voxels: no rounding ties
EPS, SIGMA = 0.8e-3, 6e-3
C = np.array([3e-3, 0.0, 1e-3])
E = np.array([0.6, 0.0, 0.8])
LO, HI, GRID = np.array([-0.014, -0.012, -0.010]), np.array([0.014, 0.012, 0.012]), (14, 12, 11)
SHAPE = (40, 36, 32)
ORIGIN = np.array([-20.0, -18.0, -16.0])  # mm, voxel (0, 0, 0)
BALL, RADIUS = np.array([2.0, 1.0, 0.0]), 5.0  # mm
LPS = np.array([-1.0, -1.0, 1.0])
# the ball's centroid after resampling: a tenth of a voxel (half a voxel would
# let a half-voxel error of the grid's origin through; measured: 0.02 mm)
TOL_SHIFT = 0.1


def u_closed(X):
    """u at RAS points X (..., 3) in metres."""
    g = EPS * np.exp(-np.sum((X - C) ** 2, axis=-1) / SIGMA**2)
    return T + g[..., None] * E


def grid_points(aff, shape):
    """RAS mm of every voxel centre, (nx, ny, nz, 3)."""
    ijk = np.stack(np.meshgrid(*[np.arange(n) for n in shape], indexing="ij"), axis=-1)
    return ijk @ aff[:3, :3].T + aff[:3, 3]


def save_reference(name, aff, data=None, units="mm", sform_code=1, qform_code=1):
    data = np.zeros(SHAPE, np.int16) if data is None else data
    img = nib.Nifti1Image(data, aff)
    img.set_sform(aff, code=sform_code)
    img.set_qform(aff, code=qform_code)
    img.header.set_xyzt_units(units)
    path = os.path.join(WORK, name)
    nib.save(img, path)
    return path


def run_field(ref, out):
    os.makedirs(out, exist_ok=True)
    args = [TOOL, "field", ref, out] + ["%.17g" % v for v in LO] + ["%.17g" % v for v in HI]
    args += [str(g) for g in GRID] + ["%.17g" % v for v in T] + ["%.17g" % EPS]
    args += ["%.17g" % v for v in C] + ["%.17g" % SIGMA] + ["%.17g" % v for v in E]
    p = subprocess.run(args, capture_output=True, text=True)
    check(p.returncode == 0 and p.stderr == "", "field %s: exit %d: %s" % (ref, p.returncode, p.stderr))
    return nib.load(os.path.join(out, "displacement.nii.gz")), nib.load(os.path.join(out, "tissue_mask.nii.gz"))


def check_header(tag, img, mask, ref):
    rh, h = ref.header, img.header
    check(int(h["intent_code"]) == 1007, "%s: intent code %d, expected 1007" % (tag, h["intent_code"]))
    check(img.shape == SHAPE + (1, 3), "%s: shape %s" % (tag, img.shape))
    check(int(h["dim"][0]) == 5, "%s: dim[0] = %d" % (tag, h["dim"][0]))
    check(img.get_data_dtype() == np.float32, "%s: dtype %s" % (tag, img.get_data_dtype()))
    check(h.get_xyzt_units()[0] == "mm", "%s: units %s" % (tag, h.get_xyzt_units()))
    scale = 1000.0 if rh.get_xyzt_units()[0] == "meter" else 1.0
    for m in ("sform", "qform"):
        ra, rc = getattr(rh, "get_" + m)(coded=True)
        a, c = getattr(h, "get_" + m)(coded=True)
        check(int(c) == int(rc), "%s: %s code %d, reference %d" % (tag, m, c, rc))
        want = ra.copy()
        want[:3, :] *= scale
        check(np.allclose(a, want, rtol=0, atol=1e-5), "%s: %s\n%s\nreference\n%s" % (tag, m, a, want))
    check(np.allclose(h["pixdim"][1:4], rh["pixdim"][1:4] * scale, rtol=1e-6), "%s: pixdim %s" % (tag, h["pixdim"]))
    check(np.array_equal(mask.affine, img.affine) and mask.get_data_dtype() == np.uint8
          and mask.shape == SHAPE, "%s: mask geometry" % tag)


def check_values(tag, img, mask, aff, nodes=True):
    d = np.asarray(img.dataobj)[:, :, :, 0, :]  # LPS mm
    x = grid_points(aff, SHAPE) * 1e-3  # RAS m
    inside = np.all((x >= LO - 1e-12) & (x <= HI + 1e-12), axis=-1)
    m = np.asarray(mask.dataobj)
    check(np.array_equal(m.astype(bool), inside), "%s: mask differs at %d voxels" % (tag, np.sum(m.astype(bool) != inside)))
    check(np.all(d[~inside] == 0), "%s: nonzero outside the mesh" % tag)
    want = u_closed(x) * 1e3 * LPS
    # voxel centres on mesh nodes: the closed form
    h = (HI - LO) / np.array(GRID)
    s = (x - LO) / h
    on_node = inside & np.all(np.abs(s - np.round(s)) < 1e-9, axis=-1)
    err = np.max(np.abs(d[on_node] - want[on_node]))
    check(on_node.sum() > (1000 if nodes else 0) and err < 1e-6,
          "%s: at %d nodes |d - closed form| = %.3g mm" % (tag, on_node.sum(), err))
    # elsewhere, outside the refined cell: the trilinear interpolant of the nodes
    q = np.clip(np.floor(s).astype(int), 0, np.array(GRID) - 1)
    w = s - q
    coarse = inside & ~np.all(q == 0, axis=-1)
    interp = np.zeros(x.shape)
    for corner in range(8):
        b = np.array([(corner >> a) & 1 for a in range(3)])
        node = LO + (q + b) * h
        wt = np.prod(np.where(b == 1, w, 1 - w), axis=-1)
        interp += wt[..., None] * u_closed(node)
    err = np.max(np.abs(d[coarse] - interp[coarse] * 1e3 * LPS))
    check(err < 1e-6, "%s: |d - trilinear interpolant| = %.3g mm" % (tag, err))
    return d


def ball_image(aff):
    x = grid_points(aff, SHAPE)
    return (np.sum((x - BALL) ** 2, axis=-1) < RADIUS**2).astype(np.int16)


def centroid(image, aff):
    """The intensity-weighted centroid (RAS mm)."""
    w = np.asarray(image, float)
    idx = np.stack(np.meshgrid(*[np.arange(n) for n in w.shape], indexing="ij"), axis=-1)
    c = np.sum(idx * w[..., None], axis=(0, 1, 2)) / np.sum(w)
    return aff[:3, :3] @ c + aff[:3, 3]


def resample_itk(moving, aff_moving, field_lps, aff_out):
    """ITK's convention: out(p) = moving(p + d(p)), p and d in physical LPS."""
    p_ras = grid_points(aff_out, SHAPE)
    q_ras = (p_ras * LPS + field_lps) * LPS
    idx = (q_ras - aff_moving[:3, 3]) @ np.linalg.inv(aff_moving[:3, :3]).T
    coords = np.moveaxis(idx, -1, 0)
    return ndimage.map_coordinates(moving.astype(float), coords, order=1, mode="constant", cval=0)


def expected_shift():
    """The centroid of {p : |p + u(p) - b| < R} (the ball the field's
    convention gives, from the closed form on a 0.1 mm grid) minus b."""
    s = np.arange(-1.6 * RADIUS, 1.6 * RADIUS, 0.1) + 0.05
    p = np.stack(np.meshgrid(s, s, s, indexing="ij"), axis=-1) + BALL - T * 1e3
    inside = np.sum((p + u_closed(p * 1e-3) * 1e3 - BALL) ** 2, axis=-1) < RADIUS**2
    return p[inside].mean(axis=0) - BALL


def transformix(field_path, aff, out, points=True):
    tx = shutil.which("transformix")
    check(tx is not None, "transformix is not installed (Debian package elastix: tools/install-deps.sh)")
    if tx is None:
        return None, None
    os.makedirs(out, exist_ok=True)
    params = os.path.join(out, "field.txt")
    p = subprocess.run([sys.executable, PARAMS, field_path, "--out", params],
                       capture_output=True, text=True)
    check(p.returncode == 0, "transformix_params.py: %s" % p.stderr)
    ball = os.path.join(out, "ball.nii.gz")
    save_reference(os.path.relpath(ball, WORK), aff, ball_image(aff))
    p = subprocess.run([tx, "-in", ball, "-out", out, "-tp", params], capture_output=True, text=True)
    check(p.returncode == 0, "transformix -in: exit %d: %s" % (p.returncode, p.stdout[-2000:]))
    image = nib.load(os.path.join(out, "result.nii.gz")) if p.returncode == 0 else None
    # points at voxel centres on mesh nodes (of the plain and flipped grids),
    # in physical LPS mm
    pts_ras = np.array([[2.0, 2.0, 0.0], [-4.0, 6.0, 4.0], [10.0, -8.0, -6.0]])
    with open(os.path.join(out, "points.txt"), "w") as f:
        f.write("point\n%d\n" % len(pts_ras))
        for q in pts_ras * LPS:
            f.write("%.17g %.17g %.17g\n" % tuple(q))
    p = subprocess.run([tx, "-def", os.path.join(out, "points.txt"), "-out", out, "-tp", params],
                       capture_output=True, text=True)
    check(p.returncode == 0, "transformix -def: exit %d: %s" % (p.returncode, p.stdout[-2000:]))
    moved = None
    if p.returncode == 0 and points:
        text = open(os.path.join(out, "outputpoints.txt")).read()
        moved = np.array([[float(v) for v in m.split()] for m in re.findall(r"OutputPoint = \[([^\]]*)\]", text)])
        want = pts_ras * LPS + u_closed(pts_ras * 1e-3) * 1e3 * LPS
        check(moved.shape == want.shape and np.max(np.abs(moved - want)) < 1e-3,
              "transformix points: %s, expected p + d(p) = %s" % (moved, want))
    return image, moved


def scalar_writer():
    aff = np.diag([1.0, 1.0, 1.0, 1.0])
    aff[:3, 3] = ORIGIN
    rng = np.random.default_rng(3)
    stored = rng.integers(-3000, 3000, SHAPE).astype(np.int16)
    img = nib.Nifti1Image(stored, aff)
    img.header.set_data_dtype(np.int16)
    ref = os.path.join(WORK, "t1_scaled.nii")
    nib.save(img, ref)
    # nibabel chooses its own scaling on save: set scl_slope, scl_inter
    # (bytes 112-119 of the header) in the file itself
    with open(ref, "r+b") as f:
        f.seek(112)
        f.write(np.array([2.0, 10.0], np.float32).tobytes())
    values = nib.load(ref).get_fdata()
    for mode, dtype in (("same", np.int16), ("float", np.float32)):
        out = os.path.join(WORK, "scalar_%s.nii.gz" % mode)
        p = subprocess.run([TOOL, "scalar", ref, out] + (["float"] if mode == "float" else []),
                           capture_output=True, text=True)
        check(p.returncode == 0 and p.stderr == "", "scalar %s: %s" % (mode, p.stderr))
        if p.returncode:
            continue
        back = nib.load(out)
        check(back.get_data_dtype() == dtype, "scalar %s: dtype %s" % (mode, back.get_data_dtype()))
        check(np.array_equal(back.get_fdata(), values), "scalar %s: values differ" % mode)
        check(np.allclose(back.affine, nib.load(ref).affine), "scalar %s: affine" % mode)
        # nibabel moves a loaded image's scaling from the header to its dataobj
        slope, inter = float(back.dataobj.slope), float(back.dataobj.inter)
        want = (2.0, 10.0) if mode == "same" else (1.0, 0.0)
        check((slope, inter) == want, "scalar %s: slope, inter %s %s, expected %s" % (mode, slope, inter, want))
    # a write that cannot happen
    missing = os.path.join(WORK, "no", "such", "folder", "displacement.nii.gz")
    p = subprocess.run([TOOL, "fail", ref, missing], capture_output=True, text=True)
    check(p.returncode == 3 and missing in p.stdout and p.stderr == "",
          "write to a missing folder: exit %d, stdout %r, stderr %r" % (p.returncode, p.stdout, p.stderr))
    check(not os.path.exists(os.path.dirname(missing)), "a folder was created")
    # a reference whose file changed size since it was read
    out = os.path.join(WORK, "changed.nii.gz")
    small = os.path.join(WORK, "ref_small.nii.gz")
    nib.save(nib.Nifti1Image(np.zeros((5, 5, 5), np.int16), aff), small)
    p = subprocess.run([TOOL, "fail", ref, out, small],
                       capture_output=True, text=True)
    check(p.returncode == 3 and "changed since it was read" in p.stdout and out in p.stdout
          and p.stderr == "" and not os.path.exists(out) and not os.path.exists(out + ".tmp"),
          "changed reference: exit %d, stdout %r, stderr %r" % (p.returncode, p.stdout, p.stderr))


def main():
    shutil.rmtree(WORK, ignore_errors=True)
    os.makedirs(WORK)
    aff = np.diag([1.0, 1.0, 1.0, 1.0])
    aff[:3, 3] = ORIGIN
    # the same grid flipped along i: voxel i is voxel n - 1 - i of the first
    flip = aff.copy()
    flip[0, 0] = -1.0
    flip[0, 3] = ORIGIN[0] + SHAPE[0] - 1
    # oblique: rotated about z by 10 degrees around the centre, so the grid's
    # points differ from the first (compared through the closed form only)
    a = np.radians(10.0)
    rot = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1.0]])
    oblique = np.eye(4)
    oblique[:3, :3] = rot
    oblique[:3, 3] = rot @ ORIGIN
    # in metres: a grid whose numbers float32 holds exactly (1/1024 m voxels)
    metres = np.diag([1 / 1024.0, 1 / 1024.0, 1 / 1024.0, 1.0])
    metres[:3, 3] = ORIGIN / 1024.0
    refs = {"plain": (aff, save_reference("ref.nii.gz", aff)),
            "flipped": (flip, save_reference("ref_flipped.nii.gz", flip)),
            "oblique": (oblique, save_reference("ref_oblique.nii.gz", oblique, sform_code=2, qform_code=1)),
            "metres": (metres * [[1e3], [1e3], [1e3], [1]], save_reference("ref_m.nii.gz", metres, units="meter"))}
    fields = {}
    for tag, (a_mm, path) in refs.items():
        img, mask = run_field(path, os.path.join(WORK, tag))
        check_header(tag, img, mask, nib.load(path))
        fields[tag] = (img, check_values(tag, img, mask, a_mm, nodes=tag in ("plain", "flipped")))
    d_plain, d_flip = fields["plain"][1], fields["flipped"][1]
    check(np.max(np.abs(d_flip[::-1] - d_plain)) < 1e-6, "flipped reference: a different physical field")

    # round trip: the ball moves by the solution of p + u(p) = b
    shift = expected_shift()
    check(np.linalg.norm(shift + T * 1e3) < 1.0, "expected shift %s is about -t" % shift)
    ball = ball_image(aff)
    out = resample_itk(ball, aff, d_plain, aff)
    moved = centroid(out, aff) - centroid(ball, aff)
    check(np.linalg.norm(moved - shift) < TOL_SHIFT, "ball moved by %s mm, expected %s (tolerance %g mm)" % (moved, shift, TOL_SHIFT))
    ball_f = ball_image(flip)
    out_f = resample_itk(ball_f, flip, d_flip, flip)
    moved_f = centroid(out_f, flip) - centroid(ball_f, flip)
    check(np.linalg.norm(moved_f - moved) < 1e-9, "flipped grid: ball moved by %s, plain %s" % (moved_f, moved))
    ball_o = ball_image(oblique)
    out_o = resample_itk(ball_o, oblique, fields["oblique"][1], oblique)
    moved_o = centroid(out_o, oblique) - centroid(ball_o, oblique)
    check(np.linalg.norm(moved_o - shift) < TOL_SHIFT, "oblique grid: ball moved by %s mm, expected %s" % (moved_o, shift))
    for tag, a_mm in (("plain", aff), ("flipped", flip), ("oblique", oblique)):
        image, _ = transformix(os.path.join(WORK, tag, "displacement.nii.gz"), a_mm, os.path.join(WORK, "tx_" + tag),
                               points=tag != "oblique")
        if image is not None:
            res = np.asarray(image.dataobj)
            moved_t = centroid(res, image.affine) - centroid(ball_image(a_mm), a_mm)
            check(np.linalg.norm(moved_t - shift) < TOL_SHIFT,
                  "transformix (%s): ball moved by %s mm, expected %s" % (tag, moved_t, shift))
            check(np.allclose(image.affine, a_mm, atol=1e-4), "transformix (%s): output affine\n%s" % (tag, image.affine))
            if os.environ.get("NH_TEST_VERBOSE"):
                print("transformix (%s): ball moved by %s mm" % (tag, moved_t))
    scalar_writer()
    if os.environ.get("NH_TEST_VERBOSE"):
        print("expected shift %s mm, measured %s (scipy), %s (scipy, oblique grid)" % (shift, moved, moved_o))
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
