#!/usr/bin/env bash
# Builds the libFuzzer targets (clang, ASan + UBSan) and runs each for SECONDS (default 300).
# Seeds: the small valid and malformed files the reader tests write (they export them when
# EVIO_FUZZ_SEED_DIR is set), plus the first 64 KiB of each real sample in ../shared/data/real.
# Prints executions and crashes per target; crash inputs are kept in build-fuzz/crashes.
#   scripts/fuzz.sh [SECONDS] [TARGET ...]      (default: every fuzz_* target)
# FUZZ_SKIP_BUILD=1 reuses the build and seeds of an earlier run (to run two target lists at once).
set -euo pipefail
cd "$(dirname "$0")/.."
[ "${EVIO_SKIP_DEPS:-0}" = 1 ] || bash scripts/setup_deps.sh
seconds=${1:-300}
shift || true
build=${FUZZ_BUILD_DIR:-build-fuzz}
skip=${FUZZ_SKIP_BUILD:-0}
[ "$skip" = 1 ] || CC=clang CXX=clang++ cmake -S . -B "$build" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DEVIO_BUILD_FUZZ=ON \
  -DEVIO_BUILD_TESTS=OFF -DEVIO_BUILD_BENCH=OFF \
  -DCMAKE_CXX_FLAGS="-fsanitize=fuzzer-no-link,address,undefined -fno-omit-frame-pointer" >/dev/null
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
  mapfile -t targets < <(grep -ohE 'evio_add_fuzzer\((fuzz_[a-z0-9_]+)' tests/fuzz/CMakeLists.txt | sed 's/.*(//')
fi
[ "$skip" = 1 ] || cmake --build "$build" -j"$(nproc)" --target "${targets[@]}"
real=../shared/data/real
mkdir -p "$build/crashes"
# Seed files from the reader tests (Release build of the test binaries in BUILD_DIR).
test_build=${BUILD_DIR:-build}
if [ "$skip" != 1 ]; then
  cmake -S . -B "$test_build" -DCMAKE_BUILD_TYPE=Release >/dev/null
  cmake --build "$test_build" -j"$(nproc)" --target test_aedat2 test_aedat4 test_evt test_h5 test_rosbag test_mcap test_rosbag2 >/dev/null
  rm -rf "$build/seeds"
  for t in test_aedat2 test_aedat4 test_evt test_h5 test_rosbag test_mcap test_rosbag2; do
    EVIO_FUZZ_SEED_DIR="$build/seeds" "$test_build/tests/sensors/$t" --gtest_brief=1 >/dev/null 2>&1 || true
  done
fi
for t in "${targets[@]}"; do
  corpus="$build/corpus/$t"
  mkdir -p "$corpus"
  # Seeds: the first 64 KiB of each sample of the target's format (cut files exercise truncation).
  case "$t" in
    fuzz_aedat4) seeds=("$real/davis346_aedat4/davis.aedat4") ;;
    fuzz_evt2) seeds=("$real/prophesee_raw/evt2_sample.raw") ;;
    fuzz_evt3) seeds=("$real/prophesee_raw/evt3_sample.raw") ;;
    fuzz_rosbag) seeds=("$real/rosbag_eventpacket/test_events_1.bag") ;;
    fuzz_aedat2) seeds=("$real/dvs128_aedat2/DVS128-2017-03-21-short.aedat") ;;
    *) seeds=() ;;
  esac
  for s in "${seeds[@]}"; do
    [ -f "$s" ] && head -c 65536 "$s" > "$corpus/seed_$(basename "$s")"
  done
  [ -d "$build/seeds/$t" ] && cp "$build/seeds/$t"/* "$corpus/" 2>/dev/null
  echo "$t: corpus of $(ls "$corpus" | wc -l) files" >&2
  log="$build/$t.log"
  set +e
  LSAN_OPTIONS="suppressions=$PWD/tests/fuzz/lsan_hdf5.supp" "$build/tests/fuzz/$t" "$corpus" -max_total_time="$seconds" -max_len=262144 -rss_limit_mb=4096 \
    -artifact_prefix="$build/crashes/$t-" -print_final_stats=1 >"$log" 2>&1
  rc=$?
  set -e
  execs=$(grep -oE 'stat::number_of_executed_units: *[0-9]+' "$log" | grep -oE '[0-9]+$' || echo '?')
  crashes=$(ls "$build/crashes" 2>/dev/null | grep -c "^$t-" || true)
  echo "$t: ${seconds}s, executions $execs, exit $rc, crash files $crashes (log $log)"
done
