#!/usr/bin/python3
"""dbs_mri_outputs.py — the DBS outputs on the patient's images, end to end
(cases/dbs-mri; docs/anatomy.md, "Markups", "Displacement fields and shifted
images"; src/sim/patient.c).

The case's brain shift (0 to 3 s, before the insertion) is run with the
ventricle labels as the warped image and a field time inside the run. Checks:

1. Markups in: the case plans its STN and entry in an LPS .mrk.json; the
   same points written here as a RAS .fcsv give the same scene points, and
   both are the analytic conversion (LPS (x, y, z) mm -> RAS (-x, -y, z) mm
   -> metres), as `check` prints them.
2. The field's header is what ITK reads: 5-D (nx, ny, nz, 1, 3), intent
   vector (1007), float32, the reference's sform and qform (matrices and
   codes); written at the listed time (the step reaching it) and the last
   step; tissue_mask.nii.gz uint8 on the same grid.
3. The field at the STN's rest point, interpolated here from the voxels
   (scipy, trilinear in index space) and turned from LPS mm into RAS m,
   equals the STN's displacement in targets.csv at the same step to 0.1 mm.
4. The warped label image (nearest label) of a ball of 5 mm around the STN:
   only the image's labels, its centroid moved by the STN's displacement in
   targets.csv to half a voxel (1 mm), and at least 99.9 % of the voxels as
   an independent resampler gives them (fixed-point inverse on scipy's
   trilinear interpolation of the written field, nearest label).
5. Markups out: targets.mrk.json holds the STN where targets.csv has it at
   the last step, electrode.mrk.json the electrode's axis ending at the tip
   of tools.csv (RAS mm, to 1e-6 mm).
Silent on success; one line per failure, exit 1.
"""
import csv
import json
import os
import shutil
import subprocess
import sys

import nibabel as nib
import numpy as np
from scipy import ndimage

BIN = sys.argv[1]
CASE = os.path.join(os.environ["NH_SOURCE_DIR"], "cases", "dbs-mri")
WORK = os.path.join(os.environ.get("NH_WORK", "."), "dbs_mri_outputs")
STN_REST_MM = np.array([12.0, -5.0, -10.0])  # the plan's STN (LPS -12, 5, -10) in RAS
failures = []


def check(cond, msg):
    if not cond:
        failures.append(msg)
        print("FAIL:", msg, file=sys.stderr)


def run(*args):
    p = subprocess.run([BIN, *args], capture_output=True, text=True)
    if p.returncode != 0:
        print("FAIL: needlehex %s: exit %d\n%s" % (" ".join(args), p.returncode, p.stderr),
              file=sys.stderr)
        sys.exit(1)
    return p.stdout


def checked_points(scene):
    """{name: [x, y, z]} of the targets as `check` prints them, and the entries."""
    out = run("check", scene)
    points = {}
    for line in out.splitlines():
        line = line.strip()
        if line.startswith("STN at ["):
            points["STN"] = [float(v) for v in line[8:line.index("]")].split(",")]
        if line.startswith("trajectory from entry ["):
            points["entry"] = [float(v) for v in line[23:line.index("]")].split(",")]
    return points


def markups_in():
    """1. The LPS .mrk.json of the case and a RAS .fcsv of the same points."""
    os.makedirs(WORK, exist_ok=True)
    with open(os.path.join(CASE, "plan.mrk.json")) as f:
        plan = json.load(f)["markups"][0]
    check(plan["coordinateSystem"] == "LPS", "the case's plan is not in LPS")
    lps = {p["label"]: np.array(p["position"]) for p in plan["controlPoints"]}
    ras = {k: v * [-1, -1, 1] for k, v in lps.items()}
    folder = os.path.join(WORK, "ras")
    shutil.rmtree(folder, ignore_errors=True)
    shutil.copytree(CASE, folder)
    with open(os.path.join(folder, "plan.fcsv"), "w") as f:
        f.write("# Markups fiducial file version = 4.11\n# CoordinateSystem = RAS\n"
                "# columns = id,x,y,z,ow,ox,oy,oz,vis,sel,lock,label,desc,associatedNodeID\n")
        for i, (label, x) in enumerate(ras.items()):
            f.write("p%d,%r,%r,%r,0,0,0,1,1,1,0,%s,,\n" % (i, x[0], x[1], x[2], label))
    scene = os.path.join(folder, "dbs-mri.yaml")
    with open(scene) as f:
        text = f.read().replace("plan.mrk.json", "plan.fcsv")
    with open(scene, "w") as f:
        f.write(text)
    a = checked_points(os.path.join(CASE, "dbs-mri.yaml"))
    b = checked_points(scene)
    for label in ("STN", "entry"):
        check(label in a and label in b, "check prints no %s point" % label)
        if label in a and label in b:
            expected = ras[label] / 1000
            check(np.allclose(a[label], expected, atol=1e-12, rtol=0)
                  and np.allclose(b[label], expected, atol=1e-12, rtol=0),
                  "%s: LPS .mrk.json %s, RAS .fcsv %s, expected %s m"
                  % (label, a[label], b[label], expected))


