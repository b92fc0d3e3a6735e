# Hard scenes (issue 27, tests/hard/, docs/cases.md "Hard cases"): each ends
# with its declared outcome (exit 0, or exit 1 for a named physical reason),
# every constraint solve within its tolerance and no step unsolved
# (tests/hard.py). A scene that fails for a reason that is not physical stays
# registered with its expected outcome, marked WILL_FAIL with the reason.
foreach(scene bevel-friction bevel-0-friction bevel-4-friction bevel-15-friction
        bevel-30-friction nu-04999-needle nu-04999-cantilever soft-100pa
        soft-100pa-overload stiff-1mpa step-1mm step-4mm grid-4x4x4 levels-2 levels-3
        nested skull-nested static-skull static-large-rotation mask-obstacle mask-domain)
  string(REPLACE "-" "_" test ${scene})
  nh_add_py_test(hard_${test} hard hard.py ${scene})
endforeach()
nh_add_py_test(hard_grid_fine slow hard.py grid-fine)
set_tests_properties(hard_grid_fine PROPERTIES LABELS "hard;slow")
nh_add_py_test(hard_bevel_series hard hard.py --bevel-series)
#   static-push: quasi-static, 2 mm per pseudo-step, mu 0.1, 10 kPa: was
#     disabled (step 13 failed); runs on main 7260008 already (6-9 coupled
#     Newton iterations per pseudo-step, none split), 5-8 with the tissue's
#     consistent tangent in the coupled step (docs/interaction.md).
nh_add_py_test(hard_static_push hard hard.py static-push)
# Known failures (findings, not physical reasons; docs/cases.md "Hard cases"):
#   nu-04999-needle: 6 of 50 steps unsolved from step 6 (Newton relative
#     residual 2.97; 45 of 50 with 5 iterations); not yet diagnosed: the
#     coupled step with tools does not use the consistent tangent (with the
#     B-bar pressure variation) that the static Newton without tools uses.
#   levels-2, levels-3: level-2 and level-3 cells invert at the tip before
#     the puncture (steps 14, 10) under the tip's point force (0.04-0.1 N on a
#     30 kPa gel needs cells larger than sqrt(F/E) ~ 1-2 mm).
# bevel-30-friction, mask-obstacle, mask-domain and grid-fine were findings
# until the channel points' default spacing became one cell edge (issue 26,
# docs/interaction.md "Why one point per cell"): at half a cell the tip
# stalled under self-equilibrated lateral forces and cells inverted.
set_tests_properties(hard_nu_04999_needle hard_levels_2 hard_levels_3
                     PROPERTIES WILL_FAIL TRUE)
