#!/usr/bin/python3
"""Independent numpy re-computation of `evio eval` (a separate code path: it does not call evio).

Usage: check_eval.py GT EST RESULTS_JSON [--index I] [--tol 1e-6]

Reads the ground truth and one estimate (TUM `t x y z qx qy qz qw` with t in s, or csv with a
header naming timestamp/x/y/z/qx/qy/qz/qw with t in ns), the protocol from results.json, and
recomputes association (nearest stamp within max_dt, each ground-truth pose used once),
alignment (none, SE3/Sim3 by Umeyama, position+yaw), ATE, mean position error %, and the
relative error of rpg_trajectory_evaluation (sub-trajectories of given length along the ground
truth path, E = (T_gt_i^-1 T_gt_j)^-1 (T_est_i^-1 T_est_j)), then asserts that every number agrees
with results.json to tol (absolute, or relative for values above 1). Exit 0 when all agree.

The functions are also used by plot_trajectory.py for the per-segment RPE values of box plots.
"""
import argparse
import json
import sys

import numpy as np


# ---------------------------------------------------------------- reading
def _time_to_ns(text, exp):
    """Decimal text in units of 10^-(9-exp) s (exp: 9 for s, 6 ms, 3 us, 0 ns) -> int ns, exactly."""
    text = text.strip()
    neg = text.startswith('-')
    if neg or text.startswith('+'):
        text = text[1:]
    if 'e' in text.lower():  # rare: exponent form, go through float
        v = int(round(float(text) * 10 ** exp))
    else:
        whole, _, frac = text.partition('.')
        frac = (frac + '0' * exp)[:exp]
        v = int(whole or '0') * 10 ** exp + (int(frac) if frac else 0)
    return -v if neg else v


def read_trajectory(path):
    """-> (t_ns int64 array, positions (n,3), quaternions (n,4) as x y z w, normalised)."""
    with open(path) as f:
        lines = [ln.strip() for ln in f if ln.strip()]
    if not lines:
        raise ValueError('%s: no poses' % path)
    data = [ln for ln in lines if not ln.startswith('#')]
    is_csv = path.lower().endswith('.csv') or (bool(data) and (data[0][0].isalpha() or ',' in data[0]))
    t, v = [], []
    if is_csv:
        hl = [ln for ln in lines if ',' in ln][0]  # the header: first line naming the columns
        header = [c.strip().lstrip('#').strip().lower() for c in hl.split(',')]
        unit = 'ns'
        if '[' in header[0]:
            unit = header[0].split('[')[1].split(']')[0].strip()
        names = [h.split('[')[0].strip() for h in header]

        def col(cands):
            for c in cands:
                if c in names:
                    return names.index(c)
            raise ValueError('%s: column %s not found' % (path, cands))
        idx = [col([a, 'p_rs_r_' + a, 'p' + a]) for a in 'xyz'] + [col(['q' + a, 'q_rs_' + a]) for a in 'xyzw']
        exp = {'s': 9, 'ms': 6, 'us': 3, 'ns': 0}[unit]
        for ln in lines[lines.index(hl) + 1:]:
            if ln.startswith('#'):
                continue
            c = ln.split(',')
            t.append(_time_to_ns(c[0], exp))
            v.append([float(c[i]) for i in idx])
    else:
        for ln in lines:
            if ln.startswith('#'):
                continue
            c = ln.split()
            if len(c) != 8:
                raise ValueError('%s: expected 8 columns' % path)
            t.append(_time_to_ns(c[0], 9))
            v.append([float(x) for x in c[1:]])
    t = np.array(t, dtype=np.int64)
    v = np.array(v, dtype=np.float64)
    q = v[:, 3:7] / np.linalg.norm(v[:, 3:7], axis=1)[:, None]
    return t, v[:, 0:3].copy(), q


def quat_to_rot(q):
    """Quaternions (n,4) x y z w -> rotation matrices (n,3,3)."""
    x, y, z, w = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    R = np.empty((len(q), 3, 3))
    R[:, 0, 0] = 1 - 2 * (y * y + z * z)
    R[:, 0, 1] = 2 * (x * y - z * w)
    R[:, 0, 2] = 2 * (x * z + y * w)
    R[:, 1, 0] = 2 * (x * y + z * w)
    R[:, 1, 1] = 1 - 2 * (x * x + z * z)
    R[:, 1, 2] = 2 * (y * z - x * w)
    R[:, 2, 0] = 2 * (x * z - y * w)
    R[:, 2, 1] = 2 * (y * z + x * w)
    R[:, 2, 2] = 1 - 2 * (x * x + y * y)
    return R


