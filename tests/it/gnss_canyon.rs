//! The measurement level's per-class pseudorange errors against the signal level's, in a
//! street canyon (`worlds/gnss-iq-urban-canyon.toml`, and the same world at another hour,
//! `worlds/gnss-iq-urban-canyon-1500.toml` and `-1300.toml`, with the antenna on a roof,
//! `worlds/gnss-iq-urban-canyon-roof.toml`, and walking, `-walk.toml`): `hybridnav gnss iq`
//! records the world's GPS
//! L1 C/A or BeiDou B1I, GNSS-SDR tracks the recording and dumps its observables, and
//! `hybridnav export --format csv` writes the measurement level's pseudoranges of the same
//! world and trial. Each satellite at each epoch is classed from the recording's
//! paths.csv (LOS, LOS + multipath, NLOS) and the two levels' error statistics are
//! compared per class (docs/validation.md, "Per-class calibration").
//!
//! The convention, the same at both levels: a pseudorange's error is its excess over the
//! direct path's true pseudorange (the world has no atmosphere or orbit residuals, so this
//! is the scene's multipath or NLOS error plus tracking noise), with the receiver clock
//! removed at each 1 s epoch by subtracting the mean error of that epoch's line-of-sight
//! satellites. Only the (satellite, epoch) pairs both levels have are compared.
//! docs/gnss-sdr/canyon_calibration.py is the same reduction by hand.

use crate::common::{hybridnav, stderr};
use crate::gnss_iq::{bds_conf, gps_conf, record_and_position};
use hybridnav::core::System;
use std::cell::Cell;
use std::collections::{BTreeMap, HashMap};
use std::path::Path;

const CANYON: &str = "worlds/gnss-iq-urban-canyon.toml";
const CANYON_1500: &str = "worlds/gnss-iq-urban-canyon-1500.toml";
const CANYON_1300: &str = "worlds/gnss-iq-urban-canyon-1300.toml";
const CANYON_WALK: &str = "worlds/gnss-iq-urban-canyon-walk.toml";
const CANYON_ROOF: &str = "worlds/gnss-iq-urban-canyon-roof.toml";
const NAV: &str = "ephemeris/ESBC00DNK_R_20201770000_01D_MN.rnx";
const C_MPS: f64 = 299_792_458.0;
const WEEK_S: f64 = 604_800.0;

/// What the reduction needs to know of a signal.
#[derive(Clone, Copy)]
struct Signal {
    /// `hybridnav gnss iq --signal`.
    name: &'static str,
    system: System,
    /// The export's `system` column.
    export_system: &'static str,
    chip_rate_hz: f64,
    /// Chips per code period; both codes last 1 ms (IS-GPS-200 §3.2.1.3; BDS-SIS-ICD-B1I
    /// 3.0 §4.2: 2046 chips at 2.046 Mchip/s).
    code_chips: f64,
}

const GPS_L1CA: Signal = Signal {
    name: "gps-l1ca",
    system: System::Gps,
    export_system: "gps",
    chip_rate_hz: 1.023e6,
    code_chips: 1023.0,
};

const BDS_B1I: Signal = Signal {
    name: "bds-b1i",
    system: System::Bds,
    export_system: "bds",
    chip_rate_hz: 2.046e6,
    code_chips: 2046.0,
};

/// A satellite's class at one instant, from paths.csv.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
enum Class {
    Los,
    LosMultipath,
    Nlos,
}

impl Class {
    fn is_los(self) -> bool {
        matches!(self, Class::Los | Class::LosMultipath)
    }
}

/// The recording's truth per satellite: the direct path's code phase (chips, unwrapped)
/// against GPS time of week on the 0.1 s grid, and the class at each grid point.
struct Paths {
    signal: Signal,
    phase: BTreeMap<u32, (Vec<f64>, Vec<f64>)>,
    class: HashMap<(u32, i64), Class>,
}

impl Paths {
    fn read(path: &Path, signal: Signal) -> Self {
        let text = std::fs::read_to_string(path).expect("paths.csv");
        let mut rows = text.lines();
        let header: Vec<&str> = rows.next().expect("header").split(',').collect();
        let col = |name: &str| header.iter().position(|h| *h == name).expect(name);
        let (t_c, prn_c, class_c, phase_c, path_c, excess_c) = (
            col("t_gpst_s"),
            col("prn"),
            col("class"),
            col("code_phase_chips"),
            col("path"),
            col("excess_delay_m"),
        );
        let code = signal.code_chips;
        let mut phase: BTreeMap<u32, (Vec<f64>, Vec<f64>)> = BTreeMap::new();
        let mut class = HashMap::new();
        for r in rows {
            let f: Vec<&str> = r.split(',').collect();
            if f[path_c] != "0" {
                continue;
            }
            let num = |c: usize| -> f64 { f[c].parse().expect("number") };
            let t = num(t_c);
            let tow = t - (t / WEEK_S).floor() * WEEK_S;
            let prn: u32 = f[prn_c].parse().expect("prn");
            let k = match f[class_c] {
                "los" => Class::Los,
                "los+mp" => Class::LosMultipath,
                "nlos" => Class::Nlos,
                other => panic!("class {other}"),
            };
            class.insert((prn, (tow * 10.0).round() as i64), k);
            // The row's code phase is its path's; the direct path's is that plus the
            // path's excess delay in chips.
            let direct = num(phase_c) + num(excess_c) / C_MPS * signal.chip_rate_hz;
            let (ts, ps) = phase.entry(prn).or_default();
            // Unwrapped across the code period, so it can be interpolated.
            let unwrapped = match ps.last() {
                Some(&last) => last + (direct - last + code / 2.0).rem_euclid(code) - code / 2.0,
                None => direct,
            };
            ts.push(tow);
            ps.push(unwrapped);
        }
        Self {
            signal,
            phase,
            class,
        }
    }

    fn class(&self, prn: u32, tow_s: f64) -> Option<Class> {
        self.class
            .get(&(prn, (tow_s * 10.0).round() as i64))
            .copied()
    }

