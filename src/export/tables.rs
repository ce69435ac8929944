//! Measurement tables (CSV, Parquet) and TUM trajectories of a recorded trial.
//!
//! Every measurement row carries the truth at its time, so a user can compute any error
//! without hybridnav: `ranges` (GNSS pseudoranges, DTMB and TC-OFDM TOAs as ranges, beacon
//! ranges) with the true geometric range — the ranges as the estimators receive them, i.e.
//! after the satellite clock and the receiver's atmosphere models are applied, so
//! `pseudorange_m − true_range_m` is the receiver clock plus the residual errors (the raw
//! observables are in the RINEX export), `fixes` (FM fingerprint and magnetic-landmark
//! positions), `fm_rssi` (each scanned FM station's RSSI), `imu` (gyro and accelerometer
//! samples), `magnetometer` (body-frame field samples with the true position at each),
//! `steps` (PDR), `range_diffs`
//! (carrier-phase range differences) and `truth` (the reference track).

use super::Recording;
use crate::io::atomic::write_atomic;
use crate::io::table::{Table, Values};
use crate::measurement::{Measurement, Truth};
use crate::world::World;
use nalgebra::Vector3;
use std::path::{Path, PathBuf};

/// The truth columns every table ends with: time, ECEF and ENU position, ENU velocity,
/// geodetic position and heading.
#[derive(Default)]
struct TruthColumns {
    t_s: Vec<f64>,
    tow_s: Vec<f64>,
    ecef: [Vec<f64>; 3],
    enu: [Vec<f64>; 3],
    vel_enu: [Vec<f64>; 3],
    lat_deg: Vec<f64>,
    lon_deg: Vec<f64>,
    h_m: Vec<f64>,
    heading_deg: Vec<f64>,
}

impl TruthColumns {
    fn push(&mut self, t: &Truth) {
        self.t_s.push(t.sim.seconds());
        self.tow_s.push(t.t.tow_s());
        for k in 0..3 {
            self.ecef[k].push(t.pos_ecef_m[k]);
            self.enu[k].push(t.enu.pos_enu_m[k]);
            self.vel_enu[k].push(t.enu.vel_enu_mps[k]);
        }
        let g = crate::core::Geodetic::from_ecef(&t.pos_ecef_m);
        self.lat_deg.push(g.lat_deg());
        self.lon_deg.push(g.lon_deg());
        self.h_m.push(g.h_m);
        self.heading_deg.push(t.enu.heading_rad.to_degrees());
    }

    /// Time columns first, so a table reads like a log.
    fn prepend_time(&self, table: &mut Table) {
        let mut front = Table::default();
        front.push("t_s", Values::F64(self.t_s.clone()));
        front.push("gpst_tow_s", Values::F64(self.tow_s.clone()));
        front.columns.append(&mut table.columns);
        *table = front;
    }

    fn append(self, table: &mut Table, prefix: &str) {
        let [x, y, z] = self.ecef;
        let [e, n, u] = self.enu;
        let [ve, vn, vu] = self.vel_enu;
        for (name, v) in [
            ("x_ecef_m", x),
            ("y_ecef_m", y),
            ("z_ecef_m", z),
            ("e_m", e),
            ("n_m", n),
            ("u_m", u),
            ("ve_mps", ve),
            ("vn_mps", vn),
            ("vu_mps", vu),
            ("lat_deg", self.lat_deg),
            ("lon_deg", self.lon_deg),
            ("h_m", self.h_m),
            ("heading_deg", self.heading_deg),
        ] {
            table.push(&format!("{prefix}{name}"), Values::F64(v));
        }
    }
}

