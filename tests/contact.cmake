# Tissue and tools in one step (Algorithm 1 across blocks): dense KKT agreement, stick-slide.
nh_add_c_test(test_coupled verify)
# Skull contact: a sphere resting in a spherical cavity (tests/test_skull.c).
nh_add_c_test(test_skull "verify;slow")
# Skull contact points from the cut cells' surface quadrature: area order 2 on an off-centre sphere (tests/test_skull_surface.c).
nh_add_c_test(test_skull_surface "unit;verify")
# Skull contact points of leaves holding both walls of the brain's fissure (odd grids): on F = 0, in their leaf, mirror symmetric, on each wall facing the gap (tests/test_skull_fissure.c).
nh_add_c_test(test_skull_fissure "unit;verify")
# Weighted-gap skull rows (tissue.skull.rows: mortar) against closed forms: a flat STL face under a linear field, a dilated off-centre sphere, a resting sphere's reaction = its weight (tests/test_skull_mortar.c).
file(MAKE_DIRECTORY ${CMAKE_CURRENT_BINARY_DIR}/skull_mortar_scratch)
nh_add_c_test(test_skull_mortar "unit;verify" ${CMAKE_CURRENT_BINARY_DIR}/skull_mortar_scratch)
# The shaft points' axial data errors: which points the goal estimate estimates, the kept δc on their axial rows, kept by a checkpoint (tests/test_anchor_points.c).
nh_add_c_test(test_anchor_points unit)
# The tip disc: a point load's compliance diverges like 1/h, the disc's converges (tests/test_tip_disc.c).
nh_add_c_test(test_tip_disc "unit;verify")
# The contact geometry continuous in the state: closest points on a bent tool converged whatever their rounding, the tip disc's rings in the tool's frame (tests/test_contact_frame.c).
nh_add_c_test(test_contact_frame "unit;verify")
# A released nested tool hangs in its host's bore: on the host's axis, its weight carried by the host (composite section), a free cantilever once the host is drawn back (tests/test_nest.c).
nh_add_c_test(test_nest "verify")
