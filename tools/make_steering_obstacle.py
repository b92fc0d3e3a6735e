#!/usr/bin/python3
"""Write the label image of cases/steering/obstacle.yaml: a stiff cylinder in a gel block.

    tools/make_steering_obstacle.py [--out cases/steering/obstacle.nii.gz]

Voxels of 1 mm over the block [0, 0.15] x [0, 0.08] x [0, 0.039] m; label 1
(gel) everywhere except label 2 (the obstacle) in the cylinder of radius
4 mm along z through the block's thickness, axis at x = 6 cm, y = 4 cm. The
affine maps voxel (i, j, k) to its centre ((i + 1/2) mm, (j + 1/2) mm,
(k + 1/2) mm), units millimetres (xyzt_units), as the scene's label images
are read (docs/anatomy.md).
"""
import argparse
import os

import nibabel as nib
import numpy as np

SIZE = (0.15, 0.08, 0.039)  # m
VOXEL = 0.001  # m
AXIS = (0.06, 0.04)  # x, y of the cylinder's axis, m
RADIUS = 0.004  # m


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=os.path.join(here, "..", "cases", "steering",
                                                  "obstacle.nii.gz"))
    args = ap.parse_args()
    n = [int(round(s / VOXEL)) for s in SIZE]
    x = (np.arange(n[0]) + 0.5) * VOXEL
    y = (np.arange(n[1]) + 0.5) * VOXEL
    inside = (x[:, None] - AXIS[0]) ** 2 + (y[None, :] - AXIS[1]) ** 2 <= RADIUS ** 2
    labels = np.ones(n, dtype=np.uint8)
    labels[inside, :] = 2
    mm = VOXEL * 1000.0
    affine = np.diag([mm, mm, mm, 1.0])
    affine[:3, 3] = 0.5 * mm
    image = nib.Nifti1Image(labels, affine)
    image.header.set_xyzt_units("mm")
    image.set_sform(affine, code=1)
    image.set_qform(affine, code=1)
    nib.save(image, args.out)
    print("%s: %d x %d x %d voxels, %d in the obstacle (%.3g cm^3)" %
          (args.out, n[0], n[1], n[2], int((labels == 2).sum()),
           (labels == 2).sum() * VOXEL ** 3 * 1e6))


if __name__ == "__main__":
    main()
