# adaptivity: refinement templates (templates/*.tmpl and templates/bad/*.tmpl).
nh_add_c_test(test_template unit)
# The refinement driver: DOF budget and Eq. 17 transfer (adapt/refine.c).
nh_add_c_test(test_adapt_step unit)

# Grading (2:1 rule) and coarsening (mesh/grade.c, mesh/coarsen.c).
nh_add_c_test(test_grade unit)

# refine_cells_tool, the driver of docs/dbs.md's controlled local refinement
# (chosen level-0 cells refined before a chosen step, the goal printed per
# step), on the traction patch test: the exact linear field survives
# refinement before either step to round-off (tests/refine_cells.py).
add_executable(refine_cells_tool refine_cells_tool.c)
target_link_libraries(refine_cells_tool PRIVATE needlehex_lib)
nh_add_py_test(refine_cells "verify" refine_cells.py $<TARGET_FILE:refine_cells_tool>)