    /// The direct path's code phase (chips, modulo the code) at `tow_s`, linearly
    /// interpolated between the 0.1 s rows.
    fn direct_chips(&self, prn: u32, tow_s: f64) -> Option<f64> {
        let (ts, ps) = self.phase.get(&prn)?;
        if ts.len() < 2 || tow_s < ts[0] || tow_s > ts[ts.len() - 1] {
            return None;
        }
        let k = ts.partition_point(|&t| t <= tow_s).clamp(1, ts.len() - 1);
        let w = (tow_s - ts[k - 1]) / (ts[k] - ts[k - 1]);
        Some((ps[k - 1] + w * (ps[k] - ps[k - 1])).rem_euclid(self.signal.code_chips))
    }
}

/// GNSS-SDR 0.0.17's Observables dump (`Observables.dump=true`, `dump_mat=false`): per
/// output epoch and per channel, seven little-endian f64: RX time (s of week),
/// TOW_at_current_symbol (the transmit time, s), Doppler (Hz), carrier phase (cycles),
/// pseudorange (m), PRN, valid flag. Both times are GPS time for BeiDou too: its B1I
/// telemetry decoder adds BDT's 14 s to the decoded SOW
/// (`BEIDOU_DNAV_BDT2GPST_LEAP_SEC_OFFSET`).
fn observables(path: &Path, channels: usize) -> Vec<Vec<[f64; 7]>> {
    let bytes = std::fs::read(path).expect("observables dump");
    let values: Vec<f64> = bytes
        .chunks_exact(8)
        .map(|b| f64::from_le_bytes(b.try_into().expect("8 bytes")))
        .collect();
    values
        .chunks_exact(7 * channels)
        .map(|epoch| {
            epoch
                .chunks_exact(7)
                .map(|c| c.try_into().expect("7 values"))
                .collect()
        })
        .filter(|e: &Vec<[f64; 7]>| e[0][0] > 0.0)
        .collect()
}

/// (epoch's whole second of week, PRN) → error (m), or true range (m).
type Errors = HashMap<(i64, u32), f64>;

/// GNSS-SDR's errors at each whole second: the transmit time it assigns against the
/// direct path's true code phase, modulo 1 ms (a later transmit time is a shorter
/// pseudorange). Its receiver time counts samples, so the recording's time is the RX time
/// minus one offset `offset_s`.
fn sdr_errors(obs: &[Vec<[f64; 7]>], paths: &Paths, offset_s: f64) -> Errors {
    let chip_rate = paths.signal.chip_rate_hz;
    let mut out = Errors::new();
    for epoch in obs {
        let tow = epoch[0][0] - offset_s;
        if (tow - tow.round()).abs() > 0.0101 {
            continue;
        }
        for ch in epoch {
            if ch[6] != 1.0 || ch[4] == 0.0 {
                continue;
            }
            let prn = ch[5] as u32;
            let Some(chips) = paths.direct_chips(prn, tow) else {
                continue;
            };
            let sdr_s = (ch[1] * 1e3).rem_euclid(1.0) * 1e-3;
            let dt_s = (sdr_s - chips / chip_rate + 0.5e-3).rem_euclid(1e-3) - 0.5e-3;
            out.insert((tow.round() as i64, prn), -C_MPS * dt_s);
        }
    }
    out
}

/// GNSS-SDR's time-tag offset to within a fraction of a millisecond, from its own
/// pseudoranges: RX − TOW = δ + ρ/c − Δt_sv, so δ = RX − TOW − ρ/c + af0 (the median over
/// the line-of-sight observables; af1 and the relativistic term move it by < 1 µs). The
/// modulo-1 ms comparison sees δ only modulo 1 ms, but a wrong whole millisecond moves
/// each satellite by its own range rate × 1 ms; until its first fix GNSS-SDR's receiver
/// time is tens of ms from the true time (120 ms in one BeiDou run), which read as a
/// 1.6 m bias between two satellites.
fn coarse_offset_s(
    obs: &[Vec<[f64; 7]>],
    paths: &Paths,
    true_range_m: &Errors,
    af0_s: &HashMap<u32, f64>,
) -> Option<f64> {
    let mut deltas: Vec<f64> = obs
        .iter()
        .flat_map(|epoch| {
            let rx = epoch[0][0];
            epoch.iter().filter_map(move |ch| {
                let prn = ch[5] as u32;
                if ch[6] != 1.0 || !paths.class(prn, rx.round()).is_some_and(Class::is_los) {
                    return None;
                }
                let rho = true_range_m.get(&(rx.round() as i64, prn))?;
                Some(rx - ch[1] - rho / C_MPS + af0_s.get(&prn)?)
            })
        })
        .collect();
    deltas.sort_by(f64::total_cmp);
    deltas.get(deltas.len() / 2).copied()
}

/// Every satellite's clock bias af0 of `system` from the world's navigation file (the first
/// record; af0 drifts by < 1 µs over the day, far below the millisecond needed).
fn af0_by_prn(system: System) -> HashMap<u32, f64> {
    let nav = hybridnav::gnss::rinex_nav::read_nav_file(Path::new(NAV)).expect("nav file");
    let mut out = HashMap::new();
    for e in nav.ephemerides.iter().filter(|e| e.sat.system == system) {
        out.entry(u32::from(e.sat.number)).or_insert(e.af0);
    }
    out
}

/// The measurement level's errors from the export's ranges.csv, pseudorange − true range
/// (the receiver clock is removed later, per epoch), and the true ranges.
fn measurement_errors(path: &Path, system: &str) -> (Errors, Errors) {
    let text = std::fs::read_to_string(path).expect("ranges.csv");
    let mut rows = text.lines();
    let header: Vec<&str> = rows.next().expect("header").split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).expect(name);
    let (tow_c, sys_c, em_c, pr_c, geo_c) = (
        col("gpst_tow_s"),
        col("system"),
        col("emitter"),
        col("pseudorange_m"),
        col("true_range_m"),
    );
    let (mut errors, mut ranges) = (Errors::new(), Errors::new());
    for f in rows.map(|r| r.split(',').collect::<Vec<_>>()) {
        if f[sys_c] != system {
            continue;
        }
        let num = |c: usize| -> f64 { f[c].parse().expect("number") };
        let prn: u32 = f[em_c][1..].parse().expect("PRN");
        let key = (num(tow_c).round() as i64, prn);
        errors.insert(key, num(pr_c) - num(geo_c));
        ranges.insert(key, num(geo_c));
    }
    (errors, ranges)
}

