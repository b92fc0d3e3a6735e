#!/usr/bin/python3
"""Pictures and numbers of the MRI-based DBS case for docs/anatomy.md.

    tools/plot_anatomy.py RUN_DIR [--out docs/img] [--frames 0,60,270]

RUN_DIR is the output of `needlehex run cases/dbs-mri/dbs-mri.yaml --out RUN_DIR`.
Writes to --out:
- anatomy_slices.png: the T1 image (nibabel's anatomical.nii) in an axial
  and a sagittal slice, with the ventricle labels of
  cases/dbs-mri/ventricles.nii.gz outlined;
- anatomy_mesh.png: the mesh at t = 0 cut by the same two planes, each cell
  coloured by its Young's modulus (the `young` cell field: mixed cells take
  the volume average of λ and μ);
- anatomy_shift.png: the ventricles' outline in both planes at rest and
  deformed by the computed displacement at the listed frames (brain shift
  done at t = 3 s, end of the procedure), the displacement interpolated
  trilinearly in the leaf of the tissue VTU's rest mesh that holds the point.
- anatomy_warped.png: a coronal slice of the T1 through the STN before the
  shift and the run's warped T1 (warped_<last>.nii.gz) after it, the
  electrode's final axis (electrode.mrk.json, projected) and the STN
  (targets.mrk.json) drawn on the second, the planned STN on both.
Prints, per frame, the mean and the spread of the ventricle voxels'
displacement (spread = the largest distance of a voxel's displacement from
the mean: what deformation, not translation, does to them).
Needs numpy, matplotlib, nibabel and vtk (Debian's python3-vtk9).
"""
import argparse
import os

import nibabel as nib
import numpy as np
from matplotlib.collections import PolyCollection
from vtkmodules.util.numpy_support import numpy_to_vtk, vtk_to_numpy
from vtkmodules.vtkCommonCore import vtkPoints
from vtkmodules.vtkIOXML import vtkXMLUnstructuredGridReader

from outputs import read_steps
from plotstyle import plt, save

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
T1 = os.path.join(os.path.dirname(nib.__file__), "tests", "data", "anatomical.nii")
LABELS = os.path.join(ROOT, "cases", "dbs-mri", "ventricles.nii.gz")
AXIAL_K, SAGITTAL_I = 16, 9  # z = 16 mm; x = 14 mm (right lateral ventricle)


def read_frame(run, step):
    """Rest mesh (vtkUnstructuredGrid with `displacement`) of tissue_<step>.vtu."""
    r = vtkXMLUnstructuredGridReader()
    r.SetFileName(os.path.join(run, f"tissue_{step:06d}.vtu"))
    r.Update()
    g = r.GetOutput()
    x = vtk_to_numpy(g.GetPoints().GetData())
    u = vtk_to_numpy(g.GetPointData().GetArray("displacement"))
    rest = vtkPoints()
    rest.SetData(numpy_to_vtk(np.ascontiguousarray(x - u), deep=True))
    g.SetPoints(rest)
    return g


def probe(grid, points):
    """Displacement at rest positions points[n, 3]: trilinear in the leaf
    containing each point (every rest cell is an axis-aligned box, VTK
    order: corner 0 at the low end, 6 at the high end); NaN outside."""
    x = vtk_to_numpy(grid.GetPoints().GetData())
    u = vtk_to_numpy(grid.GetPointData().GetArray("displacement"))
    conn = vtk_to_numpy(grid.GetCells().GetConnectivityArray()).reshape(-1, 8)
    lo, hi = x[conn[:, 0]], x[conn[:, 6]]
    corner = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                       [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]])
    out = np.full((len(points), 3), np.nan)
    for n, p in enumerate(np.asarray(points, dtype=float)):
        inside = np.nonzero(np.all((lo <= p + 1e-12) & (p <= hi + 1e-12), axis=1))[0]
        if len(inside) == 0:
            continue
        c = inside[0]
        t = (p - lo[c]) / (hi[c] - lo[c])
        w = np.prod(np.where(corner == 1, t, 1 - t), axis=1)
        out[n] = w @ u[conn[c]]
    return out


