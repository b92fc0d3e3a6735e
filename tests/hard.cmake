# Hard scenes (issue 27, tests/hard/): each must run to completion with every
# constraint solve within its tolerance (tests/hard.py).
#   bevel-friction: stiff bevel needle, mu 0.1, 5 mm cells (was: step 29,
#     "residual > tolerance after 2000 sweeps")
nh_add_py_test(hard_bevel_friction hard hard.py bevel-friction)
#   static-push: quasi-static, 2 mm per pseudo-step, mu 0.1, 10 kPa (main:
#     step 7). Not yet passing: the stick/slip set settles in the first
#     Newton iteration and every constraint solve is exact (residual
#     <= 1e-14), but the outer Newton converges linearly (rate ~0.6) and
#     30 iterations miss 1e-8 even after 16 load steps; the tangent's
#     missing terms are issue 27 item 3. Kept disabled until then.
nh_add_py_test(hard_static_push hard hard.py static-push)
set_tests_properties(hard_static_push PROPERTIES DISABLED TRUE)