/// Splits GNSS-SDR's errors into the tracked ones and the samples of a channel that had
/// lost the signal while still flagging its pseudorange valid: those more than one chip
/// from the epoch's median over all satellites. One chip is the edge of the DLL's
/// discriminator (±(1 + d/2) chips at E−L spacing d, here d ≤ 1), so an error beyond it is
/// no multipath or NLOS delay the code loop can hold but a channel tracking noise; the
/// measurement level models loss of lock as an absent satellite instead (its C/N0
/// threshold), so such samples have no counterpart to compare with. In one CI run
/// (2026-12-04) the walking receiver's NLOS G24 read 137 km off at one epoch of 27. The
/// median, not the mean, so that one such sample cannot drag its epoch's others out too.
fn split_lost_lock(errors: &Errors, chip_m: f64) -> (Errors, Errors) {
    let mut by_epoch: HashMap<i64, Vec<f64>> = HashMap::new();
    for (&(t, _), &e) in errors {
        by_epoch.entry(t).or_default().push(e);
    }
    let median: HashMap<i64, f64> = by_epoch
        .into_iter()
        .map(|(t, mut v)| {
            v.sort_by(f64::total_cmp);
            let m = v.len() / 2;
            let med = if v.len() % 2 == 1 {
                v[m]
            } else {
                0.5 * (v[m - 1] + v[m])
            };
            (t, med)
        })
        .collect();
    errors
        .iter()
        .partition(|(&(t, _), &e)| (e - median[&t]).abs() <= chip_m)
}

/// Removes each epoch's mean over its line-of-sight satellites (the receiver clock);
/// epochs with fewer than two drop out.
fn remove_clock(errors: &Errors, paths: &Paths) -> Errors {
    let mut los: HashMap<i64, Vec<f64>> = HashMap::new();
    for (&(t, prn), &e) in errors {
        if paths.class(prn, t as f64).is_some_and(Class::is_los) {
            los.entry(t).or_default().push(e);
        }
    }
    errors
        .iter()
        .filter_map(|(&(t, prn), &e)| {
            let l = los.get(&t).filter(|l| l.len() >= 2)?;
            Some(((t, prn), e - l.iter().sum::<f64>() / l.len() as f64))
        })
        .collect()
}

/// Count, mean, standard deviation and RMS (m).
fn stats(v: &[f64]) -> (usize, f64, f64, f64) {
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let rms = (v.iter().map(|x| x * x).sum::<f64>() / n).sqrt();
    let std = (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n).sqrt();
    (v.len(), mean, std, rms)
}

/// One trial's errors per class at both levels, on the same (satellite, epoch) pairs.
struct Calibration {
    /// Class → (GNSS-SDR's errors, the measurement level's errors), clock removed.
    per_class: BTreeMap<Class, (Vec<f64>, Vec<f64>)>,
    /// Class → the satellites GNSS-SDR contributed.
    satellites: BTreeMap<Class, Vec<u32>>,
    /// Class → each common sample's PRN, in `per_class`'s order.
    prns: BTreeMap<Class, Vec<u32>>,
    /// GNSS-SDR's samples from a channel that had lost the signal ([`split_lost_lock`]),
    /// left out of `per_class`.
    lost_lock: usize,
    log: String,
}

impl Calibration {
    /// GNSS-SDR's RMS over the measurement level's in `class`, with the sample count.
    fn ratio(&self, class: Class) -> (usize, f64) {
        match self.per_class.get(&class) {
            Some((a, b)) if !a.is_empty() => (a.len(), stats(a).3 / stats(b).3),
            _ => (0, f64::NAN),
        }
    }

    /// GNSS-SDR's RMS over the measurement level's in `class` over the satellites `only`,
    /// with the sample count.
    fn ratio_of(&self, class: Class, only: &[u32]) -> (usize, f64) {
        let (Some((a, b)), Some(prns)) = (self.per_class.get(&class), self.prns.get(&class)) else {
            return (0, f64::NAN);
        };
        let (a, b): (Vec<f64>, Vec<f64>) = a
            .iter()
            .zip(b)
            .zip(prns)
            .filter(|(_, p)| only.contains(p))
            .map(|((x, y), _)| (*x, *y))
            .unzip();
        if a.is_empty() {
            return (0, f64::NAN);
        }
        (a.len(), stats(&a).3 / stats(&b).3)
    }

    /// The criterion for a few satellites of `class` (the weak NLOS ones): at least `min_n`
    /// common samples of the satellites `only` together, and their RMS ratio within
    /// [0.5, 2].
    fn assert_satellites_agree(&self, class: Class, only: &[u32], min_n: usize) {
        let (n, ratio) = self.ratio_of(class, only);
        eprintln!("{class:?} PRNs {only:?}: n {n}, RMS ratio {ratio:.2}");
        assert!(n >= min_n, "{n} samples of PRNs {only:?}:\n{}", self.log);
        assert!(
            (0.5..=2.0).contains(&ratio),
            "PRNs {only:?}: GNSS-SDR RMS / measurement RMS = {ratio:.2}"
        );
    }

    /// The criterion: `required` has at least `min_n` common samples, and it and
    /// every other class with 20 or more have RMS ratios (GNSS-SDR over the measurement
    /// level) within [0.5, 2]. GNSS-SDR's lost-lock samples, left out, must be rare: at most
    /// 2 % of all (a tracking loop that loses the signal often is no calibration).
    fn assert_agrees(&self, required: Class, min_n: usize) {
        let (n, _) = self.ratio(required);
        assert!(n >= min_n, "{n} {required:?} samples:\n{}", self.log);
        let compared: usize = self.per_class.values().map(|(a, _)| a.len()).sum();
        assert!(
            self.lost_lock * 50 <= compared + self.lost_lock,
            "{} of {} GNSS-SDR samples lost lock",
            self.lost_lock,
            compared + self.lost_lock
        );
        for c in [Class::Los, Class::LosMultipath, Class::Nlos] {
            let (n, ratio) = self.ratio(c);
            if n >= 20 {
                assert!(
                    (0.5..=2.0).contains(&ratio),
                    "{c:?}: GNSS-SDR RMS / measurement RMS = {ratio:.2}"
                );
            }
        }
    }
}

