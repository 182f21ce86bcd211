#!/usr/bin/python3
"""PSNR and SSIM over time of the reconstruction methods against the simulator's true views, from
the csv written by bench/reconstruct_quality (--csv; columns scene,method,t_s,psnr_db,ssim): one
row of panels per scene (PSNR left, SSIM right), one line per method.

    scripts/plot_reconstruct_quality.py bench/results/reconstruct_quality_cutoff0.5.csv -o quality.png

matplotlib from Debian (python3-matplotlib); no numpy.
"""
import argparse
import csv
import sys


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("csv", help="csv of bench/reconstruct_quality --csv")
    ap.add_argument("-o", "--out", required=True, help="PNG to write")
    ap.add_argument("--title", default="Reconstruction against the true views")
    args = ap.parse_args()
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        sys.exit("matplotlib is missing: apt-get install python3-matplotlib")

    series = {}  # scene -> method -> [(t, psnr, ssim)]
    with open(args.csv, newline="") as f:
        for line, row in enumerate(csv.DictReader(f), start=2):
            try:
                point = (float(row["t_s"]), float(row["psnr_db"]), float(row["ssim"]))
            except (KeyError, TypeError, ValueError):
                sys.exit(f"{args.csv}:{line}: expected scene,method,t_s,psnr_db,ssim with numbers, got {row}")
            series.setdefault(row["scene"], {}).setdefault(row["method"], []).append(point)
    if not series:
        sys.exit(f"{args.csv}: no rows")
    style = {"hf": ("tab:gray", "o"), "cf": ("tab:blue", "s"), "akf": ("tab:red", "^"), "gradient": ("tab:green", "d")}
    fig, axes = plt.subplots(len(series), 2, figsize=(10, 3 * len(series)), squeeze=False)
    for r, (scene, methods) in enumerate(series.items()):
        for method, pts in methods.items():
            pts.sort()
            colour, marker = style.get(method, (None, "x"))
            t = [p[0] for p in pts]
            axes[r][0].plot(t, [p[1] for p in pts], marker=marker, color=colour, label=method)
            axes[r][1].plot(t, [p[2] for p in pts], marker=marker, color=colour, label=method)
        axes[r][0].set_ylabel(f"{scene.replace('.yaml', '')}\nPSNR (dB)")
        axes[r][1].set_ylabel("SSIM")
        axes[r][1].set_ylim(0, 1)
        for a in axes[r]:
            a.grid(alpha=0.3)
        axes[r][0].legend(fontsize=8)
    for a in axes[-1]:
        a.set_xlabel("time (s)")
    fig.suptitle(args.title)
    fig.tight_layout()
    fig.savefig(args.out, dpi=90)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
