# Sweeps through dask.distributed (tests/sweep.py): 4 cantilever variants on
# 2 workers equal the serial engine's, a restart skips complete variants, a
# worker killed mid-sweep is rescheduled or its variant reported lost.
nh_add_py_test(sweep "io;slow" sweep.py)
# Target-compensation plans on the study engine (tests/plan_sweep.py): four
# plans on a sagging block on 2 loopback workers equal the serial engine's,
# each converged and consistent with its run folders; a rigid block is on
# target in one run; the compensation scales as 1/E; plans that do not
# converge are results (not failures) and are skipped on a restart.
nh_add_py_test(sweep_plan "io;verify;slow" plan_sweep.py)
