#!/usr/bin/python3
"""Speed-accuracy curves of the CMax angular-velocity front-end from the csv files written by
bench/cmax_rotation_table (one or more, e.g. one per scene): time per event (us, x) against the
RMS angular-velocity error (deg/s, y), one curve per csv label (colour) and pyramid-level count
(marker and line style), each point one events-per-window setting (labelled). Dashed lines: the targets (0.5 us/event, 2 deg/s).

    scripts/plot_cmax_speed_accuracy.py poster.csv boxes.csv -o speed_accuracy.png

matplotlib from Debian (python3-matplotlib); no numpy.
"""
import argparse
import csv
import sys


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("csv", nargs="+", help="csv files of bench/cmax_rotation_table --csv")
    ap.add_argument("-o", "--out", required=True, help="PNG to write")
    ap.add_argument("--title", default="CMax angular velocity: speed vs accuracy (one core)")
    args = ap.parse_args()
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        sys.exit("matplotlib is missing: apt-get install python3-matplotlib")

    curves = {}  # (label, levels, warm_levels) -> [(us, rms, window_events)]
    for path in args.csv:
        with open(path, newline="") as f:
            for r in csv.DictReader(f):
                key = (r["label"], int(r["levels"]), int(r["warm_levels"]))
                curves.setdefault(key, []).append(
                    (float(r["us_per_event"]), float(r["rms_degps"]), int(r["window_events"])))
    if not curves:
        sys.exit("no rows in " + ", ".join(args.csv))

    fig, ax = plt.subplots(figsize=(8, 5.5))
    markers = "osD^vP*X"
    labels = sorted({k[0] for k in curves})
    styles = ["-", "--", ":", "-.", (0, (5, 1))]
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for (label, levels, warm), pts in sorted(curves.items()):
        pts.sort(key=lambda p: p[2])
        xs = [p[0] for p in pts]
        ys = [p[1] for p in pts]
        name = "%s, %d level%s" % (label, levels, "" if levels == 1 else "s")
        if warm != levels:
            name += " (warm %d)" % warm
        # colour: the csv label (scene, objective); marker and line: the pyramid levels
        ax.plot(xs, ys, linestyle=styles[(levels - 1) % len(styles)], marker=markers[(levels - 1) % len(markers)],
                color=colours[labels.index(label) % len(colours)], label=name)
        for x, y, n in pts:
            ax.annotate("%gk" % (n / 1000.0), (x, y), textcoords="offset points", xytext=(4, 4), fontsize=7)
    ax.axvline(0.5, color="grey", linestyle="--", linewidth=0.8)
    ax.axhline(2.0, color="grey", linestyle="--", linewidth=0.8)
    ax.set_xlabel("time per event (us)")
    ax.set_ylabel("angular velocity RMS error (deg/s)")
    ax.set_yscale("log")
    ax.set_title(args.title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(args.out, dpi=120)
    print("wrote", args.out)


if __name__ == "__main__":
    main()
