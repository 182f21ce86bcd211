#!/usr/bin/python3
"""Compares two `evio sweep` folders' results.jsonl, row by row: the reference (--engine local) and
one run by another engine. Every cell must be in both, with the same algorithm, dataset, params,
exit code, data duration and metrics (times aside: ns_per_event, time_per_event_us,
events_per_cpu_s), and the other run's rows must name their engine and have a peak RSS.

    compare_sweep_rows.py LOCAL_DIR OTHER_DIR ENGINE [--hosts H1,H2] [--returned]

--hosts: every row of OTHER ran on one of these logins. --returned: each cell's out/stats.json
came back into OTHER_DIR/cells/. Exit 1 with the first difference.
"""
import argparse
import json
import os
import sys


def rows(d):
    with open(os.path.join(d, "results.jsonl")) as f:
        return {r["cell"]: r for r in map(json.loads, f)}


def untimed(m):
    return {k: v for k, v in m.items() if "per_event" not in k and "per_cpu" not in k}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("local")
    ap.add_argument("other")
    ap.add_argument("engine")
    ap.add_argument("--hosts", default="")
    ap.add_argument("--returned", action="store_true")
    a = ap.parse_args()
    local, other = rows(a.local), rows(a.other)
    hosts = set(h for h in a.hosts.split(",") if h)
    if local.keys() != other.keys():
        sys.exit("cells differ: %s vs %s" % (sorted(local), sorted(other)))
    seen = set()
    for cell, r in sorted(local.items()):
        s = other[cell]
        for k in ("algorithm", "dataset", "params", "exit_code", "duration_s"):
            if r[k] != s[k]:
                sys.exit("%s: %s differs: %r vs %r" % (cell, k, r[k], s[k]))
        if untimed(r["metrics"]) != untimed(s["metrics"]):
            sys.exit("%s: metrics differ: %r vs %r" % (cell, r["metrics"], s["metrics"]))
        if s["engine"] != a.engine or not s["peak_rss_mb"] > 0 or not s["cpu_s"] >= 0:
            sys.exit("%s: engine %r, peak RSS %r, CPU %r" % (cell, s["engine"], s["peak_rss_mb"], s["cpu_s"]))
        if not any(v is not None for v in s["metrics"].values()):
            sys.exit("%s: no metric at all: %r" % (cell, s["metrics"]))
        if hosts and s["host"] not in hosts:
            sys.exit("%s: ran on %r, not one of %s" % (cell, s["host"], sorted(hosts)))
        if a.returned and not os.path.exists(os.path.join(a.other, "cells", cell, "out", "stats.json")):
            sys.exit("%s: its output folder did not come back" % cell)
        seen.add(s["host"])
    print("%d cells: same exit codes and metrics with --engine %s; ran on %s" % (len(local), a.engine, sorted(seen)))


if __name__ == "__main__":
    main()