/// Records `world` on `signal` for `duration_s` at `rate` sps, runs GNSS-SDR with the
/// Observables dump (`conf` is the integration tests' configuration for the signal),
/// exports the measurement level and reduces both per class. `None` when GNSS-SDR is not
/// installed.
fn calibrate(
    tag: &str,
    world: &str,
    signal: Signal,
    duration_s: u32,
    rate: f64,
    conf: impl Fn(&str, f64, &str, &[u64]) -> String,
) -> Option<Calibration> {
    let channels = Cell::new(0);
    let with_dump = |data: &str, out: &str, prns: &[u64]| {
        let c = conf(data, rate, out, prns);
        // The channel count is the configuration's `Channels_*.count`.
        channels.set(
            c.lines()
                .find_map(|l| {
                    l.strip_prefix("Channels_")
                        .and_then(|l| l.split_once(".count="))
                })
                .and_then(|(_, n)| n.trim().parse().ok())
                .expect("a channel count"),
        );
        format!(
            "{c}Observables.dump=true\nObservables.dump_filename={out}/obs.dat\n\
             Observables.dump_mat=false\n"
        )
    };
    let r = record_and_position(tag, world, signal.name, duration_s, rate, with_dump)?;
    let paths = Paths::read(&r.dir.join(format!("{tag}.paths.csv")), signal);
    let export = r.dir.join("export");
    let o = hybridnav(&[
        "export",
        world,
        "--format",
        "csv",
        "--out",
        export.to_str().expect("utf-8"),
    ]);
    assert!(o.status.success(), "export failed: {}", stderr(&o));
    let (ml, true_range) = measurement_errors(&export.join("ranges.csv"), signal.export_system);

    // GNSS-SDR steps its receiver time at its first fix (consecutive RX times not 20 ms
    // apart); each stretch between steps keeps one offset to the recording's time, found
    // on its own. Before the fix the offset is tens of ms, after it a fraction of one.
    let obs = observables(&r.dir.join("obs.dat"), channels.get());
    let af0 = af0_by_prn(signal.system);
    let mut sdr_all = Errors::new();
    let mut start = 0;
    for end in (1..=obs.len())
        .filter(|&k| k == obs.len() || ((obs[k][0][0] - obs[k - 1][0][0]) - 0.02).abs() > 1e-6)
    {
        let stretch = &obs[start..end];
        start = end;
        // The offset's whole milliseconds from GNSS-SDR's pseudoranges, its fraction from
        // the mean line-of-sight error: a common time-tag error of δ reads as a common
        // pseudorange error of c·δ (plus range rate × δ, which the iteration removes).
        let Some(mut offset_s) = coarse_offset_s(stretch, &paths, &true_range, &af0) else {
            continue;
        };
        for _ in 0..3 {
            let e = sdr_errors(stretch, &paths, offset_s);
            let los: Vec<f64> = e
                .iter()
                .filter(|((t, p), _)| paths.class(*p, *t as f64).is_some_and(Class::is_los))
                .map(|(_, v)| *v)
                .collect();
            if los.is_empty() {
                break;
            }
            offset_s += los.iter().sum::<f64>() / los.len() as f64 / C_MPS;
        }
        eprintln!(
            "{tag}: stretch of {} epochs from RX {:.2} s, offset {offset_s:.6} s",
            stretch.len(),
            stretch[0][0][0]
        );
        sdr_all.extend(sdr_errors(stretch, &paths, offset_s));
    }
    let (sdr, lost) = {
        let all: Errors = sdr_all
            .into_iter()
            .filter(|(k, _)| ml.contains_key(k))
            .collect();
        split_lost_lock(&all, C_MPS / signal.chip_rate_hz)
    };
    for ((t, prn), e) in &lost {
        eprintln!(
            "{tag}: PRN {prn} at {t} s: GNSS-SDR {e:.0} m from the epoch's median, lost lock"
        );
    }
    let both = |m: &Errors| -> Errors {
        m.iter()
            .filter(|(k, _)| sdr.contains_key(k) && ml.contains_key(k))
            .map(|(k, v)| (*k, *v))
            .collect()
    };
    let (sdr, ml) = (
        remove_clock(&both(&sdr), &paths),
        remove_clock(&both(&ml), &paths),
    );
    let mut per_class = BTreeMap::new();
    let mut satellites = BTreeMap::new();
    let mut prns = BTreeMap::new();
    for c in [Class::Los, Class::LosMultipath, Class::Nlos] {
        let keys: Vec<(i64, u32)> = sdr
            .keys()
            .filter(|(t, p)| paths.class(*p, *t as f64) == Some(c))
            .copied()
            .collect();
        let mut sats: Vec<u32> = keys.iter().map(|k| k.1).collect();
        sats.sort_unstable();
        sats.dedup();
        let (a, b): (Vec<f64>, Vec<f64>) = keys.iter().map(|k| (sdr[k], ml[k])).unzip();
        if !a.is_empty() {
            let ((n, am, asd, arms), (_, bm, bsd, brms)) = (stats(&a), stats(&b));
            eprintln!(
                "{tag}: {c:?} {sats:?}: n {n}; GNSS-SDR mean {am:.2} std {asd:.2} RMS {arms:.2} \
                 m; measurement level mean {bm:.2} std {bsd:.2} RMS {brms:.2} m; ratio {:.2}",
                arms / brms
            );
            for &sat in &sats {
                let (x, y): (Vec<f64>, Vec<f64>) = keys
                    .iter()
                    .filter(|k| k.1 == sat)
                    .map(|k| (sdr[k], ml[k]))
                    .unzip();
                let ((n, am, _, arms), (_, bm, _, brms)) = (stats(&x), stats(&y));
                eprintln!(
                    "{tag}:   {c:?} PRN {sat}: n {n}; GNSS-SDR mean {am:.2} RMS {arms:.2} m; \
                     measurement level mean {bm:.2} RMS {brms:.2} m"
                );
            }
        } else {
            eprintln!("{tag}: {c:?}: no common samples");
        }
        per_class.insert(c, (a, b));
        satellites.insert(c, sats);
        prns.insert(c, keys.iter().map(|k| k.1).collect());
    }
    let compared: usize = per_class.values().map(|(a, _)| a.len()).sum();
    eprintln!(
        "{tag}: {compared} samples compared, {} lost lock",
        lost.len()
    );
    let _ = std::fs::remove_dir_all(&r.dir);
    Some(Calibration {
        per_class,
        satellites,
        prns,
        lost_lock: lost.len(),
        log: r.log,
    })
}