def world(img, ijk):
    return (img.affine[:3, :3] @ np.asarray(ijk, dtype=float).T).T + img.affine[:3, 3]


def slice_extent(img, plane):
    """imshow extent (mm) of the axial or sagittal slice: the world coordinate
    of the first and last voxel edges along each of its axes (the sform's
    negative x spacing makes the axial x run from right to left)."""
    n = img.shape
    first, last = world(img, [-0.5, -0.5, -0.5]), world(img, [n[0] - 0.5, n[1] - 0.5, n[2] - 0.5])
    if plane == "axial":
        return [first[0], last[0], first[1], last[1]]
    return [first[1], last[1], first[2], last[2]]


def slice_of(data, plane):
    return data[:, :, AXIAL_K].T if plane == "axial" else data[SAGITTAL_I, :, :].T


def outline_points(img, labels, plane):
    """Rest positions (m) of the ventricles' outline in the slice, as lists of paths."""
    mask = slice_of((labels > 0).astype(float), plane)
    ext = slice_extent(img, plane)
    ny, nx = mask.shape
    hs = np.linspace(ext[0], ext[1], nx, endpoint=False) + (ext[1] - ext[0]) / (2 * nx)
    vs = np.linspace(ext[2], ext[3], ny, endpoint=False) + (ext[3] - ext[2]) / (2 * ny)
    cs = plt.figure().add_subplot().contour(hs, vs, mask, levels=[0.5])
    paths = [np.asarray(p) for p in cs.allsegs[0]]
    plt.close("all")
    out = []
    for v in paths:
        if plane == "axial":
            p = np.column_stack([v[:, 0], v[:, 1], np.full(len(v), world(img, [0, 0, AXIAL_K])[2])])
        else:
            p = np.column_stack([np.full(len(v), world(img, [SAGITTAL_I, 0, 0])[0]), v[:, 0], v[:, 1]])
        out.append(p * 1e-3)
    return out


def plot_slices(img, labels, out):
    t1 = np.asarray(img.dataobj, dtype=float)
    fig, axes = plt.subplots(1, 2, figsize=(10, 5))
    for ax, plane in zip(axes, ("axial", "sagittal")):
        ax.imshow(slice_of(t1, plane), origin="lower", cmap="gray", extent=slice_extent(img, plane))
        lab = slice_of(labels, plane)
        ext = slice_extent(img, plane)
        ny, nx = lab.shape
        hs = np.linspace(ext[0], ext[1], nx, endpoint=False) + (ext[1] - ext[0]) / (2 * nx)
        vs = np.linspace(ext[2], ext[3], ny, endpoint=False) + (ext[3] - ext[2]) / (2 * ny)
        for value, colour in ((4, "tab:orange"), (43, "tab:cyan")):
            if (lab == value).any():
                ax.contour(hs, vs, (lab == value).astype(float), levels=[0.5], colors=colour)
        if plane == "axial":
            ax.set(xlabel="x (mm, right +)", ylabel="y (mm, anterior +)",
                   title=f"axial, z = {world(img, [0, 0, AXIAL_K])[2]:.0f} mm")
        else:
            ax.set(xlabel="y (mm, anterior +)", ylabel="z (mm, superior +)",
                   title=f"sagittal, x = {world(img, [SAGITTAL_I, 0, 0])[0]:.0f} mm")
    fig.suptitle("anatomical.nii (T1) with the lateral ventricles: label 4 (orange), 43 (cyan)")
    save(fig, os.path.join(out, "anatomy_slices.png"))


