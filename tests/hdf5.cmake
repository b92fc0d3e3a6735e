# HDF5 results writer tests (label io).
#
# test_hdf5 writes results.h5 / results.xdmf with known contents into a fixed
# scratch folder; hdf5_readback reads them back with h5py and meshio (a
# fixture runs test_hdf5 first and skips the readback when it fails).
# hdf5_kill runs `test_hdf5 --endless` and SIGKILLs it at random instants,
# then checks that every frame results.xdmf lists reads back exactly.
set(NH_HDF5_SCRATCH ${CMAKE_CURRENT_BINARY_DIR}/hdf5_scratch)

nh_add_c_test(test_hdf5 io ${NH_HDF5_SCRATCH})
set_tests_properties(test_hdf5 PROPERTIES FIXTURES_SETUP nh_hdf5_files)

nh_add_py_test(hdf5_readback io hdf5_readback.py check ${NH_HDF5_SCRATCH})
set_tests_properties(hdf5_readback PROPERTIES FIXTURES_REQUIRED nh_hdf5_files)

nh_add_py_test(hdf5_kill "io;slow" hdf5_readback.py kill $<TARGET_FILE:test_hdf5>
  ${CMAKE_CURRENT_BINARY_DIR}/hdf5_kill 30)
set_tests_properties(hdf5_kill PROPERTIES TIMEOUT 300)

# A full disk during a run (a tmpfs of random size; needs root to mount,
# else skipped): exit 1 with "No space left on device" and the step, no
# *.tmp left, every file written so far readable. 5 trials here, the
# 20-trial campaign under `slow`.
nh_add_py_test(disk_full io disk_full.py 5)
set_tests_properties(disk_full PROPERTIES SKIP_RETURN_CODE 77 TIMEOUT 300)
nh_add_py_test(disk_full_campaign io disk_full.py 20)
set_tests_properties(disk_full_campaign PROPERTIES SKIP_RETURN_CODE 77 TIMEOUT 600 LABELS "io;slow")
