# Outputs on the patient's images and markups in and out (docs/anatomy.md,
# "Markups", "Displacement fields and shifted images").
#
# test_markups: Slicer .mrk.json and .fcsv in RAS and LPS, mm and um, give
# the same scene point; every reader error names the file; the writer's
# Curve and Fiducials read back. It leaves its written files in a scratch
# folder that markups_schema.py checks against the fields Slicer's schema
# and reader use (fixture: test_markups runs first).
set(NH_MARKUPS_SCRATCH ${CMAKE_CURRENT_BINARY_DIR}/markups_scratch)
file(MAKE_DIRECTORY ${NH_MARKUPS_SCRATCH})
nh_add_c_test(test_markups io ${NH_MARKUPS_SCRATCH})
set_tests_properties(test_markups PROPERTIES FIXTURES_SETUP nh_markups_files)
nh_add_py_test(markups_schema io markups_schema.py ${NH_MARKUPS_SCRATCH})
set_tests_properties(markups_schema PROPERTIES FIXTURES_REQUIRED nh_markups_files)

# test_sample: the nodal field at points and voxel centres of a refined mesh
# with hanging nodes (exact for a linear field, continuous across refinement
# faces, the lattice walk equal to nh_mesh_locate), the tissue mask, the
# inverse map of a linear and of a smooth displacement (iterations against
# the contraction bound) and the warped image against the analytic warp.
nh_add_c_test(test_sample verify)

# nifti_field.py: the displacement field written by a small driver
# (nifti_field_tool) on a reference image, read back with nibabel (header,
# values, a flipped-axis reference), applied to a labelled ball by an
# independent resampler (nibabel affines + scipy.ndimage) and by elastix's
# transformix (image and points), the mask and the scalar writer.
add_executable(nifti_field_tool nifti_field_tool.c)
target_link_libraries(nifti_field_tool PRIVATE needlehex_lib)
nh_add_py_test(nifti_field "io;verify" nifti_field.py $<TARGET_FILE:nifti_field_tool>)

# dbs_mri_outputs.py: cases/dbs-mri's brain shift (3 s) end to end: the plan
# from an LPS .mrk.json equals the same points as a RAS .fcsv and the
# analytic conversion; the displacement field's header is the T1's (ITK),
# its value at the STN is targets.csv's displacement (0.1 mm); a 5 mm ball
# warped with the tissue moves with the STN (half a voxel) and agrees with an
# independent resampler; the markups written match targets.csv and tools.csv.
nh_add_py_test(dbs_mri_outputs "io;verify" dbs_mri_outputs.py $<TARGET_FILE:needlehex>)
