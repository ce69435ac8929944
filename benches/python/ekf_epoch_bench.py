#!/usr/bin/env python3
"""Baseline for benches/filters.rs: one 11-state EKF epoch (predict + update with 12
pseudoranges and 12 range rates) with filterpy's ExtendedKalmanFilter, timed with timeit.

The scene is the one of benches/fusion.rs and benches/filters.rs: a receiver in Beijing,
12 emitters at 20 200 km spread over the sky with GPS-like tangential velocities, state
[x, vx, ax, y, vy, ay, z, vz, az, b, bdot] (seed 000 eqs. 4-8), white-jerk PSD 1 m^2/s^5,
TCXO clock. The measurement functions are vectorised numpy, as a Python user would write
them. Prints microseconds per epoch.
"""
import math
import sys
import timeit

try:
    import numpy as np
    from filterpy.kalman import ExtendedKalmanFilter
except ImportError:
    print("skipped: filterpy not installed")
    sys.exit(3)

A = 6378137.0
E2 = 6.69437999014e-3


def ecef(lat, lon, h):
    lat, lon = math.radians(lat), math.radians(lon)
    n = A / math.sqrt(1 - E2 * math.sin(lat) ** 2)
    return np.array([(n + h) * math.cos(lat) * math.cos(lon), (n + h) * math.cos(lat) * math.sin(lon), (n * (1 - E2) + h) * math.sin(lat)])


def scene():
    lat, lon = math.radians(39.98), math.radians(116.35)
    r = ecef(39.98, 116.35, 60.0)
    # ENU -> ECEF rotation.
    Rm = np.array([
        [-math.sin(lon), -math.sin(lat) * math.cos(lon), math.cos(lat) * math.cos(lon)],
        [math.cos(lon), -math.sin(lat) * math.sin(lon), math.cos(lat) * math.sin(lon)],
        [0.0, math.cos(lat), math.sin(lat)],
    ])
    pos, vel = [], []
    for i in range(12):
        az = math.radians(i * 30.0 + 7.0)
        el = math.radians(15.0 + (i * 37 % 70))
        u = np.array([math.cos(el) * math.sin(az), math.cos(el) * math.cos(az), math.sin(el)])
        p = r + Rm @ (u * 20_200e3)
        t = np.array([-u[1], u[0], 0.0])
        v = Rm @ (t / np.linalg.norm(t)) * 3874.0
        pos.append(p)
        vel.append(v)
    return r, np.array(pos), np.array(vel)


def main():
    r, sp, sv = scene()
    c = 299792458.0
    st, sf = c * c * 2e-19 / 2, c * c * 2 * math.pi**2 * 2e-20
    T = 1.0
    M = np.array([[1, T, T * T / 2], [0, 1, T], [0, 0, 1]])
    F = np.zeros((11, 11))
    Q = np.zeros((11, 11))
    qa = np.array([[T**5 / 20, T**4 / 8, T**3 / 6], [T**4 / 8, T**3 / 3, T**2 / 2], [T**3 / 6, T**2 / 2, T]])
    for a in range(3):
        F[3 * a:3 * a + 3, 3 * a:3 * a + 3] = M
        Q[3 * a:3 * a + 3, 3 * a:3 * a + 3] = qa
    F[9:11, 9:11] = [[1, T], [0, 1]]
    Q[9:11, 9:11] = [[st * T + sf * T**3 / 3, sf * T * T / 2], [sf * T * T / 2, sf * T]]
    P_IDX, V_IDX = [0, 3, 6], [1, 4, 7]

    def hx(x):
        p, v = x[P_IDX], x[V_IDX]
        d = sp - p
        n = np.linalg.norm(d, axis=1)
        u = d / n[:, None]
        rate = np.einsum("ij,ij->i", u, sv - v) + x[10]
        return np.concatenate([n + x[9], rate])

    def hjac(x):
        p, v = x[P_IDX], x[V_IDX]
        d = sp - p
        n = np.linalg.norm(d, axis=1)
        u = d / n[:, None]
        w = sv - v
        dr = -(w - u * np.einsum("ij,ij->i", u, w)[:, None]) / n[:, None]
        H = np.zeros((24, 11))
        H[:12, P_IDX] = -u
        H[:12, 9] = 1.0
        H[12:, P_IDX] = dr
        H[12:, V_IDX] = -u
        H[12:, 10] = 1.0
        return H

    x_true = np.zeros(11)
    x_true[P_IDX] = r
    z = hx(x_true)
    ekf = ExtendedKalmanFilter(dim_x=11, dim_z=24)
    ekf.x = x_true.copy()
    ekf.x[P_IDX] += [5.0, -3.0, 2.0]
    ekf.P = np.diag([100.0, 100, 1, 100, 100, 1, 100, 100, 1, 1e4, 9e4])
    ekf.F, ekf.Q = F, Q
    ekf.R = np.diag([9.0] * 12 + [0.0025] * 12)
    for _ in range(20):
        ekf.predict()
        ekf.update(z, hjac, hx)

    def epoch():
        ekf.predict()
        ekf.update(z, hjac, hx)

    n = 2000
    best = min(timeit.repeat(epoch, number=n, repeat=5)) / n
    print(f"filterpy ExtendedKalmanFilter epoch (11 states, 12 pr + 12 rates): {best * 1e6:.1f} us/epoch")


if __name__ == "__main__":
    main()
