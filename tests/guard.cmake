# Step guards (tests/invalid_steps.py): absurd physics (a soft or overloaded
# block, a needle too fast for its cells) ends with exit 1 naming the step and
# the reason and no output after the last plausible step; on_invalid: warn
# goes on; the dynamic step's residual and solver.newton.
nh_add_py_test(invalid_steps hard invalid_steps.py)

# unsolved.py: steps whose relative residual stayed above its bound are
# flagged in steps.csv (`unsolved`) and warned about (dbs.yaml at nu 0.4999:
# every step; at 0.45 none; a body at rest after the needle left: none).
nh_add_py_test(unsolved verify unsolved.py $<TARGET_FILE:needlehex>)

# cholmod_memory.py: a factorisation larger than the memory limit is named
# ("CHOLMOD ran out of memory in the factorisation of N unknowns"), exit 1.
# Not under the sanitizers: ASan reserves terabytes of address space for its
# shadow memory, so an address-space limit stops the process before main.
if(NOT NH_SANITIZE)
  nh_add_py_test(cholmod_memory verify cholmod_memory.py $<TARGET_FILE:needlehex>)
endif()

# static_failures.py: a static step that cannot be solved stops at once with
# exit 1 naming where and why (an unsupported body: singular tangent; a
# body held by a tiny tie off its centre of mass: no progress in 3
# iterations); a hard but converging Newton (the cantilever at 0.2 N) is not
# stopped by the rule. Slow: the soft brain on the skull tries its first
# load step in 1, 2, 4, 8 and 16 parts (about 11 s).
nh_add_py_test(static_failures "verify;slow" static_failures.py)
if(NH_SANITIZE)
  set_property(TEST static_failures APPEND PROPERTY ENVIRONMENT NH_SANITIZED=1)
endif()

# counters.py: steps.csv's factorised and tangent_updates count every
# Newton correction's factorisation and every load step of a static step.
nh_add_py_test(counters verify counters.py)
