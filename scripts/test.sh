#!/usr/bin/env bash
# Installs missing Debian packages, builds evio (Release, -O2) and runs the whole test suite.
#   scripts/test.sh [ctest args...]      e.g. scripts/test.sh -L unit   or   -R Ecd
# Environment: BUILD_DIR (default build), BUILD_TYPE (Release | Debug | Asan), EVIO_SKIP_DEPS=1.
set -euo pipefail
cd "$(dirname "$0")/.."
[ "${EVIO_SKIP_DEPS:-0}" = 1 ] || bash scripts/setup_deps.sh --tests
build_dir=${BUILD_DIR:-build}
jobs=$(nproc 2>/dev/null || echo 2)
cmake -S . -B "$build_dir" -DCMAKE_BUILD_TYPE="${BUILD_TYPE:-Release}"
cmake --build "$build_dir" -j"$jobs"
ctest --test-dir "$build_dir" -j"$jobs" --output-on-failure --timeout 600 "$@"
