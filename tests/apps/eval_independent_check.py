#!/usr/bin/python3
"""ctest: `evio eval` against the independent numpy implementation (scripts/check_eval.py) on the
real poster_6dof motion-capture trajectory and a perturbed copy of it (known rigid transform,
noise, position and yaw drift). Exit 77 (ctest SKIP_RETURN_CODE) when numpy or the data is absent.

Usage: eval_independent_check.py EVIO SOURCE_DIR WORK_DIR
"""
import os
import subprocess
import sys

SKIP = 77


def main():
    evio, src, work = sys.argv[1:4]
    try:
        import numpy as np
    except ImportError:
        print('SKIP: numpy is not installed (sudo apt-get install python3-numpy)')
        return SKIP
    root = os.environ.get('EVIO_REAL_DATA') or os.path.join(src, '..', 'shared', 'data', 'real')
    gt_path = os.path.join(root, 'trajectories', 'poster_6dof_mocap.csv')
    if not os.path.exists(gt_path):
        print('SKIP: %s not found (set EVIO_REAL_DATA)' % gt_path)
        return SKIP
    sys.path.insert(0, os.path.join(src, 'scripts'))
    import check_eval

    os.makedirs(work, exist_ok=True)
    t, p, q = check_eval.read_trajectory(gt_path)
    R = check_eval.quat_to_rot(q)
    rng = np.random.default_rng(20261121)
    s = (t - t[0]) * 1e-9
    dist = check_eval.accumulated_distances(p)

    def rz(a):
        c, si = np.cos(a), np.sin(a)
        out = np.zeros((len(a), 3, 3))
        out[:, 0, 0], out[:, 0, 1], out[:, 1, 0], out[:, 1, 1], out[:, 2, 2] = c, -si, si, c, 1
        return out

    def exp_so3(w):
        th = np.linalg.norm(w, axis=1)[:, None, None]
        K = np.zeros((len(w), 3, 3))
        K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -w[:, 2], w[:, 1], -w[:, 0]
        K[:, 1, 0], K[:, 2, 0], K[:, 2, 1] = w[:, 2], -w[:, 1], w[:, 0]
        th_s = np.where(th > 0, th, 1)
        return np.eye(3) + np.sin(th) / th_s * K + (1 - np.cos(th)) / th_s ** 2 * (K @ K)

    # Drift: 1.5 cm per m travelled along (1, -0.5, 0.2), yaw 0.3 deg per m; noise 5 mm, 0.2 deg.
    p_d = p + 0.015 * dist[:, None] * np.array([1.0, -0.5, 0.2]) + rng.normal(0, 0.005, p.shape)
    R_d = rz(np.radians(0.3) * dist) @ R @ exp_so3(rng.normal(0, np.radians(0.2), p.shape))
    # Known rigid transform of the estimate's world frame.
    R0 = exp_so3(np.array([[0.3, -0.2, 1.1]]))[0]
    t0 = np.array([1.5, -2.0, 0.7])
    p_e = p_d @ R0.T + t0
    R_e = np.einsum('ij,njk->nik', R0, R_d)
    qe = rot_to_quat(R_e)
    est_path = os.path.join(work, 'poster_6dof_perturbed.tum')
    with open(est_path, 'w') as f:
        f.write('# perturbed poster_6dof mocap: t x y z qx qy qz qw\n')
        for k in range(len(t)):
            f.write('%d.%09d %.17g %.17g %.17g %.17g %.17g %.17g %.17g\n' % (
                t[k] // 1000000000, t[k] % 1000000000, p_e[k, 0], p_e[k, 1], p_e[k, 2],
                qe[k, 0], qe[k, 1], qe[k, 2], qe[k, 3]))

    failures = 0
    for name, extra in (('se3', ['--align', 'se3']),
                        ('sim3_first5s', ['--align', 'sim3', '--align-first-s', '5']),
                        ('posyaw_metres', ['--align', 'posyaw', '--rpe-lengths', '2,5,10m'])):
        out = os.path.join(work, 'eval_' + name)
        cmd = [evio, 'eval', gt_path, est_path, '--out', out, '-q'] + extra
        print('$ ' + ' '.join(cmd), flush=True)
        r = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, universal_newlines=True)
        print(r.stdout, flush=True)
        if r.returncode != 0:
            print('FAIL: evio eval exited %d' % r.returncode)
            failures += 1
            continue
        rc = check_eval.main([gt_path, est_path, os.path.join(out, 'results.json'), '--tol', '1e-6'])
        failures += rc != 0
    return 1 if failures else 0


def rot_to_quat(R):
    """Rotation matrices (n,3,3) -> quaternions x y z w (w >= 0), by the largest-diagonal method."""
    import numpy as np
    q = np.empty((len(R), 4))
    for k, M in enumerate(R):
        tr = np.trace(M)
        if tr > 0:
            s = 2 * np.sqrt(tr + 1)
            q[k] = [(M[2, 1] - M[1, 2]) / s, (M[0, 2] - M[2, 0]) / s, (M[1, 0] - M[0, 1]) / s, s / 4]
        else:
            i = int(np.argmax(np.diag(M)))
            j, l = (i + 1) % 3, (i + 2) % 3
            s = 2 * np.sqrt(1 + M[i, i] - M[j, j] - M[l, l])
            v = np.empty(4)
            v[i] = s / 4
            v[j] = (M[j, i] + M[i, j]) / s
            v[l] = (M[l, i] + M[i, l]) / s
            v[3] = (M[l, j] - M[j, l]) / s
            q[k] = v
        if q[k, 3] < 0:
            q[k] = -q[k]
    return q


if __name__ == '__main__':
    sys.exit(main())
