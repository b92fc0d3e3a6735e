# Sweeps through dask.distributed (tests/sweep.py): 4 cantilever variants on
# 2 workers equal the serial engine's, a restart skips complete variants, a
# worker killed mid-sweep is rescheduled or its variant reported lost.
nh_add_py_test(sweep "io;slow" sweep.py)
