#!/usr/bin/env bash
# Whole-process benchmark of `evio vio` (issue 16 acceptance tables):
#  1. per-sequence accuracy for each input (events, aps, events+aps): the poster-, boxes- and
#     shapes-like 6-DoF scenes, the room (DAVIS346, radtan, camera-IMU extrinsic) and the
#     quadrotor flight from a static start (10 s each) and the whole poster_6dof motion-capture
#     replay (59.8 s; needs the shared real data), each simulated once by `evio simulate` and kept
#     in SEQ_DIR, run with datasets/vio/simulator.yaml (inputs set per row) and evaluated with SE3
#     alignment on the first 5 s: mean position error in % of distance of trajectory.tum (and of
#     trajectory_causal.tum), yaw drift deg/m, final yaw error, rotation-only keyframes, and the
#     real-time factor of the whole process (CPU time user+sys / sequence duration: one core;
#     wall time alongside);
#  2. speed-accuracy on the replay (or, without the real data, on poster_6dof), events only:
#     frames.events_per_frame x window.size x tracker (frames front-end with templates, the
#     default; frames with chained frame-to-frame KLT; corners front-end), with error
#     and real-time factor.
# Prints markdown tables and writes OUT/per_sequence.md, OUT/speed_accuracy.md and every run's
# outputs under OUT/runs. Run on an otherwise idle machine for the wall times.
#   bench/vio_tables.sh [SEQ_DIR] [OUT]        (defaults: build/vio_sequences, build/vio_tables)
#   EVIO=path/to/evio  EVIO_REAL_DATA=path/to/shared/data/real  QUICK=1 (per-sequence table only)
set -euo pipefail
cd "$(dirname "$0")/.."
evio=${EVIO:-build/apps/evio}
seqs=${1:-build/vio_sequences}
out=${2:-build/vio_tables}
real=${EVIO_REAL_DATA:-../shared/data/real}
mocap="$real/trajectories/poster_6dof_mocap.csv"
[ -x "$evio" ] || { echo "vio_tables: $evio not found (build the evio target or set EVIO)" >&2; exit 1; }
[ -x /usr/bin/time ] || { echo "vio_tables: /usr/bin/time not found (Debian package time)" >&2; exit 1; }
mkdir -p "$seqs" "$out/runs"

simulate() {  # name yaml [extra args...]
  local name=$1 yaml=$2; shift 2
  if [ ! -f "$seqs/$name/simulation.json" ]; then
    echo "== evio simulate $yaml $* --out $seqs/$name" >&2
    "$evio" -q simulate "$yaml" "$@" --out "$seqs/$name" >&2
  fi
}
names=()
for n in poster_6dof boxes_6dof shapes_6dof room_6dof quadrotor_flight; do
  simulate "$n" "datasets/$n.yaml"
  names+=("$n")
done
if [ -f "$mocap" ]; then
  simulate poster_6dof_mocap datasets/poster_6dof_mocap.yaml --set "trajectory.path=$(readlink -f "$mocap")"
  names+=(poster_6dof_mocap)
  sweep_seq=poster_6dof_mocap
else
  echo "vio_tables: $mocap not found: the motion-capture replay is skipped" >&2
  sweep_seq=poster_6dof
fi

run() {  # tag sequence config -> OUT/runs/tag (+ tag.time: wall and CPU seconds)
  local tag=$1 seq=$2 cfg=$3
  rm -rf "$out/runs/$tag"
  /usr/bin/time -f "%e %U %S" -o "$out/runs/$tag.time" \
    "$evio" -q vio "$seqs/$seq" --out "$out/runs/$tag" --config "$cfg" --gt "$seqs/$seq/groundtruth.txt" \
    > "$out/runs/$tag.log" 2>&1 || { echo "vio_tables: run $tag failed, see $out/runs/$tag.log" >&2; return 0; }
}

row() {  # label run-dir -> one markdown row
  /usr/bin/python3 - "$1" "$2" <<'EOF'
import json, sys, os
label, d = sys.argv[1], sys.argv[2]
try:
    s = json.load(open(os.path.join(d, "stats.json")))
    est = json.load(open(os.path.join(d, "eval.json")))["estimates"]
    e, c = est[0], est[1]
    wall, user, sys_ = (float(x) for x in open(d + ".time").read().split()[-3:])
except Exception as ex:
    print("| %s | failed (%s) |" % (label, ex)); sys.exit(0)
dur = s["sequence_duration_s"]
print("| %s | %.1f | %.2f | %.3f | %.3f | %.3f | %.2f | %d | %d | %.3f | %.3f |" % (
    label, dur, e["groundtruth_length_m"], e["mean_position_error_percent"], c["mean_position_error_percent"],
    e["yaw_drift_deg_per_m"], e["final_yaw_error_deg"], s["keyframes"], s["rotation_only_keyframes"],
    (user + sys_) / dur, wall / dur))
EOF
}
header="| run | duration s | length m | mean pos. err. % | causal % | yaw drift deg/m | final yaw deg | keyframes | rotation-only kf | real-time factor (CPU) | real-time factor (wall) |
|---|---|---|---|---|---|---|---|---|---|---|"

config() {  # file inputs [sed expressions...] -> a copy of datasets/vio/simulator.yaml
  local f=$1 inputs=$2; shift 2
  sed -e "s/^inputs: .*/inputs: $inputs/" "$@" datasets/vio/simulator.yaml > "$f"
  grep -q "^inputs: $inputs" "$f" || echo "inputs: $inputs" >> "$f"
}

{
  echo "### evio vio per sequence (datasets/vio/simulator.yaml, SE3 alignment on the first 5 s)"
  echo
  echo "$header"
  for inputs in events aps events+aps; do
    tag=${inputs/+/_}
    cfg="$out/runs/cfg_$tag.yaml"
    config "$cfg" "$inputs" -e "s/x/x/"
    for n in "${names[@]}"; do
      run "seq_${tag}_$n" "$n" "$cfg"
      row "$inputs: $n" "$out/runs/seq_${tag}_$n"
    done
  done
} | tee "$out/per_sequence.md"
[ "${QUICK:-0}" = 1 ] && exit 0

echo
{
  echo "### speed-accuracy on $sweep_seq (events): frames.events_per_frame x window.size x tracker"
  echo
  echo "$header"
  for tracker in templates chained corners; do
    for epf in 5000 15000 30000; do
      for k in 5 10 15; do
        [ "$tracker" = corners ] && [ "$epf" != 15000 ] && continue  # corners: no event frames
        cfg="$out/runs/cfg_${tracker}_${epf}_$k.yaml"
        extra=(-e "s/events_per_frame: [0-9]*/events_per_frame: $epf/" -e "s/window: {size: [0-9]*/window: {size: $k/")
        [ "$tracker" = chained ] && extra+=(-e "s/template_max_age_frames: [0-9]*/template_max_age_frames: 1/")
        [ "$tracker" = corners ] && extra+=(-e "s/^frontend: .*/frontend: corners/")
        config "$cfg" events "${extra[@]}"
        run "sweep_${tracker}_${epf}_$k" "$sweep_seq" "$cfg"
        row "$tracker, events/frame $epf, window $k" "$out/runs/sweep_${tracker}_${epf}_$k"
      done
    done
  done
} | tee "$out/speed_accuracy.md"
