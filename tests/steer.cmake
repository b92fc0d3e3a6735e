# Steering: the planner's kinematic (bicycle) model and obstacle distances
# (tests/test_steer.c); `needlehex plan` for a bevel-tip needle in a rigid-like
# block against the bicycle model's closed form (tests/steer_plan.py); the
# torsional friction's steady twist lag against GJ (tests/torsion.py).
nh_add_c_test(test_steer unit)
nh_add_py_test(torsion verify torsion.py)
nh_add_py_test(steer_plan "verify;slow" steer_plan.py)
