#!/usr/bin/python3
"""Speed-accuracy plots of an `evio sweep`: one figure per algorithm and dataset, the headline error
against the CPU time of every successful cell (log-scaled when it spans more than 10x), the Pareto front as a step line
and its cells labelled with their parameters. Reads DIR/report/cells.csv (written by `evio sweep`,
columns cell,algorithm,variant,dataset,params,exit_code,...,cpu_s,...,error_metric,error,pareto)
and writes OUT_DIR/<algorithm>__<dataset>.png and .pdf. When the spec averages repeats
(`mean_over:`), DIR/report/<algorithm>__<dataset>__means.csv is next to cells.csv: the means are
drawn with +-1 sample standard deviation bars, the front and its labels are the means' front, and
the single cells stay as faint dots.

    /usr/bin/python3 scripts/plot_sweep.py DIR/report/cells.csv DIR/report/plots

matplotlib from Debian (python3-matplotlib); no numpy. Exit code 2 when matplotlib is missing.
"""
import argparse
import csv
import math
import os
import sys


def number(s):
    try:
        v = float(s)
    except ValueError:
        return math.nan
    return v


def read_means(path, metric):
    """(CPU s mean, error mean, row, error sd) per row of a __means.csv; [] when there is none."""
    if not os.path.exists(path):
        return []
    out = []
    with open(path, newline="") as f:
        for r in csv.DictReader(f):
            x, y = number(r["CPU s mean"]), number(r.get(metric + "_mean", ""))
            if math.isfinite(x) and math.isfinite(y) and x > 0:
                out.append((x, y, r, number(r.get(metric + "_sd", ""))))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("csv", help="cells.csv of evio sweep")
    ap.add_argument("out_dir", help="folder for the PNG and PDF files")
    args = ap.parse_args()
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib is missing: apt-get install python3-matplotlib", file=sys.stderr)
        sys.exit(2)

    groups = {}  # (algorithm, dataset) -> [row]
    with open(args.csv, newline="") as f:
        for row in csv.DictReader(f):
            if row["error_metric"] and row["exit_code"] == "0":
                groups.setdefault((row["algorithm"], row["dataset"]), []).append(row)
    os.makedirs(args.out_dir, exist_ok=True)
    for (alg, dataset), rows in groups.items():
        pts = [(number(r["cpu_s"]), number(r["error"]), r) for r in rows]
        pts = [p for p in pts if math.isfinite(p[0]) and math.isfinite(p[1]) and p[0] > 0]
        if not pts:
            continue
        fig, ax = plt.subplots(figsize=(7, 4.5))
        variants = sorted({p[2]["variant"] for p in pts})
        colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
        color = {v: colors[i % len(colors)] for i, v in enumerate(variants)}
        means = read_means(os.path.join(os.path.dirname(args.csv), "%s__%s__means.csv" % (alg, dataset)), rows[0]["error_metric"])
        for v in variants:
            xs = [p[0] for p in pts if p[2]["variant"] == v]
            ys = [p[1] for p in pts if p[2]["variant"] == v]
            if means:
                ax.scatter(xs, ys, color=color[v], alpha=0.25, s=10)
            else:
                ax.scatter(xs, ys, color=color[v], label=v or alg, alpha=0.7)
        for v in variants if means else []:
            m = [p for p in means if p[2]["variant"] == v]
            if m:
                ax.errorbar([p[0] for p in m], [p[1] for p in m], yerr=[p[3] if math.isfinite(p[3]) else 0 for p in m],
                            fmt="o", color=color[v], capsize=2, label=(v or alg) + " (mean +- sd)")
        if means:
            front = sorted((p for p in means if p[2]["Pareto"] == "yes"), key=lambda p: p[0])
        else:
            front = sorted((p for p in pts if p[2]["pareto"] == "1"), key=lambda p: p[0])
        if front:
            ax.step([p[0] for p in front], [p[1] for p in front], where="post", color="k", lw=1,
                    label="Pareto front of the means" if means else "Pareto front")
            # Front cells labelled by their values only (the keys are in the title), alternately
            # above and below the line so that neighbours do not overlap.
            for k, (x, y, r, *_) in enumerate(front):
                values = ", ".join(p.split("=", 1)[-1] for p in r["params"].split(", "))
                label = (r["variant"] + ": " if r["variant"] else "") + values
                ax.annotate(label, (x, y), textcoords="offset points", xytext=(4, 6 if k % 2 == 0 else -12), fontsize=7)
        xs = [p[0] for p in pts]
        if max(xs) > 10 * min(xs):  # log time only over a wide range
            ax.set_xscale("log")
        ys = [p[1] for p in pts]
        if min(ys) > 0 and max(ys) > 10 * min(ys):  # log error too over a wide range
            ax.set_yscale("log")
        keys = [p.split("=", 1)[0] for p in (means[0][2] if means else rows[0])["params"].split(", ") if "=" in p]
        ax.set_xlabel("CPU time of the cell, s")
        ax.set_ylabel(rows[0]["error_metric"])
        ax.set_title("%s on %s%s" % (alg, dataset, ("\nfront labelled by " + ", ".join(keys)) if keys else ""), fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
        fig.tight_layout()
        stem = os.path.join(args.out_dir, "%s__%s" % (alg, dataset))
        print("%s__%s: %d cells%s" % (alg, dataset, len(pts), (", %d means with +-1 sd, the front of the means" % len(means)) if means else ""))
        fig.savefig(stem + ".png", dpi=110)
        fig.savefig(stem + ".pdf")
        plt.close(fig)


if __name__ == "__main__":
    main()
