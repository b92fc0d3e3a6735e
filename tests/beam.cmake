# Beam (needle, cannula, electrode): element, tool, Hermite points, solvers.
nh_add_c_test(test_beam verify)
