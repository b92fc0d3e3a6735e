# Constraint-force solver (mixed complementarity on W): bilateral, unilateral, friction laws.
nh_add_c_test(test_mcp unit)
