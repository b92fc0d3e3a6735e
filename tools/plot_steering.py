#!/usr/bin/python3
"""Plot the needle paths of the steering cases (docs/cases.md, "Steering").

    tools/plot_steering.py ONE_BEND_RUN TWO_BEND_RUN OBSTACLE_RUN [--out PNG]
    tools/plot_steering.py --plan PLAN_DIR [OPEN_LOOP_RUN] [--out PNG]

Each RUN is the output folder of `needlehex run` on cases/steering/
gel-one-bend.yaml, gel-two-bend.yaml and obstacle.yaml. Draws, in the plane
of the bend (x, y), the tip's path from tools.csv and the needle's last
frame (the last needle_NNNNNN.vtu), with the obstacle (the cylinder of
tools/make_steering_obstacle.py) and the target T of obstacle.yaml, and
prints per run the tip's end point, its lateral deviation from the line of
insertion and (obstacle) the final distance to the target and the closest
approach of the path to the obstacle's axis.

With --plan, the folder of a `needlehex plan` of a bevel-tip needle
(plan.yaml, run_NN/): the tip path of every run (the converged one bold),
the open-loop run's if given, the obstacles of the scene's plan.obstacles
(cylinders and spheres as circles in the plane z of the target; label
regions as the outline of their voxels in that slice) and the target, and
next to it the miss and the clearance per run; prints one line per run.
"""
import argparse
import glob
import os

import meshio
import numpy as np

from outputs import read_csv
from plotstyle import legend_outside, plt, save

OBSTACLE = (0.06, 0.04, 0.004)  # x, y of the axis, radius (tools/make_steering_obstacle.py)


def tip_path(run):
    rows = read_csv(os.path.join(run, "tools.csv"))
    return np.array([[float(r["tip_x"]), float(r["tip_y"]), float(r["depth"])] for r in rows])


def needle(run):
    frames = sorted(glob.glob(os.path.join(run, "needle_*.vtu")))
    return meshio.read(frames[-1]).points if frames else None


def target(run):
    rows = read_csv(os.path.join(run, "targets.csv"), missing=True)
    return rows[-1] if rows else None


def obstacles(ax, scene_path, z, y0, color="0.6"):
    """Draw the scene's plan.obstacles in the plane z (cm, y relative to y0)."""
    import yaml
    with open(scene_path) as f:
        scene = yaml.safe_load(f)
    labels = None
    for i, o in enumerate((scene.get("plan") or {}).get("obstacles") or []):
        name = "obstacle" if i == 0 else None
        if "cylinder" in o or "sphere" in o:
            c = o.get("cylinder") or o["sphere"]
            centre = c["start"] if "cylinder" in o else c["center"]
            ax.add_patch(plt.Circle((centre[0] * 100, (centre[1] - y0) * 100), c["radius"] * 100,
                                    color=color, label=name))
        elif "label" in o:
            import nibabel as nib
            if labels is None:
                t = scene["tissue"]
                f = (t.get("labels") or t["domain"].get("mask"))["file"]
                img = nib.load(os.path.join(os.path.dirname(scene_path), f))
                unit = {"meter": 1.0, "micron": 1e-6}.get(img.header.get_xyzt_units()[0], 1e-3)
                labels = (np.asarray(img.dataobj), img.affine, unit)
            data, A, unit = labels  # world (m) = unit * (A ijk + t); axis-aligned voxels
            k = int(round((z / unit - A[2, 3]) / A[2, 2]))
            sl = (data[:, :, k] == o["label"]).astype(float)
            X = unit * (A[0, 0] * np.arange(sl.shape[0]) + A[0, 3])
            Y = unit * (A[1, 1] * np.arange(sl.shape[1]) + A[1, 3])
            ax.contourf(X * 100, (Y - y0) * 100, sl.T, levels=[0.5, 1.5], colors=[color])
            if name:
                ax.plot([], [], "s", color=color, label="obstacle (label %d)" % o["label"])


