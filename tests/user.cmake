# What a user meets first: the installed program, the docs' snippets, the
# pictures of a run.
# install: `cmake --install` into a scratch prefix; the installed binary finds
# its templates next to itself and prints the git revision (tests/install.py).
nh_add_py_test(install io install.py ${CMAKE_COMMAND} ${PROJECT_BINARY_DIR})
# render: tools/render.py on a short DBS run makes PNGs of the requested size
# that are not blank, frames.csv, view.py and (with ffmpeg) an MP4; skipped
# (77) without a display or xvfb-run.
nh_add_py_test(render io render.py)
set_tests_properties(render PROPERTIES SKIP_RETURN_CODE 77 TIMEOUT 300)
# docs: every snippet of README.md and docs/*.md runs (tests/docs.py). In the
# Release build only: the snippets run whole cases, which under the
# sanitizers take longer than CI allows, and the code paths they reach are
# the other tests' (which run under ASan + UBSan).
if(NOT NH_SANITIZE)
  nh_add_py_test(docs verify docs.py)
  set_tests_properties(docs PROPERTIES TIMEOUT 900 LABELS "verify;slow")
endif()
