"""Per-class pseudorange errors of one urban-canyon trial at two levels (docs/validation.md,
"Per-class calibration"): GNSS-SDR's observables on `hybridnav gnss iq`'s recording and
hybridnav's measurement level (`hybridnav export --format csv`) of the same world and trial.

Usage: canyon_calibration.py RUN EXP [gps|bds] [x]
  RUN  a directory with cy.paths.csv (from `gnss iq ... --out RUN/cy`), obs.dat
       (GNSS-SDR's Observables dump: Observables.dump=true, dump_mat=false) and cy.conf
       (GNSS-SDR's configuration, for its channel count; 8 if absent)
  EXP  the output directory of `hybridnav export WORLD --format csv`
  gps  the recording is GPS L1 C/A (`--signal gps-l1ca`, the default); bds: BeiDou B1I
       (`--signal bds-b1i`)
  x    also print GNSS-SDR's errors every 5 s

With CAL_DUMP=FILE in the environment, every common (epoch, satellite) sample is also
written to FILE as CSV: tow_s,prn,class,gnss_sdr_m,measurement_m (both clock-removed), for
statistics over a window or a satellite of one's choice.

Convention (the same for both levels): a pseudorange's error is its excess over the direct
path's true pseudorange, i.e. the scene's multipath/NLOS error plus tracking noise (the
world has no atmosphere or orbit residuals), with the receiver clock removed at each
1 s epoch by subtracting the mean over that epoch's line-of-sight satellites (classes los
and los+mp of paths.csv). For GNSS-SDR the true direct-path code phase comes from
paths.csv (interpolated at the epoch's true time) and is compared with the transmit time
GNSS-SDR assigns (TOW_at_current_symbol) modulo 1 ms. GNSS-SDR's receiver time is tied to
the sample count and steps at its first fix; each stretch between steps has its one offset
to the recording's time fitted (a common time-tag offset reads as a common error). A
channel's sample more than one chip from its epoch's median (a loop that lost the signal
but still flags it valid) is counted and left out. Only (satellite, epoch) pairs present in both levels
are tabulated.

BeiDou B1I: the code is 2046 chips at 2.046 Mchip/s (the same 1 ms period as C/A, so the
transmit time is compared modulo 1 ms as for GPS). GNSS-SDR 0.0.17's B1I telemetry decoder reports TOW_at_current_symbol as GPS time
(the decoded SOW + BEIDOU_DNAV_BDT2GPST_LEAP_SEC_OFFSET = 14 s), so its receiver time is GPS
time too.

GNSS-SDR's receiver time is only set to GPS time at its first fix (GPS: ≈ 48 s in); without
a fix (two BeiDou satellites in the canyon) it stays where the observables started it, tens
of ms from the true time. The modulo-1 ms comparison sees a time-tag offset δ only modulo
1 ms, but each satellite's range rate × δ is not common, so δ's whole milliseconds are first
taken from GNSS-SDR's own pseudoranges: δ ≈ RX − TOW − ρ/c + Δt_sv over the LOS
satellites (ρ the export's true range, Δt_sv = af0 + af1 (t − toc) from the world's RINEX
navigation file, up to 0.86 ms for BeiDou here), after which the fraction is fitted as
before. A residual of 0.01 ms moves a satellite by its range rate × 10 µs, < 1 cm.
"""
import os, sys, csv, numpy as np, collections
run, exp = sys.argv[1], sys.argv[2]
args = sys.argv[3:]
system = args.pop(0) if args and args[0] in ("gps", "bds") else "gps"
C_MPS = 299792458.0; WEEK = 2111 * 604800.0
CHIP, CODE, LETTER = (1.023e6, 1023.0, "G") if system == "gps" else (2.046e6, 2046.0, "C")
channels = 8
NAV = __file__.rsplit("/", 3)[0] + "/ephemeris/ESBC00DNK_R_20201770000_01D_MN.rnx"
try:
    for line in open(f"{run}/cy.conf"):
        if line.startswith(("Channels_1C.count=", "Channels_B1.count=")):
            channels = int(line.split("=")[1])
