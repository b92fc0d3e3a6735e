# Step guards (tests/invalid_steps.py): absurd physics (a soft or overloaded
# block, a needle too fast for its cells) ends with exit 1 naming the step and
# the reason and no output after the last plausible step; on_invalid: warn
# goes on; the dynamic step's residual and solver.newton.
nh_add_py_test(invalid_steps hard invalid_steps.py)

# unsolved.py: steps whose relative residual stayed above its bound are
# flagged in steps.csv (`unsolved`) and warned about (dbs.yaml at nu 0.4999:
# every step; at 0.45 none; a body at rest after the needle left: none).
nh_add_py_test(unsolved verify unsolved.py $<TARGET_FILE:needlehex>)
