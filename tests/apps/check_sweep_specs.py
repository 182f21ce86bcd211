#!/usr/bin/python3
"""Every spec in datasets/sweeps/ parses and expands (`evio sweep SPEC --list`), and every cell's
arguments are accepted by its command: `evio ALG --print-config ARGS` with the cell's fixed
arguments and grid --set values, without DATASET, --out and --gt (which name files the sweep makes
later). A misspelt config key or a value out of range in a spec fails here, not hours into a sweep.
  check_sweep_specs.py EVIO SPEC_DIR OUT_DIR    (EVIO_REAL_DATA: any value; --list reads no data)"""
import glob
import os
import shlex
import subprocess
import sys

evio, spec_dir, out = sys.argv[1], sys.argv[2], sys.argv[3]
env = dict(os.environ)
env.setdefault("EVIO_REAL_DATA", "/nonexistent/real-data")  # {env:EVIO_REAL_DATA} must only be set to list
specs = sorted(glob.glob(os.path.join(spec_dir, "*.yaml")))
if not specs:
    sys.exit("no specs in " + spec_dir)
failures = 0
for spec in specs:
    name = os.path.splitext(os.path.basename(spec))[0]
    p = subprocess.run([evio, "sweep", spec, "--out", os.path.join(out, name), "--list"], env=env,
                       capture_output=True, text=True)
    lines = [l for l in p.stdout.splitlines() if l.strip()]
    if p.returncode != 0 or not lines:
        print("FAIL %s: --list exit %d, %d cells\n%s" % (spec, p.returncode, len(lines), p.stderr))
        failures += 1
        continue
    checked = set()
    for line in lines:
        cell, command = line.split("\t", 1)
        words = shlex.split(command)
        algorithm, dataset, rest = words[1], words[2], words[3:]  # evio ALG DATASET ...
        args, i = [], 0
        while i < len(rest):
            if rest[i] in ("--out", "--gt"):
                i += 2
                continue
            args.append(rest[i])
            i += 1
        key = (algorithm, tuple(a.replace(dataset, "DATASET") for a in args))  # one check per entry and grid point
        if key in checked:
            continue
        checked.add(key)
        c = subprocess.run([evio, algorithm, "--print-config"] + args, env=env, capture_output=True, text=True)
        if c.returncode != 0:
            print("FAIL %s: cell %s: evio %s --print-config %s: exit %d\n%s" %
                  (spec, cell, algorithm, " ".join(args), c.returncode, c.stderr))
            failures += 1
    print("%s: %d cells, %d distinct argument lists checked" % (name, len(lines), len(checked)))
sys.exit(1 if failures else 0)