except FileNotFoundError:
    pass
# paths.csv: direct-path code phase and class per (sat, row time)
ph = collections.defaultdict(list); cls = {}
for r in csv.DictReader(open(f"{run}/cy.paths.csv")):
    if r["path"] != "0": continue
    t = round(float(r["t_gpst_s"]) - WEEK, 3)
    ph[int(r["prn"])].append((t, float(r["code_phase_chips"])))
    cls[(int(r["prn"]), t)] = r["class"]
# Satellite clock polynomial (af0, af1) per PRN at the nearest toc (RINEX 3 navigation).
clock = collections.defaultdict(list)
for line in open(NAV):
    if line[:1] == LETTER and line[1:3].strip().isdigit() and len(line) > 60 and line[3] == " ":
        y, mo, dd, hh, mi, ss = (int(x) for x in line[4:23].split())
        dow = (np.datetime64(f"{y:04d}-{mo:02d}-{dd:02d}") - np.datetime64("1980-01-06")).astype(int) % 7
        toc = dow * 86400 + hh * 3600 + mi * 60 + ss
        clock[int(line[1:3])].append((toc, float(line[23:42].replace("D", "E")), float(line[42:61].replace("D", "E"))))
def sat_clock_s(prn, tow):
    toc, a0, a1 = min(clock[prn], key=lambda c: abs(c[0] - tow))
    return a0 + a1 * (tow - toc)
phase = {}
for prn, v in ph.items():
    v = np.array(v); u = np.unwrap(v[:, 1] * 2 * np.pi / CODE) * CODE / (2 * np.pi)
    phase[prn] = (v[:, 0], u)
def klass(prn, t):
    return cls.get((prn, round(round(t * 10) / 10, 3)))
# GNSS-SDR observables dump: epochs x 8 channels x (RX_time, TOW, Doppler, phase, PR, PRN, valid)
d = np.fromfile(f"{run}/obs.dat", dtype="<f8").reshape(-1, channels, 7)
# GNSS-SDR steps its receiver time at its first fix; each stretch between steps keeps one
# offset to the recording's time, found on its own (tens of ms before the fix).
d = d[d[:, 0, 0] > 0]
steps = np.nonzero(np.abs(np.diff(d[:, 0, 0]) - 0.02) > 1e-6)[0]
print("receiver-time steps at", [(d[i, 0, 0], d[i + 1, 0, 0]) for i in steps])
stretches = np.split(d, steps + 1)
def sdr_errors(rows, Cs):
    out = []
    for row in rows:
        R = row[0, 0]
        if R == 0: continue
        t = R - Cs
        if abs(t - round(t)) > 0.0101: continue  # one row per second
        for ch in row:
            if ch[6] != 1 or ch[4] == 0: continue
            prn = int(ch[5]); tt, u = phase[prn]
            if t < tt[0] or t > tt[-1]: continue
            chips = np.interp(t, tt, u) % CODE
            dt = (ch[1] * 1e3 % 1.0) * 1e-3 - chips / CHIP
            dt = (dt + 0.5e-3) % 1e-3 - 0.5e-3
            out.append((round(t), prn, -C_MPS * dt))
    return out
# Whole milliseconds of GNSS-SDR's time-tag offset from its pseudoranges (see above).
rho = {}
for r in csv.DictReader(open(f"{exp}/ranges.csv")):
    if r["system"] == system:
        rho[(round(float(r["gpst_tow_s"])), int(r["emitter"][1:]))] = float(r["true_range_m"])
