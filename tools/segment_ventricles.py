#!/usr/bin/python3
"""Segment the lateral ventricles of a T1-weighted MRI into a NIfTI label image.

    tools/segment_ventricles.py [--input T1.nii] [--out labels.nii.gz] [--fraction 0.45]
                                [--min-voxels 50]

Default input: the T1 crop that Debian's python3-nibabel installs
(nibabel/tests/data/anatomical.nii, 33 x 41 x 25 voxels of 2 mm). Default
output: cases/dbs-mri/ventricles.nii.gz, the label image of cases/dbs-mri.

The method (docs/anatomy.md, "Segmenting the ventricles"):
1. Threshold. Cerebrospinal fluid is the darkest tissue of a T1 image. The
   crop is mostly white and grey matter, so its median intensity is a
   tissue intensity; voxels below `fraction` x median (default 0.45) are
   candidate CSF.
2. Connected components of the candidates, 6-connected (faces only), so
   that CSF touching along an edge or a corner only (partial-volume voxels
   between the ventricles and the sulci) is not merged.
3. The lateral ventricles are the components of at least `min_voxels` voxels
   (default 50, 0.4 mL at 2 mm) whose centroid lies in the central half of
   the image along i and j and in its upper two thirds along k: sulcal CSF,
   the interhemispheric fissure and the basal cisterns lie at the borders
   of the crop.
4. Labels as FreeSurfer's aseg numbers them: 4 (Left-Lateral-Ventricle) for
   a component whose centroid has world x < 0 (RAS: x grows to the right),
   43 (Right-Lateral-Ventricle) otherwise; 0 elsewhere.
The output keeps the input's sform and qform, so it lies exactly on the
input in world coordinates. It prints each label's voxel count and volume.
"""
import argparse
import os
import sys

import nibabel as nib
import numpy as np
import scipy.ndimage as ndi

HERE = os.path.dirname(os.path.abspath(__file__))
DEFAULT_INPUT = os.path.join(os.path.dirname(nib.__file__), "tests", "data", "anatomical.nii")
DEFAULT_OUT = os.path.join(HERE, "..", "cases", "dbs-mri", "ventricles.nii.gz")
LEFT, RIGHT = 4, 43


def segment(image, fraction=0.45, min_voxels=50):
    """Label array (int16) of the lateral ventricles of `image` (a nibabel image)."""
    data = np.asarray(image.dataobj, dtype=float)
    threshold = fraction * np.median(data)
    candidate = data < threshold
    components, count = ndi.label(candidate)  # default structure: 6-connected
    labels = np.zeros(data.shape, dtype=np.int16)
    n = np.array(data.shape, dtype=float)
    for index in range(1, count + 1):
        voxels = np.argwhere(components == index)
        if len(voxels) < min_voxels:
            continue
        centre = voxels.mean(axis=0)
        central = (n[0] / 4 <= centre[0] <= 3 * n[0] / 4 and n[1] / 4 <= centre[1] <= 3 * n[1] / 4
                   and centre[2] >= n[2] / 3)
        if not central:
            continue
        x = image.affine[:3, :3] @ centre + image.affine[:3, 3]
        labels[components == index] = LEFT if x[0] < 0 else RIGHT
    return labels, threshold


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--input", default=DEFAULT_INPUT)
    ap.add_argument("--out", default=DEFAULT_OUT)
    ap.add_argument("--fraction", type=float, default=0.45)
    ap.add_argument("--min-voxels", type=int, default=50)
    args = ap.parse_args()
    image = nib.load(args.input)
    labels, threshold = segment(image, args.fraction, args.min_voxels)
    out = nib.Nifti1Image(labels, image.affine, image.header)
    out.set_data_dtype(np.int16)
    out.header["scl_slope"], out.header["scl_inter"] = 1.0, 0.0
    out.set_sform(image.get_sform(), int(image.header["sform_code"]))
    out.set_qform(image.get_qform(), int(image.header["qform_code"]))
    nib.save(out, args.out)
    voxel_ml = abs(np.linalg.det(image.affine[:3, :3])) / 1000.0
    print(f"{args.input}: threshold {threshold:.1f} (= {args.fraction} x median)")
    for value, name in ((LEFT, "left lateral ventricle"), (RIGHT, "right lateral ventricle")):
        count = int((labels == value).sum())
        print(f"label {value:2d} {name}: {count} voxels, {count * voxel_ml:.2f} mL")
    if not (labels == LEFT).any() or not (labels == RIGHT).any():
        sys.exit("segment_ventricles: did not find both lateral ventricles")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
