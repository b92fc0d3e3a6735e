# The DBS case through the binary (tests/dbs.py): a planned trajectory puts
# the cannula's tip on the STN (1e-6 m) in a rigid brain; the whole
# procedure of cases/dbs/dbs.yaml, shortened, runs to its end with finite
# values, the brain shifting, the cannula back at its start and the
# electrode left in place.
nh_add_py_test(dbs verify dbs.py)
