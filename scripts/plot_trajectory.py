#!/usr/bin/python3
"""Plots of `evio eval` outputs (numpy + matplotlib from Debian; run with /usr/bin/python3).

Usage: plot_trajectory.py RESULTS_DIR [--out PLOT_DIR] [--formats png,pdf]

Reads RESULTS_DIR/results.json and the per-estimate files it names (aligned estimate and matched
ground truth as TUM, per-pair errors as csv) and writes, as PNG and PDF:
  trajectory_top      x-y view of the aligned estimates and the ground truth
  trajectory_side     x-z view
  errors_over_time    translation [m] and rotation [deg] error over time, one line per estimate
  rpe_boxplot         relative translation error [%] per sub-trajectory length, one box per estimate
  comparison          (several methods) ATE RMSE and mean RPE per method label, mean and min..max over runs
Missing numpy/matplotlib: `sudo apt-get install python3-numpy python3-matplotlib`.
"""
import argparse
import json
import os
import sys

try:
    import numpy as np
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
except ImportError as e:  # pragma: no cover
    sys.stderr.write('plot_trajectory.py: %s; install with `sudo apt-get install python3-numpy python3-matplotlib` '
                     '(or scripts/setup_deps.sh)\n' % e)
    sys.exit(2)

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import check_eval  # noqa: E402  (trajectory reading and the per-segment relative errors)


def save(fig, out, name, formats):
    fig.tight_layout()
    paths = []
    for ext in formats:
        p = os.path.join(out, '%s.%s' % (name, ext))
        fig.savefig(p, dpi=150)
        paths.append(p)
    plt.close(fig)
    return paths


def load(dirname, results):
    runs = []
    for e in results['estimates']:
        o = e['outputs']
        gt = check_eval.read_trajectory(os.path.join(dirname, o['matched_groundtruth']))
        est = check_eval.read_trajectory(os.path.join(dirname, o['aligned_estimate']))
        err = np.loadtxt(os.path.join(dirname, o['errors']), delimiter=',', comments='#', ndmin=2)
        runs.append(dict(meta=e, gt=gt, est=est, err=err))
    return runs


def short(label, n=28):
    label = os.path.basename(label)
    return label if len(label) <= n else label[:n - 1] + '~'


def plot_views(runs, out, formats):
    written = []
    for name, (a, b), (la, lb) in (('trajectory_top', (0, 1), ('x [m]', 'y [m]')),
                                   ('trajectory_side', (0, 2), ('x [m]', 'z [m]'))):
        fig, ax = plt.subplots(figsize=(6, 5))
        g = runs[0]['gt'][1]
        ax.plot(g[:, a], g[:, b], 'k-', lw=1.5, label='ground truth')
        for r in runs:
            p = r['est'][1]
            ax.plot(p[:, a], p[:, b], lw=1, label='%s (%s)' % (short(r['meta']['label']), r['meta']['align']))
        ax.plot(g[0, a], g[0, b], 'ko', ms=5)
        ax.set_xlabel(la)
        ax.set_ylabel(lb)
        ax.set_aspect('equal', adjustable='datalim')
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7)
        ax.set_title('%s view, aligned estimates' % ('top' if b == 1 else 'side'))
        written += save(fig, out, name, formats)
    return written


def plot_errors(runs, out, formats):
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(7, 5), sharex=True)
    for r in runs:
        e = r['err']
        t = e[:, 0] - e[0, 0]
        lab = short(r['meta']['label'])
        ax1.plot(t, e[:, 1], lw=0.8, label=lab)
        ax2.plot(t, e[:, 2], lw=0.8, label=lab)
    ax1.set_ylabel('translation error [m]')
    ax2.set_ylabel('rotation error [deg]')
    ax2.set_xlabel('time since the first pair [s]')
    for ax in (ax1, ax2):
        ax.grid(True, alpha=0.3)
    ax1.legend(fontsize=7)
    return save(fig, out, 'errors_over_time', formats)