/// The positioning tests' GPS configuration with the canyon worlds' correlator spacing.
/// GNSS-SDR's `early_late_space_chips` is each of E and L's offset from P, so its E−L
/// spacing is twice it; ±0.25 chips is the world's `correlator_spacing_chips = 0.5` (and
/// GNSS-SDR's own default, which the B1I configuration keeps). The positioning tests'
/// ±0.5 chips would be a 1-chip spacing, √2 more code noise than the world's.
fn gps_conf_matched(data: &str, rate: f64, out: &str, _: &[u64]) -> String {
    gps_conf(data, rate, out).replace(
        "Tracking_1C.early_late_space_chips=0.5",
        "Tracking_1C.early_late_space_chips=0.25",
    )
}

/// [`gps_conf_matched`] set for weak signals, the GPS NLOS satellites at 30–34 dB-Hz
/// (docs/validation.md, "GPS NLOS at 30–34 dB-Hz"), with GNSS-SDR's documented options only:
///
/// - Acquisition: 10 ms coherent integration (`coherent_integration_time_ms=10`): the
///   coherent SNR C/N0·T is 3.4 dB at 33.4 dB-Hz over 1 ms, 13.4 dB over 10 ms (Kaplan &
///   Hegarty, *Understanding GPS/GNSS*, 3rd ed., acquisition chapter: below ≈ 35 dB-Hz a
///   1 ms search does not detect). 10 ms is half a 20 ms LNAV bit, so of two consecutive
///   10 ms blocks at least one has no bit transition; `bit_transition_flag=true` is GNSS-SDR's
///   option for that, with `max_dwells=2`. The Doppler bins shrink with T: 50 Hz = 1/(2T)
///   (a ±25 Hz worst-case error costs sinc(π·25 Hz·10 ms) = 0.9 dB). `pfa=1e-4`: with the
///   default 10⁻³ GNSS-SDR's threshold let through 11 false alarms in 663 searches of PRNs
///   absent or below 20 dB-Hz (1.7 %, one 90 s run), each holding a channel for seconds;
///   at 10⁻⁴, 4 in 1157 (0.3 %) (docs/validation.md).
/// - Tracking: after bit synchronisation, 20 ms correlations (`extend_correlation_symbols=20`),
///   the measurement level's predetection time (`link::TrackingConfig::integration_time_s`,
///   default 0.02 s), with the same DLL: `dll_bw_narrow_hz=2.0` and
///   `early_late_space_narrow_chips=0.25` (the world's `dll_bandwidth_hz` and half its
///   `correlator_spacing_chips`). `pll_bw_narrow_hz=10`: B_n·T = 0.2, well below 1 so the
///   digital loop behaves as its analogue design (the code comparison does not depend on it;
///   the DLL is carrier-aided).
/// - `carrier_lock_th=0.3`: GNSS-SDR 0.0.17's carrier-lock test (cos 2φ of the prompt,
///   smoothed) is run on 1 ms correlations until the tracking's bit synchronisation, and
///   at 1 ms its expected value for a locked carrier is 0.37 at 30 dB-Hz, 0.57 at 33 and
///   ≈ 0.7 at 35 (E[cos 2 arg(A + n)] at C/N0·T, by Monte Carlo, docs/validation.md), so
///   below ≈ 35 dB-Hz the default 0.7 fails on average and its 5000 failures drop the
///   channel within seconds. 0.3 lies below the value at 30 dB-Hz, the class's lower
///   bound; noise (expected 0) still fails it. The bit synchronisation itself (GPS L1:
///   all 160 one-millisecond symbols of an LNAV preamble read correctly,
///   (1 − Q(√(2·C/N0·T)))¹⁶⁰ = 2–9 % per 6 s subframe at 32.9–33.7 dB-Hz) comes seconds
///   to tens of seconds after acquisition; after it the 20 ms test (expected 0.975 at 33 dB-Hz) passes.
fn gps_conf_weak(data: &str, rate: f64, out: &str, p: &[u64]) -> String {
    let c = gps_conf_matched(data, rate, out, p)
        .replace(
            "Acquisition_1C.coherent_integration_time_ms=1\n",
            "Acquisition_1C.coherent_integration_time_ms=10\nAcquisition_1C.bit_transition_flag=true\n",
        )
        .replace("Acquisition_1C.max_dwells=4", "Acquisition_1C.max_dwells=2")
        .replace("Acquisition_1C.pfa=0.001", "Acquisition_1C.pfa=0.0001")
        .replace("Acquisition_1C.doppler_step=250", "Acquisition_1C.doppler_step=50");
    format!(
        "{c}Tracking_1C.extend_correlation_symbols=20\nTracking_1C.pll_bw_narrow_hz=10.0\n\
         Tracking_1C.dll_bw_narrow_hz=2.0\nTracking_1C.early_late_space_narrow_chips=0.25\n\
         Tracking_1C.carrier_lock_th=0.3\n"
    )
}

