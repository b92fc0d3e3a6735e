# scene module: unit test of nh_scene_load (fixtures written by the test itself)
# and the bad-input suite that runs `needlehex check` on tests/bad/*.yaml.
nh_add_c_test(test_scene unit)
nh_add_py_test(bad_input bad-input bad_input.py)