sdr = {}
for rows in stretches:
    coarse = []
    for row in rows:
        for ch in row:
            if ch[6] != 1: continue
            prn = int(ch[5]); t = round(row[0, 0])
            if klass(prn, t) in ("los", "los+mp") and (t, prn) in rho:
                coarse.append(row[0, 0] - ch[1] - rho[(t, prn)] / C_MPS + sat_clock_s(prn, t))
    if not coarse: continue
    Cs = float(np.median(coarse))
    for _ in range(3):
        los = [x[2] for x in sdr_errors(rows, Cs) if klass(x[1], x[0]) in ("los", "los+mp")]
        if not los: break
        Cs += np.mean(los) / C_MPS  # a late time tag reads as a common positive error
    print(f"stretch of {len(rows)} epochs from RX {rows[0, 0, 0]:.2f} s: GNSS-SDR time offset {Cs*1e3:.4f} ms")
    sdr.update({(t, p): v for t, p, v in sdr_errors(rows, Cs)})
# A channel that has lost the signal but still flags its pseudorange valid: more than one
# chip from its epoch's median, beyond the DLL's reach; counted and left out.
by_t = collections.defaultdict(list)
for (t, p), v in sdr.items(): by_t[t].append(v)
lost = {k: v for k, v in sdr.items() if abs(v - np.median(by_t[k[0]])) > C_MPS / CHIP}
print("lost lock:", {k: round(v) for k, v in lost.items()})
sdr = {k: v for k, v in sdr.items() if k not in lost}
ml = {}
for r in csv.DictReader(open(f"{exp}/ranges.csv")):
    if r["system"] != system: continue
    ml[(round(float(r["gpst_tow_s"])), int(r["emitter"][1:]))] = float(r["pseudorange_m"]) - float(r["true_range_m"])
def demean(m):
    by = collections.defaultdict(list)
    for (t, p), v in m.items():
        if klass(p, t) in ("los", "los+mp"): by[t].append(v)
    return {(t, p): v - np.mean(by[t]) for (t, p), v in m.items() if len(by[t]) >= 2}
t_max = max(t for t, _ in sdr)
common = set(sdr) & set(ml)
print("sdr only", collections.Counter(klass(p,t) for t,p in set(sdr)-set(ml)), "ml only", collections.Counter((p,klass(p,t)) for t,p in set(ml)-set(sdr) if t <= t_max and t>=min(t for t,_ in sdr)))
for name, m in (("GNSS-SDR", sdr), ("measurement", ml)):
    m = demean({k: v for k, v in m.items() if k in common})
    print(name)
    for c in ("los", "los+mp", "nlos"):
        v = np.array([x for (t, p), x in m.items() if klass(p, t) == c])
        if len(v) == 0: print(f"  {c:7} 0"); continue
        a = np.abs(v)
        print(f"  {c:7} n={len(v):4} mean={v.mean():7.3f} std={v.std():6.3f} rms={np.sqrt((v**2).mean()):6.3f} p68={np.percentile(a,68):6.3f} p95={np.percentile(a,95):6.3f}")
    per = collections.defaultdict(list)
    for (t, p), x in m.items(): per[p].append(x)
    print("  per sat:", {p: (round(np.mean(v),2), round(np.std(v),2), len(v)) for p, v in sorted(per.items())})
if os.environ.get("CAL_DUMP"):
    a = demean({k: v for k, v in sdr.items() if k in common})
    b = demean({k: v for k, v in ml.items() if k in common})
    with open(os.environ["CAL_DUMP"], "w") as f:
        f.write("tow_s,prn,class,gnss_sdr_m,measurement_m\n")
        for (t, p) in sorted(set(a) & set(b)):
            f.write(f"{t},{p},{klass(p, t)},{a[(t, p)]:.4f},{b[(t, p)]:.4f}\n")
if args:
    m = demean({k: v for k, v in sdr.items() if k in common})
    for t in sorted(set(t for t, _ in m))[::5]:
        print(t, " ".join(f"{LETTER}{p:02d}:{m[(t,p)]:7.2f}" for p in sorted(set(p for _, p in m)) if (t, p) in m))
