#!/usr/bin/python3
"""Write the elastix parameter file with which transformix applies a
displacement field written by needlehex (displacement_<step>.nii.gz).

    tools/transformix_params.py FIELD [--reference IMAGE] [--nearest] [--out FILE]

transformix needs the output grid spelled out in ITK's physical frame (LPS
millimetres): Size, Spacing, Origin and Direction (column by column). They
are read from --reference (default: FIELD itself, which lies on the grid of
the reference image it was sampled on) with nibabel, as ITK reads a NIfTI
file: origin and direction cosines of the sform (else the qform) with x and
y negated. The transform is elastix's DeformationFieldTransform on FIELD
(linear interpolation of the field). Images are resampled with linear
interpolation (a B-spline of order 1), or the nearest voxel with --nearest
(label images; order 0). Then, with the file written to field.txt:

    transformix -in IMAGE.nii.gz -out DIR -tp field.txt    # DIR/result.nii.gz
    transformix -def points.txt -out DIR -tp field.txt     # DIR/outputpoints.txt

The field maps a point p of the reference (the anatomy before the shift) to
p + u(p), where that tissue is after it: -in pulls an image of the shifted
anatomy back onto the reference (out(p) = IMAGE(p + u(p))), -def moves
points planned before the shift to where they are after it
(docs/anatomy.md, "Displacement fields and shifted images").
"""
import argparse
import os
import sys

import nibabel as nib
import numpy as np


def itk_grid(path):
    """Size, spacing, origin and direction (LPS) of a NIfTI file as ITK sees it."""
    img = nib.load(path)
    aff = img.affine  # sform if coded, else qform: mm (nibabel converts nothing)
    scale = {"meter": 1e3, "micron": 1e-3}.get(img.header.get_xyzt_units()[0], 1.0)
    lps = np.diag([-1.0, -1.0, 1.0])
    spacing = np.linalg.norm(aff[:3, :3], axis=0) * scale
    direction = lps @ aff[:3, :3] * scale / spacing
    origin = lps @ aff[:3, 3] * scale
    return img.shape[:3], spacing, origin, direction


def parameters(field, reference, nearest):
    size, spacing, origin, direction = itk_grid(reference)
    # a B-spline of order 1 is linear interpolation, of order 0 the nearest
    # voxel (Debian's elastix has no FinalLinearInterpolator)
    interpolator = ('(ResampleInterpolator "FinalBSplineInterpolator")\n(FinalBSplineInterpolationOrder %d)\n'
                    % (0 if nearest else 1))
    return ('(Transform "DeformationFieldTransform")\n'
            '(DeformationFieldFileName "%s")\n'
            "(DeformationFieldInterpolationOrder 1)\n"
            "(NumberOfParameters 0)\n"
            '(InitialTransformParametersFileName "NoInitialTransform")\n'
            '(HowToCombineTransforms "Compose")\n'
            "(FixedImageDimension 3)\n(MovingImageDimension 3)\n"
            '(FixedInternalImagePixelType "float")\n(MovingInternalImagePixelType "float")\n'
            "(Size %d %d %d)\n(Index 0 0 0)\n"
            "(Spacing %.17g %.17g %.17g)\n(Origin %.17g %.17g %.17g)\n(Direction %s)\n"
            '(UseDirectionCosines "true")\n%s'
            '(Resampler "DefaultResampler")\n(DefaultPixelValue 0)\n'
            '(ResultImageFormat "nii.gz")\n(ResultImagePixelType "%s")\n(CompressResultImage "false")\n'
            % ((os.path.abspath(field),) + tuple(size) + tuple(spacing) + tuple(origin)
               + (" ".join("%.17g" % v for v in direction.T.ravel()), interpolator,
                  "short" if nearest else "float")))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("field", help="the displacement field (NIfTI, ITK convention)")
    ap.add_argument("--reference", help="the output grid (default: the field's own)")
    ap.add_argument("--nearest", action="store_true", help="nearest-neighbour resampling (labels)")
    ap.add_argument("--out", default="field.txt", help="the parameter file (default field.txt)")
    a = ap.parse_args()
    reference = a.reference or a.field
    if not os.path.exists(reference):
        sys.exit("transformix_params.py: %s: no such file" % reference)
    with open(a.out, "w") as f:
        f.write(parameters(a.field, reference, a.nearest))


if __name__ == "__main__":
    main()