def rows(path):
    with open(path) as f:
        return list(csv.DictReader(f))


def field_checks(out, t1):
    """2. and 3."""
    targets = rows(os.path.join(out, "targets.csv"))
    stn = {int(r["step"]): np.array([float(r[k]) for k in "xyz"]) for r in targets
           if r["name"] == "STN"}
    rest = stn[0]
    last = max(stn)
    ijk = np.linalg.solve(t1.affine, np.r_[rest * 1000, 1])[:3]
    mask = nib.load(os.path.join(out, "tissue_mask.nii.gz"))
    check(mask.get_data_dtype() == np.uint8 and mask.shape == t1.shape
          and np.allclose(mask.affine, t1.affine), "tissue_mask.nii.gz: not uint8 on the T1's grid")
    check(np.asanyarray(mask.dataobj)[tuple(np.round(ijk).astype(int))] == 1,
          "tissue_mask.nii.gz: the STN's voxel is not in the tissue")
    for step in (30, last):  # at: [1.5] -> step 30; the last step
        path = os.path.join(out, "displacement_%06d.nii.gz" % step)
        if not os.path.exists(path):
            check(False, "no %s" % os.path.basename(path))
            continue
        img = nib.load(path)
        h = img.header
        check(img.shape == t1.shape + (1, 3), "%s: shape %s" % (path, img.shape))
        check(int(h["intent_code"]) == 1007, "%s: intent %d" % (path, h["intent_code"]))
        check(img.get_data_dtype() == np.float32, "%s: dtype %s" % (path, img.get_data_dtype()))
        for form in ("sform", "qform"):
            m, code = getattr(img, "get_" + form)(coded=True)
            m0, code0 = getattr(t1, "get_" + form)(coded=True)
            check(int(code) == int(code0) and np.allclose(m, m0, atol=1e-6),
                  "%s: %s %s (code %s), the reference's %s (code %s)" % (path, form, m, code,
                                                                       m0, code0))
        d = np.asanyarray(img.dataobj)[:, :, :, 0, :]
        v = np.array([ndimage.map_coordinates(d[..., c], ijk.reshape(3, 1), order=1)[0]
                      for c in range(3)])
        u_field = v * [-1, -1, 1] / 1000
        u_csv = stn[step] - rest
        check(np.linalg.norm(u_field - u_csv) <= 1e-4,
              "step %d: the field at the STN %s m, targets.csv's displacement %s m (tol 0.1 mm)"
              % (step, u_field, u_csv))
    return last, stn[last] - rest


BALL_RADIUS = 5.0  # mm


def ball_image(t1, centre_mm):
    """A label image on the T1's grid: 1 within BALL_RADIUS of centre_mm (RAS)."""
    ijk = np.indices(t1.shape).reshape(3, -1).T
    x = ijk @ t1.affine[:3, :3].T + t1.affine[:3, 3]
    inside = np.linalg.norm(x - centre_mm, axis=1) < BALL_RADIUS
    data = inside.reshape(t1.shape).astype(np.int16)
    path = os.path.join(WORK, "ball.nii.gz")
    nib.save(nib.Nifti1Image(data, t1.affine, t1.header), path)
    return path, data