/// The goal: per class, GNSS-SDR's RMS pseudorange error on the recording and the
/// measurement level's on the same satellites and epochs agree within 2×. With GNSS-SDR's
/// E−L spacing equal to the world's (±0.25 chips, 2026-12-04, by hand): LOS + multipath
/// 1.04 m against 0.98 m over 120 s, a ratio of 1.06, and 1.03 m against 0.96 m over 240 s
/// (1.08). With the positioning tests' ±0.5 chips, a 1-chip spacing, it was 1.37–1.42
/// (2026-12-03), that spacing's √2. The NLOS satellite G24 (a 3.3 m wall reflection at
/// 36 dB-Hz) gave 4.7 m against 4.6 m (1.02, 240 s) when GNSS-SDR acquired it, which it
/// did in one of three 120 s runs, so that comparison is asserted only when GNSS-SDR
/// tracked it for 20 s or more.
#[test]
fn gnss_canyon_per_class_errors_agree_with_gnss_sdr() {
    // 120 s: GNSS-SDR's first fix (≈ 48 s in, after subframes 1–3) sets its receiver time,
    // and the epochs after it are compared.
    let Some(cal) = calibrate("canyon", CANYON, GPS_L1CA, 120, 2.6e6, gps_conf_matched) else {
        return;
    };
    cal.assert_agrees(Class::LosMultipath, 150);
}

/// The same for BeiDou B1I, at another hour (`worlds/gnss-iq-urban-canyon-1500.toml`: at
/// 02:00 GNSS-SDR tracks one BeiDou satellite in the canyon, C19, too few to remove the
/// receiver clock). At 15:00 C09 and C11 are in line of sight (42 and 46 dB-Hz, each with a
/// ground reflection), C34 too (47 dB-Hz) but GNSS-SDR 0.0.17 has no B1I code above PRN 33
/// (docs/validation.md), so it cannot acquire it, and the NLOS C12, C21, C22 (their wall reflections at 28–34 dB-Hz)
/// were not acquired in 120 s or 240 s. 2026-12-04 (by hand, docs/validation.md): LOS +
/// multipath 0.52 m (GNSS-SDR) against 0.48 m over 51 epochs (120 s), a ratio of 1.08, and
/// 0.50 m against 0.49 m over 195 epochs (240 s), 1.02; by this test 1.04 and 1.05.
/// Asserted: every class with 20 or more common samples within 2×, and the LOS + multipath
/// class has them (GNSS-SDR tracked C09 and C11 together for 10 s or more). 110 s at
/// 4.2 Msps, the BeiDou tests' rate: in one run by hand GNSS-SDR's tracking of C11 lost its
/// NH-code synchronisation twice and its time of week was decoded only ≈ 68 s in (the
/// test's runs tracked it from the start).
#[test]
fn gnss_canyon_bds_per_class_errors_agree_with_gnss_sdr() {
    let Some(cal) = calibrate("canyon-bds", CANYON_1500, BDS_B1I, 110, 4.2e6, bds_conf) else {
        return;
    };
    eprintln!("canyon-bds: satellites per class {:?}", cal.satellites);
    cal.assert_agrees(Class::LosMultipath, 20);
}

/// The line-of-sight class without a ground reflection, which the street never has: the
/// same canyon with the antenna on the south block's roof
/// (`worlds/gnss-iq-urban-canyon-roof.toml`), where every satellite above the mask is
/// `los` (the roof hides the ground's specular points). GPS at 02:00, 120 s at 2.6 Msps,
/// GNSS-SDR at the world's spacing. By hand over 240 s (2026-12-04, docs/validation.md):
/// eight satellites, 1578 samples, 1.63 m against 1.44 m, a ratio of 1.13. Asserted: ≥ 300
/// common LOS samples (GNSS-SDR tracks the six or more satellites above 20° from its first
/// fix on), the ratio within 2×, and no multipath or NLOS sample at either level. Its run
/// (2026-12-04): n = 646, 1.62 m against 1.40 m, 1.15.
#[test]
fn gnss_roof_line_of_sight_errors_agree_with_gnss_sdr() {
    let Some(cal) = calibrate("roof", CANYON_ROOF, GPS_L1CA, 120, 2.6e6, gps_conf_matched) else {
        return;
    };
    eprintln!("roof: satellites per class {:?}", cal.satellites);
    cal.assert_agrees(Class::Los, 300);
    for c in [Class::LosMultipath, Class::Nlos] {
        assert_eq!(cal.ratio(c).0, 0, "{c:?} samples on the roof:\n{}", cal.log);
    }
}

/// BeiDou's NLOS class: at 13:00 (`worlds/gnss-iq-urban-canyon-1300.toml`) C11 is received
/// only by a wall reflection (2.9 m excess, 36 dB-Hz; its direct path through the block at
/// 18 dB-Hz), with C09, C12 and C25 in line of sight. GNSS-SDR's default acquisition (4
/// non-coherent 1 ms dwells at P_fa 10⁻³) never acquired it in 240 s; with 20 dwells, a
/// receiver set for weak signals, it does. The acquisition setting changes only which
/// satellites are tracked, not how, so the tracking errors stay comparable. By hand over
/// 240 s (2026-12-04, docs/validation.md): NLOS C11 n = 93, mean 2.89 m and RMS 3.46 m
/// against 2.84 m and 3.37 m (1.03); LOS + multipath 0.91 m against 0.78 m (1.17).
/// Asserted: ≥ 20 common NLOS samples, and every class with 20 or more within 2×. Its two
/// runs (150 s, 2026-12-04): NLOS n = 92 and 77, ratios 0.99 and 0.97; LOS + multipath
/// (C09, C12, C25) n = 303, 1.10.
#[test]
fn gnss_canyon_bds_nlos_errors_agree_with_gnss_sdr() {
    let conf = |data: &str, rate: f64, out: &str, prns: &[u64]| {
        bds_conf(data, rate, out, prns).replace(
            "Acquisition_B1.max_dwells=4",
            "Acquisition_B1.max_dwells=20",
        )
    };
    let Some(cal) = calibrate("canyon-bds-nlos", CANYON_1300, BDS_B1I, 150, 4.2e6, conf) else {
        return;
    };
    eprintln!("canyon-bds-nlos: satellites per class {:?}", cal.satellites);
    cal.assert_agrees(Class::Nlos, 20);
}

