# Patient anatomy (docs/anatomy.md).
# test_anatomy: STL ellipsoid (volume, inside test on 1e5 points, rays through
# vertices, ray entry, reader errors) and NIfTI reading (nibabel's
# anatomical.nii: size, spacing, orientation, world transform).
file(MAKE_DIRECTORY ${CMAKE_CURRENT_BINARY_DIR}/anatomy_scratch)
nh_add_c_test(test_anatomy verify ${CMAKE_CURRENT_BINARY_DIR}/anatomy_scratch)
