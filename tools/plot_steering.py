#!/usr/bin/python3
"""Plot the needle paths of the steering cases (docs/cases.md, "Steering").

    tools/plot_steering.py ONE_BEND_RUN TWO_BEND_RUN OBSTACLE_RUN [--out PNG]

Each RUN is the output folder of `needlehex run` on cases/steering/
gel-one-bend.yaml, gel-two-bend.yaml and obstacle.yaml. Draws, in the plane
of the bend (x, y), the tip's path from tools.csv and the needle's last
frame (the last needle_NNNNNN.vtu), with the obstacle (the cylinder of
tools/make_steering_obstacle.py) and the target T of obstacle.yaml, and
prints per run the tip's end point, its lateral deviation from the line of
insertion and (obstacle) the final distance to the target and the closest
approach of the path to the obstacle's axis.
"""
import argparse
import glob
import os

import meshio
import numpy as np

from outputs import read_csv
from plotstyle import plt, save

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


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs=3, metavar="RUN")
    ap.add_argument("--out", default=os.path.join(here, "..", "docs", "img",
                                                  "steering_paths.png"))
    args = ap.parse_args()
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
