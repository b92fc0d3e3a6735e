# Tissue and tools in one step (Algorithm 1 across blocks): dense KKT agreement, stick-slide.
nh_add_c_test(test_coupled verify)
