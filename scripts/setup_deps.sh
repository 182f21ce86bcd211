#!/usr/bin/env bash
# Installs the Debian 12 packages evio builds against. Idempotent: installs only what is
# missing, runs `apt-get update` at most once, works as root or through sudo.
#   scripts/setup_deps.sh            # build dependencies (what demo.sh needs)
#   scripts/setup_deps.sh --tests    # and what only the tests use: a headless browser, GNU parallel,
#                                    # an sshd and a one-node Slurm (test.sh; they start no service
#                                    # the tests do not start themselves, but Debian enables munge)
#   scripts/setup_deps.sh PKG...     # these Debian packages instead (e.g. python3-skimage)
#   EVIO_SKIP_DEPS=1 scripts/...     # callers (demo.sh, test.sh) skip this step entirely
set -euo pipefail

packages=(
  build-essential cmake pkg-config ccache
  libeigen3-dev libceres-dev libopencv-dev libopengv-dev libpcl-dev
  libgtest-dev libgmock-dev libbenchmark-dev libyaml-cpp-dev libcli11-dev libhdf5-dev
  liblz4-dev libzstd-dev libbz2-dev libsqlite3-dev hdf5-filter-plugin-blosc-serial
  clang libclang-rt-14-dev
  python3-numpy python3-matplotlib
)
test_packages=(
  chromium                                       # the sweep report in a browser: cli.*report_browser
  parallel rsync openssh-client openssh-server   # evio sweep --engine parallel [--hosts]: cli.sweep_parallel_ssh
  slurm-wlm munge                                # evio sweep --engine slurm: cli.sweep_slurm (scripts/test_slurm.sh)
)
if [ "${1:-}" = --tests ]; then
  packages+=("${test_packages[@]}")
elif [ $# -gt 0 ]; then
  packages=("$@")
fi

missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if [ ${#missing[@]} -eq 0 ]; then
  echo "setup_deps: all ${#packages[@]} Debian packages present"
  exit 0
fi

if [ "$(id -u)" -eq 0 ]; then
  SUDO=()
elif command -v sudo >/dev/null 2>&1; then
  SUDO=(sudo)
else
  echo "setup_deps: missing packages (${missing[*]}) and not root and no sudo; install them as root:" >&2
  echo "  apt-get install --no-install-recommends ${missing[*]}" >&2
  exit 1
fi

echo "setup_deps: installing ${#missing[@]} package(s): ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
"${SUDO[@]}" apt-get update -qq
"${SUDO[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}"
echo "setup_deps: done"
