#!/usr/bin/env bash
# Fuzz the scene reader and the template loader with clang's libFuzzer under
# AddressSanitizer + UndefinedBehaviorSanitizer.
#   tools/fuzz.sh SECONDS      each target for SECONDS (CI: 60)
# Builds build-fuzz/ (clang, -DNH_FUZZ=ON), seeds each corpus from cases/,
# tests/ and templates/, and runs fuzz_scene and fuzz_template in turn. The
# corpora grow in build-fuzz/corpus/TARGET. A crash (or an input-error
# message that is not "FILE:LINE: ..." on one printable line:
# tests/fuzz/fuzz_common.h) stops with exit 1 and leaves the input as
# build-fuzz/crash-TARGET-*: copy it to tests/fuzz/regressions/TARGET/ with
# a name saying what it broke, fix the bug, and the replay test keeps it fixed.
set -euo pipefail
cd "$(dirname "$0")/.."
seconds=${1:?usage: tools/fuzz.sh SECONDS}
dir=build-fuzz
CC=clang cmake -S . -B "$dir" -DCMAKE_BUILD_TYPE=Debug -DNH_FUZZ=ON >/dev/null
cmake --build "$dir" -j"$(nproc)" --target fuzz_scene fuzz_template >/dev/null
export ASAN_OPTIONS=detect_leaks=1:abort_on_error=1
export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
mkdir -p "$dir/corpus/scene" "$dir/corpus/template"
cp cases/*.yaml cases/*/*.yaml tests/bad/*.yaml tests/data/*.yaml tests/fuzz/regressions/scene/* \
  "$dir/corpus/scene/" 2>/dev/null || true
cp templates/*.tmpl templates/bad/* tests/fuzz/regressions/template/* "$dir/corpus/template/" \
  2>/dev/null || true
status=0
for target in scene template; do
  echo "fuzz_$target: $seconds s"
  if ! TMPDIR="$PWD/$dir" "$dir/tests/fuzz_$target" -max_total_time="$seconds" -timeout=10 \
    -rss_limit_mb=2048 -max_len=8192 -close_fd_mask=3 -print_final_stats=1 \
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
