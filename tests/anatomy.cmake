# Patient anatomy (docs/anatomy.md).
# test_anatomy: STL ellipsoid (volume, inside test on 1e5 points, rays through
# vertices, ray entry, reader errors) and NIfTI reading (nibabel's
# anatomical.nii: size, spacing, orientation, world transform).
file(MAKE_DIRECTORY ${CMAKE_CURRENT_BINARY_DIR}/anatomy_scratch)
nh_add_c_test(test_anatomy verify ${CMAKE_CURRENT_BINARY_DIR}/anatomy_scratch)
# anatomy.py: through the binary: a brain rasterised to NIfTI by nibabel at
# 4 and 2 mm against the analytic brain (volumes, static shift), the same mask
# flipped by its affine, a two-material bar in series, the segmentation
# script against the shipped label image, bad input (exit 2, file and key).
nh_add_py_test(anatomy verify anatomy.py)
set_tests_properties(anatomy PROPERTIES TIMEOUT 600 LABELS "verify;slow")
