# Fuzz targets (tests/fuzz/): the scene reader and the template loader.
#
# In every build, replay_scene and replay_template run each target's entry
# point over its seed corpus (cases/, tests/bad/, tests/data/, templates/)
# and over the inputs the fuzzer once crashed on (tests/fuzz/regressions/),
# label bad-input. With -DNH_FUZZ=ON (clang, tools/fuzz.sh) the libFuzzer
# binaries fuzz_scene and fuzz_template are built as well.
foreach(target scene template)
  add_executable(replay_${target} fuzz/replay.c fuzz/fuzz_${target}.c)
  target_link_libraries(replay_${target} PRIVATE needlehex_lib)
  if(NH_FUZZ)
    add_executable(fuzz_${target} fuzz/fuzz_${target}.c)
    target_link_libraries(fuzz_${target} PRIVATE needlehex_lib)
    target_link_options(fuzz_${target} PRIVATE -fsanitize=fuzzer)
  endif()
endforeach()
set(NH_SRC ${PROJECT_SOURCE_DIR})
add_test(NAME fuzz_replay_scene COMMAND replay_scene ${NH_SRC}/cases ${NH_SRC}/cases/dbs
  ${NH_SRC}/cases/phantom ${NH_SRC}/tests/bad ${NH_SRC}/tests/data)
# (no scene input has crashed the reader yet: the first one found goes to
# tests/fuzz/regressions/scene/, and that folder into the list above)
add_test(NAME fuzz_replay_template COMMAND replay_template ${NH_SRC}/templates
  ${NH_SRC}/templates/bad ${NH_SRC}/tests/fuzz/regressions/template)
set_tests_properties(fuzz_replay_scene fuzz_replay_template PROPERTIES LABELS bad-input)
