# SPR error estimation and marking (adapt/spr.c, adapt/mark.c, fem/stress.c).
nh_add_c_test(test_spr verify)