/// A moving receiver in the canyon (`worlds/gnss-iq-urban-canyon-walk.toml`: a pedestrian
/// walking the 02:00 street's centre line at 1.4 m/s for 200 s): the recording's code and
/// carrier follow the walk and GNSS-SDR's loops track them. Walking along the street, the
/// ground and wall reflections keep the direct path's Doppler (paths.csv: no reflection
/// differs by 0.01 Hz), so the multipath is as static as for the parked antenna, and the
/// two levels should agree as they do there. By hand (2026-12-04, docs/validation.md): LOS +
/// multipath n = 604, 1.01 m against 0.96 m (1.05); NLOS G24 n = 70, 4.60 m against 3.98 m
/// (1.15), means 2.81 and 2.75 m. Asserted: ≥ 150 common LOS + multipath samples within 2×,
/// and the NLOS class within 2× when it has 20 samples or more. Its run: LOS + multipath
/// n = 679 (G24's line-of-sight epochs near the blocks' ends included), 1.09; NLOS n = 61,
/// 1.11.
#[test]
fn gnss_canyon_walking_receiver_errors_agree_with_gnss_sdr() {
    let Some(cal) = calibrate("walk", CANYON_WALK, GPS_L1CA, 200, 2.6e6, gps_conf_matched) else {
        return;
    };
    eprintln!("walk: satellites per class {:?}", cal.satellites);
    cal.assert_agrees(Class::LosMultipath, 150);
}

/// GPS's NLOS class at 30–34 dB-Hz: at 15:00 (`worlds/gnss-iq-urban-canyon-1500.toml`) G08,
/// G10 and G32 are received only by wall reflections (6.7–8.5 m excess, 33–34 dB-Hz; their
/// direct paths through the blocks at 21–25 dB-Hz), with G01 and G11 in line of sight.
/// GNSS-SDR's default 1 ms acquisition never acquires them; set for weak signals
/// ([`gps_conf_weak`]) it acquires and tracks them. Asserted: ≥ 20 common samples of these
/// three satellites and their RMS ratio (GNSS-SDR over the measurement level) within 2×, and
/// every class with 20 or more samples within 2× (G21, NLOS by a 1.6–1.8 m reflection after
/// it sets ≈ 30 s in, belongs to the NLOS class too).
///
/// The compared epochs include those before GNSS-SDR's first fix (each stretch between its
/// receiver-time steps reduced with its own offset): here the fix waits for an NLOS
/// satellite's bit synchronisation and ephemeris (only G01 and G11 are in line of sight),
/// so the epochs after it alone were too few and too random to assert on (2026-12-04: 90 s
/// with the fix ≈ 78 s in, n = 33; 120 s with 5 epochs after it, n = 15). With both
/// stretches (a later run the same day, 90 s): G08 and G10 n = 92, ratio 0.92; see docs/validation.md.
#[test]
fn gnss_canyon_gps_weak_nlos_errors_agree_with_gnss_sdr() {
    const WEAK_NLOS: [u32; 3] = [8, 10, 32];
    let Some(cal) = calibrate(
        "canyon-gps-nlos",
        CANYON_1500,
        GPS_L1CA,
        90,
        2.6e6,
        gps_conf_weak,
    ) else {
        return;
    };
    eprintln!("canyon-gps-nlos: satellites per class {:?}", cal.satellites);
    cal.assert_satellites_agree(Class::Nlos, &WEAK_NLOS, 20);
    cal.assert_agrees(Class::Nlos, 20);
}

/// [`bds_conf`] set for the BeiDou NLOS satellites at 28–34 dB-Hz (docs/validation.md,
/// "BeiDou NLOS at 28–34 dB-Hz"), with GNSS-SDR 0.0.17's documented B1I options only. The
/// GPS settings ([`gps_conf_weak`]) do not carry over, because B1I's D1 signal (MEO/IGSO)
/// carries a 20-bit Neumann-Hoffman code at 1 kbit/s over its 50 bit/s data
/// (BDS-SIS-ICD-B1I 3.0 §5.1.2), and GNSS-SDR's B1I acquisition correlates with the primary
/// code alone (`beidou_b1i_pcps_acquisition.cc`: the 1 ms code repeated):
///
/// - Acquisition, coherent time: 1 ms (kept). Over M ms the NH code's sign changes cancel
///   part of the correlation: its mean power gain M·E[a²] over a randomly placed window
///   (a the window's mean sign, by Monte Carlo over the code and the data) is 0.65 at 1 ms,
///   0.79 at 2, 0.93 at 5 and 1.04 at 10 ms, so 10 ms buys 2 dB where GPS gains 10 dB, at
///   ten times the cells (50 Hz Doppler bins), whose threshold is higher: in a Monte Carlo of
///   GNSS-SDR's test (below) 10 ms blocks detected 33.6 dB-Hz less often than 1 ms dwells
///   at the same total time. `bit_transition_flag` makes a single dwell of it.
/// - Acquisition, non-coherent dwells: `max_dwells=180`. GNSS-SDR sums the dwells' |X|²
///   (`pcps_acquisition.cc`), so in noise its statistic (the peak over the input power)
///   is χ² with 2K degrees of freedom, but its CFAR threshold is
///   2·gamma_p_inv(2K, (1 − P_fa)^(1/N)), the χ²(4K) quantile, twice the noise mean:
///   957.7 for K = 180 and N = 4200 × 40 cells (its log: 957.742; noise searches gave
///   502 ± 11). A signal of coherent SNR s per dwell (C/N0·1 ms times the NH, code-phase
///   and Doppler losses, 0.65 × 0.78 × 0.98 ≈ 0.50 on average) adds 2Ks, so it is detected
///   only when s ≳ 1 + z·√(2/K), z ≈ 6.3 at P_fa = 10⁻³ and ≥ 3.7 for any P_fa: s ≥ 1.66
///   (35.2 dB-Hz at the mean loss) at K = 180, s ≥ 1 (33.0 dB-Hz) as K → ∞. In a Monte
///   Carlo of the test at K = 180 a search detects 4 % at 33.3, 8 % at 33.6, 13 % at 34.0
///   and 0 at 31.0 dB-Hz. Each satellite's attenuated direct path (0.06 chip ahead) beats
///   with its reflection over 80–120 s (paths.csv's amplitudes and phases), so the received
///   C/N0 swings: C21 30.3–36.2 dB-Hz, C12 26.4–33.5 (≥ 33 dB-Hz 16 % of the time), C22
///   23.9–31.3. C21 is acquirable, C12 only near its beat's peaks, C22 not, with any of
///   0.0.17's B1I acquisition options (P_fa only moves the threshold's tail; the peak-ratio
///   test used without `pfa` compares each dwell with the same threshold, and at the first
///   dwell noise alone gives a ratio ≈ 1.4, above C12's ≈ 1.25 after 180 at 30.7 dB-Hz).
///   K = 180: the code's Doppler drifts the peak by ≤ ¼ chip (half a 4.2 Msps cell) over
///   the dwells at C21's 1.0–1.1 kHz (1.4 chip/s). `pfa` stays 10⁻³:
///   the threshold lies 22 standard deviations of a noise cell above its mean (χ²(360)),
///   so false alarms do not occur (noise searches peaked at ≤ 597).
/// - `Channels.in_acquisition` = the channel count: with a few percent per search, one
///   search at a time (each 180 ms of data, eight unacquired satellites in turn) reaches
///   C21 once per ≈ 1.8 s and needs tens of seconds to succeed (one run: at 49.8 s, its 28th
///   search); searching every channel at once tries each satellite every 180 ms.
/// - Tracking: after the NH synchronisation, 20 ms correlations
///   (`extend_correlation_symbols=20`, one D1 bit: GNSS-SDR wipes the NH code), the
///   measurement level's predetection time,
///   with the world's DLL (`dll_bw_narrow_hz=2.0`, `early_late_space_narrow_chips=0.25`) and
///   `pll_bw_narrow_hz=10` (B_n·T = 0.2), as for GPS.
/// - `carrier_lock_th` stays at its default 0.7, unlike GPS: GNSS-SDR runs no lock test in
///   its 10 s pull-in (`pull_in_time_s`), and the NH synchronisation needs only the 20
///   one-millisecond symbols of one bit read correctly, (1 − Q(√(2·C/N0·T)))²⁰ = 0.67 per
///   20 ms at 33.3 dB-Hz (GPS's LNAV preamble needs 160), so it follows the pull-in within
///   tens of ms, before the 1 ms test's 5000 failures; after it the test runs on 20 ms
///   correlations (expected 0.97).
fn bds_conf_weak(data: &str, rate: f64, out: &str, prns: &[u64]) -> String {
    let c = bds_conf(data, rate, out, prns)
        .replace(
            "Acquisition_B1.max_dwells=4",
            "Acquisition_B1.max_dwells=180",
        )
        .replace(
            "Channels.in_acquisition=1\n",
            &format!("Channels.in_acquisition={}\n", prns.len()),
        );
    format!(
        "{c}Tracking_B1.extend_correlation_symbols=20\nTracking_B1.pll_bw_narrow_hz=10.0\n\
         Tracking_B1.dll_bw_narrow_hz=2.0\nTracking_B1.early_late_space_narrow_chips=0.25\n"
    )
}

