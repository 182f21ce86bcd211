#!/usr/bin/env bash
# Installs missing Debian packages, builds evio and runs it on its embedded default: a synthetic
# Event Camera Dataset sequence written by the build (events, 1 kHz IMU, 100 Hz ground truth,
# calib.txt), summarised by `evio info`, converted to HDF5 with `evio convert` and summarised again.
# With ../shared/data/real present, also a real recording.
#   scripts/demo.sh [OUT_DIR]      (default build/demo)
set -euo pipefail
cd "$(dirname "$0")/.."
[ "${EVIO_SKIP_DEPS:-0}" = 1 ] || bash scripts/setup_deps.sh
build_dir=${BUILD_DIR:-build}
jobs=$(nproc 2>/dev/null || echo 2)
cmake -S . -B "$build_dir" -DCMAKE_BUILD_TYPE="${BUILD_TYPE:-Release}" >/dev/null
cmake --build "$build_dir" -j"$jobs" --target evio make_ecd_sequence
out=${1:-$build_dir/demo}
rm -rf "$out/sequence"
"$build_dir/bench/make_ecd_sequence" "$out/sequence" 500000 1e6 >/dev/null
echo "== evio info $out/sequence"
"$build_dir/apps/evio" info "$out/sequence" --sensor 240x180
echo
echo "== evio convert $out/sequence $out/sequence.h5 (lossless HDF5, DSEC layout), then evio info on it"
"$build_dir/apps/evio" -q convert "$out/sequence" "$out/sequence.h5" --sensor 240x180
"$build_dir/apps/evio" -q info "$out/sequence.h5"
real=../shared/data/real/ecd_slider_depth_head
if [ -d "$real" ]; then
  echo
  echo "== evio info $real (real DAVIS240C recording)"
  "$build_dir/apps/evio" info "$real" --sensor 240x180
fi