def rot_angle(R):
    """Rotation angle of matrices (n,3,3), rad; atan2 form, accurate near 0 and pi."""
    s = 0.5 * np.sqrt((R[:, 2, 1] - R[:, 1, 2]) ** 2 + (R[:, 0, 2] - R[:, 2, 0]) ** 2 + (R[:, 1, 0] - R[:, 0, 1]) ** 2)
    c = 0.5 * (R[:, 0, 0] + R[:, 1, 1] + R[:, 2, 2] - 1)
    return np.arctan2(s, c)


def yaw_of(R):
    """ZYX Euler yaw of matrices (n,3,3), rad."""
    return np.arctan2(R[:, 1, 0], R[:, 0, 0])


# ---------------------------------------------------------------- protocol
def associate(t_gt, t_est, max_dt_s, offset_s):
    """Nearest ground-truth stamp within max_dt for each estimate stamp (+offset), each ground-truth
    pose used at most once, in time order. -> (est indices, gt indices)."""
    t_e = t_est + int(round(offset_s * 1e9))
    max_dt = max_dt_s * 1e9
    ie, ig = [], []
    last = -1
    for k, t in enumerate(t_e):
        j = int(np.searchsorted(t_gt, t))
        best, best_d = -1, None
        for c in (j - 1, j):
            if 0 <= c < len(t_gt) and c > last:
                d = abs(int(t_gt[c]) - int(t))
                if d <= max_dt and (best_d is None or d < best_d):
                    best, best_d = c, d
        if best >= 0:
            ie.append(k)
            ig.append(best)
            last = best
    return np.array(ie, dtype=int), np.array(ig, dtype=int)


def umeyama(p_gt, p_est, with_scale):
    """p_gt ~ s R p_est + t (Umeyama 1991). -> (R, t, s)."""
    mu_g, mu_e = p_gt.mean(0), p_est.mean(0)
    g, e = p_gt - mu_g, p_est - mu_e
    n = len(p_gt)
    C = g.T @ e / n
    U, D, Vt = np.linalg.svd(C)
    S = np.eye(3)
    if np.linalg.det(U) * np.linalg.det(Vt) < 0:
        S[2, 2] = -1
    R = U @ S @ Vt
    s = 1.0
    if with_scale:
        var_e = (e ** 2).sum() / n
        s = np.trace(np.diag(D) @ S) / var_e
    t = mu_g - s * R @ mu_e
    return R, t, s


def align_posyaw(p_gt, p_est):
    """Rotation about z + translation minimising position error."""
    mu_g, mu_e = p_gt.mean(0), p_est.mean(0)
    g, e = p_gt - mu_g, p_est - mu_e
    a = np.sum(e[:, 0] * g[:, 0] + e[:, 1] * g[:, 1])
    b = np.sum(e[:, 0] * g[:, 1] - e[:, 1] * g[:, 0])
    th = np.arctan2(b, a)
    R = np.array([[np.cos(th), -np.sin(th), 0], [np.sin(th), np.cos(th), 0], [0, 0, 1]])
    return R, mu_g - R @ mu_e, 1.0


def spans_plane(p):
    """RMS spread >= 1 mm and second singular value >= 1e-3 of the first (evio's rule)."""
    if len(p) < 3:
        return False
    c = p - p.mean(axis=0)
    w = np.sqrt(np.clip(np.linalg.eigvalsh(c.T @ c / len(p)), 0, None))  # ascending
    return w[2] >= 1e-3 and w[1] >= 1e-3 * w[2]


def fit_alignment(method, t_ns, p_gt, p_est, first_s, first_n, R_gt0=None, R_est0=None):
    n = len(t_ns)
    use = n
    if first_s > 0:
        use = int(np.sum(t_ns - t_ns[0] <= int(round(first_s * 1e9))))
    if first_n > 0:
        use = min(use, first_n)
    g, e = p_gt[:use], p_est[:use]
    if method == 'none':
        return np.eye(3), np.zeros(3), 1.0, use
    if method in ('se3', 'sim3') and use >= 2 and R_gt0 is not None and not (spans_plane(g) and spans_plane(e)):
        # no plane spanned (still / rotating in place / a line): align the first pair's poses
        R = R_gt0 @ R_est0.T
        return R, g[0] - R @ e[0], 1.0, use
    if method == 'se3':
        return umeyama(g, e, False) + (use,)
    if method == 'sim3':
        return umeyama(g, e, True) + (use,)
    if method == 'posyaw':
        return align_posyaw(g, e) + (use,)
    raise ValueError('unknown alignment ' + method)


def stats(v):
    v = np.asarray(v, dtype=np.float64)
    if len(v) == 0:
        return dict(rmse=0.0, mean=0.0, median=0.0, std=0.0, min=0.0, max=0.0, count=0)
    return dict(rmse=float(np.sqrt(np.mean(v ** 2))), mean=float(np.mean(v)), median=float(np.median(v)),
                std=float(np.std(v)), min=float(np.min(v)), max=float(np.max(v)), count=len(v))


