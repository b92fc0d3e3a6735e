# Effectivity of the SPR estimator against a manufactured solution (tests/test_effectivity.c).
nh_add_c_test(test_effectivity "verify;slow")
