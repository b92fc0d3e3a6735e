# scene module: unit test of nh_scene_load (fixtures written by the test itself)
# and the bad-input suite that runs `needlehex check` on tests/bad/*.yaml.
nh_add_c_test(test_scene unit)
nh_add_py_test(bad_input bad-input bad_input.py)
# Under the sanitizers (Debug, 5-10 times slower) the time and memory limits
# are recorded and printed, not asserted.
if(NH_SANITIZE)
  set_property(TEST bad_input APPEND PROPERTY ENVIRONMENT NH_SANITIZED=1)
endif()
# Planned trajectories, gravity schedules and buoyancy through the binary
# (tests/plan.py): the tip on the target and back at its start in a rigid
# block along a line of nodes, buoyancy against plain gravity, a scheduled
# gravity on a tool. The oblique path's tip-on-target check (label hard): the
# puncture must not bend the needle sideways (docs/interaction.md, Puncture).
nh_add_py_test(plan verify plan.py)
nh_add_py_test(plan_oblique hard plan.py --oblique)
