#!/usr/bin/env bash
# Install dependencies, build, and run the test suite (ctest).
#   tools/test.sh              Release build in build/, all tests (what CI runs)
#   tools/test.sh --sanitize   Debug build with -fsanitize=address,undefined in build-asan/
#   tools/test.sh --quick      the tests without the label `slow` (ctest -LE slow):
#                              about 4 minutes in Release (README.md)
# The options combine (--sanitize --quick).
set -euo pipefail
cd "$(dirname "$0")/.."
sanitize=0
select=()
for arg in "$@"; do
  case "$arg" in
  --sanitize) sanitize=1 ;;
  --quick) select=(-LE slow) ;;
  *)
    echo "usage: tools/test.sh [--sanitize] [--quick]" >&2
    exit 2
    ;;
  esac
done
tools/install-deps.sh
if [ "$sanitize" = 1 ]; then
  dir=build-asan
  cmake -S . -B "$dir" -DCMAKE_BUILD_TYPE=Debug -DNH_SANITIZE=ON >/dev/null
  export ASAN_OPTIONS=detect_leaks=1:abort_on_error=1
  export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
else
  dir=build
  cmake -S . -B "$dir" -DCMAKE_BUILD_TYPE=Release >/dev/null
fi
cmake --build "$dir" -j"$(nproc)"
ctest --test-dir "$dir" --output-on-failure -j"$(nproc)" ${select[@]+"${select[@]}"}
