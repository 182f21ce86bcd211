#!/usr/bin/env bash
# Generates one sequence with the crosscheck simulator (a second event-camera simulator, written
# separately from evio: ../shared/crosscheck_sim/crosssim.py), for the sweep specs that check evio
# on data it was not developed on (datasets/sweeps/vio_crosscheck.yaml).
#   scripts/crosscheck_generate.sh OUT PRESET SEED [crosssim generate options ...]
# e.g. scripts/crosscheck_generate.sh /tmp/p6 planes_random6dof 303 --set frames_hz=20
# The simulator is found at $EVIO_CROSSCHECK_SIM (the crosssim.py file), else at
# ../shared/crosscheck_sim/crosssim.py beside the repository; without it the script exits with
# code 77 and says so (the sweep then skips the dataset). Its texture photos (Debian's opencv-doc)
# are fetched once into $EVIO_CROSSCHECK_IMAGES (default ${XDG_CACHE_HOME:-~/.cache}/evio/crosscheck_images),
# together with the synthetic textures evio's variants name: blank.png (uniform grey, for a pass
# over a wall without texture). Needs /usr/bin/python3 with numpy, scipy and OpenCV (Debian's
# python3-numpy, python3-scipy, python3-opencv: `scripts/setup_deps.sh python3-scipy python3-opencv`;
# without them this script exits 77 and the tests that use it skip).
# With $EVIO_CROSSCHECK_CACHE set, each sequence is generated once into that folder, under a key
# of the simulator file's checksum and the arguments, and OUT is a symbolic link to it (sweeps into
# new folders then reuse the sequences); `--key PRESET SEED [options]` prints the key.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
sim=${EVIO_CROSSCHECK_SIM:-$root/../shared/crosscheck_sim/crosssim.py}
key() {  # the cache key of PRESET SEED [options]
  { sha1sum < "$sim" | cut -d' ' -f1; printf '%s\n' "$@"; } | sha1sum | cut -c1-16
}
if [ "${1:-}" = --key ]; then
  shift
  [ -f "$sim" ] || { echo "crosscheck simulator not found at $sim" >&2; exit 77; }
  key "$@"
  exit 0
fi
if [ $# -lt 3 ]; then
  echo "usage: $0 OUT PRESET SEED [crosssim generate options ...]" >&2
  exit 2
fi
out=$1 preset=$2 seed=$3
shift 3
if [ ! -f "$sim" ]; then
  echo "crosscheck simulator not found at $sim (set EVIO_CROSSCHECK_SIM to its crosssim.py)" >&2
  exit 77
fi
py=/usr/bin/python3
if ! "$py" -c 'import numpy, scipy, cv2' 2>/dev/null; then
  echo "the crosscheck simulator needs $py with numpy, scipy and cv2 (apt-get install python3-numpy python3-scipy python3-opencv)" >&2
  exit 77
fi
images=${EVIO_CROSSCHECK_IMAGES:-${XDG_CACHE_HOME:-$HOME/.cache}/evio/crosscheck_images}
mkdir -p "$images"
# The photos, once (concurrent sweeps: one fetch at a time under a lock).
(
  flock 9
  if [ ! -f "$images/.fetched" ]; then
    "$py" "$sim" fetch-images --dest "$images" >&2
    touch "$images/.fetched"
  fi
  if [ ! -f "$images/blank.png" ]; then
    "$py" -c "import cv2, numpy as np, sys; cv2.imwrite(sys.argv[1], np.full((768, 1024), 128, np.uint8))" "$images/blank.png"
  fi
) 9>"$images/.lock"
extra=()
if [ "$preset" = planes_quadrotor ]; then
  extra=(--traj-file "$(dirname "$sim")/traj/quadrotor_circles.csv")
fi
if [ -n "${EVIO_CROSSCHECK_CACHE:-}" ]; then
  cached=$EVIO_CROSSCHECK_CACHE/$(key "$preset" "$seed" "$@")
  if [ ! -f "$cached/meta.json" ]; then
    rm -rf "$cached"
    mkdir -p "$EVIO_CROSSCHECK_CACHE"
    "$py" "$sim" generate --preset "$preset" --seed "$seed" --out "$cached" --image-dir "$images" --workers 1 "${extra[@]}" "$@"
  fi
  rm -rf "$out"
  ln -s "$cached" "$out"
  exit 0
fi
exec "$py" "$sim" generate --preset "$preset" --seed "$seed" --out "$out" --image-dir "$images" --workers 1 "${extra[@]}" "$@"
