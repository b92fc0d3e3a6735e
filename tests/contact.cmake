# Tissue and tools in one step (Algorithm 1 across blocks): dense KKT agreement, stick-slide.
nh_add_c_test(test_coupled verify)
# Skull contact: a sphere resting in a spherical cavity (tests/test_skull.c).
nh_add_c_test(test_skull "verify;slow")