def accumulated_distances(p):
    return np.concatenate(([0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))))


def comparison_pairs(dist, length, max_diff):
    """For each start i, the end j >= i whose distance from start is closest to `length`, within
    max_diff (strictly), as in rpg_trajectory_evaluation. -> list of (i, j)."""
    pairs = []
    for i in range(len(dist)):
        target = dist[i] + length
        k = int(np.searchsorted(dist, target))
        best, err = -1, max_diff
        for c in (k - 1, k):
            if i <= c < len(dist):
                d = abs(dist[c] - target)
                if d < err:
                    best, err = c, d
        if best >= 0:
            pairs.append((i, best))
    return pairs


def relative_errors(p_gt, R_gt, p_est, R_est, length, max_diff, scale=1.0):
    """Per-segment errors of one length: dict of arrays trans_m, rot_deg, yaw_deg.

    E = (T_gt_i^-1 T_gt_j)^-1 (T_est_i^-1 T_est_j) with the estimate's relative translation times
    `scale`; the yaw is taken of E expressed in the world frame, R_est_j E R_est_j^T (rpg's
    T_error_in_w). A rigid alignment of the estimate changes none of these, so the aligned or the
    unaligned estimate may be passed (with the Sim3 scale when unaligned)."""
    pairs = comparison_pairs(accumulated_distances(p_gt), length, max_diff)
    out = dict(trans_m=np.zeros(0), rot_deg=np.zeros(0), yaw_deg=np.zeros(0))
    if not pairs:
        return out
    i = np.array([a for a, _ in pairs])
    j = np.array([b for _, b in pairs])
    # relative motions T_i^-1 T_j
    Rg = np.einsum('nki,nkj->nij', R_gt[i], R_gt[j])
    tg = np.einsum('nki,nk->ni', R_gt[i], p_gt[j] - p_gt[i])
    Re = np.einsum('nki,nkj->nij', R_est[i], R_est[j])
    te = scale * np.einsum('nki,nk->ni', R_est[i], p_est[j] - p_est[i])
    # E = (Tg)^-1 Te: rotation Rg^T Re, translation Rg^T (te - tg)
    RE = np.einsum('nki,nkj->nij', Rg, Re)
    tE = np.einsum('nki,nk->ni', Rg, te - tg)
    RE_w = np.einsum('nij,njk,nlk->nil', R_est[j], RE, R_est[j])
    out['trans_m'] = np.linalg.norm(tE, axis=1)
    out['rot_deg'] = np.degrees(rot_angle(RE))
    out['yaw_deg'] = np.abs(np.degrees(yaw_of(RE_w)))
    return out


def evaluate(gt, est, protocol):
    """gt, est: (t_ns, p, q). protocol: results.json's "protocol". -> dict like one results.json estimate."""
    a = protocol['association']
    ie, ig = associate(gt[0], est[0], a['max_dt_s'], a['time_offset_s'])
    if a.get('interpolate_groundtruth'):
        raise NotImplementedError('check_eval.py checks exact/nearest association only')
    t = est[0][ie] + int(round(a['time_offset_s'] * 1e9))
    p_g, R_g = gt[1][ig], quat_to_rot(gt[2][ig])
    p_e, R_e = est[1][ie], quat_to_rot(est[2][ie])
    al = protocol['alignment']
    R, tr, s, used = fit_alignment(al['method'], t, p_g, p_e, al['first_s'], al['first_poses'], R_g[0], R_e[0])
    p_a = s * p_e @ R.T + tr
    R_a = np.einsum('ij,njk->nik', R, R_e)
    e_t = np.linalg.norm(p_g - p_a, axis=1)
    e_r = np.degrees(rot_angle(np.einsum('nki,nkj->nij', R_g, R_a)))
    L = float(accumulated_distances(p_g)[-1])
    res = dict(matched_poses=len(t), groundtruth_length_m=L,
               ate=dict(trans_m=stats(e_t), rot_deg=stats(e_r)),
               mean_position_error_percent=100.0 * float(np.mean(e_t)) / L if L > 0 else 0.0,
               alignment=dict(rotation=R.tolist(), translation=tr.tolist(), scale=s, pairs_used=used),
               rpe=[], trans_errors=e_t, rot_errors=e_r)
    # world-frame yaw error of the last pair, R_est_aligned R_gt^T (rpg's abs_e_ypr)
    y_end = float(np.degrees(yaw_of((R_a[-1] @ R_g[-1].T)[None])[0]))
    res['final_yaw_error_deg'] = y_end
    res['yaw_drift_deg_per_m'] = abs(y_end) / L if L > 0 else 0.0
    rp = protocol['rpe']
    in_percent = rp['lengths_unit'].startswith('percent')
    # Percentages are of the whole ground-truth file's path length (not only the matched part),
    # truncated to centimetres, as rpg's compute_boxplot_distances; 0 m lengths are left out.
    L_all = float(accumulated_distances(gt[1])[-1])
    for length in rp['lengths']:
        d = np.trunc(length / 100.0 * L_all * 100.0) / 100.0 if in_percent else float(length)
        if d > 0:
            res['rpe'].append(rpe_entry(p_g, R_g, p_e, R_e, d, s))
    return res


