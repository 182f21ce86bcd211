#!/bin/bash
# evio sweep --engine parallel --hosts against a real sshd: starts sshd on 127.0.0.1 (a free port,
# a generated host key and an authorized client key in a temp folder), writes an sshloginfile
# with two logins to it (evio-a, evio-b: Host entries of a generated ssh config), runs the same
# sweep with --engine local and with --engine parallel --hosts, and checks that results.jsonl has
# the same rows (cell, exit code, params, metrics; times and per-event timings aside), that every cell ran through one of
# the two logins and that its output folder came back. Then a cell is killed (kill -9 of its
# program on the "remote" side) mid-run: it is recorded with exit code -9 and rerun by --resume.
# Usage: sweep_ssh_test.sh EVIO SPEC PYTHON. Exit 77 (skipped) when a package is missing.
set -u
evio=$1
spec=$2
here=$(cd "$(dirname "$0")" && pwd)
python=${3:-/usr/bin/python3}
sshd=/usr/sbin/sshd
for need in parallel:parallel rsync:rsync ssh:openssh-client ssh-keygen:openssh-client; do
  command -v "${need%%:*}" > /dev/null || { echo "SKIP: ${need%%:*} is not installed (Debian package ${need#*:})"; exit 77; }
done
[ -x $sshd ] || { echo "SKIP: $sshd is not installed (Debian package openssh-server)"; exit 77; }

t=$(mktemp -d /tmp/evio_sweep_ssh.XXXXXX)
cleanup() {
  [ -f "$t/sshd.pid" ] && kill "$(cat "$t/sshd.pid")" 2> /dev/null
  rm -rf "$t"
}
trap cleanup EXIT
fail() { echo "FAIL: $*"; [ -f "$t/sshd.log" ] && tail -5 "$t/sshd.log"; exit 1; }

port=$($python -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
ssh-keygen -q -t ed25519 -N '' -f "$t/host_key" || fail "ssh-keygen"
ssh-keygen -q -t ed25519 -N '' -f "$t/client_key" || fail "ssh-keygen"
cp "$t/client_key.pub" "$t/authorized_keys"
chmod 600 "$t/authorized_keys"
[ "$(id -u)" = 0 ] && mkdir -p /run/sshd  # the privilege-separation folder sshd wants when run as root
cat > "$t/sshd_config" << EOF
Port $port
ListenAddress 127.0.0.1
HostKey $t/host_key
PidFile $t/sshd.pid
AuthorizedKeysFile $t/authorized_keys
PubkeyAuthentication yes
PasswordAuthentication no
KbdInteractiveAuthentication no
PermitRootLogin prohibit-password
UsePAM no
StrictModes no
MaxStartups 50
MaxSessions 50
LogLevel ERROR
AcceptEnv SHLVL
EOF
$sshd -f "$t/sshd_config" -E "$t/sshd.log" || fail "sshd did not start"
user=$(id -un)
for h in evio-a evio-b; do
  cat >> "$t/ssh_config" << EOF
Host $h
  HostName 127.0.0.1
  Port $port
  User $user
  IdentityFile $t/client_key
  IdentitiesOnly yes
  BatchMode yes
  StrictHostKeyChecking no
  UserKnownHostsFile /dev/null
  LogLevel ERROR
  SetEnv SHLVL=1
EOF
done
# SHLVL=1: bash then does not read the account's ~/.bashrc for the ssh commands (it does when sshd
# starts it at level 0), so a slow shell setup of the account (pyenv, conda) does not slow each transfer.
export PARALLEL_SSH="ssh -F $t/ssh_config"
for i in $(seq 50); do ssh -F "$t/ssh_config" evio-a true 2> /dev/null && break; sleep 0.1; done
ssh -F "$t/ssh_config" evio-b true || fail "cannot log in to sshd on 127.0.0.1:$port"
printf '1/evio-a\n1/evio-b\n' > "$t/hosts"

start=$(date +%s.%N)
"$evio" sweep "$spec" --out "$t/local" -q --no-report -j 2 || fail "the local sweep failed"
mid=$(date +%s.%N)
"$evio" sweep "$spec" --out "$t/ssh" -q --no-report --engine parallel --hosts "$t/hosts" || fail "the parallel --hosts sweep failed: $(tail -n 3 "$t"/ssh/parallel/*.log "$t"/ssh/cells/*/stderr.log)"
end=$(date +%s.%N)
echo "local: $($python -c "print(round($mid - $start, 1))") s, parallel over 2 ssh logins: $($python -c "print(round($end - $mid, 1))") s"

$python "$here/compare_sweep_rows.py" "$t/local" "$t/ssh" parallel --hosts evio-a,evio-b --returned || fail "the rows differ"
ls "$t/ssh/parallel/bin" | grep -q '^evio-sweep$' || fail "the runner was not shipped"

# A cell killed mid-run: a cell of a few seconds (reconstruct on 2 s of the poster wall) whose
# program, started on the "remote" side by the runner, is killed with -9.
cat > "$t/slow.yaml" << EOF
name: slow
datasets:
  - {name: wall, scene: $(cd "$(dirname "$spec")/../../../.." && pwd)/datasets/poster_6dof.yaml, duration: 2}
algorithms:
  - {algorithm: reconstruct, datasets: [wall], grid: {method: [cf]}}
EOF
printf 'evio-a\n' > "$t/one_host"  # one login: the 2 s scene (47 MB) is sent once per run
"$evio" sweep "$t/slow.yaml" --out "$t/kill" -q --no-report --engine parallel --hosts "$t/one_host" &
sweep=$!
pid=
for i in $(seq 1200); do  # the program as the runner starts it in the remote work dir
  pid=$(pgrep -f -n '^parallel/bin/evio-reconstruct ' || true)
  [ -n "$pid" ] && break
  sleep 0.05
done
[ -n "$pid" ] || fail "the slow cell never ran"
kill -9 "$pid"
wait $sweep
rc=$?
[ $rc = 1 ] || fail "the sweep with a killed cell exited $rc, not 1"
grep -q '"exit_code": -9' "$t/kill/results.jsonl" || fail "the killed cell is not recorded with -9: $(cat "$t/kill/results.jsonl")"
"$evio" sweep "$t/slow.yaml" --out "$t/kill" -q --no-report --engine parallel --hosts "$t/one_host" --resume || fail "--resume failed"
[ "$(grep -c '"exit_code": 0' "$t/kill/results.jsonl")" = 1 ] || fail "--resume did not rerun the killed cell"
echo "a cell killed with -9 was recorded with exit code -9 and rerun by --resume"
