#!/usr/bin/env bash
# Whole-process benchmark of `evio vio` (issue 8 acceptance tables):
#  1. per-sequence accuracy: the poster-, boxes- and shapes-like 6-DoF scenes (10 s each) and the
#     poster_6dof motion-capture replay (first 20 s; needs the shared real data), each simulated
#     once by `evio simulate` and kept in SEQ_DIR, run with datasets/vio/simulator.yaml and
#     evaluated with SE3 alignment on the first 5 s (mean position error as % of distance, final
#     yaw error, ATE, real-time factor);
#  2. speed-accuracy: frames.events_per_frame x window.size on the poster replay (or, without the
#     real data, on poster_6dof), with error and real-time factor.
# Prints markdown tables and writes OUT/per_sequence.md, OUT/speed_accuracy.md and every run's
# outputs under OUT/runs. Timings are one-core wall times of the whole process; run on an
# otherwise idle machine.
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
mkdir -p "$seqs" "$out/runs"

simulate() {  # name yaml [extra args...]
  local name=$1 yaml=$2; shift 2
  if [ ! -f "$seqs/$name/simulation.json" ]; then
    echo "== evio simulate $yaml $* --out $seqs/$name" >&2
    "$evio" -q simulate "$yaml" "$@" --out "$seqs/$name" >&2
  fi
}
simulate poster_6dof datasets/poster_6dof.yaml
simulate boxes_6dof datasets/boxes_6dof.yaml
simulate shapes_6dof datasets/shapes_6dof.yaml
names=(poster_6dof boxes_6dof shapes_6dof)
if [ -f "$mocap" ]; then
  simulate poster_6dof_mocap datasets/poster_6dof_mocap.yaml --duration 20 \
    --set "trajectory.path=$(readlink -f "$mocap")"
  names+=(poster_6dof_mocap)
  sweep_seq=poster_6dof_mocap
else
  echo "vio_tables: $mocap not found: the motion-capture replay is skipped" >&2
  sweep_seq=poster_6dof
fi

run() {  # tag sequence config -> OUT/runs/tag
  local tag=$1 seq=$2 cfg=$3
  rm -rf "$out/runs/$tag"
  "$evio" -q vio "$seqs/$seq" --out "$out/runs/$tag" --config "$cfg" --gt "$seqs/$seq/groundtruth.txt" \
    > "$out/runs/$tag.log" 2>&1 || { echo "vio_tables: run $tag failed, see $out/runs/$tag.log" >&2; return 0; }
}

row() {  # label run-dir -> one markdown row
  /usr/bin/env python3 - "$1" "$2" <<'EOF'
import json, sys, os
label, d = sys.argv[1], sys.argv[2]
try:
    s = json.load(open(os.path.join(d, "stats.json")))
    e = json.load(open(os.path.join(d, "eval.json")))["estimates"][0]
except Exception as ex:
    print("| %s | failed (%s) |" % (label, ex)); sys.exit(0)
print("| %s | %.1f | %.2f | %.3f | %.2f | %.3f | %.1f | %d | %.3f |" % (
    label, e["time_span_s"][1] - e["time_span_s"][0], e["groundtruth_length_m"],
    e["mean_position_error_percent"], e["final_yaw_error_deg"], e["ate"]["trans_m"]["rmse"],
    s["events"] / 1e6, s["keyframes"], s["real_time_factor"]))
EOF
}
header="| run | span s | length m | mean pos. err. % | final yaw err. deg | ATE rmse m | events M | keyframes | real-time factor |
|---|---|---|---|---|---|---|---|---|"

{
  echo "### evio vio per sequence (datasets/vio/simulator.yaml, SE3 alignment on the first 5 s)"
  echo
  echo "$header"
  for n in "${names[@]}"; do
    run "seq_$n" "$n" datasets/vio/simulator.yaml
    row "$n" "$out/runs/seq_$n"
  done
} | tee "$out/per_sequence.md"
[ "${QUICK:-0}" = 1 ] && exit 0

echo
{
  echo "### speed-accuracy on $sweep_seq: frames.events_per_frame x window.size"
  echo
  echo "$header"
  for epf in 5000 10000 15000 30000; do
    for k in 5 10 15; do
      cfg="$out/runs/cfg_${epf}_$k.yaml"
      sed -e "s/events_per_frame: [0-9]*/events_per_frame: $epf/" -e "s/window: {size: [0-9]*/window: {size: $k/" \
        datasets/vio/simulator.yaml > "$cfg"
      run "sweep_${epf}_$k" "$sweep_seq" "$cfg"
      row "events/frame $epf, window $k" "$out/runs/sweep_${epf}_$k"
    done
  done
} | tee "$out/speed_accuracy.md"
