# Hard scenes (issue 27, tests/hard/): each must run to completion with every
# constraint solve within its tolerance (tests/hard.py).
#   bevel-friction: stiff bevel needle, mu 0.1, 5 mm cells (was: step 29,
#     "residual > tolerance after 2000 sweeps")
nh_add_py_test(hard_bevel_friction hard hard.py bevel-friction)
#   static-push: quasi-static, 2 mm per pseudo-step, mu 0.1, 10 kPa (main:
#     step 7; with the tied set's hysteresis, docs/interaction.md
#     "Hysteresis of the tied set": step 13). Not yet passing: every
#     constraint solve is exact (residual <= 1e-14) and the tied set and
#     stick/slip states settle, but the outer Newton contracts by ~0.6 per
#     iteration (the needle's symmetrised beam tangent, measured, see
#     "Which tangent limits the rate") and 30 iterations of 16 load steps
#     miss 1e-8. Kept disabled until then.
nh_add_py_test(hard_static_push hard hard.py static-push)
set_tests_properties(hard_static_push PROPERTIES DISABLED TRUE)
#   static-push up to step 12: past main's failure at step 7 (the newest
#     channel point toggled tied/untied within the Newton iteration), which
#     the tied set's hysteresis removes.
nh_add_py_test(hard_static_push_12 hard hard.py static-push:12)
