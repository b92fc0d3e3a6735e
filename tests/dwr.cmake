# Goal-oriented (dual-weighted residual) estimate: the DWR identity and effectivity (tests/test_dwr.c).
nh_add_c_test(test_dwr "verify;slow")
# adapt.resolve: a re-solved step equals the direct solve on its final mesh (tests/test_resolve.c).
nh_add_c_test(test_resolve verify)
# adapt.resolve_tip: the puncture step solved with the tip's leaves at max_level (tests/test_resolve_tip.c).
nh_add_c_test(test_resolve_tip verify)
# The constrained dual (active skull/tool/tie rows) and the combined dual of several goals (tests/test_dwr_rows.c).
nh_add_c_test(test_dwr_rows verify)
# The constraint-data term against the skull points one lattice finer, run both ways (tests/test_dwr_skull.c).
nh_add_c_test(test_dwr_skull verify)
# The local enriched dual where a held tool row and the goal share a cell, against nested fine solves (tests/test_dwr_local.c).
nh_add_c_test(test_dwr_local verify)
# adapt.marking.goals: the marked set of the goals' summed indicators and the union of each goal's own marking (tests/test_goal_marking.c).
nh_add_c_test(test_goal_marking verify)
# The fronts' errors in the goal estimate's pass: bitwise those of each front alone, the goals' unchanged (tests/test_dwr_fronts.c).
nh_add_c_test(test_dwr_fronts verify)
# The estimate's Gauss-point kernel against its terms formed point by point from their definitions (tests/test_dwr_kernel.c).
nh_add_c_test(test_dwr_kernel unit)
# The memory term's links: their sum against the static dual, an exact identity with and without held rows (tests/test_dwr_memory.c).
nh_add_c_test(test_dwr_memory verify)
