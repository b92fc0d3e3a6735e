# Reuse of factorisations (tests/reuse.py): solver.refactor auto against every
# on the needle phantom (uniform and adaptive) and a shortened DBS procedure;
# results agree to steps x solver.tolerance.
nh_add_py_test(reuse "verify;slow" reuse.py)
