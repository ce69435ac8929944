#!/usr/bin/env python3
"""Cross-check of hybridnav's generic EKF and UKF against filterpy.

Reads a problem and a recorded measurement sequence (JSON, written by
tests/fusion_family.rs), runs filterpy's ExtendedKalmanFilter and UnscentedKalmanFilter
(MerweScaledSigmaPoints) on it and writes their state estimates after every epoch as JSON.

Problem: 2-D constant velocity, state [x, vx, y, vy], F = [[1, T], [0, 1]] per axis,
Q = q [[T^3/3, T^2/2], [T^2/2, T]] per axis (white acceleration), measurements are ranges
to fixed beacons, z_j = |b_j - r| + noise, R = diag(sigma_j^2).

Usage: filterpy_crosscheck.py IN.json OUT.json
Exit status 3 when filterpy or numpy is missing (the caller then skips).
"""
import json
import sys

try:
    import numpy as np
    from filterpy.kalman import ExtendedKalmanFilter, MerweScaledSigmaPoints, UnscentedKalmanFilter
except ImportError:
    print("skipped: filterpy not installed")
    sys.exit(3)


def cv_f_q(dt, q):
    f1 = np.array([[1.0, dt], [0.0, 1.0]])
    q1 = q * np.array([[dt**3 / 3.0, dt**2 / 2.0], [dt**2 / 2.0, dt]])
    f = np.zeros((4, 4))
    qq = np.zeros((4, 4))
    for a in range(2):
        f[2 * a:2 * a + 2, 2 * a:2 * a + 2] = f1
        qq[2 * a:2 * a + 2, 2 * a:2 * a + 2] = q1
    return f, qq


def main():
    with open(sys.argv[1]) as fh:
        prob = json.load(fh)
    beacons = np.array(prob["beacons"], dtype=float)
    sig = np.array(prob["sigma_m"], dtype=float)
    m = len(beacons)
    R = np.diag(sig**2)
    x0 = np.array(prob["x0"], dtype=float)
    P0 = np.array(prob["p0"], dtype=float)
    dt = float(prob["dt_s"])
    F, Q = cv_f_q(dt, float(prob["accel_psd"]))

    def hx(x):
        r = np.array([x[0], x[2]])
        return np.linalg.norm(beacons - r, axis=1)

    def hjac(x):
        r = np.array([x[0], x[2]])
        d = beacons - r
        n = np.linalg.norm(d, axis=1)
        H = np.zeros((m, 4))
        H[:, 0] = -d[:, 0] / n
        H[:, 2] = -d[:, 1] / n
        return H

    ekf = ExtendedKalmanFilter(dim_x=4, dim_z=m)
    ekf.x = x0.copy()
    ekf.P = P0.copy()
    ekf.F = F
    ekf.Q = Q
    ekf.R = R

    a, b, k = prob["alpha"], prob["beta"], prob["kappa"]
    points = MerweScaledSigmaPoints(4, alpha=a, beta=b, kappa=k)
    ukf = UnscentedKalmanFilter(dim_x=4, dim_z=m, dt=dt, hx=hx, fx=lambda x, dt: F @ x, points=points)
    ukf.x = x0.copy()
    ukf.P = P0.copy()
    ukf.Q = Q
    ukf.R = R

    out = {"ekf": [], "ukf": [], "ekf_p": [], "ukf_p": []}
    for z in prob["z"]:
        z = np.array(z, dtype=float)
        ekf.predict()
        ekf.update(z, hjac, hx)
        ukf.predict()
        # filterpy 1.x keeps the propagated points for the update, filterpy 2 redraws them
        # from the predicted moments; redrawing here makes both versions use the latter,
        # the convention hybridnav's SigmaPointKf implements.
        ukf.sigmas_f = ukf.points_fn.sigma_points(ukf.x, ukf.P)
        ukf.update(z)
        out["ekf"].append(ekf.x.tolist())
        out["ukf"].append(ukf.x.tolist())
        out["ekf_p"].append(np.diag(ekf.P).tolist())
        out["ukf_p"].append(np.diag(ukf.P).tolist())
    with open(sys.argv[2], "w") as fh:
        json.dump(out, fh)


if __name__ == "__main__":
    main()
