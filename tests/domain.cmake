# Immersed domain (tests/test_domain.c): the brain's fill-fraction volume and
# mirror symmetry, ray entry on the implicit surface, sphere and cylinder
# regions and their loads, refinement of cut cells, a brain under gravity.
nh_add_c_test(test_domain verify)
# Brain shift: drainage level, fixed-region ties (tests/test_brainshift.c).
nh_add_c_test(test_brainshift verify)
# Cut cells: the finite cell quadrature (tests/test_cutcell.c): exactness on
# planes and boxes, moment fitting, additivity, ball/ellipsoid/brain/mask/STL
# volumes and moments against closed forms and Monte Carlo, closed surfaces.
file(MAKE_DIRECTORY ${CMAKE_CURRENT_BINARY_DIR}/cutcell_scratch)
nh_add_c_test(test_cutcell "unit;verify" ${CMAKE_CURRENT_BINARY_DIR}/cutcell_scratch)
# Connected components of a cut cell's tissue (tests/test_cut_components.c):
# a slot through a middle column (closed form), the brain's fissure in the
# middle column of odd grids, none beside x = 0 on an even one.
nh_add_c_test(test_cut_components "unit;verify")
# Cut cells in the tissue (tests/test_fcm.c): immersed patch test to round-off,
# O(α) consistency, closed pressure, a tie smaller than a cell holds a ball.
nh_add_c_test(test_fcm "unit;verify" ${CMAKE_CURRENT_BINARY_DIR})
# The same on an ellipsoid as an STL surface (tilted) and as a NIfTI mask, written by the
# test (libnifti2): patch test, closed pressure, the quadrature's volume of order 2.
add_test(NAME test_fcm_anatomy COMMAND test_fcm ${CMAKE_CURRENT_BINARY_DIR} anatomy)
set_tests_properties(test_fcm_anatomy PROPERTIES LABELS "verify;slow"
  ENVIRONMENT "NH_SOURCE_DIR=${PROJECT_SOURCE_DIR};NH_BINARY=$<TARGET_FILE:needlehex>")
# Aggregated nodes of integrated cut cells (tests/test_aggregate.c): linear
# precision of every aggregated node, the immersed patch test solved with them
# on 5 grids, bounded motion as a cut sliver shrinks from 1e-2 to 1e-6.
nh_add_c_test(test_aggregate "unit;verify")
# The immersed sphere under pressure, end to end (tests/sphere_pressure.py):
# an STL ball held by a tie smaller than a cell, integrated cut cells; probe
# errors against the closed form of the tied ball, order >= 1 (issue 25's
# goal). Non-slow: 8, 12, 16 cells across; slow: the goal's 12 ... 24.
nh_add_py_test(sphere_pressure verify sphere_pressure.py 8 12 16)
nh_add_py_test(sphere_pressure_goal "verify;slow" sphere_pressure.py 12 14 16 20 24)
set_tests_properties(sphere_pressure_goal PROPERTIES TIMEOUT 900)
# The same with an ellipsoid (30, 22, 16 mm, turned; tests/sphere_pressure.py --ellipsoid).
nh_add_py_test(ellipsoid_pressure verify sphere_pressure.py --ellipsoid 8 12 16)
nh_add_py_test(ellipsoid_pressure_ladder "verify;slow" sphere_pressure.py --ellipsoid 12 14 16 20 24)
set_tests_properties(ellipsoid_pressure_ladder PROPERTIES TIMEOUT 900)
# Both bodies as NIfTI label masks (0.5 mm voxels; tests/sphere_pressure.py --mask).
nh_add_py_test(sphere_pressure_mask verify sphere_pressure.py --mask 8 12 16)
nh_add_py_test(sphere_pressure_mask_goal "verify;slow" sphere_pressure.py --mask 12 14 16 20 24)
nh_add_py_test(ellipsoid_pressure_mask verify sphere_pressure.py --ellipsoid --mask 8 12 16)
nh_add_py_test(ellipsoid_pressure_mask_ladder "verify;slow" sphere_pressure.py --ellipsoid --mask
  12 14 16 20 24)
set_tests_properties(sphere_pressure_mask_goal ellipsoid_pressure_mask_ladder PROPERTIES TIMEOUT 900)
# The sphere with its tie resolved (tissue.fixed.0.refine 0.5 mm; --tie-refine): the error
# below 10 ε = 1e-3 on every grid, those between included (unrefined: 3.98, 6.43, 2.78 % on 9, 10,
# 11). Non-slow: 9, 10, 11; slow: the thirteen grids 8 ... 24.
nh_add_py_test(sphere_pressure_tie verify sphere_pressure.py --tie-refine 0.5 9 10 11)
nh_add_py_test(sphere_pressure_tie_ladder "verify;slow" sphere_pressure.py --tie-refine 0.5
  8 9 10 11 12 13 14 15 16 18 20 22 24)
set_tests_properties(sphere_pressure_tie_ladder PROPERTIES TIMEOUT 900)
# The geometry term of the goal estimate (tests/test_geometry_term.c): zero on
# a box domain and with scaled, round-off in cut cells with a planar level set,
# -ΔV ε(z):D:ε(u) for linear fields on a ball at order 2, and no net
# residual for the immersed patch test.
file(MAKE_DIRECTORY ${CMAKE_CURRENT_BINARY_DIR}/geometry_term_scratch)
nh_add_c_test(test_geometry_term "unit;verify" ${CMAKE_CURRENT_BINARY_DIR}/geometry_term_scratch)
# Its part 7 alone (argument "drainage"): the body force on the mass above a
# drainage plane, each depth's own half-space cut.
add_test(NAME test_geometry_term_drainage COMMAND test_geometry_term
  ${CMAKE_CURRENT_BINARY_DIR}/geometry_term_scratch drainage)
set_tests_properties(test_geometry_term_drainage PROPERTIES LABELS "unit;verify")
# The stiffness's condition number with cut cells of shrinking tissue (tests/test_fcm.c, part 10).
add_test(NAME test_fcm_conditioning COMMAND test_fcm ${CMAKE_CURRENT_BINARY_DIR} conditioning)
set_tests_properties(test_fcm_conditioning PROPERTIES LABELS "unit;verify"
  ENVIRONMENT "NH_SOURCE_DIR=${PROJECT_SOURCE_DIR}")
# The sag of a ball hung by a sub-cell cap on 14 grids (tests/test_fcm.c, part 7).
add_test(NAME test_fcm_tie COMMAND test_fcm ${CMAKE_CURRENT_BINARY_DIR} tie-ladder)
set_tests_properties(test_fcm_tie PROPERTIES LABELS "verify;slow"
  ENVIRONMENT "NH_SOURCE_DIR=${PROJECT_SOURCE_DIR}")
# `needlehex check` notes each fixed region of an immersed domain that its cells do not resolve
# (an edge above 1/8 of its smallest size) with the refine that does (tests/check_ties.py).
nh_add_py_test(check_ties unit check_ties.py)
