# Hard scenes (issue 27, tests/hard/): each must run to completion with every
# constraint solve within its tolerance (tests/hard.py).
#   bevel-friction: stiff bevel needle, mu 0.1, 5 mm cells (was: step 29,
#     "residual > tolerance after 2000 sweeps")
nh_add_py_test(hard_bevel_friction hard hard.py bevel-friction)
