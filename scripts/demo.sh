#!/usr/bin/env bash
# Installs missing Debian packages, builds evio and runs it on its embedded default: `evio
# simulate` renders 1 s of the poster_6dof scene of datasets/ (DAVIS240C, 6-DoF, sensor noise,
# 1 kHz IMU, APS frames, ground truth) into an Event Camera Dataset folder, `evio info` summarises
# it, `evio convert` writes it to HDF5 and `evio info` summarises that. With ../shared/data/real
# present, also a real recording.
#   scripts/demo.sh [OUT_DIR]      (default build/demo)
set -euo pipefail
cd "$(dirname "$0")/.."
[ "${EVIO_SKIP_DEPS:-0}" = 1 ] || bash scripts/setup_deps.sh
build_dir=${BUILD_DIR:-build}
jobs=$(nproc 2>/dev/null || echo 2)
cmake -S . -B "$build_dir" -DCMAKE_BUILD_TYPE="${BUILD_TYPE:-Release}" >/dev/null
cmake --build "$build_dir" -j"$jobs" --target evio
out=${1:-$build_dir/demo}
rm -rf "$out/sequence"
echo "== evio simulate datasets/poster_6dof.yaml --duration 1 --out $out/sequence"
"$build_dir/apps/evio" simulate datasets/poster_6dof.yaml --duration 1 --out "$out/sequence"
echo
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