def resample_independent(labels, affine, field_ras_mm):
    """x -> labels[nearest voxel of X], X + u(X) = x by fixed-point iteration
    on the field's trilinear interpolation (scipy), 50 iterations."""
    inv = np.linalg.inv(affine)
    ijk = np.indices(labels.shape).reshape(3, -1).T.astype(float)
    x = ijk @ affine[:3, :3].T + affine[:3, 3]
    X = x.copy()
    for _ in range(50):
        ij = X @ inv[:3, :3].T + inv[:3, 3]
        u = np.stack([ndimage.map_coordinates(field_ras_mm[..., c], ij.T, order=1, mode="nearest")
                      for c in range(3)], 1)
        X = x - u
    ij = np.rint(X @ inv[:3, :3].T + inv[:3, 3]).astype(int)
    ok = np.all((ij >= 0) & (ij < np.array(labels.shape)), 1)
    out = np.zeros(len(x), labels.dtype)
    out[ok] = labels[ij[ok, 0], ij[ok, 1], ij[ok, 2]]
    return out.reshape(labels.shape)


def warped_checks(out, last, ball, t1, u_stn):
    """4. The ball warped with the tissue: its centroid moved by the STN's
    displacement (targets.csv) to half a voxel (the displacement varies by
    little over 5 mm), and the same labels as an independent resampler."""
    warped = nib.load(os.path.join(out, "warped_%06d.nii.gz" % last))
    w = np.asanyarray(warped.dataobj)
    check(warped.get_data_dtype().kind == "i" and warped.get_data_dtype().itemsize == 2
          and w.shape == ball.shape, "warped: dtype %s shape %s" % (warped.get_data_dtype(),
                                                                     w.shape))
    check(set(np.unique(w)) <= {0, 1}, "warped labels %s, the image's are 0 and 1" % np.unique(w))
    A = t1.affine
    c0 = A[:3, :3] @ np.argwhere(ball == 1).mean(0)
    c1 = A[:3, :3] @ np.argwhere(w == 1).mean(0)
    check(np.linalg.norm((c1 - c0) - u_stn * 1000) <= 1.0,
          "ball: centroid moved %s mm, the STN %s mm (tol half a voxel, 1 mm)"
          % (c1 - c0, u_stn * 1000))
    field = np.asanyarray(nib.load(os.path.join(out, "displacement_%06d.nii.gz" % last))
                          .dataobj)[:, :, :, 0, :] * [-1, -1, 1]  # RAS mm
    agree = (resample_independent(ball, A, field) == w).mean()
    check(agree >= 0.999, "warped ball: %.4f of the voxels as the independent resampler's "
          "(at least 0.999)" % agree)


def markups_out(out, last):
    """5."""
    targets = [r for r in rows(os.path.join(out, "targets.csv")) if int(r["step"]) == last]
    tools = [r for r in rows(os.path.join(out, "tools.csv")) if int(r["step"]) == last]
    with open(os.path.join(out, "targets.mrk.json")) as f:
        doc = json.load(f)["markups"][0]
    check(doc["type"] == "Fiducial" and doc["coordinateSystem"] == "RAS", "targets.mrk.json type")
    for r in targets:
        p = [q for q in doc["controlPoints"] if q["label"] == r["name"]]
        x = np.array([float(r[k]) for k in "xyz"]) * 1000
        check(len(p) == 1 and np.allclose(p[0]["position"], x, atol=1e-6, rtol=0),
              "targets.mrk.json %s: %s, targets.csv %s mm" % (r["name"], p, x))
    for r in tools:
        with open(os.path.join(out, r["name"] + ".mrk.json")) as f:
            doc = json.load(f)["markups"][0]
        tip = np.array([float(r["tip_" + k]) for k in "xyz"]) * 1000
        end = np.array(doc["controlPoints"][-1]["position"])
        check(doc["type"] == "Curve" and np.allclose(end, tip, atol=1e-6, rtol=0),
              "%s.mrk.json: %s ends at %s, tools.csv's tip %s mm" % (r["name"], doc["type"],
                                                                     end, tip))


def main():
    markups_in()
    t1 = nib.load(os.path.join(CASE, "t1.nii.gz"))
    ball_path, ball = ball_image(t1, STN_REST_MM)
    out = os.path.join(WORK, "run")
    run("run", os.path.join(CASE, "dbs-mri.yaml"), "--out", out, "--overwrite", "--quiet",
        "--set", "time.end=3.0", "--set", "output.every=0",
        "--set", "output.displacement_field.at=[1.5]",
        "--set", "output.warped.image=" + ball_path, "--set", "output.warped.at=[]")
    last, u_stn = field_checks(out, t1)
    warped_checks(out, last, ball, t1, u_stn)
    markups_out(out, last)
    sys.exit(1 if failures else 0)


main()
