# Immersed domain (tests/test_domain.c): the brain's fill-fraction volume and
# mirror symmetry, ray entry on the implicit surface, sphere and cylinder
# regions and their loads, refinement of cut cells, a brain under gravity.
nh_add_c_test(test_domain verify)
# Brain shift: drainage level, fixed-region ties (tests/test_brainshift.c).
nh_add_c_test(test_brainshift verify)
