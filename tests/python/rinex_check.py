"""Reads a `hybridnav export --format rinex,csv,tum` directory with georinex and RTKLIB.

1. georinex loads the observation file: the satellites, the observables and the epochs
   are those of the file, and the values equal the text.
2. RTKLIB's rnx2rtkp computes single-point positions (broadcast ephemeris, Klobuchar,
   Saastamoinen, 10° mask) from the observation and navigation files; their error
   against the exported truth is compared with the error of hybridnav's own snapshot WLS
   solution of the same trial ("GPS WLS", GPS only, written as GPS_WLS.tum): the same
   measurements through an independent solver must give the same error budget.

Usage: rinex_check.py DIR. Prints the figures; exits non-zero on a failed check.
"""

import os
import subprocess
import sys

import georinex as gr
import numpy as np
import pandas as pd

d = sys.argv[1]
obs_path = os.path.join(d, "hybridnav.obs")
nav_path = os.path.join(d, "hybridnav.nav")


def fail(msg):
    print("FAIL:", msg)
    sys.exit(1)


# 1. georinex.
with open(obs_path) as f:
    lines = f.read().splitlines()
n_epochs = sum(1 for l in lines if l.startswith(">"))
sats_in_text = sorted({l[:3] for l in lines[lines.index(next(l for l in lines if "END OF HEADER" in l)) + 1 :] if not l.startswith(">")})
obs = gr.load(obs_path)
if len(obs.time) != n_epochs:
    fail(f"georinex read {len(obs.time)} epochs, the file has {n_epochs}")
if sorted(str(s) for s in obs.sv.values) != sats_in_text:
    fail(f"georinex satellites {sorted(obs.sv.values)} vs {sats_in_text}")
for v in ["C1C", "L1C", "D1C", "S1C", "C2I", "L2I", "D2I", "S2I"]:
    if v not in obs.data_vars:
        fail(f"georinex has no {v}")
# The first epoch's first satellite, value by value.
first = next(i for i, l in enumerate(lines) if l.startswith(">"))
row = lines[first + 1]
sv = row[:3]
text_vals = [float(row[3 + 16 * k : 3 + 16 * k + 14]) for k in range(4)]
names = ["C1C", "L1C", "D1C", "S1C"] if sv[0] == "G" else ["C2I", "L2I", "D2I", "S2I"]
got = [float(obs[n].sel(sv=sv).isel(time=0)) for n in names]
if not np.allclose(got, text_vals, rtol=0, atol=1e-3):
    fail(f"georinex {sv} {got} vs text {text_vals}")
print(f"georinex: {n_epochs} epochs, {len(sats_in_text)} satellites, 8 observables; values match the text")

# 2. RTKLIB single-point positioning.
truth = pd.read_csv(os.path.join(d, "truth.csv"))
truth_by_tow = {round(t, 3): np.array([x, y, z]) for t, x, y, z in zip(truth.gpst_tow_s, truth.x_ecef_m, truth.y_ecef_m, truth.z_ecef_m)}


def rtklib(navsys):
    conf = os.path.join(d, f"spp{navsys}.conf")
    with open(conf, "w") as f:
        f.write(
            "pos1-posmode=single\npos1-frequency=l1\npos1-elmask=10\npos1-ionoopt=brdc\n"
            f"pos1-tropopt=saas\npos1-navsys={navsys}\nout-solformat=xyz\nout-timesys=gpst\n"
            "out-timeform=tow\n"
        )
    out = os.path.join(d, f"rtklib{navsys}.pos")
    subprocess.run(["rnx2rtkp", "-k", conf, "-o", out, obs_path, nav_path], check=True, capture_output=True)
    errs = {}
    for l in open(out):
        if l.startswith("%"):
            continue
        p = l.split()
        tow = round(float(p[1]), 3)
        # RTKLIB tags its solutions with the true reception time it estimated (receiver
        # time minus its clock estimate): within a microsecond of the truth's epochs.
        key = min(truth_by_tow, key=lambda k: abs(k - tow)) if tow not in truth_by_tow else tow
        if abs(key - tow) > 1e-3:
            fail(f"RTKLIB epoch {tow} matches no truth epoch")
        errs[key] = np.linalg.norm(np.array([float(p[2]), float(p[3]), float(p[4])]) - truth_by_tow[key])
    return errs


gps = rtklib(1)
both = rtklib(1 + 32)

# hybridnav's own WLS (GPS), from the TUM files (ENU; the 3-D error is frame-free).
def tum(path):
    a = np.loadtxt(path)
    return {round(t, 3): p for t, p in zip(a[:, 0], a[:, 1:4])}


t0 = truth.gpst_tow_s.iloc[0] - truth.t_s.iloc[0]
truth_enu = tum(os.path.join(d, "truth.tum"))
wls = {round(t + t0, 3): np.linalg.norm(p - truth_enu[t]) for t, p in tum(os.path.join(d, "GPS_WLS.tum")).items() if t in truth_enu}

common = sorted(set(gps) & set(wls))
if len(common) < 0.8 * len(wls):
    fail(f"RTKLIB solved {len(gps)} epochs; hybridnav's WLS {len(wls)}; common {len(common)}")


def rms(v):
    return float(np.sqrt(np.mean(np.square(v))))


r_rtk = rms([gps[k] for k in common])
r_wls = rms([wls[k] for k in common])
med_rtk = float(np.median([gps[k] for k in common]))
med_wls = float(np.median([wls[k] for k in common]))
r_both = rms(list(both.values()))
print(f"RTKLIB GPS SPP: {len(gps)} epochs, 3-D RMS {r_rtk:.2f} m, median {med_rtk:.2f} m (on {len(common)} common epochs)")
print(f"hybridnav GPS WLS: {len(wls)} epochs, 3-D RMS {r_wls:.2f} m, median {med_wls:.2f} m")
print(f"RTKLIB GPS+BDS SPP: {len(both)} epochs, 3-D RMS {r_both:.2f} m")
ratio = r_rtk / r_wls
# Under an open sky the two solvers see the same errors; their weighting differs
# (RTKLIB: elevation-dependent variances; hybridnav: the receiver's C/N0-based σ).
if not 0.8 <= ratio <= 1.25:
    fail(f"RTKLIB's RMS is {ratio:.2f}× hybridnav's")
if len(both) < len(gps):
    fail("GPS+BDS solved fewer epochs than GPS alone")
print(f"ok: RTKLIB / hybridnav RMS ratio {ratio:.2f}")
