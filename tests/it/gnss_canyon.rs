//! The measurement level's per-class pseudorange errors against the signal level's, in a
//! street canyon (`worlds/gnss-iq-urban-canyon.toml`): `hybridnav gnss iq` records the
//! world's GPS L1 C/A, GNSS-SDR tracks the recording and dumps its observables, and
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

use crate::common::{hybridnav, stderr};
use crate::gnss_iq::{gps_conf, record_and_position};
use std::collections::{BTreeMap, HashMap};
use std::path::Path;

const CANYON: &str = "worlds/gnss-iq-urban-canyon.toml";
const C_MPS: f64 = 299_792_458.0;
const CHIP_RATE_HZ: f64 = 1.023e6;
const CODE_CHIPS: f64 = 1023.0;
const WEEK_S: f64 = 604_800.0;

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
    phase: BTreeMap<u32, (Vec<f64>, Vec<f64>)>,
    class: HashMap<(u32, i64), Class>,
}

impl Paths {
    fn read(path: &Path) -> Self {
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
            let direct = num(phase_c) + num(excess_c) / C_MPS * CHIP_RATE_HZ;
            let (ts, ps) = phase.entry(prn).or_default();
            // Unwrapped across the code period, so it can be interpolated.
            let unwrapped = match ps.last() {
                Some(&last) => {
                    last + (direct - last + CODE_CHIPS / 2.0).rem_euclid(CODE_CHIPS)
                        - CODE_CHIPS / 2.0
                }
                None => direct,
            };
            ts.push(tow);
            ps.push(unwrapped);
        }
        Self { phase, class }
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
        Some((ps[k - 1] + w * (ps[k] - ps[k - 1])).rem_euclid(CODE_CHIPS))
    }
}

/// GNSS-SDR 0.0.17's Observables dump (`Observables.dump=true`, `dump_mat=false`): per
/// output epoch and per channel, seven little-endian f64: RX time (s of week),
/// TOW_at_current_symbol (the transmit time, s), Doppler (Hz), carrier phase (cycles),
/// pseudorange (m), PRN, valid flag.
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

/// (epoch's whole second of week, PRN) → error (m).
type Errors = HashMap<(i64, u32), f64>;

/// GNSS-SDR's errors at each whole second: the transmit time it assigns against the
/// direct path's true code phase, modulo 1 ms (a later transmit time is a shorter
/// pseudorange). Its receiver time counts samples, so the recording's time is the RX time
/// minus one offset `offset_s`.
fn sdr_errors(obs: &[Vec<[f64; 7]>], paths: &Paths, offset_s: f64) -> Errors {
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
            let dt_s = (sdr_s - chips / CHIP_RATE_HZ + 0.5e-3).rem_euclid(1e-3) - 0.5e-3;
            out.insert((tow.round() as i64, prn), -C_MPS * dt_s);
        }
    }
    out
}

