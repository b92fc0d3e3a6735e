# The DBS case through the binary (tests/dbs.py): a planned trajectory puts
# the cannula's tip on the STN (1e-6 m) in a rigid brain; the whole
# procedure of cases/dbs/dbs.yaml, shortened, runs to its end with finite
# values, the brain shifting, the cannula back at its start and the
# electrode left in place.
nh_add_py_test(dbs verify dbs.py)
# Target compensation (tests/dbs.py --plan): `needlehex plan` on the shortened
# procedure gets the electrode within 0.5 mm of the STN in at most 6 runs,
# keeping the entry; on a rigid brain the first run is on the target.
nh_add_py_test(dbs_plan verify dbs.py --plan)
set_tests_properties(dbs_plan PROPERTIES TIMEOUT 600 LABELS "verify;slow")
# Quasi-static brain shift with skull contact (tests/static_skull.py): the
# STN of cases/dbs/dbs-skull-static.yaml against the dynamic run of
# dbs-skull.yaml (no tools) settled at 3 s, within the dynamic run's own
# settling amplitude; coarse 10 x 12 x 9 grid.
nh_add_py_test(static_skull verify static_skull.py)
set_tests_properties(static_skull PROPERTIES LABELS "verify;slow")
# The same with a cannula at rest outside the tissue: the STN as without it
# (tests/static_skull_tool.py; the quasi-static redo's lost predictor).
nh_add_py_test(static_skull_tool verify static_skull_tool.py)

# The skull's force in steps.csv balances the weight of a brain at rest in
# its skull (tests/skull_force.py).
nh_add_py_test(skull_force verify skull_force.py)
# The same under tissue.cut_cells: integrated (aggregated nodes, docs/theory.md §5c).
nh_add_py_test(skull_force_integrated verify skull_force.py tissue.cut_cells=integrated)
# On a grid with an odd cell count across x (a cell column holds both walls of
# the fissure: one skull point per wall, docs/theory.md §5c), both modes.
nh_add_py_test(skull_force_odd verify skull_force.py tissue.grid=[9,11,8] tissue.cut_cells=integrated)
nh_add_py_test(skull_force_odd_scaled verify skull_force.py tissue.grid=[9,11,8] tissue.cut_cells=scaled)
# The same with the weighted-gap rows (tissue.skull.rows: mortar, docs/theory.md §5c), an odd grid
# (slow: 41 s against 2 s, gap 0 gives every node near the surface a row; docs/dbs.md).
nh_add_py_test(skull_force_mortar verify skull_force.py tissue.grid=[9,11,8] tissue.cut_cells=integrated tissue.skull.rows=mortar)
set_tests_properties(skull_force_mortar PROPERTIES LABELS "verify;slow")
# The brain shift of dbs-skull.yaml on an odd grid (11 x 13 x 10) stays mirror
# symmetric to 1e-6 max|u| (no skull point on a crease of F; tests/skull_mirror.py).
nh_add_py_test(skull_mirror verify skull_mirror.py)
# The same with the weighted-gap rows (tissue.skull.rows: mortar): mirror-symmetric rows, net
# skull force without an x part, and shift.
nh_add_py_test(skull_mirror_mortar verify skull_mirror.py tissue.skull.rows=mortar)

# The per-step reference of tools/study.py dbs-goal (tools/richardson.py; tests/study_reference.py):
# Richardson through three meshes recovers f∞, the order and the error bar of
# f(h) = f∞ − C h^p; an order outside [1, 6) or differences changing sign fall
# back to the finest value with the last difference as its error bar.
nh_add_py_test(study_reference unit study_reference.py)

# tools/study.py convergence on synthetic run folders (tests/study_convergence.py): h
# from the scene's box, the shifts of a closed form f(h) = f∞ − C h^p tabulated, the
# observed order of every triple of consecutive grids (ratios not constant) and their
# spread; a run stopped by inverted cells is a row, left out of the triples.
nh_add_py_test(study_convergence unit study_convergence.py)

# tools/study.py --set (tests/study_set.py): the override reaches every run of a sweep and
# of the engine's variants, after their own sets (the cantilever's tip deflection scales as
# 1/E); the default folder carries its values; another study's option exits 2.
nh_add_py_test(study_set "unit;io" study_set.py)

# The DBS procedure's phases as the studies cut them (tests/study_phases.py): a whole
# procedure's tools.csv and a run that ends in the shift (--steps), phases by construction.
nh_add_py_test(study_phases unit study_phases.py)
