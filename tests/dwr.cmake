# Goal-oriented (dual-weighted residual) estimate: the DWR identity and effectivity (tests/test_dwr.c).
nh_add_c_test(test_dwr "verify;slow")