def plot_mesh(img, grid, out):
    """Cells cut by the two planes, coloured by `young`."""
    x = vtk_to_numpy(grid.GetPoints().GetData())
    young = vtk_to_numpy(grid.GetCellData().GetArray("young"))
    conn = vtk_to_numpy(grid.GetCells().GetConnectivityArray()).reshape(-1, 8)
    fig, axes = plt.subplots(1, 2, figsize=(11, 5))
    z0 = world(img, [0, 0, AXIAL_K])[2] * 1e-3
    x0 = world(img, [SAGITTAL_I, 0, 0])[0] * 1e-3
    for ax, (axis, value, h, v) in zip(axes, ((2, z0, 0, 1), (0, x0, 1, 2))):
        polys, colours = [], []
        for c, nodes in enumerate(conn):
            p = x[nodes]
            if not p[:, axis].min() <= value < p[:, axis].max():
                continue
            lo, hi = p.min(axis=0) * 1e3, p.max(axis=0) * 1e3
            polys.append([(lo[h], lo[v]), (hi[h], lo[v]), (hi[h], hi[v]), (lo[h], hi[v])])
            colours.append(young[c])
        pc = PolyCollection(polys, array=np.array(colours), cmap="viridis", edgecolors="k",
                            linewidths=0.3)
        ax.add_collection(pc)
        ax.autoscale()
        ax.set_aspect("equal")
        fig.colorbar(pc, ax=ax, label="young (Pa)", shrink=0.8)
        ext = slice_extent(img, "axial" if axis == 2 else "sagittal")
        ax.add_patch(plt.Rectangle((min(ext[0], ext[1]), ext[2]), abs(ext[1] - ext[0]),
                                   ext[3] - ext[2], fill=False, ls="--", ec="r"))
        if axis == 2:
            ax.set(xlabel="x (mm)", ylabel="y (mm)", title=f"cells cut by z = {z0 * 1e3:.0f} mm")
        else:
            ax.set(xlabel="y (mm)", ylabel="z (mm)", title=f"cells cut by x = {x0 * 1e3:.0f} mm")
    fig.suptitle("dbs-mri mesh at t = 0 (red dashes: the image's extent)")
    save(fig, os.path.join(out, "anatomy_mesh.png"))


def plot_shift(img, labels, run, frames, out):
    fig, axes = plt.subplots(1, 2, figsize=(11, 5))
    styles = ["k-", "tab:red", "tab:blue", "tab:green"]
    ijk = np.argwhere(labels > 0)
    voxels = world(img, ijk) * 1e-3
    print("| frame | t (s) | mean displacement of the ventricle voxels (mm) | spread (mm) |")
    print("|---|---|---|---|")
    st = read_steps(run)
    times = {int(s): float(t) for s, t in zip(st["step"], st["time"])}
    for n, step in enumerate(frames):
        grid = read_frame(run, step)
        u = probe(grid, voxels)
        missing = int(np.isnan(u[:, 0]).sum())
        if missing:
            raise SystemExit(f"{missing} ventricle voxels lie outside the mesh of frame {step}")
        mean = u.mean(axis=0)
        spread = np.linalg.norm(u - mean, axis=1).max()
        print(f"| {step} | {times.get(step, 0.0):.2f} | [{mean[0] * 1e3:.2f}, {mean[1] * 1e3:.2f}, "
              f"{mean[2] * 1e3:.2f}] | {spread * 1e3:.2f} |")
        for ax, plane in zip(axes, ("axial", "sagittal")):
            for k, path in enumerate(outline_points(img, labels, plane)):
                d = probe(grid, path)
                p = (path + d) * 1e3
                h, v = (0, 1) if plane == "axial" else (1, 2)
                label = f"t = {times.get(step, 0.0):.2f} s" if k == 0 else None
                kw = {"color": styles[n % len(styles)][-8:]} if n else {"color": "k"}
                # earlier frames wider, so that a later one drawn over them leaves them visible
                lw = 1.2 if n in (0, len(frames) - 1) else 3.0
                ax.plot(p[:, h], p[:, v], "-" if n else "--", lw=lw, label=label, **kw)
    for ax, plane in zip(axes, ("axial", "sagittal")):
        ax.set_aspect("equal")
        if plane == "axial":
            ax.set(xlabel="x (mm)", ylabel="y (mm)", title="ventricles, axial plane (rest z)")
            ax.invert_xaxis()
        else:
            ax.set(xlabel="y (mm)", ylabel="z (mm)", title="right ventricle, sagittal plane")
    fig.suptitle("lateral ventricles at rest (dashed) and deformed by the brain shift "
                 "(gravity -y)")
    fig.tight_layout()
    handles, labels = axes[0].get_legend_handles_labels()  # one legend, below the plots
    fig.legend(handles, labels, fontsize=9, loc="upper center", ncol=len(labels),
               bbox_to_anchor=(0.5, 0.02), frameon=False)
    save(fig, os.path.join(out, "anatomy_shift.png"), layout=False)


