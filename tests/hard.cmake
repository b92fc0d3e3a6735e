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
#   static-push: quasi-static, 2 mm per pseudo-step, mu 0.1, 10 kPa (main:
#     step 7; with the tied set's hysteresis, docs/interaction.md
#     "Hysteresis of the tied set": step 13). Not yet passing: every
#     constraint solve is exact (residual <= 1e-14) and the tied set and
#     stick/slip states settle, but the outer Newton contracts by ~0.6 per
#     iteration (not the beam tangent: its full, unsymmetric form changes
#     nothing, "Which tangent limits the rate") and 30 iterations of 16 load steps
#     miss 1e-8. Kept disabled until then.
nh_add_py_test(hard_static_push hard hard.py static-push)
set_tests_properties(hard_static_push PROPERTIES DISABLED TRUE)
#   static-push up to step 12: past main's failure at step 7 (the newest
#     channel point toggled tied/untied within the Newton iteration), which
#     the tied set's hysteresis removes.
nh_add_py_test(hard_static_push_12 hard hard.py static-push:12)
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
