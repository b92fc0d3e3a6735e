# docs/design.md against the code (tests/design.py): the module layering (no
# src/<module>/*.[ch] includes a module above its own in the `layering:` line,
# nor another module's private header) and the page's references (every nh_
# name defined, every file there, each function in the file the page names).
nh_add_py_test(layering unit design.py layering)
nh_add_py_test(design_refs unit design.py refs)
# No malloc/calloc/realloc in src/ outside the checked allocator (core/error.c).
nh_add_py_test(design_alloc unit design.py alloc)
