#!/usr/bin/python3
"""A pivot table of `evio sweep` results, in Markdown (or CSV): one row per value of --rows, one
column per value of --cols, each cell the mean of --value over the sweep cells that fall in it.
This is how the README's tables are made from a sweep folder (README, section `evio sweep`,
"Specs and the README tables"); the sweep's own report has one table per algorithm and dataset.

    /usr/bin/python3 scripts/sweep_table.py DIR [DIR...] --rows variant --cols dataset \\
        --value mean_position_error_percent --mean-over tracker.seed [--where inputs=events] \\
        [--format %.3f] [--mean-column] [--csv]

DIR: sweep folders (their results.jsonl; the last record of each cell counts, as in the report).
--rows / --cols: comma-separated fields: `algorithm`, `variant`, `dataset`, `cell`, or a grid key
  (a key of `params`, e.g. window.size). A row or column label joins the values with ", ".
--value: a metric of `metrics` (e.g. rot_rms_deg) or a record field (cpu_s, wall_s, peak_rss_mb,
  real_time_factor, real_time_factor_cpu, duration_s), a ratio of two (duration_s/windows) and either
  times a number (duration_s/windows*1000: ms per window); repeat --value for "a / b" cells.
--mean-over: grid keys (comma-separated) whose cells are averaged (repeats such as seeds). Cells that
  land in one table cell and differ in anything else are an error: the table would hide a setting.
--where FIELD=VALUE: keep only the cells whose field (as for --rows) has this value; repeatable.
Rows and columns: numbers ascending, other values in the order first met in results.jsonl (the
spec's order when the sweep ran with -j 1). A table cell shows `-` when it has no cell, `failed (k/n)` when k of its n cells did not exit 0,
`n/a` when its cells ran but do not report the value (`n/a (k/n)` for some of them; the mean of the
others follows in brackets), and the mean otherwise. Exit code 1 on
a bad argument or an ambiguous table, with a message that says why.
"""
import argparse
import csv
import io
import json
import math
import os
import sys

RECORD_FIELDS = ("cpu_s", "wall_s", "peak_rss_mb", "real_time_factor", "real_time_factor_cpu", "duration_s")


def fail(msg):
    print("sweep_table.py: error: " + msg, file=sys.stderr)
    sys.exit(1)


def read_latest(folder):
    path = os.path.join(folder, "results.jsonl")
    if not os.path.exists(path):
        fail("%s: no such file (expected: a folder written by `evio sweep`)" % path)
    latest = {}
    with open(path) as f:
        for n, line in enumerate(f, 1):
            line = line.strip()
            if not line:
                continue
            try:
                r = json.loads(line)
            except ValueError:
                print("sweep_table.py: warning: %s:%d: not a JSON line, skipped (a torn write)" % (path, n), file=sys.stderr)
                continue
            latest[r["cell"]] = r
    return list(latest.values())


def field(r, name):
    if name in ("algorithm", "variant", "dataset", "cell"):
        return str(r.get(name) or "")
    params = r.get("params") or {}
    if name in params:
        return str(params[name])
    return None


def value(r, spec):
    """A value of the record: NAME, or NAME/NAME2 (a ratio), either optionally times a number (NAME/NAME2*1000)."""
    factor = 1.0
    if "*" in spec:
        spec, k = spec.rsplit("*", 1)
        try:
            factor = float(k)
        except ValueError:
            fail("--value: '%s' after '*' is not a number" % k)
    if "/" in spec:
        a, b = spec.split("/", 1)
        return value1(r, a) / value1(r, b) * factor if value1(r, b) != 0 else math.nan
    return value1(r, spec) * factor


def value1(r, name):
    if name in RECORD_FIELDS:
        v = r.get(name)
    else:
        v = (r.get("metrics") or {}).get(name)
    try:
        v = float(v)
    except (TypeError, ValueError):
        return math.nan
    return v


