#!/usr/bin/env bash
# Whole-process benchmark of `evio mosaic` (issue 9 acceptance tables):
#  1. rotation error and mosaic quality for slow, medium and fast rotation of the poster-like
#     panorama (datasets/poster_rotation.yaml with its sinusoid frequencies scaled by 0.25, 1 and
#     2.5: peaks of about 66, 270 and 670 deg/s), spans 30 s, 10 s and 4 s (about 30-36 M events
#     each), with the gyro and from events only, at the default settings;
#  2. speed-accuracy: particles {100, 300, 1000, 3000} x batch size {10, 100} on 1 s of the medium
#     scene, with the gyro (events only at batch 10 up to 1000 particles).
# Each scene is simulated once by `evio simulate` into SEQ_DIR. Prints markdown tables and writes
# OUT/sweep.md, OUT/particles_batch.md and every run's outputs under OUT/runs. Timings are of the
# whole process on one core (reading the events included, simulation excluded): events/s = events
# / wall time, and events / CPU time (the figure to trust on a shared machine: it does not count
# time spent waiting for the core). THREADS=2 runs the mapper on a second thread.
#   bench/mosaic_tables.sh [SEQ_DIR] [OUT]     (defaults: build/mosaic_sequences, build/mosaic_tables)
#   EVIO=path/to/evio   QUICK=1 (sweep table only)   THREADS=2   SCENE=boxes_rotation (any
#   datasets/*_rotation.yaml with the poster's sinusoid frequencies; default poster_rotation; use a
#   SEQ_DIR per scene)
set -euo pipefail
cd "$(dirname "$0")/.."
evio=${EVIO:-build/apps/evio}
seqs=${1:-build/mosaic_sequences}
out=${2:-build/mosaic_tables}
[ -x "$evio" ] || { echo "mosaic_tables: $evio not found (build the evio target or set EVIO)" >&2; exit 1; }
scene=${SCENE:-poster_rotation}
[ -f "datasets/$scene.yaml" ] || { echo "mosaic_tables: datasets/$scene.yaml not found (SCENE)" >&2; exit 1; }
mkdir -p "$seqs" "$out/runs"

simulate() {  # name duration_s [extra args...]
  local name=$1 dur=$2; shift 2
  if [ ! -f "$seqs/$name/simulation.json" ]; then
    echo "== evio simulate datasets/$scene.yaml --duration $dur $* --out $seqs/$name" >&2
    "$evio" -q simulate "datasets/$scene.yaml" --duration "$dur" "$@" --out "$seqs/$name" >&2
  fi
}
simulate slow 30 --set "trajectory.angle_frequency_hz=[0.275, 0.225, 0.175]"
simulate medium 10
simulate fast 4 --set "trajectory.angle_frequency_hz=[2.75, 2.25, 1.75]"
simulate medium_1s 1

json() {  # file key -> value
  grep -o "\"$2\": [-0-9.eE+]*" "$1" | head -1 | awk '{print $2}'
}
run() {  # seq out_name [args...]; prints "rms max events/s rtf psnr ssim events/cpu-s mean-particles"
  local seq=$1 name=$2; shift 2
  local o="$out/runs/$name"
  "$evio" -q mosaic "$seqs/$seq" --out "$o" --gt "$seqs/$seq/groundtruth.txt" --threads "${THREADS:-1}" "$@" > "$o.log" 2>&1
  printf '%.3f %.3f %.0f %.2f %.1f %.3f %.0f %.1f\n' "$(json "$o/eval.json" rot_rms_deg)" "$(json "$o/eval.json" rot_max_deg)" \
    "$(json "$o/stats.json" events_per_s)" "$(json "$o/stats.json" real_time_factor)" \
    "$(json "$o/eval.json" psnr_db)" "$(json "$o/eval.json" ssim)" "$(json "$o/stats.json" events_per_cpu_s)" \
    "$(json "$o/stats.json" mean_particles)"
}

{
  echo "| scene | input | rot. RMS deg | rot. max deg | events/s (wall) | events/s (CPU) | real-time factor | mean particles | PSNR dB | SSIM |"
  echo "|---|---|---|---|---|---|---|---|---|---|"
  for s in slow medium fast; do
    for m in gyro events; do
      flag=(); [ $m = gyro ] && flag=(--use-imu)
      read -r rms mx eps rtf psnr ssim cpu np < <(run $s "${s}_$m" "${flag[@]}")
      echo "| $s | $m | $rms | $mx | $eps | $cpu | $rtf | $np | $psnr | $ssim |"
    done
  done
} | tee "$out/sweep.md"
[ "${QUICK:-0}" = 1 ] && exit 0

{
  echo "| input | particles | batch | rot. RMS deg | rot. max deg | events/s (wall) | events/s (CPU) | PSNR dB |"
  echo "|---|---|---|---|---|---|---|"
  for m in gyro events; do
    for b in 10 100; do
      for n in 100 300 1000 3000; do
        [ $m = events ] && { [ $b = 100 ] || [ $n = 3000 ]; } && continue
        flag=(); [ $m = gyro ] && flag=(--use-imu)
        read -r rms mx eps rtf psnr ssim cpu np < <(run medium_1s "pb_${m}_${n}_$b" "${flag[@]}" --particles $n --batch $b)
        echo "| $m | $n | $b | $rms | $mx | $eps | $cpu | $psnr |"
      done
    done
  done
} | tee "$out/particles_batch.md"
