#!/usr/bin/env bash
# Install dependencies, build needlehex (Release) and run a case.
#   tools/run-case.sh [SCENE.yaml] [needlehex run options...]
# Default: cases/phantom-tissue.yaml, outputs in out/phantom-tissue/.
set -euo pipefail
cd "$(dirname "$0")/.."
tools/install-deps.sh
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build build -j"$(nproc)"
scene=${1:-cases/phantom-tissue.yaml}
shift || true
build/needlehex run "$scene" --overwrite "$@"
