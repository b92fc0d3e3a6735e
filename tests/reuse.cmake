# Reuse of factorisations (tests/reuse.py): solver.refactor auto against every
# on the needle phantom (uniform and adaptive) and a shortened DBS procedure;
# results agree to steps x solver.tolerance.
nh_add_py_test(reuse "verify;slow" reuse.py phantom-uniform phantom-adaptive dbs-short dbs-skull)
# The goal-oriented phantom (2 s): also, an estimated step factorises at most once.
nh_add_py_test(reuse_goal verify reuse.py phantom-goal)
# Reuse across a mesh change (tests/test_inherit.c): the old mesh's factor
# extended to the new unknowns, a PCG solve after refinement and after
# coarsening against a factorisation, within tol·√κ(BA) in the energy norm.
nh_add_c_test(test_inherit verify)