def plot_rpe(runs, out, formats):
    # Per-segment values recomputed from the aligned estimate and matched ground truth, with the
    # lengths evio used (results.json), through the same protocol as check_eval.py.
    lengths = [q['length_m'] for q in runs[0]['meta']['rpe']]
    if not lengths:
        return []
    data = []
    for r in runs:
        t, pg, qg = r['gt']
        _, pe, qe = r['est']
        Rg, Re = check_eval.quat_to_rot(qg), check_eval.quat_to_rot(qe)
        per = []
        for d in lengths:
            v = check_eval.relative_errors(pg, Rg, pe, Re, d, 0.2 * d)['trans_m'] if d > 0 else np.array([])
            per.append(100.0 * v / d if len(v) else np.array([np.nan]))
        data.append(per)
    fig, ax = plt.subplots(figsize=(max(5, 1.2 * len(lengths) * len(runs) ** 0.5 + 2), 4))
    n = len(runs)
    width = 0.8 / n
    colors = plt.rcParams['axes.prop_cycle'].by_key()['color']
    for k, per in enumerate(data):
        pos = np.arange(len(lengths)) + (k - (n - 1) / 2) * width
        bp = ax.boxplot([p[np.isfinite(p)] if np.any(np.isfinite(p)) else [np.nan] for p in per], positions=pos,
                        widths=width * 0.9, patch_artist=True, showfliers=False)
        for box in bp['boxes']:
            box.set_facecolor(colors[k % len(colors)])
            box.set_alpha(0.6)
        ax.plot([], [], 's', color=colors[k % len(colors)], label=short(runs[k]['meta']['label']))
    ax.set_xticks(np.arange(len(lengths)))
    ax.set_xticklabels(['%.3g' % d for d in lengths])
    ax.set_xlabel('sub-trajectory length [m]')
    ax.set_ylabel('relative translation error [%]')
    ax.grid(True, axis='y', alpha=0.3)
    if n > 1:
        ax.legend(fontsize=7)
    return save(fig, out, 'rpe_boxplot', formats)


def plot_comparison(runs, out, formats):
    labels = []
    for r in runs:
        if r['meta']['label'] not in labels:
            labels.append(r['meta']['label'])
    if len(runs) < 2:
        return []

    def rpe_mean(m):
        v = [q['trans_percent']['mean'] for q in m['rpe'] if q['count'] > 0]
        return float(np.mean(v)) if v else np.nan

    fig, axes = plt.subplots(1, 2, figsize=(8, 3.5))
    for ax, (title, f) in zip(axes, (('ATE RMSE [m]', lambda m: m['ate']['trans_m']['rmse']),
                                     ('mean RPE [%]', rpe_mean))):
        for k, lab in enumerate(labels):
            v = np.array([f(r['meta']) for r in runs if r['meta']['label'] == lab], dtype=float)
            v = v[np.isfinite(v)]
            if len(v) == 0:
                continue
            ax.bar(k, v.mean(), color='C%d' % (k % 10), alpha=0.7)
            ax.errorbar(k, v.mean(), yerr=[[v.mean() - v.min()], [v.max() - v.mean()]], color='k', capsize=4)
            ax.plot(np.full(len(v), k), v, 'k.', ms=4)
        ax.set_xticks(range(len(labels)))
        ax.set_xticklabels([short(l, 16) for l in labels], rotation=20, ha='right', fontsize=7)
        ax.set_title(title + ', mean and min..max over runs', fontsize=8)
        ax.grid(True, axis='y', alpha=0.3)
    return save(fig, out, 'comparison', formats)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('results_dir')
    ap.add_argument('--out', help='plot folder (default: RESULTS_DIR)')
    ap.add_argument('--formats', default='png,pdf')
    a = ap.parse_args(argv)
    out = a.out or a.results_dir
    os.makedirs(out, exist_ok=True)
    with open(os.path.join(a.results_dir, 'results.json')) as f:
        results = json.load(f)
    runs = load(a.results_dir, results)
    if not runs:
        sys.stderr.write('plot_trajectory.py: no estimates in results.json\n')
        return 1
    formats = [x for x in a.formats.split(',') if x]
    written = plot_views(runs, out, formats) + plot_errors(runs, out, formats) + plot_rpe(runs, out, formats)
    written += plot_comparison(runs, out, formats)
    print('plot_trajectory.py: wrote %d files in %s' % (len(written), out))
    return 0


if __name__ == '__main__':
    sys.exit(main())
