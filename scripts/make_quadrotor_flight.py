#!/usr/bin/env python3
"""Writes datasets/trajectories/quadrotor_flight.tum: a quadrotor-like flight for
datasets/quadrotor_flight.yaml (TUM: t[s] tx ty tz qx qy qz qw, body = IMU, world z up).

The body hovers still for 1 s, then its path parameter s accelerates smoothly (quintic ramp over
2 s, zero velocity and acceleration at both ends) along a figure eight (lemniscate) of 3 m x 2 m
half-widths at 1.2 m height with a +-0.25 m height wave, reaching 1-2 m/s. The attitude is that
of a multirotor: thrust axis (body z) along the required specific force a_w - g_w (banking into
the turns), yaw a slow sinusoid. Body axes: x forward, y left, z up. Deterministic, no
dependencies beyond the standard library:
    python3 scripts/make_quadrotor_flight.py > datasets/trajectories/quadrotor_flight.tum
"""
import math

RATE_HZ = 100
DURATION_S = 12.5
T_STILL = 1.0      # s, hover before the ramp
T_RAMP = 2.0       # s, quintic speed ramp
OMEGA = 0.4        # rad/s, path-parameter rate after the ramp
A, B, H, DH = 3.0, 2.0, 1.2, 0.25
G = 9.81


def ramp_integral(t):
    """s(t): integral of OMEGA * smoothstep5((t - T_STILL) / T_RAMP)."""
    if t <= T_STILL:
        return 0.0
    u = min((t - T_STILL) / T_RAMP, 1.0)
    # integral of 10u^3 - 15u^4 + 6u^5 du = 2.5u^4 - 3u^5 + u^6
    s = OMEGA * T_RAMP * (2.5 * u ** 4 - 3 * u ** 5 + u ** 6)
    if t > T_STILL + T_RAMP:
        s += OMEGA * (t - T_STILL - T_RAMP)
    return s


def position(t):
    s = ramp_integral(t)
    return (A * math.sin(s), B * math.sin(2 * s), H + DH * math.sin(1.5 * s))


def accel(t, h=1e-3):
    p0, p1, p2 = position(t - h), position(t), position(t + h)
    return [(p0[i] - 2 * p1[i] + p2[i]) / (h * h) for i in range(3)]


def normalize(v):
    n = math.sqrt(sum(x * x for x in v))
    return [x / n for x in v]


def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def quat_from_matrix(m):
    tr = m[0][0] + m[1][1] + m[2][2]
    if tr > 0:
        s = math.sqrt(tr + 1.0) * 2
        return ((m[2][1] - m[1][2]) / s, (m[0][2] - m[2][0]) / s, (m[1][0] - m[0][1]) / s, 0.25 * s)
    if m[0][0] > m[1][1] and m[0][0] > m[2][2]:
        s = math.sqrt(1.0 + m[0][0] - m[1][1] - m[2][2]) * 2
        return (0.25 * s, (m[0][1] + m[1][0]) / s, (m[0][2] + m[2][0]) / s, (m[2][1] - m[1][2]) / s)
    if m[1][1] > m[2][2]:
        s = math.sqrt(1.0 + m[1][1] - m[0][0] - m[2][2]) * 2
        return ((m[0][1] + m[1][0]) / s, 0.25 * s, (m[1][2] + m[2][1]) / s, (m[0][2] - m[2][0]) / s)
    s = math.sqrt(1.0 + m[2][2] - m[0][0] - m[1][1]) * 2
    return ((m[0][2] + m[2][0]) / s, (m[1][2] + m[2][1]) / s, 0.25 * s, (m[1][0] - m[0][1]) / s)


def main():
    prev_q = None
    for i in range(int(DURATION_S * RATE_HZ) + 1):
        t = i / RATE_HZ
        p = position(t)
        a = accel(t)
        z_b = normalize([a[0], a[1], a[2] + G])  # thrust along the specific force
        yaw = 0.5 * math.sin(0.35 * ramp_integral(t) / OMEGA)
        x_c = [math.cos(yaw), math.sin(yaw), 0.0]
        y_b = normalize(cross(z_b, x_c))
        x_b = cross(y_b, z_b)
        m = [[x_b[r], y_b[r], z_b[r]] for r in range(3)]  # columns: body axes in the world
        q = quat_from_matrix(m)
        if prev_q is not None and sum(q[k] * prev_q[k] for k in range(4)) < 0:
            q = tuple(-c for c in q)
        prev_q = q
        print(f"{t:.2f} {p[0]:.7f} {p[1]:.7f} {p[2]:.7f} {q[0]:.8f} {q[1]:.8f} {q[2]:.8f} {q[3]:.8f}")


if __name__ == "__main__":
    main()
