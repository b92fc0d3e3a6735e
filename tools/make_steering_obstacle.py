#!/usr/bin/python3
"""Write the label images of cases/steering/obstacle.yaml and two-obstacles.yaml:
stiff cylinders in a gel block.

    tools/make_steering_obstacle.py [--out cases/steering/obstacle.nii.gz]
    tools/make_steering_obstacle.py --two [--out cases/steering/two-obstacles.nii.gz]

Voxels of 1 mm over the block [0, 0.15] x [0, 0.08] x [0, 0.039] m; label 1
(gel) everywhere except in cylinders of radius 4 mm along z through the
block's thickness: label 2 with its axis at x = 6 cm, y = 4 cm (one obstacle,
across the line of insertion y = 4 cm); with --two, label 2 at x = 5 cm,
y = 3.5 cm (below the line, its top 1 mm under it) and label 3 at x = 9 cm,
y = 4.7 cm (above it, its bottom 3 mm over it). A voxel belongs to a
cylinder when its centre does. The affine maps voxel (i, j, k) to its
centre ((i + 1/2) mm, (j + 1/2) mm, (k + 1/2) mm), units millimetres
(xyzt_units), as the scene's label images are read (docs/anatomy.md).
"""
import argparse
import os

import nibabel as nib
import numpy as np

SIZE = (0.15, 0.08, 0.039)  # m
VOXEL = 0.001  # m
ONE = [(2, (0.06, 0.04))]  # label, (x, y) of the cylinder's axis, m
TWO = [(2, (0.05, 0.035)), (3, (0.09, 0.047))]
RADIUS = 0.004  # m


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--two", action="store_true", help="the two-obstacle image")
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    out = args.out or os.path.join(here, "..", "cases", "steering",
                                   "two-obstacles.nii.gz" if args.two else "obstacle.nii.gz")
    n = [int(round(s / VOXEL)) for s in SIZE]
    x = (np.arange(n[0]) + 0.5) * VOXEL
    y = (np.arange(n[1]) + 0.5) * VOXEL
    labels = np.ones(n, dtype=np.uint8)
    for label, axis in (TWO if args.two else ONE):
        inside = (x[:, None] - axis[0]) ** 2 + (y[None, :] - axis[1]) ** 2 <= RADIUS ** 2
        labels[inside, :] = label
    mm = VOXEL * 1000.0
    affine = np.diag([mm, mm, mm, 1.0])
    affine[:3, 3] = 0.5 * mm
    image = nib.Nifti1Image(labels, affine)
    image.header.set_xyzt_units("mm")
    image.set_sform(affine, code=1)
    image.set_qform(affine, code=1)
    nib.save(image, out)
    inside = int((labels > 1).sum())
    print("%s: %d x %d x %d voxels, %d in the obstacles (%.3g cm^3)" %
          (out, n[0], n[1], n[2], inside, inside * VOXEL ** 3 * 1e6))


if __name__ == "__main__":
    main()
