# Step guards (tests/invalid_steps.py): absurd physics (a soft or overloaded
# block, a needle too fast for its cells) ends with exit 1 naming the step and
# the reason and no output after the last plausible step; on_invalid: warn
# goes on; the dynamic step's residual and solver.newton.
nh_add_py_test(invalid_steps hard invalid_steps.py)
