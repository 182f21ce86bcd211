#!/usr/bin/python3
"""cli.sweep_table: scripts/sweep_table.py on a results.jsonl written here with known numbers.
Checks the pivot (rows, columns, means over a repeat key, numeric order), that a cell's last record
counts, that failed repeats are shown as such, --where, --mean-column, CSV, and the errors (an
ambiguous table cell, an unknown field, no match).

    python3 tests/apps/sweep_table_test.py scripts/sweep_table.py
"""
import json
import os
import subprocess
import sys
import tempfile

script = sys.argv[1]
failures = []


def run(*args):
    p = subprocess.run([sys.executable, script] + list(args), capture_output=True, text=True)
    return p.returncode, p.stdout, p.stderr


def expect(name, got, want):
    if got != want:
        failures.append("%s:\n--- got\n%s\n--- want\n%s" % (name, got, want))


def rec(cell, mode, scene, seed, err, cpu, exit_code=0, inputs="events"):
    return {"cell": cell, "algorithm": "vio", "variant": "", "dataset": scene,
            "params": {"inputs": inputs, "mode": mode, "tracker.seed": seed}, "exit_code": exit_code,
            "cpu_s": cpu, "wall_s": cpu, "metrics": {"err": err if exit_code == 0 else None}}


with tempfile.TemporaryDirectory() as d:
    lines = [
        rec("a1", "split", "poster", 1, 0.2, 1.0), rec("a2", "split", "poster", 2, 0.4, 3.0),
        rec("b1", "drop", "poster", 1, 0.5, 1.0), rec("b2", "drop", "poster", 2, 0.7, 1.0),
        rec("c1", "split", "boxes", 1, 1.0, 2.0), rec("c2", "split", "boxes", 2, 9.0, 2.0, exit_code=1),
        rec("d1", "drop", "boxes", 1, 2.0, 2.0), rec("d2", "drop", "boxes", 2, 4.0, 2.0),
        rec("e1", "split", "poster", 1, 0.0, 1.0, inputs="aps"),
        rec("f1", "split", "room", 1, None, 1.0), rec("f2", "split", "room", 2, 1.5, 1.0),  # ran, no value
        rec("g1", "drop", "room", 1, None, 1.0), rec("g2", "drop", "room", 2, None, 1.0),
        rec("a1", "split", "poster", 1, 0.6, 1.0),  # a rerun: the last record counts (0.6, not 0.2)
    ]
    with open(os.path.join(d, "results.jsonl"), "w") as f:
        f.write("".join(json.dumps(l) + "\n" for l in lines))
    base = ["--rows", "mode", "--cols", "dataset", "--mean-over", "tracker.seed", "--where", "inputs=events"]

    rc, out, err = run(d, *base, "--value", "err", "--format", "%.2f", "--mean-column")
    expect("pivot rc", rc, 0)
    expect("pivot", out, "| mode | poster | boxes | room | mean |\n|---|---|---|---|---|\n"
                         "| split | 0.50 | failed (1/2) [1.00] | n/a (1/2) [1.50] | - |\n| drop | 0.60 | 3.00 | n/a | - |\n")

    rc, out, err = run(d, *base, "--value", "err", "--value", "cpu_s", "--format", "%.1f", "--csv")
    expect("csv", out, "mode,poster,boxes,room\nsplit,0.5 / 2.0,failed (1/2) [1.0] / failed (1/2) [2.0],n/a (1/2) [1.5] / 1.0\n"
                       "drop,0.6 / 1.0,3.0 / 2.0,n/a / 1.0\n")

    # the mean of the per-cell ratios: (0.6 / 1 + 0.4 / 3) * 10 / 2
    rc, out, err = run(d, *base, "--value", "err/cpu_s*10", "--format", "%.2f")
    expect("ratio", out, "| mode | poster | boxes | room |\n|---|---|---|---|\n| split | 3.67 | failed (1/2) [5.00] | n/a (1/2) [15.00] |\n"
                         "| drop | 6.00 | 15.00 | n/a |\n")

    rc, out, err = run(d, "--rows", "tracker.seed", "--cols", "dataset", "--value", "err", "--where", "inputs=events",
                       "--where", "mode=drop")
    expect("numeric order", out, "| tracker.seed | poster | boxes | room |\n|---|---|---|---|\n| 1 | 0.5 | 2 | n/a |\n| 2 | 0.7 | 4 | n/a |\n")

    rc, out, err = run(d, "--rows", "mode", "--cols", "dataset", "--value", "err", "--mean-over", "tracker.seed")
    expect("ambiguous rc", rc, 1)
    expect("ambiguous message", "differ in inputs: add it to --rows, --cols, --mean-over or --where" in err, True)

    rc, out, err = run(d, "--rows", "nosuch", "--cols", "dataset", "--value", "err")
    expect("unknown field rc", rc, 1)
    expect("unknown field message", "no field or grid key 'nosuch' for --rows" in err, True)

    rc, out, err = run(d, *base[:-1], "inputs=none", "--value", "err")
    expect("no match rc", rc, 1)
    expect("no match message", "no cell matches --where inputs=none" in err, True)

for f in failures:
    print("FAIL " + f)
print("%d failure(s)" % len(failures))
sys.exit(1 if failures else 0)