/// The tables of a recording, by file stem; tables without rows are left out.
pub fn tables(world: &World, rec: &Recording) -> Vec<(&'static str, Table)> {
    type Build = fn(&World, &Recording) -> Option<Table>;
    let builds: [(&'static str, Build); 8] = [
        ("ranges", ranges_table),
        ("fixes", fixes_table),
        ("fm_rssi", fm_rssi_table),
        ("imu", imu_table),
        ("magnetometer", magnetometer_table),
        ("steps", steps_table),
        ("range_diffs", range_diffs_table),
        ("truth", truth_table),
    ];
    builds
        .into_iter()
        .filter_map(|(stem, build)| build(world, rec).map(|t| (stem, t)))
        .collect()
}

/// Ranges: every range measurement with the geometric range from the truth.
fn ranges_table(_world: &World, rec: &Recording) -> Option<Table> {
    let mut tr = TruthColumns::default();
    let (mut src, mut emitter, mut system) = (Vec::new(), Vec::new(), Vec::new());
    let mut cols: [Vec<f64>; 7] = Default::default();
    let mut rate: Vec<Option<f64>> = Vec::new();
    let mut em: [Vec<f64>; 3] = Default::default();
    let mut batch_of: Vec<usize> = Vec::new();
    for (k_batch, b) in rec.batches.iter().enumerate() {
        for m in &b.items {
            if let Measurement::Range(r) = m {
                tr.push(&b.truth);
                batch_of.push(k_batch);
                src.push(b.source.name().to_string());
                emitter.push(r.emitter.to_string());
                system.push(format!("{:?}", r.emitter.system).to_lowercase());
                let geometric_m = (r.emitter_pos_ecef_m - b.truth.pos_ecef_m).norm();
                let u = (b.truth.pos_ecef_m - r.emitter_pos_ecef_m) / geometric_m;
                let true_rate = u.dot(&(b.truth.vel_ecef_mps - r.emitter_vel_ecef_mps));
                for (k, v) in [
                    r.pseudorange_m,
                    r.sigma_m,
                    r.sigma_rate_mps,
                    r.cn0_dbhz,
                    r.elevation_rad.to_degrees(),
                    geometric_m,
                    true_rate,
                ]
                .into_iter()
                .enumerate()
                {
                    cols[k].push(v);
                }
                rate.push(r.range_rate_mps);
                for (col, x) in em.iter_mut().zip(r.emitter_pos_ecef_m.iter()) {
                    col.push(*x);
                }
            }
        }
    }
    if !src.is_empty() {
        let mut t = Table::default();
        t.push("source", Values::Str(src));
        let (excess, wrong) = excess_ranges(&batch_of, &system, &cols[0], &cols[5]);
        t.push("system", Values::Str(system));
        t.push("emitter", Values::Str(emitter));
        let [pr, sig, sig_rate, cn0, el, geo, true_rate] = cols;
        t.push("pseudorange_m", Values::F64(pr));
        t.push("sigma_m", Values::F64(sig));
        t.push("range_rate_mps", Values::OptF64(rate));
        t.push("sigma_rate_mps", Values::F64(sig_rate));
        t.push("cn0_dbhz", Values::F64(cn0));
        t.push("elevation_deg", Values::F64(el));
        let [ex, ey, ez] = em;
        t.push("emitter_x_ecef_m", Values::F64(ex));
        t.push("emitter_y_ecef_m", Values::F64(ey));
        t.push("emitter_z_ecef_m", Values::F64(ez));
        t.push("true_range_m", Values::F64(geo));
        t.push("true_range_rate_mps", Values::F64(true_rate));
        t.push("excess_range_m", Values::OptF64(excess));
        t.push("wrong_peak", Values::I64(wrong));
        tr.prepend_time(&mut t);
        tr.append(&mut t, "truth_");
        return Some(t);
    }
    None
}

/// Excess range beyond which a range is flagged as a wrong-peak acquisition (m): the
/// longest echo of the COST 207 channel profiles (hilly terrain, 20 µs) is 6 km, so a
/// range that much longer or shorter than its epoch's others did not come from the
/// direct path or a physical echo; it locked onto a sidelobe or noise peak (TC-OFDM
/// ranges off by 9–94 km were seen).
const WRONG_PEAK_EXCESS_M: f64 = 6_000.0;

/// For each range row: its excess range, (pseudorange − true range) minus the consensus
/// of that over the same epoch's ranges of the same system (which removes the receiver's
/// clock of that system), and whether it exceeds [`WRONG_PEAK_EXCESS_M`]. `None` (and
/// not flagged) when the epoch has fewer than 3 ranges of the system, too few to say
/// which one is off.
///
/// The consensus is the median of the largest group of residuals lying within
/// [`WRONG_PEAK_EXCESS_M`] of one of them ([`consensus_m`]), not the median of all: with
/// six base stations of which two locked onto wrong peaks tens of kilometres long, the
/// plain median is the mean of a right and a wrong residual and lands kilometres from
/// both, so a wrong peak could read as a few kilometres' excess and the right ranges as
/// wrong. Wrong peaks scatter over 9–94 km and do not form a group; the right ranges
/// agree to within their multipath.
fn excess_ranges(
    batch_of: &[usize],
    system: &[String],
    pr_m: &[f64],
    true_m: &[f64],
) -> (Vec<Option<f64>>, Vec<i64>) {
    let mut excess = vec![None; pr_m.len()];
    let mut i = 0;
    while i < pr_m.len() {
        let end = (i..pr_m.len())
            .find(|&j| batch_of[j] != batch_of[i])
            .unwrap_or(pr_m.len());
        let mut systems: Vec<&String> = system[i..end].iter().collect();
        systems.sort();
        systems.dedup();
        for sys in systems {
            let rows: Vec<usize> = (i..end).filter(|&j| &system[j] == sys).collect();
            if rows.len() < 3 {
                continue;
            }
            let res: Vec<f64> = rows.iter().map(|&j| pr_m[j] - true_m[j]).collect();
            let reference = consensus_m(&res, WRONG_PEAK_EXCESS_M);
            for &j in &rows {
                excess[j] = Some(pr_m[j] - true_m[j] - reference);
            }
        }
        i = end;
    }
    let wrong = excess
        .iter()
        .map(|e| i64::from(e.is_some_and(|x| x.abs() > WRONG_PEAK_EXCESS_M)))
        .collect();
    (excess, wrong)
}

/// The median of the largest group of `values` that lie within `radius` of one of them
/// (the first such group in ascending order on a tie); the median of all when every
/// group has one member. `values` must not be empty.
pub fn consensus_m(values: &[f64], radius: f64) -> f64 {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let (mut best_lo, mut best_hi) = (0, v.len());
    let mut best_n = 1;
    for &c in &v {
        let lo = v.partition_point(|&x| x < c - radius);
        let hi = v.partition_point(|&x| x <= c + radius);
        if hi - lo > best_n {
            (best_lo, best_hi, best_n) = (lo, hi, hi - lo);
        }
    }
    let g = &v[best_lo..best_hi];
    let n = g.len();
    if n % 2 == 1 {
        g[n / 2]
    } else {
        0.5 * (g[n / 2 - 1] + g[n / 2])
    }
}

/// Position fixes (FM fingerprinting, magnetic landmarks).
fn fixes_table(world: &World, rec: &Recording) -> Option<Table> {
    let frame = &world.frame;
    let mut tr = TruthColumns::default();
    let mut src = Vec::new();
    let mut cols: [Vec<f64>; 6] = Default::default();
    let mut support = Vec::new();
    for b in &rec.batches {
        for m in &b.items {
            if let Measurement::Position(f) = m {
                tr.push(&b.truth);
                src.push(b.source.name().to_string());
                let enu = frame.enu_of_ecef(&f.pos_ecef_m);
                let r = frame.rotation();
                let cov_enu = r * f.cov_m2 * r.transpose();
                let err = enu - b.truth.enu.pos_enu_m;
                for (k, v) in [
                    enu.x,
                    enu.y,
                    enu.z,
                    cov_enu[(0, 0)].max(0.0).sqrt(),
                    cov_enu[(1, 1)].max(0.0).sqrt(),
                    (err.x * err.x + err.y * err.y).sqrt(),
                ]
                .into_iter()
                .enumerate()
                {
                    cols[k].push(v);
                }
                support.push(i64::from(f.support));
            }
        }
    }
    if !src.is_empty() {
        let mut t = Table::default();
        t.push("source", Values::Str(src));
        let [e, n, u, se, sn, err_h] = cols;
        t.push("e_m", Values::F64(e));
        t.push("n_m", Values::F64(n));
        t.push("u_m", Values::F64(u));
        t.push("sigma_e_m", Values::F64(se));
        t.push("sigma_n_m", Values::F64(sn));
        t.push("support", Values::I64(support));
        t.push("err_h_m", Values::F64(err_h));
        tr.prepend_time(&mut t);
        tr.append(&mut t, "truth_");
        return Some(t);
    }
    None
}

/// FM scans: each station's RSSI.
fn fm_rssi_table(_world: &World, rec: &Recording) -> Option<Table> {
    let mut tr = TruthColumns::default();
    let (mut freq, mut rssi) = (Vec::new(), Vec::new());
    for b in &rec.batches {
        for &(f_mhz, p_dbm) in &b.raw.fm_rssi {
            tr.push(&b.truth);
            freq.push(f_mhz);
            rssi.push(p_dbm.is_finite().then_some(p_dbm));
        }
    }
    if !freq.is_empty() {
        let mut t = Table::default();
        t.push("freq_mhz", Values::F64(freq));
        t.push("rssi_dbm", Values::OptF64(rssi));
        tr.prepend_time(&mut t);
        tr.append(&mut t, "truth_");
        return Some(t);
    }
    None
}

/// IMU samples, with the truth's specific force in ENU and the body's true attitude for
/// reference. The attitude is the one the IMU was simulated with: the world's trajectory
/// dressed by its `[platform]` attitude model with the trial's gait stream, rebuilt here
/// (it is a deterministic function of the world, seed and trial), as the quaternion that
/// rotates body (FLU: x forward, y left, z up) vectors into ENU and as heading (from north,
/// clockwise), pitch (nose up) and roll (right side down) in degrees (`truth_body_…`; the
/// `truth_heading_deg` of the truth columns is the velocity's course).
fn imu_table(world: &World, rec: &Recording) -> Option<Table> {
    use crate::inertial::attitude::{euler_from_attitude, PlatformTruth};
    let rng = crate::core::TrialRng::new(rec.seed, rec.trial);
    // The trial was recorded from this world, so both builds succeed; were one to fail,
    // the attitude columns say NaN rather than a made-up level attitude.
    let attitude = world.build_trajectory(&rng).ok().and_then(|trajectory| {
        PlatformTruth::of_trial(trajectory, &world.file.platform.attitude(), &rng).ok()
    });
    let mut tr = TruthColumns::default();
    let mut cols: [Vec<f64>; 16] = Default::default();
    for b in &rec.batches {
        for m in &b.items {
            if let Measurement::Imu(s) = m {
                tr.push(&b.truth);
                let a = b.truth.enu.acc_enu_mps2;
                // [w, x, y, z, heading°, pitch°, roll°] of the true attitude.
                let truth_attitude = attitude.as_ref().map_or([f64::NAN; 7], |body| {
                    let q = body.attitude_at(s.t_s);
                    let (h, p, r) = euler_from_attitude(&q);
                    [
                        q.w,
                        q.i,
                        q.j,
                        q.k,
                        h.to_degrees(),
                        p.to_degrees(),
                        r.to_degrees(),
                    ]
                });
                for (k, v) in [
                    s.gyro_rps.x,
                    s.gyro_rps.y,
                    s.gyro_rps.z,
                    s.accel_mps2.x,
                    s.accel_mps2.y,
                    s.accel_mps2.z,
                    a.x,
                    a.y,
                    a.z,
                ]
                .into_iter()
                .chain(truth_attitude)
                .enumerate()
                {
                    cols[k].push(v);
                }
            }
        }
    }
    if !cols[0].is_empty() {
        let mut t = Table::default();
        let names = [
            "gyro_x_rps",
            "gyro_y_rps",
            "gyro_z_rps",
            "accel_x_mps2",
            "accel_y_mps2",
            "accel_z_mps2",
            "truth_acc_e_mps2",
            "truth_acc_n_mps2",
            "truth_acc_u_mps2",
            "truth_q_nb_w",
            "truth_q_nb_x",
            "truth_q_nb_y",
            "truth_q_nb_z",
            "truth_body_heading_deg",
            "truth_body_pitch_deg",
            "truth_body_roll_deg",
        ];
        for (name, v) in names.into_iter().zip(cols) {
            t.push(name, Values::F64(v));
        }
        tr.prepend_time(&mut t);
        tr.append(&mut t, "truth_");
        return Some(t);
    }
    None
}

/// A time in seconds rounded to whole nanoseconds, the resolution of simulation time, so
/// that a sum such as 15.000000000000002 prints as 15.0.
fn whole_ns(t_s: f64) -> f64 {
    (t_s * 1e9).round() / 1e9
}

/// Magnetometer samples, each with the true position at its own time.
fn magnetometer_table(_world: &World, rec: &Recording) -> Option<Table> {
    let mut cols: [Vec<f64>; 8] = Default::default();
    for b in &rec.batches {
        for m in &b.raw.mag {
            let [bx, by, bz] = m.b_body_ut;
            let [e, n, u] = m.true_pos_enu_m;
            let norm = (bx * bx + by * by + bz * bz).sqrt();
            for (k, v) in [whole_ns(m.t_s), bx, by, bz, norm, e, n, u]
                .into_iter()
                .enumerate()
            {
                cols[k].push(v);
            }
        }
    }
    if !cols[0].is_empty() {
        let mut t = Table::default();
        let names = [
            "t_s",
            "b_x_ut",
            "b_y_ut",
            "b_z_ut",
            "b_norm_ut",
            "truth_e_m",
            "truth_n_m",
            "truth_u_m",
        ];
        for (name, v) in names.into_iter().zip(cols) {
            t.push(name, Values::F64(v));
        }
        return Some(t);
    }
    None
}

/// PDR steps.
fn steps_table(_world: &World, rec: &Recording) -> Option<Table> {
    let mut tr = TruthColumns::default();
    let mut cols: [Vec<f64>; 4] = Default::default();
    for b in &rec.batches {
        for m in &b.items {
            if let Measurement::Step(s) = m {
                tr.push(&b.truth);
                for (k, v) in [
                    s.length_m,
                    s.sigma_length_m,
                    s.heading_rad.to_degrees(),
                    s.sigma_heading_rad.to_degrees(),
                ]
                .into_iter()
                .enumerate()
                {
                    cols[k].push(v);
                }
            }
        }
    }
    if !cols[0].is_empty() {
        let mut t = Table::default();
        let [l, sl, h, sh] = cols;
        t.push("length_m", Values::F64(l));
        t.push("sigma_length_m", Values::F64(sl));
        t.push("heading_deg", Values::F64(h));
        t.push("sigma_heading_deg", Values::F64(sh));
        tr.prepend_time(&mut t);
        tr.append(&mut t, "truth_");
        return Some(t);
    }
    None
}

/// Range differences (seed 002's carrier-frequency-offset integrals).
fn range_diffs_table(world: &World, rec: &Recording) -> Option<Table> {
    let mut tr = TruthColumns::default();
    let mut emitter = Vec::new();
    let mut cols: [Vec<f64>; 4] = Default::default();
    for b in &rec.batches {
        for m in &b.items {
            if let Measurement::RangeDifference(d) = m {
                tr.push(&b.truth);
                emitter.push(d.emitter.to_string());
                for (k, v) in [
                    d.t0.seconds_since(world.start),
                    d.delta_range_m,
                    d.sigma_m,
                    (d.emitter_pos_ecef_m - b.truth.pos_ecef_m).norm(),
                ]
                .into_iter()
                .enumerate()
                {
                    cols[k].push(v);
                }
            }
        }
    }
    if !emitter.is_empty() {
        let mut t = Table::default();
        t.push("emitter", Values::Str(emitter));
        let [t0, dr, s, geo] = cols;
        t.push("t0_s", Values::F64(t0));
        t.push("delta_range_m", Values::F64(dr));
        t.push("sigma_m", Values::F64(s));
        t.push("true_range_m", Values::F64(geo));
        tr.prepend_time(&mut t);
        tr.append(&mut t, "truth_");
        return Some(t);
    }
    None
}

/// The reference track.
fn truth_table(_world: &World, rec: &Recording) -> Option<Table> {
    let mut tr = TruthColumns::default();
    for t in rec.truth_track() {
        tr.push(t);
    }
    let mut t = Table::default();
    tr.prepend_time(&mut t);
    tr.append(&mut t, "");
    Some(t)
}

/// Writes every table as `DIR/<stem>.csv`.
pub fn write_csv(world: &World, rec: &Recording, dir: &Path) -> Result<Vec<PathBuf>, String> {
    let mut files = Vec::new();
    for (stem, t) in tables(world, rec) {
        let path = dir.join(format!("{stem}.csv"));
        write_atomic(&path, t.to_csv()?.as_bytes()).map_err(|e| e.to_string())?;
        files.push(path);
    }
    Ok(files)
}

/// Writes every table as `DIR/<stem>.parquet`.
pub fn write_parquet(world: &World, rec: &Recording, dir: &Path) -> Result<Vec<PathBuf>, String> {
    let mut files = Vec::new();
    for (stem, t) in tables(world, rec) {
        let path = dir.join(format!("{stem}.parquet"));
        write_atomic(&path, &t.to_parquet()?).map_err(|e| e.to_string())?;
        files.push(path);
    }
    Ok(files)
}

/// Writes `DIR/truth.tum` and `DIR/<estimator>.tum`: seconds since the trial start and the
/// position in the world's ENU frame (its `[world] origin`), identity orientation — the
/// TUM RGB-D format evo reads (`evo_ape tum truth.tum EKF.tum`).
pub fn write_tum(world: &World, rec: &Recording, dir: &Path) -> Result<Vec<PathBuf>, String> {
    use crate::metrics::trajectory::write_tum as tum;
    let frame = &world.frame;
    let mut files = Vec::new();
    let track = rec.truth_track();
    let t: Vec<f64> = track.iter().map(|t| whole_ns(t.sim.seconds())).collect();
    let p: Vec<Vector3<f64>> = track.iter().map(|t| t.enu.pos_enu_m).collect();
    let path = dir.join("truth.tum");
    tum(&path, &t, &p).map_err(|e| e.to_string())?;
    files.push(path);
    for (est, stem) in rec.estimators.iter().zip(rec.estimator_stems()) {
        let (t, p): (Vec<f64>, Vec<Vector3<f64>>) = est
            .epochs
            .iter()
            .filter_map(|e| {
                e.est_ecef_m
                    .map(|x| (whole_ns(e.t_s), frame.enu_of_ecef(&Vector3::from(x))))
            })
            .unzip();
        let path = dir.join(format!("{stem}.tum"));
        tum(&path, &t, &p).map_err(|e| e.to_string())?;
        files.push(path);
    }
    Ok(files)
}
