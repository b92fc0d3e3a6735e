# Needle insertion through the binary (tests/needle.py): puncture threshold and
# indentation stiffness against an independent point-load run, a needle beside
# the block, full retraction, re-insertion into the channel, stick/slide.
nh_add_py_test(needle verify needle.py)
# Hard cases: needle 10 GPa in tissue 6 kPa, nu 0.45/0.49, h 1e-3/5e-2 s, tip
# path through nodes, in a face plane, through faces.
nh_add_py_test(needle_hard "hard;slow" needle.py --hard)
# Tools in the quasi-static mode (tests/static_insertion.py): the needle under
# its own weight against q L^4 / 8EI, and a static insertion against slow,
# heavily damped dynamic insertions (order 1 in the slowness, and the dynamic
# step's known lag of the shaft forces).
nh_add_py_test(static_insertion verify static_insertion.py)
# Bevel-tip steering (tests/steering.py): psi = 0 straight under base spin,
# deviation monotone in psi and along the bevel, a 180 deg turn at half depth
# flips the curvature, circular paths with kappa proportional to tan(psi) in a
# rigid-like medium (the bicycle model).
nh_add_py_test(steering "verify;slow" steering.py)
# The channel points' default spacing, one cell edge (tests/channel_spacing.py,
# docs/interaction.md "Why one point per cell"): an explicit spacing finer than
# the cell warns once; on the phantom's 48x24x24 grid, where half a cell edge
# locked the tip at step 32, the first 40 steps cut within the friction bound.
nh_add_py_test(channel_spacing verify channel_spacing.py)
nh_add_py_test(channel_spacing_lock "verify;slow" channel_spacing.py --lock)
set_tests_properties(channel_spacing_lock PROPERTIES TIMEOUT 900)
# The shaft's friction as the line integral over the inserted length
# (tests/shaft_friction.py): axial force = cutting force + friction_per_length
# x depth while cutting, -friction_per_length x depth while withdrawing, to
# 1e-9 N at every step, on two grids and two channel spacings.
nh_add_py_test(shaft_friction verify shaft_friction.py)
# A needle at constant speed cuts at every step, its axial force F_c + the
# shaft's friction (tests/cut_steady.py; issue 29's chatter).
nh_add_py_test(cut_steady verify cut_steady.py)
