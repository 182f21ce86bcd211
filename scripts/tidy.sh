#!/usr/bin/env bash
# Runs clang-tidy (the checks in .clang-tidy) over evio's sources: every module (calib, sensors,
# frontend, backend, mapping, evaluation, pipeline, simulator, sweep) and apps, with the compile commands
# of a build folder. Prints each warning and a count per check; exits 1 when there is any.
#   scripts/tidy.sh                 every source file (a few minutes per 10 files on one core)
#   scripts/tidy.sh --changed [REV] the .cc files changed since REV (default: HEAD), plus the .cc
#                                   files next to changed headers
#   scripts/tidy.sh FILE...         these files
# (gcc builds C++17 without a -std flag; clang-tidy is told, as its own default is older.)
# Environment: BUILD_DIR (default build; configured if it has no compile_commands.json), JOBS.
set -euo pipefail
cd "$(dirname "$0")/.."
build_dir=${BUILD_DIR:-build}
jobs=${JOBS:-$(nproc 2>/dev/null || echo 2)}
tidy=$(command -v clang-tidy || command -v clang-tidy-14 || true)
if [ -z "$tidy" ]; then
  echo "tidy.sh: clang-tidy is not installed (Debian: apt-get install clang-tidy)" >&2
  exit 2
fi
[ -f "$build_dir/compile_commands.json" ] || cmake -S . -B "$build_dir" -DCMAKE_BUILD_TYPE=Release >/dev/null
modules="calib sensors frontend backend mapping evaluation pipeline simulator sweep apps"
files=()
if [ "${1:-}" = "--changed" ]; then
  rev=${2:-HEAD}
  while IFS= read -r f; do
    case "$f" in
      *.cc) [ -f "$f" ] && files+=("$f") ;;
      *.h) for c in "$(dirname "$f")"/../src/*.cc "$(dirname "$f")"/*.cc; do [ -f "$c" ] && files+=("$c"); done ;;
    esac
  done < <({ git diff --name-only "$rev" -- $modules; git ls-files --others --exclude-standard -- $modules; } | sort -u)
elif [ $# -gt 0 ]; then
  files=("$@")
else
  while IFS= read -r f; do files+=("$f"); done < <(git ls-files -- $(for m in $modules; do echo "$m/*.cc"; done))
fi
# Keep only files the build compiles (tests and generated sources are not in the list).
mapfile -t files < <(printf '%s\n' "${files[@]}" | sort -u | while IFS= read -r f; do
  [ -n "$f" ] && grep -q "\"file\": \"$(realpath "$f")\"" "$build_dir/compile_commands.json" && echo "$f"; done || true)
if [ ${#files[@]} -eq 0 ]; then
  echo "tidy.sh: no source files to check"
  exit 0
fi
echo "tidy.sh: ${#files[@]} files, $jobs jobs, $("$tidy" --version | grep -o 'version [0-9.]*')" >&2
log=$(mktemp)
trap 'rm -f "$log"' EXIT
printf '%s\n' "${files[@]}" | xargs -P "$jobs" -I{} "$tidy" -p "$build_dir" --quiet --extra-arg=-std=c++17 {} >"$log" 2>/dev/null || true
warnings=$(grep -E "^[^ ].*: (warning|error): " "$log" | sort -u || true)
n=0
if [ -n "$warnings" ]; then
  printf '%s\n' "$warnings"
  printf '%s\n' "$warnings" | sed -E 's/.*\[([a-z0-9.,-]+)\]$/\1/' | sort | uniq -c | sort -rn >&2
  n=$(printf '%s\n' "$warnings" | wc -l)
fi
echo "tidy.sh: $n warnings" >&2
[ "$n" -eq 0 ]