def plot_plan(args):
    """The runs of a plan, the open-loop run, the obstacles; miss and clearance per run."""
    import yaml
    with open(os.path.join(args.plan, "plan.yaml")) as f:
        doc = yaml.safe_load(f)
    T = np.array(doc["target_point"])
    y0 = doc["entry"][1]
    fig = plt.figure(figsize=(13, 4.6))
    grid = fig.add_gridspec(1, 2, width_ratios=[2.6, 1])
    ax, bx = fig.add_subplot(grid[0, 0]), fig.add_subplot(grid[0, 1])
    final = int(doc["final_run"].split("_")[1])
    if args.open_loop:
        tip = tip_path(args.open_loop)
        inside = tip[:, 2] > 0
        ax.plot(tip[inside, 0] * 100, (tip[inside, 1] - y0) * 100, "--", color="C1", lw=1.5,
                label="open loop (bicycle plan by hand)")
    failed_label = "failed runs (simulation stopped)"
    for k, it in enumerate(doc["iterations"]):
        run = os.path.join(args.plan, "run_%02d" % (k + 1))
        if "failed" in it:
            print("run %d (%s): turns %s mm, depth %.2f mm: FAILED: %s" % (
                k + 1, it["kind"], ["%.2f" % (1e3 * d) for d in it["schedule"]["turns"]],
                1e3 * it["schedule"]["depth"], it["failed"][:60]))
            if os.path.exists(os.path.join(run, "tools.csv")):
                tip = tip_path(run)
                inside = tip[:, 2] > 0
                ax.plot(tip[inside, 0] * 100, (tip[inside, 1] - y0) * 100, ":", color="0.5",
                        lw=0.8, label=failed_label)
                failed_label = None
            continue
        tip = tip_path(run)
        inside = tip[:, 2] > 0
        last = k + 1 == final
        ax.plot(tip[inside, 0] * 100, (tip[inside, 1] - y0) * 100, "-",
                color="C3" if last else "C0", lw=2 if last else 0.8, alpha=1 if last else 0.5,
                label="planned (run %d)" % (k + 1) if last else ("other runs" if k == 0 else None))
        print("run %d (%s): turns %s mm, depth %.2f mm: miss %.3f mm, clearance %.3f mm" % (
            k + 1, it["kind"], ["%.2f" % (1e3 * d) for d in it["schedule"]["turns"]],
            1e3 * it["schedule"]["depth"], 1e3 * it["miss"], 1e3 * float(it["clearance"])))
    # the scene as given to the plan (its label images lie next to it), relative to the
    # folder the plan ran in or to the repository
    here = os.path.dirname(os.path.abspath(__file__))
    scene = next((p for p in (doc["scene"], os.path.join(here, "..", doc["scene"]))
                  if os.path.exists(p)), None)
    if scene:
        obstacles(ax, scene, T[2], y0)
    ax.plot(T[0] * 100, (T[1] - y0) * 100, "x", color="k", ms=10, mew=2, label="target")
    ax.axhline(0, color="0.7", lw=0.8, ls=":")
    ax.set_xlabel("x (cm): depth along the insertion line")
    ax.set_ylabel("y − y₀ (cm): towards the initial bevel")
    ax.set_aspect("equal")
    ax.grid(alpha=0.3)
    legend_outside(ax)
    n = np.arange(1, len(doc["iterations"]) + 1)
    ok = np.array(["failed" not in i for i in doc["iterations"]])
    miss = np.array([1e3 * float(i["miss"]) for i in doc["iterations"]])
    bx.semilogy(n[ok], miss[ok], "o-", label="miss")
    if not ok.all():
        bx.plot(n[~ok], np.full((~ok).sum(), miss[ok].max() if ok.any() else 1.0), "x",
                color="0.4", label="failed run")
    cl = np.array([1e3 * float(i.get("clearance", "nan")) for i in doc["iterations"]])
    if np.isfinite(cl[ok]).all():
        neg = ", ".join(str(k) for k in n[ok][cl[ok] < 0])
        bx.plot(n[ok], np.maximum(np.abs(cl[ok]), 1e-3), "s--",
                label=f"|clearance| (negative: runs {neg})" if neg else "clearance")
    bx.axhline(1e3 * doc["tolerance"], color="C0", ls=":", lw=0.8, label="tolerance")
    bx.axhline(1e3 * doc["clearance_required"], color="C1", ls=":", lw=0.8,
               label="clearance required")
    bx.set_xlabel("run")
    bx.set_ylabel("mm")
    bx.grid(alpha=0.3, which="both")
    bx.legend(fontsize=8)
    save(fig, args.out)


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="*", metavar="RUN")
    ap.add_argument("--plan", help="a plan's folder: its runs, miss and clearance per run")
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    if args.plan:
        if len(args.runs) > 1:
            ap.error("--plan takes at most one RUN: the open-loop run")
        args.open_loop = args.runs[0] if args.runs else None
        args.out = args.out or os.path.join(here, "..", "docs", "img", "steering_plan.png")
        return plot_plan(args)
    if len(args.runs) != 3:
        ap.error("three runs: one bend, two bends, obstacle")
    args.out = args.out or os.path.join(here, "..", "docs", "img", "steering_paths.png")
    titles = ["one bend (gel block)", "two bends: 180° turn at 6 cm", "around a stiff obstacle"]
    fig = plt.figure(figsize=(13, 9.5))
    grid = fig.add_gridspec(2, 2, height_ratios=[1.6, 1])
    axes = [fig.add_subplot(grid[0, 0]), fig.add_subplot(grid[0, 1]), fig.add_subplot(grid[1, :])]
    for ax, run, title in zip(axes, args.runs, titles):
        tip = tip_path(run)
        inside = tip[:, 2] > 0
        y0 = tip[0, 1]
        ax.plot(tip[inside, 0] * 100, (tip[inside, 1] - y0) * 100, "-", color="C3", lw=2,
                label="tip path")
        pts = needle(run)
        if pts is not None:
            ax.plot(pts[:, 0] * 100, (pts[:, 1] - y0) * 100, "-", color="0.3", lw=1,
                    label="needle, last frame")
        ax.axhline(0, color="0.7", lw=0.8, ls="--")
        ax.axvline(0, color="0.5", lw=0.8)
        end = tip[-1]
        msg = "%s: tip end (%.2f, %.2f) cm, lateral deviation %.2f cm" % (
            os.path.basename(os.path.normpath(run)), end[0] * 100, end[1] * 100,
            (end[1] - y0) * 100)
        t = target(run)
        if t is not None:
            ox, oy, r = OBSTACLE
            ax.add_patch(plt.Circle((ox * 100, (oy - y0) * 100), r * 100, color="0.6",
                                    label="obstacle (100 × stiffer)"))
            ax.plot(float(t["x"]) * 100, (float(t["y"]) - y0) * 100, "x", color="C0", ms=10,
                    mew=2, label="target T")
            gap = np.hypot(tip[inside, 0] - ox, tip[inside, 1] - oy).min() - r
            msg += ", distance to T %.2f mm, closest to the obstacle's surface %.2f mm" % (
                float(t["distance"]) * 1000, gap * 1000)
        print(msg)
        ax.set_title(title)
        ax.set_xlabel("x (cm): depth along the insertion line")
        ax.set_ylabel("y − y₀ (cm): towards the initial bevel")
        ax.set_xlim(-1, max(13, end[0] * 100 + 1))
        if t is not None:
            ax.set_ylim(-1.5, 1.5)
        ax.set_aspect("equal")
        ax.grid(alpha=0.3)
        ax.legend(loc="upper left", fontsize=8)
    save(fig, args.out)


if __name__ == "__main__":
    main()
