# Numerics: element, solver and time-integration verification.
nh_add_c_test(test_polar unit)
nh_add_c_test(test_rotation verify)
nh_add_c_test(test_hex_kernels unit)
nh_add_c_test(test_tangent verify)
nh_add_c_test(test_newton_rate verify)
nh_add_py_test(newton_dynamic verify newton_dynamic.py)
nh_add_c_test(test_patch verify)
nh_add_c_test(test_locking verify)
nh_add_c_test(test_parallel unit)
# CHOLMOD's own OpenMP teams inside a factorisation run on one thread
# (solve/cholesky.c); the test counts the process's threads, so it needs
# teams of 2 allowed.
nh_add_c_test(test_cholmod_teams unit)
set_property(TEST test_cholmod_teams APPEND PROPERTY ENVIRONMENT "OMP_NUM_THREADS=2;OMP_THREAD_LIMIT=2")
nh_add_c_test(test_lazy verify)
nh_add_c_test(test_cantilever verify)
nh_add_c_test(test_dynamic verify)
nh_add_c_test(test_static_dynamic verify)
nh_add_c_test(test_hanging verify)
nh_add_c_test(test_lagrange verify)
nh_add_c_test(test_compliance verify)
nh_add_c_test(test_transfer verify)
nh_add_py_test(restart "io;slow" restart.py)
nh_add_py_test(run_hdf5 io run_hdf5.py)

# Restart with tools (tests/restart_tools.py): the needle phantom (also with
# static friction), and under `slow` the shortened adaptive DBS procedure
# (nested electrode, release) with solver.refactor auto and every, and a small
# DBS procedure with skull contact (point rows, and the weighted-gap rows of
# tissue.skull.rows: mortar), stopped by SIGTERM (continued by the
# printed command) and by SIGKILL (continued from its checkpoint) equal the
# uninterrupted run to 1e-12.
nh_add_py_test(restart_tools io restart_tools.py needle)
nh_add_py_test(restart_tools_dbs io restart_tools.py dbs)
# The goal estimate's carried state (adapt.memory's links, adapt.separate_every's weights) across a restart.
nh_add_py_test(restart_tools_goal io restart_tools.py goal)
set_tests_properties(restart_tools_dbs PROPERTIES LABELS "io;slow" TIMEOUT 900)
nh_add_py_test(restart_tools_skull io restart_tools.py skull)
nh_add_py_test(restart_tools_mri io restart_tools.py mri)
set_tests_properties(restart_tools_skull PROPERTIES LABELS "io;slow" TIMEOUT 600)
nh_add_py_test(restart_tools_skull_mortar io restart_tools.py skull-mortar)
set_tests_properties(restart_tools_skull_mortar PROPERTIES LABELS "io;slow" TIMEOUT 900)

# Restart from anywhere, every shipped case (tests/restart_cases.py; cases
# found by globbing cases/, study files skipped): each case shortened to 10
# steps, stopped by SIGINT (needle-phantom: SIGTERM) after step 3, its frames
# and results.h5 read, DIR/scene.yaml checked for relative file paths, the
# printed command run from another folder and the result compared with the
# uninterrupted run (1e-12; 1e-6 where docs/performance.md's inherited-factor
# exception applies). About 25 s of runs on a loaded 2-core machine.
nh_add_py_test(restart_cases io restart_cases.py cases)
set_tests_properties(restart_cases PROPERTIES TIMEOUT 600)
nh_add_c_test(test_traction verify)
nh_add_py_test(traction_patch verify traction_patch.py)

# Lazy element tangents in whole runs (tests/lazy_run.py): the needle phantom
# with solver.lazy_rotation 0 and 1e-3, 1 and 2 threads, identical outputs.
nh_add_py_test(lazy_run verify lazy_run.py)
# W's OpenMP tasks call BLAS single-threaded, as needlehex runs it (src/main.c)
set_property(TEST test_compliance APPEND PROPERTY ENVIRONMENT OPENBLAS_NUM_THREADS=1)
