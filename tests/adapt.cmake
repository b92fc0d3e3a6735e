# adaptivity: refinement templates (templates/*.tmpl and templates/bad/*.tmpl).
nh_add_c_test(test_template unit)
