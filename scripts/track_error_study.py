#!/usr/bin/python3
"""What the event tracks' error follows: per-track models fitted to `oracle_observations.csv`.

    evio vio SEQ --gt SEQ/groundtruth.txt --oracle-tracks SCENE --oracle-error real \
        --oracle-observations --out OUT
    scripts/track_error_study.py OUT/oracle_observations.csv [more.csv ...]

For every track with at least --min-observations observations (all of them within 10 px of the
truth), its error against its first observation, E_k = e_k - e_0 (px; e: observed minus true
projection), is fitted by least squares with a few parameters per track, and the script prints
the share of the tracks' summed squared error each model leaves unexplained (1: nothing explained):

  linear in age  E_k = k w                  (2 parameters: a constant drift per frame)
  roll x lever   E_k = theta_k J c          (2: the camera's turn about its optical axis since the
                                             first observation, theta_k, times a per-track lever c;
                                             J turns by 90 deg: translation-only alignment against
                                             a turned patch)
  scale x lever  E_k = (z_0 / z_k - 1) c    (2: the patch's scale change times a lever)
  roll + linear, scale + linear            (4 each)

With --independent the frame's common mode c is taken out first (e - c, as `--oracle-error
independent`). It also prints the tracks' initial slip: the share of tracks whose error moves by more than
--slip-px within their first three steps, by the time the track was born. Needs numpy.
"""
import argparse
import sys
from collections import defaultdict

import numpy as np

from check_eval import quat_to_rot  # quaternions x y z w -> rotation matrices


def residual(A, y):
    p, *_ = np.linalg.lstsq(A, y, rcond=None)
    return float(((y - A @ p) ** 2).sum())


def study(path, min_obs, slip_px, independent):
    names = open(path).readline().strip().split(",")
    a = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    col = {n: i for i, n in enumerate(names)}
    t = a[:, col["t_s"]]
    tid = a[:, col["track_id"]].astype(np.int64)
    age = a[:, col["age"]].astype(np.int64)
    e = a[:, [col["error_x_px"], col["error_y_px"]]]
    if independent:
        e = e - a[:, [col["common_x_px"], col["common_y_px"]]]
    z = a[:, col["depth_m"]]
    R = quat_to_rot(a[:, [col["qx_c_w"], col["qy_c_w"], col["qz_c_w"], col["qw_c_w"]]])
    rows = defaultdict(list)
    for i in range(len(a)):
        rows[tid[i]].append(i)
    total = 0.0
    n = 0
    res = defaultdict(float)
    slips = []
    for idx in rows.values():
        idx = np.array(idx)
        idx = idx[np.argsort(age[idx])]
        if age[idx[0]] != 0:
            continue
        if len(idx) >= 4:
            E = e[idx] - e[idx[0]]
            slips.append((t[idx[0]] - t[0], np.linalg.norm(E[1:4], axis=1).max()))
        if len(idx) < min_obs or not (np.linalg.norm(e[idx], axis=1) < 10).all():
            continue
        E = (e[idx] - e[idx[0]]).reshape(-1)
        m = len(idx)
        Rk0 = R[idx] @ R[idx[0]].T  # camera at k from camera at the first observation
        theta = np.arctan2(Rk0[:, 1, 0] - Rk0[:, 0, 1], Rk0[:, 0, 0] + Rk0[:, 1, 1])
        scale = z[idx[0]] / z[idx] - 1
        k = np.arange(m, dtype=float)

        def pair(v, turn=False):
            A = np.zeros((2 * m, 2))
            if turn:  # theta J c = theta (-c_y, c_x)
                A[0::2, 1] = -v
                A[1::2, 0] = v
            else:
                A[0::2, 0] = v
                A[1::2, 1] = v
            return A

        L, Rt, S = pair(k), pair(theta, True), pair(scale)
        res["linear in age"] += residual(L, E)
        res["roll x lever"] += residual(Rt, E)
        res["scale x lever"] += residual(S, E)
        res["roll + linear"] += residual(np.hstack([Rt, L]), E)
        res["scale + linear"] += residual(np.hstack([S, L]), E)
        total += float((E * E).sum())
        n += m
    print(f"{path}: {len(rows)} tracks, {n} observations in tracks of >= {min_obs}")
    if total > 0:
        print(f"  rms error against the first observation {np.sqrt(total / n):.3f} px; share left unexplained:")
        for name in ("linear in age", "roll x lever", "scale x lever", "roll + linear", "scale + linear"):
            print(f"    {name:15s} {res[name] / total:.3f}")
    if slips:
        s = np.array(slips)
        print(f"  initial slip (> {slip_px} px within the first three steps), by birth time:")
        for lo, hi in ((0, 0.5), (0.5, 1), (1, 2), (2, 5), (5, np.inf)):
            sel = (s[:, 0] >= lo) & (s[:, 0] < hi)
            if sel.any():
                print(f"    born {lo:g}-{hi:g} s: {sel.sum()} tracks, {np.mean(s[sel, 1] > slip_px):.3f}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("csv", nargs="+", help="oracle_observations.csv of `evio vio ... --oracle-observations`")
    ap.add_argument("--min-observations", type=int, default=8, help="shortest track fitted (observations)")
    ap.add_argument("--slip-px", type=float, default=1.0, help="initial-slip threshold (px)")
    ap.add_argument("--independent", action="store_true", help="take each frame's common mode out of the errors first")
    args = ap.parse_args()
    for p in args.csv:
        study(p, args.min_observations, args.slip_px, args.independent)
    return 0


if __name__ == "__main__":
    sys.exit(main())