def rpe_entry(p_g, R_g, p_e, R_e, d, scale):
    r = relative_errors(p_g, R_g, p_e, R_e, d, 0.2 * d, scale)
    return dict(length_m=d, count=len(r['trans_m']), trans_m=stats(r['trans_m']),
                trans_percent=stats(100.0 * r['trans_m'] / d if d > 0 else r['trans_m']),
                rot_deg=stats(r['rot_deg']), yaw_deg=stats(r['yaw_deg']),
                yaw_deg_per_m=stats(r['yaw_deg'] / d if d > 0 else r['yaw_deg']))


# ---------------------------------------------------------------- comparison
class Checker:
    def __init__(self, tol):
        self.tol = tol
        self.failures = []
        self.checked = 0
        self.worst = 0.0

    def num(self, name, mine, theirs):
        self.checked += 1
        if theirs is None:
            self.failures.append('%s: results.json has null, numpy %r' % (name, mine))
            return
        diff = abs(float(mine) - float(theirs))
        rel = diff / max(1.0, abs(float(theirs)))
        self.worst = max(self.worst, rel)
        if rel > self.tol:
            self.failures.append('%s: numpy %.17g vs results.json %.17g (diff %.3g)' % (name, mine, theirs, diff))

    def stats(self, name, mine, theirs):
        for k in ('rmse', 'mean', 'median', 'std', 'min', 'max'):
            self.num(name + '.' + k, mine[k], theirs[k])


def compare(mine, theirs, tol):
    c = Checker(tol)
    c.num('matched_poses', mine['matched_poses'], theirs['matched_poses'])
    c.stats('ate.trans_m', mine['ate']['trans_m'], theirs['ate']['trans_m'])
    c.stats('ate.rot_deg', mine['ate']['rot_deg'], theirs['ate']['rot_deg'])
    c.num('mean_position_error_percent', mine['mean_position_error_percent'], theirs['mean_position_error_percent'])
    c.num('groundtruth_length_m', mine['groundtruth_length_m'], theirs['groundtruth_length_m'])
    c.num('yaw_drift_deg_per_m', mine['yaw_drift_deg_per_m'], theirs['yaw_drift_deg_per_m'])
    c.num('alignment.scale', mine['alignment']['scale'], theirs['alignment']['scale'])
    for r in range(3):
        c.num('alignment.translation[%d]' % r, mine['alignment']['translation'][r], theirs['alignment']['translation'][r])
        for k in range(3):
            c.num('alignment.rotation[%d][%d]' % (r, k), mine['alignment']['rotation'][r][k],
                  theirs['alignment']['rotation'][r][k])
    if len(mine['rpe']) != len(theirs['rpe']):
        c.failures.append('rpe: %d lengths vs %d' % (len(mine['rpe']), len(theirs['rpe'])))
    for m, t in zip(mine['rpe'], theirs['rpe']):
        n = 'rpe[%g m]' % m['length_m']
        c.num(n + '.length_m', m['length_m'], t['length_m'])
        c.num(n + '.count', m['count'], t['count'])
        for k in ('trans_percent', 'yaw_deg_per_m', 'trans_m', 'rot_deg', 'yaw_deg'):
            if k in t:
                c.stats(n + '.' + k, m[k], t[k])
    return c


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('gt')
    ap.add_argument('est')
    ap.add_argument('results')
    ap.add_argument('--index', type=int, default=0, help='which estimate of results.json (default 0)')
    ap.add_argument('--tol', type=float, default=1e-6)
    a = ap.parse_args(argv)
    with open(a.results) as f:
        results = json.load(f)
    theirs = results['estimates'][a.index]
    mine = evaluate(read_trajectory(a.gt), read_trajectory(a.est), results['protocol'])
    c = compare(mine, theirs, a.tol)
    print('check_eval: %d numbers compared, worst relative difference %.3g (tol %g); ATE rmse %.6f m, %d pairs, '
          'RPE lengths %s m' % (c.checked, c.worst, a.tol, mine['ate']['trans_m']['rmse'], mine['matched_poses'],
                                 ', '.join('%g' % r['length_m'] for r in mine['rpe'])))
    if c.failures:
        print('check_eval: %d disagreements:' % len(c.failures))
        for f in c.failures[:40]:
            print('  ' + f)
        return 1
    print('check_eval: all agree')
    return 0


if __name__ == '__main__':
    sys.exit(main())
