# The readers of the files a scene names: NIfTI images, STL surfaces,
# refinement templates, checkpoints (docs/reliability.md, "File readers").
# bad_files: tests/bad/files/make_bad_files.py writes a few hundred malformed
# or unusual files, each named by a small scene; every bad one must exit 2
# with one line naming the file, the key and the problem, every control
# exit 0, each under 10 s and 600 MB (tests/bad_files.py).
nh_add_py_test(bad_files "bad-input;slow" bad_files.py)
set_tests_properties(bad_files PROPERTIES TIMEOUT 900)
