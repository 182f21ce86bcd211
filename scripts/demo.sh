#!/usr/bin/env bash
# Installs missing Debian packages, builds evio and runs its main job on the embedded default:
# `evio simulate` renders 8 s of the poster_6dof scene of datasets/ (DAVIS240C, 6-DoF motion,
# sensor noise, 1 kHz IMU, ground truth) into an Event Camera Dataset folder (kept and reused on
# later runs), `evio vio` estimates the trajectory from events and IMU and evaluates it against the
# ground truth, and `evio eval --plot` draws the trajectory and error plots.
#   scripts/demo.sh [OUT_DIR]      (default build/demo)
set -euo pipefail
cd "$(dirname "$0")/.."
[ "${EVIO_SKIP_DEPS:-0}" = 1 ] || bash scripts/setup_deps.sh
build_dir=${BUILD_DIR:-build}
jobs=$(nproc 2>/dev/null || echo 2)
cmake -S . -B "$build_dir" -DCMAKE_BUILD_TYPE="${BUILD_TYPE:-Release}" >/dev/null
cmake --build "$build_dir" -j"$jobs" --target evio
evio="$build_dir/apps/evio"
out=${1:-$build_dir/demo}
seq="$out/poster_6dof_8s"
if [ -f "$seq/simulation.json" ] && [ -f "$seq/events.txt" ]; then
  echo "== reusing the simulated sequence in $seq"
else
  rm -rf "$seq"
  echo "== evio simulate datasets/poster_6dof.yaml --duration 8 --out $seq"
  "$evio" simulate datasets/poster_6dof.yaml --duration 8 --out "$seq"
fi
echo
echo "== evio vio $seq --out $out/vio --config datasets/vio/simulator.yaml --gt $seq/groundtruth.txt"
"$evio" vio "$seq" --out "$out/vio" --config datasets/vio/simulator.yaml --gt "$seq/groundtruth.txt"
echo
echo "== evio eval (table and plots of the estimate against the ground truth)"
"$evio" -q eval "$seq/groundtruth.txt" "$out/vio/trajectory.tum" --align se3 --align-first-s 5 \
  --out "$out/eval" --plot "$out/eval/plots"
echo
echo "outputs: $out/vio (trajectory.tum, keyframes.txt, map.ply, stats.json, eval.json), plots in $out/eval/plots"
