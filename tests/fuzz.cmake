# Fuzz targets (tests/fuzz/): the scene reader, the template loader, and the
# readers of the files a scene names: NIfTI images, STL surfaces,
# checkpoints, 3D Slicer markups (docs/reliability.md).
#
# In every build, replay_TARGET runs each target's entry point over its seed
# corpus (cases/, tests/bad/, tests/data/, templates/; for the file readers
# the files tests/bad/files/make_bad_files.py writes, made by the fixture
# test fuzz_corpus) and over the inputs the fuzzer once crashed on
# (tests/fuzz/regressions/TARGET/), label bad-input. With -DNH_FUZZ=ON
# (clang, tools/fuzz.sh) the libFuzzer binaries fuzz_TARGET are built as well.
foreach(target scene template nifti stl checkpoint markups)
  add_executable(replay_${target} fuzz/replay.c fuzz/fuzz_${target}.c)
  target_link_libraries(replay_${target} PRIVATE needlehex_lib)
  if(NH_FUZZ)
    add_executable(fuzz_${target} fuzz/fuzz_${target}.c)
    target_link_libraries(fuzz_${target} PRIVATE needlehex_lib)
    target_link_options(fuzz_${target} PRIVATE -fsanitize=fuzzer)
  endif()
endforeach()
set(NH_SRC ${PROJECT_SOURCE_DIR})
set(NH_CORPUS ${CMAKE_CURRENT_BINARY_DIR}/fuzz_corpus)
add_test(NAME fuzz_replay_scene COMMAND replay_scene ${NH_SRC}/cases ${NH_SRC}/cases/dbs
  ${NH_SRC}/cases/phantom ${NH_SRC}/tests/bad ${NH_SRC}/tests/data)
# (no scene input has crashed the reader yet: the first one found goes to
# tests/fuzz/regressions/scene/, and that folder into the list above)
add_test(NAME fuzz_replay_template COMMAND replay_template ${NH_SRC}/templates
  ${NH_SRC}/templates/bad ${NH_SRC}/tests/fuzz/regressions/template)
add_test(NAME fuzz_corpus COMMAND ${NH_PYTHON} ${NH_SRC}/tests/bad/files/make_bad_files.py
  ${CMAKE_CURRENT_BINARY_DIR}/fuzz_corpus_cases --binary $<TARGET_FILE:needlehex>
  --corpus ${NH_CORPUS})
set_tests_properties(fuzz_corpus PROPERTIES FIXTURES_SETUP fuzz_corpus)
add_test(NAME fuzz_replay_nifti COMMAND replay_nifti ${NH_SRC}/cases/dbs-mri/ventricles.nii.gz
  ${NH_SRC}/cases/steering/obstacle.nii.gz ${NH_CORPUS}/nifti)
add_test(NAME fuzz_replay_stl COMMAND replay_stl ${NH_CORPUS}/stl
  ${NH_SRC}/tests/fuzz/regressions/stl)
add_test(NAME fuzz_replay_checkpoint COMMAND replay_checkpoint ${NH_CORPUS}/checkpoint
  ${NH_SRC}/tests/fuzz/regressions/checkpoint)
set_tests_properties(fuzz_replay_nifti fuzz_replay_stl fuzz_replay_checkpoint PROPERTIES
  FIXTURES_REQUIRED fuzz_corpus)
# markups: the case's plan and the .mrk.json and .fcsv files test_markups
# writes (good ones in RAS/LPS, mm/um, and its malformed ones).
add_test(NAME fuzz_replay_markups COMMAND replay_markups ${NH_SRC}/cases/dbs-mri/plan.mrk.json
  ${CMAKE_CURRENT_BINARY_DIR}/markups_scratch)
# (no markups input has crashed the reader yet: the first one found goes to
# tests/fuzz/regressions/markups/, and that folder into the list above)
set_tests_properties(fuzz_replay_markups PROPERTIES FIXTURES_REQUIRED nh_markups_files)
set_tests_properties(fuzz_corpus fuzz_replay_scene fuzz_replay_template fuzz_replay_nifti
  fuzz_replay_stl fuzz_replay_checkpoint fuzz_replay_markups PROPERTIES LABELS bad-input)
