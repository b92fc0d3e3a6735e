# Numerics: element, solver and time-integration verification.
nh_add_c_test(test_polar unit)
nh_add_c_test(test_rotation verify)
nh_add_c_test(test_patch verify)
nh_add_c_test(test_parallel unit)
nh_add_c_test(test_cantilever verify)
nh_add_c_test(test_dynamic verify)
nh_add_c_test(test_static_dynamic verify)
nh_add_c_test(test_hanging verify)
