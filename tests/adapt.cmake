# adaptivity: refinement templates (templates/*.tmpl and templates/bad/*.tmpl).
nh_add_c_test(test_template unit)
# The refinement driver: DOF budget and Eq. 17 transfer (adapt/refine.c).
nh_add_c_test(test_adapt_step unit)

# Grading (2:1 rule) and coarsening (mesh/grade.c, mesh/coarsen.c).
nh_add_c_test(test_grade unit)
