#!/usr/bin/env bash
# Fuzz the scene reader, the template loader and the readers of the files a
# scene names (NIfTI images, STL surfaces, checkpoints, 3D Slicer markups) with clang's
# libFuzzer under AddressSanitizer + UndefinedBehaviorSanitizer.
#   tools/fuzz.sh SECONDS [TARGET...]    each target for SECONDS (CI: 60);
#                                        targets: scene template nifti stl checkpoint
#                                        markups
# Builds build-fuzz/ (clang, -DNH_FUZZ=ON), seeds each corpus from cases/,
# tests/, templates/, nibabel's test images and the files
# tests/bad/files/make_bad_files.py and test_markups write, and runs the
# targets in turn.
# The corpora grow in build-fuzz/corpus/TARGET. A crash (or an input-error
# message that is not "FILE[:LINE]: ..." on one printable line:
# tests/fuzz/fuzz_common.h) stops with exit 1 and leaves the input as
# build-fuzz/crash-TARGET-*: copy it to tests/fuzz/regressions/TARGET/ with
# a name saying what it broke, fix the bug, and the replay test keeps it fixed.
set -euo pipefail
cd "$(dirname "$0")/.."
seconds=${1:?usage: tools/fuzz.sh SECONDS [TARGET...]}
shift
targets=${*:-scene template nifti stl checkpoint markups}
dir=build-fuzz
CC=clang cmake -S . -B "$dir" -DCMAKE_BUILD_TYPE=Debug -DNH_FUZZ=ON >/dev/null
cmake --build "$dir" -j"$(nproc)" --target needlehex test_markups $(for t in $targets; do echo fuzz_$t; done) \
  >/dev/null
export ASAN_OPTIONS=detect_leaks=1:abort_on_error=1
export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
for t in scene template nifti stl checkpoint markups; do mkdir -p "$dir/corpus/$t"; done
# The malformed files of the bad-input test, as seeds (ASAN_OPTIONS: the
# needlehex of this build makes the checkpoints they start from; without leak
# detection, which the sanitizer suite does: clang 14's LeakSanitizer crashes
# in some runs on a dynamic TLS block of Debian 12's glibc, "Tracer caught
# signal 11" at its bogus address, before it looks at any leak).
ASAN_OPTIONS=detect_leaks=0:abort_on_error=1 /usr/bin/python3 tests/bad/files/make_bad_files.py \
  "$dir/bad" --binary "$dir/needlehex" --corpus "$dir/corpus" >/dev/null
cp cases/*.yaml cases/*/*.yaml tests/bad/*.yaml tests/data/*.yaml tests/fuzz/regressions/scene/* \
  "$dir/corpus/scene/" 2>/dev/null || true
cp templates/*.tmpl templates/bad/* tests/fuzz/regressions/template/* "$dir/corpus/template/" \
  2>/dev/null || true
cp cases/*/*.nii.gz /usr/lib/python3/dist-packages/nibabel/tests/data/*.nii* \
  tests/fuzz/regressions/nifti/* "$dir/corpus/nifti/" 2>/dev/null || true
cp tests/fuzz/regressions/stl/* "$dir/corpus/stl/" 2>/dev/null || true
cp tests/fuzz/regressions/checkpoint/* "$dir/corpus/checkpoint/" 2>/dev/null || true
# markups: the case's plan and the good and malformed files test_markups writes
"$dir/tests/test_markups" "$dir/markups_seed" >/dev/null 2>&1 || true
cp cases/*/*.mrk.json "$dir"/markups_seed/* tests/fuzz/regressions/markups/* "$dir/corpus/markups/" \
  2>/dev/null || true
status=0
for target in $targets; do
  case $target in scene | template) max_len=8192 ;; *) max_len=65536 ;; esac
  echo "fuzz_$target: $seconds s"
  if ! TMPDIR="$PWD/$dir" "$dir/tests/fuzz_$target" -max_total_time="$seconds" -timeout=10 \
    -rss_limit_mb=2048 -max_len=$max_len -close_fd_mask=3 -print_final_stats=1 \
    -artifact_prefix="$dir/crash-$target-" "$dir/corpus/$target" 2>"$dir/fuzz_$target.log"; then
    echo "fuzz_$target: FAILED (input and report: $dir/crash-$target-*, $dir/fuzz_$target.log)"
    tail -40 "$dir/fuzz_$target.log"
    status=1
  else
    grep -E "stat::number_of_executed_units|stat::new_units_added" "$dir/fuzz_$target.log" |
      sed "s/^/fuzz_$target: /"
  fi
done
exit $status
