# io module tests (label io).
#
# test_io writes VTU/PVD/CSV files with known contents into a fixed scratch
# folder; io_readback reads that folder back with VTK and meshio. The fixture
# makes ctest run test_io first (also under -R io_readback) and skip
# io_readback when test_io fails.
set(NH_IO_SCRATCH ${CMAKE_CURRENT_BINARY_DIR}/io_scratch)

nh_add_c_test(test_io io ${NH_IO_SCRATCH})
set_tests_properties(test_io PROPERTIES FIXTURES_SETUP nh_io_files)

nh_add_py_test(io_readback io io_readback.py ${NH_IO_SCRATCH})
set_tests_properties(io_readback PROPERTIES FIXTURES_REQUIRED nh_io_files)

# End to end: runs needlehex on cases/phantom-tissue.yaml and checks that its
# VTU, PVD and CSV outputs agree. Exit 77 (skipped) while the case file does
# not exist yet.
nh_add_py_test(run_readback io run_readback.py)
set_tests_properties(run_readback PROPERTIES SKIP_RETURN_CODE 77 TIMEOUT 600)

# Output folder hygiene: a run into another run's folder is refused (exit 2)
# unless --overwrite (removes that run's files, not the user's) or --restart.
nh_add_py_test(output_folder io output_folder.py)
