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
#   nu-04999-needle: 5 of 50 steps unsolved (6 with the point rows before
#     the tip disc): exactly steps 6-10, the contact before the puncture.
#     Measured: not the constraint solve (its residual <= 7.8e-11 every
#     step) and not locking (probe lift 1.13 x the nu 0.45 run's); the
#     dynamic coupled step is linearised once (iterations = 1), and the
#     tissue's relative residual after it is 2.99 at step 6 falling to 1.20
#     at step 10, 0.49 at the puncture and <= 0.36 after: the linearisation
#     error of the B-bar internal force under the puncture load. A cure is
#     Newton iterations in the coupled dynamic step (not done).
#   levels-2, levels-3: level-2 and level-3 cells invert at the tip before
#     the puncture (steps 13, 10). The tip and puncture rows now act through
#     the needle's cross-section (docs/interaction.md, "Tip disc": mesh-
#     independent, tests/test_tip_disc.c), but the 0.4 mm disc under the
#     0.1 N puncture force compresses a linear 30 kPa gel by ~7
#     ((1 - nu)(1 + 2 nu) F / (pi a^2 E)): beyond the material model once the
#     cells resolve the disc. A hand-set 1.5 mm disc runs both (one unsolved
#     step in levels-3); 1 mm does not.
# bevel-30-friction, mask-obstacle, mask-domain and grid-fine were findings
# until the channel points' default spacing became one cell edge (issue 26,
# docs/interaction.md "Why one point per cell"): at half a cell the tip
# stalled under self-equilibrated lateral forces and cells inverted.
set_tests_properties(hard_nu_04999_needle hard_levels_2 hard_levels_3
                     PROPERTIES WILL_FAIL TRUE)