def label(r, names, what):
    vals = []
    for n in names:
        v = field(r, n)
        if v is None:
            fail("cell %s has no field or grid key '%s' for %s (fields: algorithm, variant, dataset, cell, %s)"
                 % (r["cell"], n, what, ", ".join(sorted((r.get("params") or {}).keys())) or "no grid keys"))
        vals.append(v)
    return ", ".join(vals)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dirs", nargs="+", help="sweep folders")
    ap.add_argument("--rows", required=True)
    ap.add_argument("--cols", required=True)
    ap.add_argument("--value", action="append", required=True)
    ap.add_argument("--mean-over", default="")
    ap.add_argument("--where", action="append", default=[])
    ap.add_argument("--format", default="%.4g", help="printf form of a number (default %%.4g)")
    ap.add_argument("--mean-column", action="store_true",
                    help="add a column with the mean of each row's table cells (`-` when one of them is empty or has a failed cell)")
    ap.add_argument("--csv", action="store_true", help="CSV instead of Markdown")
    args = ap.parse_args()
    rows_f = [s for s in args.rows.split(",") if s]
    cols_f = [s for s in args.cols.split(",") if s]
    over = set(s for s in args.mean_over.split(",") if s)
    wheres = []
    for w in args.where:
        if "=" not in w:
            fail("--where '%s' is not FIELD=VALUE" % w)
        wheres.append(w.split("=", 1))
    try:
        args.format % 1.0
    except (TypeError, ValueError):
        fail("--format '%s' is not a printf form of one number, e.g. %%.3f" % args.format)

    records = []
    for d in args.dirs:
        records += read_latest(d)
    kept = [r for r in records if all(field(r, k) == v for k, v in wheres)]
    if not kept:
        fail("no cell matches --where %s (of %d cells)" % (" ".join(args.where), len(records)))
    buckets = {}  # (row, col) -> [records]
    row_order, col_order = [], []
    for r in kept:
        rl, cl = label(r, rows_f, "--rows"), label(r, cols_f, "--cols")
        if rl not in row_order:
            row_order.append(rl)
        if cl not in col_order:
            col_order.append(cl)
        buckets.setdefault((rl, cl), []).append(r)
    # What tells cells apart besides rows, columns and the averaged keys must not vary in a bucket.
    shown = set(rows_f) | set(cols_f) | over
    for key, rs in buckets.items():
        first = rs[0]
        for r in rs[1:]:
            diff = [k for k in ("algorithm", "variant", "dataset") if k not in shown and field(r, k) != field(first, k)]
            keys = set((r.get("params") or {}).keys()) | set((first.get("params") or {}).keys())
            diff += [k for k in sorted(keys) if k not in shown and field(r, k) != field(first, k)]
            if diff:
                fail("the table cell (row '%s', column '%s') holds cells %s and %s, which differ in %s: add it to --rows, "
                     "--cols, --mean-over or --where" % (key[0], key[1], first["cell"], r["cell"], ", ".join(diff)))

    def cell_text(rs):
        texts, means = [], []
        failed = sum(1 for r in rs if r.get("exit_code") != 0)
        for name in args.value:
            vals = [value(r, name) if r.get("exit_code") == 0 else math.nan for r in rs]
            good = [v for v in vals if math.isfinite(v)]
            mean = sum(good) / len(good) if good else math.nan
            means.append(mean if len(good) == len(vals) else math.nan)  # the mean column needs every cell
            part = (" [" + args.format % mean + "]") if good else ""
            if len(good) == len(vals):
                texts.append(args.format % mean)
            elif failed:
                texts.append("failed (%d/%d)%s" % (failed, len(vals), part))
            else:  # the cells ran and do not report it (e.g. no reference to score against)
                texts.append("n/a" if not good else "n/a (%d/%d)%s" % (len(vals) - len(good), len(vals), part))
        return " / ".join(texts), means

    # Numbers in ascending order, other values in the order first met (the spec's order with -j 1).
    def order(labels, nfields):
        seen = [dict() for _ in range(nfields)]
        for l in labels:
            for i, v in enumerate(l.split(", ")[:nfields]):
                seen[i].setdefault(v, len(seen[i]))

        def key(l):
            k = []
            for i, v in enumerate(l.split(", ")[:nfields]):
                try:
                    k.append((0, float(v), 0))
                except ValueError:
                    k.append((1, 0.0, seen[i].get(v, 0)))
            return k
        return sorted(labels, key=key)
    row_order = order(row_order, len(rows_f))
    col_order = order(col_order, len(cols_f))

    header = [args.rows] + col_order + (["mean"] if args.mean_column else [])
    table = []
    for rl in row_order:
        line = [rl]
        sums = [[] for _ in args.value]
        for cl in col_order:
            rs = buckets.get((rl, cl))
            if not rs:
                line.append("-")
                continue
            text, means = cell_text(rs)
            line.append(text)
            for i, m in enumerate(means):
                sums[i].append(m)
        if args.mean_column:
            line.append(" / ".join(args.format % (sum(s) / len(s)) if s and all(math.isfinite(x) for x in s) else "-"
                                   for s in sums))
        table.append(line)
    if args.csv:
        out = io.StringIO()
        w = csv.writer(out, lineterminator="\n")
        w.writerow(header)
        w.writerows(table)
        sys.stdout.write(out.getvalue())
    else:
        print("| " + " | ".join(header) + " |")
        print("|" + "---|" * len(header))
        for line in table:
            print("| " + " | ".join(line) + " |")


if __name__ == "__main__":
    main()