def markups_points(path):
    """Control points (RAS mm) of the one markup of a .mrk.json we write."""
    import json
    with open(path) as f:
        markup = json.load(f)["markups"][0]
    return np.array([p["position"] for p in markup["controlPoints"]])


def plot_warped(img, run, out):
    """The T1 before and after the shift in the coronal plane through the STN."""
    warped = sorted(f for f in os.listdir(run) if f.startswith("warped_"))
    if not warped:
        raise SystemExit(f"{run}: no warped_*.nii.gz (the case's output.warped)")
    after = nib.load(os.path.join(run, warped[-1]))
    stn = markups_points(os.path.join(run, "targets.mrk.json"))[0]
    electrode = markups_points(os.path.join(run, "electrode.mrk.json"))
    planned = np.array([12.0, -5.0, -10.0])  # cases/dbs-mri/plan.mrk.json, RAS mm
    j = int(round(np.linalg.solve(img.affine, np.r_[planned, 1])[1]))
    n = img.shape
    first, last = world(img, [-0.5, j, -0.5]), world(img, [n[0] - 0.5, j, n[2] - 0.5])
    extent = [first[0], last[0], first[2], last[2]]
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.6))
    for ax, image, title in ((axes[0], img, "T1 before the shift"),
                             (axes[1], after, f"{warped[-1]}: shifted with the tissue")):
        data = np.asarray(image.dataobj, dtype=float)[:, j, :].T
        ax.imshow(data, origin="lower", cmap="gray", extent=extent)
        ax.plot(planned[0], planned[2], "o", mfc="none", mec="tab:orange", ms=9, label="STN planned")
        ax.set(xlabel="x (mm, right +)", ylabel="z (mm, superior +)",
               title=f"{title}, y = {world(img, [0, j, 0])[1]:.0f} mm")
        ax.set_xlim(extent[0], extent[1]), ax.set_ylim(extent[2], extent[3])
    axes[1].plot(electrode[:, 0], electrode[:, 2], "-", color="tab:red", lw=2,
                 label="electrode (final, projected)")
    axes[1].plot(stn[0], stn[2], "x", color="tab:cyan", ms=9, mew=2, label="STN after the shift")
    handles, labels = axes[1].get_legend_handles_labels()
    fig.legend(handles, labels, fontsize=9, loc="upper center", ncol=3,
               bbox_to_anchor=(0.5, 0.02), frameon=False)
    save(fig, os.path.join(out, "anatomy_warped.png"), layout=False)
    print(f"STN moved {np.round(stn - planned, 2)} mm (targets.mrk.json)")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("run")
    ap.add_argument("--out", default=os.path.join(ROOT, "docs", "img"))
    ap.add_argument("--frames", default="0,60,270")
    args = ap.parse_args()
    img, labels = nib.load(T1), np.asarray(nib.load(LABELS).dataobj)
    frames = [int(f) for f in args.frames.split(",")]
    plot_slices(img, labels, args.out)
    plot_mesh(img, read_frame(args.run, frames[0]), args.out)
    plot_shift(img, labels, args.run, frames, args.out)
    plot_warped(img, args.run, args.out)


if __name__ == "__main__":
    main()