/// The measurement level's errors from the export's ranges.csv: pseudorange − true range
/// (the receiver clock is removed later, per epoch).
fn measurement_errors(path: &Path) -> Errors {
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
    rows.map(|r| r.split(',').collect::<Vec<_>>())
        .filter(|f| f[sys_c] == "gps")
        .map(|f| {
            let num = |c: usize| -> f64 { f[c].parse().expect("number") };
            let prn: u32 = f[em_c][1..].parse().expect("PRN");
            ((num(tow_c).round() as i64, prn), num(pr_c) - num(geo_c))
        })
        .collect()
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

/// The goal: per class, GNSS-SDR's RMS pseudorange error on the recording and the
/// measurement level's on the same satellites and epochs agree within 2×. 2026-12-03 (by
/// hand and by this test): LOS + multipath 1.35–1.41 m (GNSS-SDR) against 0.96–1.01 m, a
/// ratio of 1.37–1.42, the same ratio as in open sky (GNSS-SDR's code noise, not the
/// multipath model); the NLOS satellite G24 (a 3.3 m wall reflection at 36 dB-Hz) 5.4–5.6 m
/// against 4.8–4.9 m (ratio 1.1–1.2) when GNSS-SDR acquired it, which it did in one of
/// three 120 s runs, so that comparison is asserted only when GNSS-SDR tracked it for
/// 20 s or more.
#[test]
fn gnss_canyon_per_class_errors_agree_with_gnss_sdr() {
    const RATE: f64 = 2.6e6;
    let with_dump = |data: &str, out: &str, _: &[u64]| {
        format!(
            "{}Observables.dump=true\nObservables.dump_filename={out}/obs.dat\n\
             Observables.dump_mat=false\n",
            gps_conf(data, RATE, out)
        )
    };
    // 120 s: GNSS-SDR's first fix (≈ 48 s in, after subframes 1–3) sets its receiver time,
    // and the epochs after it are compared.
    let Some(r) = record_and_position("canyon", CANYON, "gps-l1ca", 120, RATE, with_dump) else {
        return;
    };
    let paths = Paths::read(&r.dir.join("canyon.paths.csv"));
    let export = r.dir.join("export");
    let o = hybridnav(&[
        "export",
        CANYON,
        "--format",
        "csv",
        "--out",
        export.to_str().expect("utf-8"),
    ]);
    assert!(o.status.success(), "export failed: {}", stderr(&o));
    let ml = measurement_errors(&export.join("ranges.csv"));

    // GNSS-SDR steps its receiver time once, at its first fix; the rows after the last
    // step (consecutive RX times 20 ms apart) keep one offset to the recording's time.
    let mut obs = observables(&r.dir.join("obs.dat"), 8);
    if let Some(k) = obs
        .windows(2)
        .rposition(|w| ((w[1][0][0] - w[0][0][0]) - 0.02).abs() > 1e-6)
    {
        obs.drain(..=k);
    }
    assert!(
        obs.len() >= 1000,
        "{} observable epochs after GNSS-SDR's last time step:\n{}",
        obs.len(),
        r.log
    );
    // The offset from the mean line-of-sight error: a common time-tag error of δ reads as
    // a common pseudorange error of c·δ (plus range rate × δ, which the iteration removes).
    let mut offset_s = 0.0;
    for _ in 0..3 {
        let e = sdr_errors(&obs, &paths, offset_s);
        let los: Vec<f64> = e
            .iter()
            .filter(|((t, p), _)| paths.class(*p, *t as f64).is_some_and(Class::is_los))
            .map(|(_, v)| *v)
            .collect();
        assert!(!los.is_empty(), "no line-of-sight observables:\n{}", r.log);
        offset_s += los.iter().sum::<f64>() / los.len() as f64 / C_MPS;
    }
    let sdr = sdr_errors(&obs, &paths, offset_s);
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
    let per_class = |m: &Errors, c: Class| -> Vec<f64> {
        m.iter()
            .filter(|((t, p), _)| paths.class(*p, *t as f64) == Some(c))
            .map(|(_, v)| *v)
            .collect()
    };
    for c in [Class::Los, Class::LosMultipath, Class::Nlos] {
        let (a, b) = (per_class(&sdr, c), per_class(&ml, c));
        if a.is_empty() {
            eprintln!("canyon: {c:?}: no common samples");
            continue;
        }
        let ((n, am, asd, arms), (_, bm, bsd, brms)) = (stats(&a), stats(&b));
        eprintln!(
            "canyon: {c:?}: n {n}; GNSS-SDR mean {am:.2} std {asd:.2} RMS {arms:.2} m; \
             measurement level mean {bm:.2} std {bsd:.2} RMS {brms:.2} m; ratio {:.2}",
            arms / brms
        );
    }
    let (los_sdr, los_ml) = (
        per_class(&sdr, Class::LosMultipath),
        per_class(&ml, Class::LosMultipath),
    );
    assert!(
        los_sdr.len() >= 150,
        "{} LOS + multipath samples",
        los_sdr.len()
    );
    let ratio = stats(&los_sdr).3 / stats(&los_ml).3;
    assert!(
        (0.5..=2.0).contains(&ratio),
        "LOS + multipath: GNSS-SDR RMS / measurement RMS = {ratio:.2}"
    );
    let (nlos_sdr, nlos_ml) = (per_class(&sdr, Class::Nlos), per_class(&ml, Class::Nlos));
    if nlos_sdr.len() >= 20 {
        let ratio = stats(&nlos_sdr).3 / stats(&nlos_ml).3;
        assert!(
            (0.5..=2.0).contains(&ratio),
            "NLOS: GNSS-SDR RMS / measurement RMS = {ratio:.2}"
        );
    }
    let _ = std::fs::remove_dir_all(&r.dir);
}