/// BeiDou's NLOS class at 28–34 dB-Hz: at 15:00 (`worlds/gnss-iq-urban-canyon-1500.toml`)
/// C12, C21 and C22 are received only by wall reflections (8.4–8.7, 7.4–7.7 and 8.7–9.0 m
/// excess at 30.4–31.1, 33.3–34.0 and 28.0–28.6 dB-Hz; their direct paths through the
/// blocks at 20–23 dB-Hz, beating with the reflections: 30.3–36.2, 26.4–33.5 and
/// 23.9–31.3 dB-Hz together), with C09 and C11 in line of sight. Set for weak signals
/// ([`bds_conf_weak`]) GNSS-SDR acquires and tracks C21, and now and then C12 (near its
/// beat's peaks); C22 stays below what its acquisition test can detect. Asserted: ≥ 20
/// common samples of the three and their RMS ratio (GNSS-SDR over the measurement level)
/// within 2×, and every class with 20 or more samples within 2×. By hand on one 150 s
/// recording (2026-12-04, docs/validation.md): one search at a time, C21 acquired 49.8 s in
/// (its 28th search), n = 69, RMS 8.31 m against 8.61 m (0.97), LOS + multipath 0.54 m
/// against 0.48 m (1.11); with every channel searching, C21 acquired 2.3 s in (its 11th),
/// n = 117, 8.47 m against 8.25 m (1.03), LOS + multipath 1.10. The test's three runs: C21
/// n = 117, ratio 1.03, each time; C12 acquired in each, held in the second only (n = 34,
/// 9.32 m against 8.84 m; the three together 1.03); LOS + multipath 1.09–1.10. GNSS-SDR
/// takes 9–15 min here (every channel searching, on two cores shared at a load of 10–13).
///
/// GNSS-SDR's run on the same recording is not repeatable at these C/N0: in one CI dry run
/// of eight (2026-12-05) it acquired C21 and locked its secondary code but never decoded
/// its message, so C21 had no observables (n = 0; C09 and C11 as always). When none of
/// the three has 20 common samples, the test runs GNSS-SDR once more (the same trial,
/// recorded again into its own directory: the same samples) and asserts on that run; the
/// criteria are unchanged.
#[test]
fn gnss_canyon_bds_weak_nlos_errors_agree_with_gnss_sdr() {
    const WEAK_NLOS: [u32; 3] = [12, 21, 22];
    let run = |name: &str| calibrate(name, CANYON_1500, BDS_B1I, 150, 4.2e6, bds_conf_weak);
    let Some(mut cal) = run("canyon-bds-weak") else {
        return;
    };
    if cal.ratio_of(Class::Nlos, &WEAK_NLOS).0 < 20 {
        eprintln!(
            "canyon-bds-weak: GNSS-SDR gave no observables of PRNs {WEAK_NLOS:?} \
             (satellites per class {:?}); running it once more",
            cal.satellites
        );
        let Some(again) = run("canyon-bds-weak-2") else {
            return;
        };
        cal = again;
    }
    eprintln!("canyon-bds-weak: satellites per class {:?}", cal.satellites);
    cal.assert_satellites_agree(Class::Nlos, &WEAK_NLOS, 20);
    cal.assert_agrees(Class::Nlos, 20);
}
