//! Integration tests of the fusion filters: the EKF of seed 000 (Cong et al., Sensors
//! 2018, §5) against an independent textbook Kalman filter, its statistical consistency
//! (NEES) in Monte Carlo, outlier gating and robustness to bad input; the weighted
//! least-squares fix and its dilutions of precision.
//!
//! Everything random comes from named `TrialRng` streams, so every figure is reproducible.

use hybridnav::core::stats::chi2;
use hybridnav::core::{EmitterId, EnuFrame, Geodetic, StreamRng, System, TrialRng};
use hybridnav::fusion::ekf11::{idx, Ekf11, Ekf11Config, IsbConfig, RejectReason, UpdateOutcome};
use hybridnav::fusion::linear_kf::LinearKf;
use hybridnav::fusion::wls::{self, WlsError, WlsOptions};
use hybridnav::measurement::{PositionFix, RangeMeasurement};
use nalgebra::{DMatrix, DVector, Matrix3, Vector3};
use rand::Rng;
use rand_distr::StandardNormal;

/// GPS orbit radius (m) and the Earth's gravitational parameter (IS-GPS-200, m³/s²).
const GPS_RADIUS_M: f64 = 26_560e3;
const MU_M3PS2: f64 = 3.986_005e14;

/// The receiver site: the Beihang University campus, seed 000's first test area.
fn site() -> EnuFrame {
    EnuFrame::new(Geodetic::from_deg(39.98, 116.35, 60.0))
}

fn gauss(rng: &mut StreamRng) -> f64 {
    rng.sample(StandardNormal)
}

// ---------------------------------------------------------------------------------------
// Synthetic sky: satellites on circular orbits of GPS radius.
// ---------------------------------------------------------------------------------------

/// A satellite on a circular orbit through `p_hat` at t = 0, moving towards `q_hat`.
struct Sat {
    id: EmitterId,
    p_hat: Vector3<f64>,
    q_hat: Vector3<f64>,
}

impl Sat {
    fn pos_vel(&self, t_s: f64) -> (Vector3<f64>, Vector3<f64>) {
        let w = (MU_M3PS2 / GPS_RADIUS_M.powi(3)).sqrt();
        let (s, c) = (w * t_s).sin_cos();
        let p = (self.p_hat * c + self.q_hat * s) * GPS_RADIUS_M;
        let v = (self.q_hat * c - self.p_hat * s) * (GPS_RADIUS_M * w);
        (p, v)
    }
}

/// Satellites seen from the site at the given azimuths and elevations (degrees) at
/// t = 0, each on an orbit plane of random orientation.
fn sky(frame: &EnuFrame, az_el_deg: &[(f64, f64, System)], rng: &mut StreamRng) -> Vec<Sat> {
    let r0 = frame.origin_ecef();
    az_el_deg
        .iter()
        .enumerate()
        .map(|(i, &(az, el, system))| {
            let (az, el) = (az.to_radians(), el.to_radians());
            let dir = frame.ecef_vector_of_enu(&Vector3::new(
                el.cos() * az.sin(),
                el.cos() * az.cos(),
                el.sin(),
            ));
            // The ray r0 + s·dir meets the orbit sphere at s = −r0·d + √((r0·d)² − |r0|² + R²).
            let b = r0.dot(&dir);
            let s = -b + (b * b - r0.norm_squared() + GPS_RADIUS_M * GPS_RADIUS_M).sqrt();
            let p_hat = (r0 + dir * s) / GPS_RADIUS_M;
            let random = Vector3::new(gauss(rng), gauss(rng), gauss(rng));
            let q_hat = (random - p_hat * p_hat.dot(&random)).normalize();
            Sat {
                id: EmitterId::new(system, i as u16 + 1),
                p_hat,
                q_hat,
            }
        })
        .collect()
}

/// Nine GPS satellites in a typical open-sky spread (elevation 12°–80°).
const OPEN_SKY: [(f64, f64, System); 9] = [
    (15.0, 78.0, System::Gps),
    (60.0, 35.0, System::Gps),
    (105.0, 52.0, System::Gps),
    (140.0, 18.0, System::Gps),
    (190.0, 41.0, System::Gps),
    (230.0, 12.0, System::Gps),
    (275.0, 63.0, System::Gps),
    (320.0, 27.0, System::Gps),
    (350.0, 15.0, System::Gps),
];

/// Five GPS and four BeiDou satellites.
const MIXED_SKY: [(f64, f64, System); 9] = [
    (15.0, 78.0, System::Gps),
    (60.0, 35.0, System::Bds),
    (105.0, 52.0, System::Gps),
    (140.0, 18.0, System::Bds),
    (190.0, 41.0, System::Gps),
    (230.0, 12.0, System::Bds),
    (275.0, 63.0, System::Gps),
    (320.0, 27.0, System::Bds),
    (350.0, 15.0, System::Gps),
];

fn range_meas(
    id: EmitterId,
    pos: Vector3<f64>,
    vel: Vector3<f64>,
    pr: f64,
    rate: Option<f64>,
) -> RangeMeasurement {
    RangeMeasurement {
        emitter: id,
        emitter_pos_ecef_m: pos,
        emitter_vel_ecef_mps: vel,
        pseudorange_m: pr,
        sigma_m: 3.0,
        range_rate_mps: rate,
        sigma_rate_mps: 0.05,
        cn0_dbhz: 45.0,
        elevation_rad: 0.5,
    }
}

// ---------------------------------------------------------------------------------------
// An independent statement of the model (eqs. 5–17) on dynamic matrices.
// ---------------------------------------------------------------------------------------

/// Φ of eq. 5 on `n` = 11 (paper) or 12 (with the ISB random walk) states.
fn phi_ref(n: usize, t: f64) -> DMatrix<f64> {
    let mut phi = DMatrix::identity(n, n);
    for k in 0..3 {
        let o = 3 * k;
        phi[(o, o + 1)] = t;
        phi[(o, o + 2)] = t * t / 2.0;
        phi[(o + 1, o + 2)] = t;
    }
    phi[(9, 10)] = t;
    phi
}

/// Q of eqs. 6–8 on `n` states (the 12th, when present, is `S_isb·T`).
fn q_ref(n: usize, cfg: &Ekf11Config, t: f64) -> DMatrix<f64> {
    let mut q = DMatrix::zeros(n, n);
    for k in 0..3 {
        let o = 3 * k;
        let s = cfg.accel_psd_m2ps5[k];
        let m = [
            [t.powi(5) / 20.0, t.powi(4) / 8.0, t.powi(3) / 6.0],
            [t.powi(4) / 8.0, t.powi(3) / 3.0, t.powi(2) / 2.0],
            [t.powi(3) / 6.0, t.powi(2) / 2.0, t],
        ];
        for i in 0..3 {
            for j in 0..3 {
                q[(o + i, o + j)] = s * m[i][j];
            }
        }
    }
    let (st, sf) = (cfg.clock_bias_psd_m2ps, cfg.clock_drift_psd_m2ps3);
    q[(9, 9)] = st * t + sf * t.powi(3) / 3.0;
    q[(9, 10)] = sf * t * t / 2.0;
    q[(10, 9)] = sf * t * t / 2.0;
    q[(10, 10)] = sf * t;
    if n == 12 {
        q[(11, 11)] = cfg.isb_bds.map_or(0.0, |i| i.psd_m2ps) * t;
    }
    q
}

fn pos_of(x: &DVector<f64>) -> Vector3<f64> {
    Vector3::new(x[0], x[3], x[6])
}
fn vel_of(x: &DVector<f64>) -> Vector3<f64> {
    Vector3::new(x[1], x[4], x[7])
}

/// Predicted pseudorange and its Jacobian row (eqs. 9–15), written out again here.
fn pseudorange_model(x: &DVector<f64>, m: &RangeMeasurement) -> (f64, DVector<f64>) {
    let n = x.len();
    let los = m.emitter_pos_ecef_m - pos_of(x);
    let d = los.norm();
    let mut h = DVector::zeros(n);
    for k in 0..3 {
        h[3 * k] = -los[k] / d;
    }
    h[9] = 1.0;
    let mut pred = d + x[9];
    if n == 12 && m.emitter.system == System::Bds {
        h[11] = 1.0;
        pred += x[11];
    }
    (pred, h)
}

/// Predicted range rate `u·(v_s − v) + ḃ` and its exact Jacobian row.
fn rate_model(x: &DVector<f64>, m: &RangeMeasurement) -> (f64, DVector<f64>) {
    let los = m.emitter_pos_ecef_m - pos_of(x);
    let d = los.norm();
    let u = los / d;
    let w = m.emitter_vel_ecef_mps - vel_of(x);
    let mut h = DVector::zeros(x.len());
    let dpos = (u * u.dot(&w) - w) / d;
    for k in 0..3 {
        h[3 * k] = dpos[k];
        h[3 * k + 1] = -u[k];
    }
    h[10] = 1.0;
    (u.dot(&w) + x[10], h)
}

/// One EKF-style update of the linear KF: linearise at its own state, then a linear
/// update with `z_lin = z − h(x̂) + H x̂`, which makes the linear innovation `z − h(x̂)`.
fn lkf_nonlinear_update(kf: &mut LinearKf, z: f64, model: (f64, DVector<f64>), r_var: f64) {
    let (pred, h) = model;
    let z_lin = z - pred + h.dot(kf.state());
    kf.update(
        &DVector::from_element(1, z_lin),
        &DMatrix::from_row_slice(1, h.len(), h.as_slice()),
        &DMatrix::from_element(1, 1, r_var),
    )
    .unwrap();
}

/// Largest state difference relative to max(|x_i|, σ_i), and largest covariance
/// difference relative to √(P_ii P_jj), over the first `n` states.
fn disagreement(ekf: &Ekf11, kf: &LinearKf, n: usize) -> (f64, f64) {
    let (xe, pe) = (ekf.state(), ekf.covariance());
    let (xk, pk) = (kf.state(), kf.covariance());
    let mut dx: f64 = 0.0;
    let mut dp: f64 = 0.0;
    for i in 0..n {
        let scale = xk[i].abs().max(pk[(i, i)].sqrt());
        dx = dx.max((xe[i] - xk[i]).abs() / scale);
        for j in 0..n {
            let s = (pk[(i, i)] * pk[(j, j)]).sqrt();
            dp = dp.max((pe[(i, j)] - pk[(i, j)]).abs() / s);
        }
    }
    (dx, dp)
}

fn dvec_state(ekf: &Ekf11, n: usize) -> (DVector<f64>, DMatrix<f64>) {
    let x = DVector::from_iterator(n, ekf.state().iter().copied().take(n));
    let p = DMatrix::from_fn(n, n, |i, j| ekf.covariance()[(i, j)]);
    (x, p)
}

fn random_fix_cov(rng: &mut StreamRng) -> Matrix3<f64> {
    // A random SPD covariance with σ of a few metres and correlations.
    let a = Matrix3::from_fn(|_, _| gauss(rng) * 2.0);
    a * a.transpose() + Matrix3::identity() * 1.0
}

#[test]
fn ekf_equals_linear_kf_on_position_fixes() {
    // With position fixes only the measurement model is linear (eq. 18), so the EKF must
    // be a Kalman filter: same states and covariances as the textbook filter.
    let cfg = Ekf11Config {
        gate_chi2: None,
        gate_chi2_position: None,
        ..Default::default()
    };
    let trial = TrialRng::new(2018, 0);
    let mut rng = trial.stream("test/linear-fixes");
    let mut ekf = Ekf11::new(cfg).unwrap();
    let r0 = site().origin_ecef();
    ekf.initialise(r0, 150.0, 30.0, 100.0).unwrap();
    let (x0, p0) = dvec_state(&ekf, 11);
    let mut kf = LinearKf::new(x0, p0).unwrap();
    let mut worst = (0.0f64, 0.0f64);
    let mut hf = DMatrix::zeros(3, 11);
    hf[(0, 0)] = 1.0;
    hf[(1, 3)] = 1.0;
    hf[(2, 6)] = 1.0;
    for _ in 0..50 {
        let dt = 0.5 + rng.random::<f64>();
        ekf.predict(dt).unwrap();
        kf.predict(&phi_ref(11, dt), &q_ref(11, &cfg, dt)).unwrap();
        let cov = random_fix_cov(&mut rng);
        let z = r0 + Vector3::new(gauss(&mut rng), gauss(&mut rng), gauss(&mut rng)) * 5.0;
        let out = ekf.update_position(&PositionFix {
            pos_ecef_m: z,
            cov_m2: cov,
            support: 0,
        });
        let nis = kf
            .update(
                &DVector::from_column_slice(z.as_slice()),
                &hf,
                &DMatrix::from_column_slice(3, 3, cov.as_slice()),
            )
            .unwrap();
        assert!(out.is_accepted());
        assert!(
            (out.nis() - nis).abs() <= 1e-9 * nis.max(1.0),
            "NIS {} vs {nis}",
            out.nis()
        );
        let d = disagreement(&ekf, &kf, 11);
        worst = (worst.0.max(d.0), worst.1.max(d.1));
    }
    println!(
        "position fixes, 50 steps: state {:.2e}, covariance {:.2e}",
        worst.0, worst.1
    );
    assert!(worst.0 < 1e-9 && worst.1 < 1e-9, "{worst:?}");
}

/// Runs the EKF and a relinearised textbook KF side by side over 50 epochs of
/// pseudoranges, range rates (GPS and BDS satellites, a DTMB tower) and position fixes,
/// and returns the worst disagreement.
fn ekf_vs_relinearised_kf(cfg: Ekf11Config, n: usize, seed: u64) -> (f64, f64) {
    let trial = TrialRng::new(seed, 0);
    let mut rng = trial.stream("test/relinearised");
    let frame = site();
    let sats = sky(&frame, &MIXED_SKY[..6], &mut rng);
    let tower_id = EmitterId::new(System::Dtmb, 1);
    let tower = frame.ecef_of_enu(&Vector3::new(3_000.0, -4_000.0, 200.0));
    let mut ekf = Ekf11::new(cfg).unwrap();
    ekf.initialise(
        frame.origin_ecef() + Vector3::new(20.0, -10.0, 5.0),
        500.0,
        30.0,
        100.0,
    )
    .unwrap();
    let (x0, p0) = dvec_state(&ekf, n);
    let mut kf = LinearKf::new(x0, p0).unwrap();
    // The truth drives at 15 m/s east; the clock bias grows at 80 m/s.
    let truth = |t: f64| frame.ecef_of_enu(&Vector3::new(15.0 * t, 0.0, 0.0));
    let truth_vel = frame.ecef_vector_of_enu(&Vector3::new(15.0, 0.0, 0.0));
    let mut worst = (0.0f64, 0.0f64);
    for k in 1..=50 {
        let t = k as f64;
        ekf.predict(1.0).unwrap();
        kf.predict(&phi_ref(n, 1.0), &q_ref(n, &cfg, 1.0)).unwrap();
        let (r, b, bdot) = (truth(t), 500.0 + 80.0 * t, 80.0);
        let mut ms: Vec<RangeMeasurement> = sats
            .iter()
            .map(|s| {
                let (p, v) = s.pos_vel(t);
                let isb = if s.id.system == System::Bds {
                    12.0
                } else {
                    0.0
                };
                let u = (p - r).normalize();
                let pr = (p - r).norm() + b + isb + 3.0 * gauss(&mut rng);
                let rate = u.dot(&(v - truth_vel)) + bdot + 0.05 * gauss(&mut rng);
                range_meas(s.id, p, v, pr, Some(rate))
            })
            .collect();
        let u = (tower - r).normalize();
        ms.push(range_meas(
            tower_id,
            tower,
            Vector3::zeros(),
            (tower - r).norm() + b + 3.0 * gauss(&mut rng),
            Some(-u.dot(&truth_vel) + bdot + 0.05 * gauss(&mut rng)),
        ));
        for m in &ms {
            let out = ekf.update_range(m);
            assert!(
                out.range.is_accepted() && out.rate.unwrap().is_accepted(),
                "{out:?}"
            );
            let range_model_now = pseudorange_model(kf.state(), m);
            lkf_nonlinear_update(&mut kf, m.pseudorange_m, range_model_now, m.sigma_m.powi(2));
            let rate_model_now = rate_model(kf.state(), m);
            lkf_nonlinear_update(
                &mut kf,
                m.range_rate_mps.unwrap(),
                rate_model_now,
                m.sigma_rate_mps.powi(2),
            );
        }
        if k % 5 == 0 {
            let cov = random_fix_cov(&mut rng);
            let z = r + Vector3::new(gauss(&mut rng), gauss(&mut rng), gauss(&mut rng));
            assert!(ekf
                .update_position(&PositionFix {
                    pos_ecef_m: z,
                    cov_m2: cov,
                    support: 0,
                })
                .is_accepted());
            let mut hf = DMatrix::zeros(3, n);
            hf[(0, 0)] = 1.0;
            hf[(1, 3)] = 1.0;
            hf[(2, 6)] = 1.0;
            kf.update(
                &DVector::from_column_slice(z.as_slice()),
                &hf,
                &DMatrix::from_column_slice(3, 3, cov.as_slice()),
            )
            .unwrap();
        }
        let d = disagreement(&ekf, &kf, n);
        worst = (worst.0.max(d.0), worst.1.max(d.1));
    }
    worst
}

#[test]
fn ekf_equals_relinearised_textbook_kf_on_ranges_rates_and_fixes() {
    // The EKF's update is, by definition, the Kalman update of the model linearised at the
    // current estimate. A textbook filter fed with the independently written Jacobians of
    // eqs. 9–17 (linearised at its own estimate) must therefore follow the same path.
    // With the ISB inert the reference has 11 states: this is the paper's filter exactly.
    let cfg = Ekf11Config {
        gate_chi2: None,
        gate_chi2_position: None,
        ..Default::default()
    };
    let worst = ekf_vs_relinearised_kf(cfg, 11, 7);
    println!(
        "ranges + rates + fixes, 11 states (ISB inert), 50 epochs: state {:.2e}, covariance {:.2e}",
        worst.0, worst.1
    );
    assert!(worst.0 < 1e-9 && worst.1 < 1e-9, "{worst:?}");
    // With the ISB configured, the reference has 12 states and BDS ranges observe it.
    let cfg = Ekf11Config {
        isb_bds: Some(IsbConfig::default()),
        ..cfg
    };
    let worst = ekf_vs_relinearised_kf(cfg, 12, 8);
    println!(
        "ranges + rates + fixes, 12 states (ISB live), 50 epochs: state {:.2e}, covariance {:.2e}",
        worst.0, worst.1
    );
    assert!(worst.0 < 1e-9 && worst.1 < 1e-9, "{worst:?}");
}

// ---------------------------------------------------------------------------------------
// Consistency: NEES over Monte Carlo runs.
// ---------------------------------------------------------------------------------------

/// Run-averaged NEES per epoch for one group of Monte Carlo runs.
struct NeesGroup {
    /// Per epoch, the position NEES averaged over the group's runs.
    pos: Vec<f64>,
    /// Per epoch, the NEES of every live state averaged over the group's runs.
    full: Vec<f64>,
}

/// Monte Carlo results.
struct NeesResult {
    groups: Vec<NeesGroup>,
    /// Number of live states (11, or 12 with the ISB configured).
    n_full: usize,
    /// Every single-run position NEES after the first `SKIP` epochs.
    single_pos: Vec<f64>,
    gate_rejections: usize,
    updates: usize,
    /// Sums and counts of the NIS of every pseudorange and every range-rate update after
    /// `SKIP` (accepted or gated), for the mean NIS, which is 1 for a consistent filter.
    nis_range: (f64, usize),
    nis_rate: (f64, usize),
}

/// Epochs left out of the statistics while the filter converges from its first fix.
const SKIP: usize = 5;

/// `groups × runs` Monte Carlo runs of `epochs` one-second epochs. The truth is a sample
/// of the filter's own process model (eqs. 5–8, plus the ISB random walk when
/// configured), started from a draw of the initial covariance, so a consistent filter
/// gives NEES ~ χ²(n) at every epoch.
fn nees_monte_carlo(
    cfg: Ekf11Config,
    sky_def: &[(f64, f64, System)],
    groups: u64,
    runs: u64,
    epochs: usize,
) -> NeesResult {
    let n = if cfg.isb_bds.is_some() { 12 } else { 11 };
    let frame = site();
    let q = q_ref(n, &cfg, 1.0);
    let phi = phi_ref(n, 1.0);
    let q_chol = q
        .clone()
        .cholesky()
        .expect("Q is positive definite on the live states")
        .l();
    let (pos_sigma, clock_sigma) = (50.0, 1e4);
    let mut result = NeesResult {
        groups: Vec::new(),
        n_full: n,
        single_pos: Vec::new(),
        gate_rejections: 0,
        updates: 0,
        nis_range: (0.0, 0),
        nis_rate: (0.0, 0),
    };
    for group in 0..groups {
        let mut g = NeesGroup {
            pos: vec![0.0; epochs],
            full: vec![0.0; epochs],
        };
        for run in 0..runs {
            let trial = TrialRng::new(20_181_010, group * runs + run);
            let mut sky_rng = trial.stream("test/nees/sky");
            let mut proc_rng = trial.stream("test/nees/process");
            let mut meas_rng = trial.stream("test/nees/measurement");
            let sats = sky(&frame, sky_def, &mut sky_rng);
            // Truth at t = 0: the nominal site and a random clock; the estimate is the
            // truth plus an error drawn from the initial covariance.
            let mut x = DVector::<f64>::zeros(n);
            let r0 = frame.origin_ecef();
            for k in 0..3 {
                x[3 * k] = r0[k];
                x[3 * k + 1] = cfg.init_vel_sigma_mps * gauss(&mut proc_rng);
                x[3 * k + 2] = cfg.init_acc_sigma_mps2 * gauss(&mut proc_rng);
            }
            x[9] = 3e4 + clock_sigma * gauss(&mut proc_rng);
            x[10] = cfg.init_clock_drift_sigma_mps * gauss(&mut proc_rng);
            if let Some(isb) = cfg.isb_bds {
                x[11] = isb.initial_sigma_m * gauss(&mut proc_rng);
            }
            let pos_est = r0
                + Vector3::new(
                    gauss(&mut proc_rng),
                    gauss(&mut proc_rng),
                    gauss(&mut proc_rng),
                ) * pos_sigma;
            let mut ekf = Ekf11::new(cfg).unwrap();
            ekf.initialise(pos_est, 3e4, pos_sigma, clock_sigma)
                .unwrap();
            for epoch in 0..epochs {
                let t = (epoch + 1) as f64;
                let w = DVector::from_fn(n, |_, _| gauss(&mut proc_rng));
                x = &phi * &x + &q_chol * w;
                ekf.predict(1.0).unwrap();
                let (r, v) = (pos_of(&x), vel_of(&x));
                for s in &sats {
                    let (p, sv) = s.pos_vel(t);
                    let isb = if n == 12 && s.id.system == System::Bds {
                        x[11]
                    } else {
                        0.0
                    };
                    let u = (p - r).normalize();
                    let pr = (p - r).norm() + x[9] + isb + 3.0 * gauss(&mut meas_rng);
                    let rate = u.dot(&(sv - v)) + x[10] + 0.05 * gauss(&mut meas_rng);
                    let out = ekf.update_range(&range_meas(s.id, p, sv, pr, Some(rate)));
                    if epoch >= SKIP {
                        let rate_nis = out.rate.map_or(f64::NAN, |o| o.nis());
                        result.nis_range =
                            (result.nis_range.0 + out.range.nis(), result.nis_range.1 + 1);
                        result.nis_rate = (result.nis_rate.0 + rate_nis, result.nis_rate.1 + 1);
                    }
                    for o in [Some(out.range), out.rate].into_iter().flatten() {
                        result.updates += 1;
                        match o {
                            UpdateOutcome::Accepted { .. } => {}
                            UpdateOutcome::Rejected {
                                reason: RejectReason::Gate { .. },
                                ..
                            } => result.gate_rejections += 1,
                            other => panic!("unexpected outcome {other:?}"),
                        }
                    }
                }
                let nees_pos = ekf.nees_position(&r).unwrap();
                if epoch >= SKIP {
                    result.single_pos.push(nees_pos);
                }
                g.pos[epoch] += nees_pos / runs as f64;
                let e = DVector::from_fn(n, |i, _| ekf.state()[i] - x[i]);
                let p = DMatrix::from_fn(n, n, |i, j| ekf.covariance()[(i, j)]);
                let full = (e.transpose() * p.cholesky().unwrap().solve(&e))[(0, 0)];
                g.full[epoch] += full / runs as f64;
            }
        }
        result.groups.push(g);
    }
    result
}

/// Over all groups and every epoch after `SKIP`, the fraction of run-averaged NEES
/// values inside the two-sided 95 % band `N·ε̄ ~ χ²(N·n)` (Bar-Shalom, Li & Kirubarajan
/// §5.4.2), the band, and the overall mean.
fn band_coverage(series: &[&Vec<f64>], runs: u64, n: usize) -> (f64, f64, f64, f64) {
    let dof = (runs as usize * n) as f64;
    let lo = chi2::quantile(0.025, dof) / runs as f64;
    let hi = chi2::quantile(0.975, dof) / runs as f64;
    let tail: Vec<f64> = series
        .iter()
        .flat_map(|s| s[SKIP..].iter().copied())
        .collect();
    let inside = tail.iter().filter(|&&e| e >= lo && e <= hi).count();
    let mean = tail.iter().sum::<f64>() / tail.len() as f64;
    (inside as f64 / tail.len() as f64, lo, hi, mean)
}

fn check_nees(label: &str, cfg: Ekf11Config, sky_def: &[(f64, f64, System)]) {
    // The errors are strongly correlated from epoch to epoch (the filter averages over
    // tens of seconds), so the in-band fraction of a single group of runs is a noisy
    // statistic (seen between 69 % and 100 % for single groups of 100 runs). Its
    // expectation is 95 % for a consistent filter whatever the correlation, so it is
    // pooled over 40 independent groups of 50 runs each.
    let (groups, runs) = (40, 50);
    let res = nees_monte_carlo(cfg, sky_def, groups, runs, 120);
    let pos: Vec<&Vec<f64>> = res.groups.iter().map(|g| &g.pos).collect();
    let full: Vec<&Vec<f64>> = res.groups.iter().map(|g| &g.full).collect();
    let (cov_pos, lo3, hi3, mean_pos) = band_coverage(&pos, runs, 3);
    let (cov_full, lo_n, hi_n, mean_full) = band_coverage(&full, runs, res.n_full);
    let single = &res.single_pos;
    let q_hi = chi2::quantile(0.975, 3.0);
    let q_lo = chi2::quantile(0.025, 3.0);
    let above = single.iter().filter(|&&e| e > q_hi).count() as f64 / single.len() as f64;
    let below = single.iter().filter(|&&e| e < q_lo).count() as f64 / single.len() as f64;
    println!(
        "{label}: {groups}×{runs} runs × 120 epochs. Position NEES mean {mean_pos:.3}, band per group \
         [{lo3:.3}, {hi3:.3}], {:.1} % of group-epochs inside; {}-state NEES mean {mean_full:.3}, band \
         [{lo_n:.3}, {hi_n:.3}], {:.1} % inside. Single runs: {:.2} % above χ²₀.₉₇₅(3), {:.2} % below \
         χ²₀.₀₂₅(3). Mean NIS: pseudorange {:.4}, range rate {:.4}. Gate rejections {}/{} ({:.3} %).",
        100.0 * cov_pos,
        res.n_full,
        100.0 * cov_full,
        100.0 * above,
        100.0 * below,
        res.nis_range.0 / res.nis_range.1 as f64,
        res.nis_rate.0 / res.nis_rate.1 as f64,
        res.gate_rejections,
        res.updates,
        100.0 * res.gate_rejections as f64 / res.updates as f64
    );
    assert!(
        cov_pos >= 0.9,
        "{label}: position NEES inside its 95 % band in only {:.1} % of epochs",
        100.0 * cov_pos
    );
    assert!(
        cov_full >= 0.9,
        "{label}: full NEES inside its 95 % band in only {:.1} % of epochs",
        100.0 * cov_full
    );
    // The pooled means: within 5 % of the state dimension.
    assert!((mean_pos / 3.0 - 1.0).abs() < 0.05, "{mean_pos}");
    assert!(
        (mean_full / res.n_full as f64 - 1.0).abs() < 0.05,
        "{mean_full}"
    );
    // Single-run tails: 2.5 % each for χ²(3), allowing for the correlation of samples.
    assert!(above < 0.04 && below < 0.04, "{above} {below}");
    // A 0.1 % gate should reject about 0.1 % of consistent measurements.
    assert!((res.gate_rejections as f64) < 0.005 * res.updates as f64);
}

#[test]
fn nees_is_consistent_in_open_sky_gps() {
    // Without the gate the filter is exactly consistent (NEES means within 0.5 % of n).
    // With the default 0.1 % gate the NEES and NIS run about 1 % high: the gate rejects
    // large innovations, which come more often from large state errors, and leaves those
    // errors uncorrected while P does not know — the known price of gating.
    let no_gate = Ekf11Config {
        gate_chi2: None,
        gate_chi2_position: None,
        ..Default::default()
    };
    check_nees("open sky, 9 GPS, 11 states, no gate", no_gate, &OPEN_SKY);
    check_nees(
        "open sky, 9 GPS, 11 states, default gate",
        Ekf11Config::default(),
        &OPEN_SKY,
    );
}

#[test]
fn nees_is_consistent_with_a_live_beidou_isb() {
    let cfg = Ekf11Config {
        isb_bds: Some(IsbConfig::default()),
        ..Default::default()
    };
    check_nees("5 GPS + 4 BDS, 12 states", cfg, &MIXED_SKY);
}

#[test]
fn chi2_quantiles_match_tables() {
    // Standard tables (e.g. NIST/SEMATECH e-Handbook §1.3.6.7.4), to their printed digits.
    assert!((chi2::quantile(0.975, 100.0) - 129.561).abs() < 5e-4);
    assert!((chi2::quantile(0.025, 100.0) - 74.222).abs() < 5e-4);
    assert!((chi2::quantile(0.95, 1.0) - 3.841).abs() < 5e-4);
    assert!((chi2::quantile(0.95, 3.0) - 7.815).abs() < 5e-4);
    assert!((chi2::quantile(0.05, 10.0) - 3.940).abs() < 5e-4);
    // Wilson–Hilferty alone: within 0.05 % at 100 degrees of freedom.
    assert!((chi2::quantile_wilson_hilferty(0.975, 100.0) / 129.561 - 1.0).abs() < 5e-4);
    assert!((chi2::quantile_wilson_hilferty(0.025, 100.0) / 74.222 - 1.0).abs() < 5e-4);
}

// ---------------------------------------------------------------------------------------
// Gating and robustness.
// ---------------------------------------------------------------------------------------

/// A filter converged on 30 s of open-sky GPS, with the sky and truth it saw.
fn converged_filter(cfg: Ekf11Config) -> (Ekf11, Vec<Sat>, Vector3<f64>) {
    let frame = site();
    let trial = TrialRng::new(99, 0);
    let mut rng = trial.stream("test/converge");
    let sats = sky(&frame, &OPEN_SKY, &mut rng);
    let r = frame.origin_ecef();
    let mut ekf = Ekf11::new(cfg).unwrap();
    ekf.initialise(r + Vector3::new(30.0, -20.0, 10.0), 0.0, 50.0, 1e3)
        .unwrap();
    for k in 1..=30 {
        ekf.predict(1.0).unwrap();
        for s in &sats {
            let (p, v) = s.pos_vel(k as f64);
            let u = (p - r).normalize();
            let pr = (p - r).norm() + 100.0 + 3.0 * gauss(&mut rng);
            let rate = u.dot(&v) + 0.05 * gauss(&mut rng);
            ekf.update_range(&range_meas(s.id, p, v, pr, Some(rate)));
        }
    }
    (ekf, sats, r)
}

#[test]
fn a_one_kilometre_outlier_is_gated_and_absorbed_without_the_gate() {
    let (gated, sats, r) = converged_filter(Ekf11Config::default());
    let err_before = (gated.position_ecef() - r).norm();
    let (p, v) = sats[3].pos_vel(30.0);
    let outlier = range_meas(sats[3].id, p, v, (p - r).norm() + 100.0 + 1_000.0, None);

    let mut with_gate = gated.clone();
    let out = with_gate.update_range(&outlier).range;
    // A converged filter is far more certain along the line of sight than a range is, so
    // the refusal is the measurement's doing, not the state's.
    assert_eq!(
        out.reject_reason(),
        Some(RejectReason::Gate { state_led: false }),
        "{out:?}"
    );
    assert!(out.nis() > 1e4);
    assert_eq!(
        with_gate.state(),
        gated.state(),
        "a rejected update must leave the state untouched"
    );
    assert_eq!(with_gate.covariance(), gated.covariance());

    let mut cfg = *gated.config();
    cfg.gate_chi2 = None;
    let mut without_gate = Ekf11::new(cfg).unwrap();
    without_gate
        .set_state(*gated.state(), *gated.covariance())
        .unwrap();
    assert!(without_gate.update_range(&outlier).range.is_accepted());
    let err_after = (without_gate.position_ecef() - r).norm();
    println!("1 km outlier: position error {err_before:.2} m before, {err_after:.1} m after an ungated update");
    // The converged filter trusts its prediction (range σ well below the 3 m noise), so the
    // gain is small, but a kilometre times a few per cent is still tens of metres.
    assert!(err_before < 5.0, "{err_before}");
    assert!(
        err_after > 10.0 * err_before && err_after > 15.0,
        "the outlier should drag the estimate: {err_after}"
    );
}

#[test]
fn non_finite_and_invalid_input_is_rejected_and_the_state_stays_finite() {
    let (mut ekf, sats, r) = converged_filter(Ekf11Config {
        gate_chi2: None,
        ..Default::default()
    });
    let before = (*ekf.state(), *ekf.covariance());
    let (p, v) = sats[0].pos_vel(30.0);
    let good = range_meas(
        sats[0].id,
        p,
        v,
        (p - r).norm() + 100.0,
        Some(v.dot(&(p - r).normalize())),
    );
    let cases: Vec<(RangeMeasurement, RejectReason)> = vec![
        (
            RangeMeasurement {
                pseudorange_m: f64::NAN,
                ..good
            },
            RejectReason::NonFiniteInput,
        ),
        (
            RangeMeasurement {
                pseudorange_m: f64::INFINITY,
                ..good
            },
            RejectReason::NonFiniteInput,
        ),
        (
            RangeMeasurement {
                emitter_pos_ecef_m: Vector3::new(f64::NAN, 0.0, 0.0),
                ..good
            },
            RejectReason::NonFiniteInput,
        ),
        (
            RangeMeasurement {
                sigma_m: 0.0,
                ..good
            },
            RejectReason::InvalidNoise,
        ),
        (
            RangeMeasurement {
                sigma_m: f64::NAN,
                ..good
            },
            RejectReason::InvalidNoise,
        ),
        (
            RangeMeasurement {
                emitter_pos_ecef_m: ekf.position_ecef(),
                ..good
            },
            RejectReason::DegenerateGeometry,
        ),
        // Finite but absurd: the innovation squared overflows, so the NIS is not finite.
        (
            RangeMeasurement {
                pseudorange_m: f64::MAX,
                ..good
            },
            RejectReason::NumericalFailure,
        ),
    ];
    for (m, reason) in cases {
        let out = ekf.update_pseudorange(&m);
        assert_eq!(out.reject_reason(), Some(reason), "{m:?} → {out:?}");
    }
    let bad_rate = RangeMeasurement {
        range_rate_mps: Some(f64::NAN),
        ..good
    };
    let out = ekf.update_range(&bad_rate);
    assert_eq!(
        out.rate.unwrap().reject_reason(),
        Some(RejectReason::NonFiniteInput)
    );
    let before_fix = (*ekf.state(), *ekf.covariance());
    let bad_fix = PositionFix {
        pos_ecef_m: Vector3::new(f64::NAN, 0.0, 0.0),
        cov_m2: Matrix3::identity(),
        support: 0,
    };
    assert_eq!(
        ekf.update_position(&bad_fix).reject_reason(),
        Some(RejectReason::NonFiniteInput)
    );
    let bad_cov = PositionFix {
        pos_ecef_m: r,
        cov_m2: Matrix3::new(1.0, 2.0, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0, 1.0),
        support: 0,
    };
    assert_eq!(
        ekf.update_position(&bad_cov).reject_reason(),
        Some(RejectReason::InvalidNoise)
    );
    assert_eq!((*ekf.state(), *ekf.covariance()), before_fix);
    assert!(ekf.predict(f64::NAN).is_err());
    assert!(ekf.predict(-1.0).is_err());
    assert!(ekf.predict(f64::INFINITY).is_err());
    assert!(
        ekf.state().iter().all(|v| v.is_finite()) && ekf.covariance().iter().all(|v| v.is_finite())
    );
    // Only the good pseudorange inside `bad_rate` was used; everything else left no trace.
    let mut reference = Ekf11::new(*ekf.config()).unwrap();
    reference.set_state(before.0, before.1).unwrap();
    reference.update_pseudorange(&bad_rate);
    assert_eq!(ekf.state(), reference.state());
}

// ---------------------------------------------------------------------------------------
// Weighted least squares.
// ---------------------------------------------------------------------------------------

fn static_ranges(
    frame: &EnuFrame,
    sats: &[Sat],
    truth: Vector3<f64>,
    clock: impl Fn(System) -> f64,
) -> Vec<RangeMeasurement> {
    let _ = frame;
    sats.iter()
        .map(|s| {
            let (p, v) = s.pos_vel(0.0);
            range_meas(s.id, p, v, (p - truth).norm() + clock(s.id.system), None)
        })
        .collect()
}

#[test]
fn wls_noise_free_recovers_position_and_per_system_clocks() {
    let frame = site();
    let mut rng = TrialRng::new(5, 0).stream("test/wls/sky");
    let sats = sky(&frame, &MIXED_SKY, &mut rng);
    let truth = frame.ecef_of_enu(&Vector3::new(120.0, -40.0, 3.0));
    let clock = |s: System| if s == System::Gps { 1_234.5 } else { -250.25 };
    let ms = static_ranges(&frame, &sats, truth, clock);
    let fix = wls::solve(&ms, &WlsOptions::default()).unwrap();
    let err = (fix.pos_ecef_m - truth).norm();
    println!(
        "WLS noise-free GPS+BDS: error {err:.2e} m in {} iterations, GDOP {:.2}",
        fix.iterations, fix.dop.gdop
    );
    assert!(err < 1e-3);
    assert_eq!(fix.n_clocks, 2);
    assert!((fix.clock_m(System::Gps).unwrap() - 1_234.5).abs() < 1e-3);
    assert!((fix.clock_m(System::Bds).unwrap() + 250.25).abs() < 1e-3);
    assert_eq!(fix.clock_m(System::Dtmb), None);

    // GPS with DTMB towers on one shared clock (seed 000's assumption), and the same
    // ranges with a clock each: both recover the truth.
    let towers: Vec<Vector3<f64>> = [
        (2_000.0, 1_000.0, 150.0),
        (-3_000.0, 2_500.0, 300.0),
        (500.0, -4_000.0, 80.0),
    ]
    .iter()
    .map(|&(e, n, u)| frame.ecef_of_enu(&Vector3::new(e, n, u)))
    .collect();
    let mut ms = static_ranges(&frame, &sats[..5], truth, |_| 77.0);
    for (i, t) in towers.iter().enumerate() {
        ms.push(range_meas(
            EmitterId::new(System::Dtmb, i as u16 + 1),
            *t,
            Vector3::zeros(),
            (t - truth).norm() + 77.0,
            None,
        ));
    }
    let shared = wls::solve(
        &ms,
        &WlsOptions {
            shared_clock: true,
            ..Default::default()
        },
    )
    .unwrap();
    assert!((shared.pos_ecef_m - truth).norm() < 1e-3);
    assert_eq!(shared.n_clocks, 1);
    assert_eq!(shared.clock_m(System::Dtmb), shared.clock_m(System::Gps));
    let separate = wls::solve(&ms, &WlsOptions::default()).unwrap();
    assert!((separate.pos_ecef_m - truth).norm() < 1e-3);
    assert!((separate.clock_m(System::Dtmb).unwrap() - 77.0).abs() < 1e-3);
    assert!(
        separate.dop.gdop > shared.dop.gdop,
        "an extra clock unknown cannot improve the geometry"
    );
}

#[test]
fn wls_gdop_for_a_hand_checked_geometry() {
    // Zenith + three satellites on the horizon 120° apart. In ENU the rows of H are
    // [0,0,1,1], [0,1,0,1], [±√3/2,−1/2,0,1]; HᵀH = diag(3/2, 3/2) ⊕ [[1,1],[1,4]], whose
    // inverse has trace 2/3 + 2/3 + 4/3 + 1/3 = 3: GDOP = √3, PDOP = √(8/3),
    // HDOP = VDOP = √(4/3), TDOP = √(1/3).
    let frame = site();
    let r = frame.origin_ecef();
    let at = |az: f64, el: f64| {
        let (az, el) = (f64::to_radians(az), f64::to_radians(el));
        frame.ecef_of_enu(
            &(Vector3::new(el.cos() * az.sin(), el.cos() * az.cos(), el.sin()) * 2.0e7),
        )
    };
    let sats = [at(0.0, 90.0), at(0.0, 0.0), at(120.0, 0.0), at(240.0, 0.0)];
    let g = wls::gdop(&r, &sats).unwrap();
    assert!((g - 3f64.sqrt()).abs() < 1e-9, "{g}");
    let ms: Vec<_> = sats
        .iter()
        .enumerate()
        .map(|(i, &s)| {
            range_meas(
                EmitterId::new(System::Gps, i as u16 + 1),
                s,
                Vector3::zeros(),
                (s - r).norm(),
                None,
            )
        })
        .collect();
    let fix = wls::solve(&ms, &WlsOptions::default()).unwrap();
    assert!((fix.pos_ecef_m - r).norm() < 1e-3);
    assert!((fix.dop.gdop - 3f64.sqrt()).abs() < 1e-6);
    assert!((fix.dop.pdop - (8.0f64 / 3.0).sqrt()).abs() < 1e-6);
    assert!((fix.dop.hdop - (4.0f64 / 3.0).sqrt()).abs() < 1e-6);
    assert!((fix.dop.vdop - (4.0f64 / 3.0).sqrt()).abs() < 1e-6);
    // Removing the zenith satellite leaves too few.
    assert!(wls::gdop(&r, &sats[1..]).is_none());
}

#[test]
fn wls_errors_instead_of_panics() {
    let frame = site();
    let r = frame.origin_ecef();
    let mut rng = TrialRng::new(6, 0).stream("test/wls/errors");
    let sats = sky(&frame, &MIXED_SKY, &mut rng);
    // Three GPS + one BDS is four ranges for five unknowns; sharing the clock makes it four.
    let gps: Vec<&Sat> = sats
        .iter()
        .filter(|s| s.id.system == System::Gps)
        .take(3)
        .collect();
    let bds = sats.iter().find(|s| s.id.system == System::Bds).unwrap();
    let mut ms: Vec<RangeMeasurement> = gps
        .iter()
        .chain(std::iter::once(&bds))
        .map(|s| {
            let (p, v) = s.pos_vel(0.0);
            range_meas(s.id, p, v, (p - r).norm(), None)
        })
        .collect();
    assert_eq!(
        wls::solve(&ms, &WlsOptions::default()),
        Err(WlsError::TooFewMeasurements { have: 4, need: 5 })
    );
    let shared = wls::solve(
        &ms,
        &WlsOptions {
            shared_clock: true,
            ..Default::default()
        },
    )
    .unwrap();
    assert!((shared.pos_ecef_m - r).norm() < 1e-3);
    ms.truncate(2);
    assert!(matches!(
        wls::solve(&ms, &WlsOptions::default()),
        Err(WlsError::TooFewMeasurements { .. })
    ));

    // Towers all in the horizontal plane through the receiver: height is unobservable.
    let towers: Vec<RangeMeasurement> = [
        (3e3, 0.0),
        (0.0, 4e3),
        (-2e3, -1e3),
        (1e3, -5e3),
        (-4e3, 3e3),
    ]
    .iter()
    .enumerate()
    .map(|(i, &(e, n))| {
        let t = frame.ecef_of_enu(&Vector3::new(e, n, 0.0));
        range_meas(
            EmitterId::new(System::Dtmb, i as u16 + 1),
            t,
            Vector3::zeros(),
            (t - r).norm(),
            None,
        )
    })
    .collect();
    let at_truth = WlsOptions {
        initial_pos_ecef_m: Some(r),
        ..Default::default()
    };
    assert_eq!(
        wls::solve(&towers, &at_truth),
        Err(WlsError::SingularGeometry)
    );
    assert!(wls::solve(&towers, &WlsOptions::default()).is_err());
    // Every satellite at one elevation: the vertical and the clock are inseparable.
    let cone: Vec<RangeMeasurement> = [0.0, 72.0, 144.0, 216.0, 288.0]
        .iter()
        .enumerate()
        .map(|(i, &az)| {
            let (az, el) = (f64::to_radians(az), 30f64.to_radians());
            let s = frame.ecef_of_enu(
                &(Vector3::new(el.cos() * az.sin(), el.cos() * az.cos(), el.sin()) * 2.0e7),
            );
            range_meas(
                EmitterId::new(System::Gps, i as u16 + 1),
                s,
                Vector3::zeros(),
                (s - r).norm(),
                None,
            )
        })
        .collect();
    assert_eq!(
        wls::solve(&cone, &at_truth),
        Err(WlsError::SingularGeometry)
    );

    // Random junk: coincident emitters, huge and tiny values, NaNs. Never a panic.
    let mut junk_rng = TrialRng::new(6, 1).stream("test/wls/junk");
    for _ in 0..2_000 {
        let n = junk_rng.random_range(0..9);
        let ms: Vec<RangeMeasurement> = (0..n)
            .map(|i| {
                let pick = |rng: &mut StreamRng| match rng.random_range(0..6) {
                    0 => 0.0,
                    1 => f64::NAN,
                    2 => 1e300,
                    _ => gauss(rng) * 2e7,
                };
                let pos = Vector3::new(
                    pick(&mut junk_rng),
                    pick(&mut junk_rng),
                    pick(&mut junk_rng),
                );
                let sys = [System::Gps, System::Bds, System::Dtmb, System::Tcofdm]
                    [junk_rng.random_range(0..4)];
                let pr = pick(&mut junk_rng).abs();
                RangeMeasurement {
                    sigma_m: junk_rng.random_range(-1.0..5.0),
                    ..range_meas(EmitterId::new(sys, i + 1), pos, Vector3::zeros(), pr, None)
                }
            })
            .collect();
        let shared_clock = junk_rng.random::<bool>();
        let _ = wls::solve(
            &ms,
            &WlsOptions {
                shared_clock,
                ..Default::default()
            },
        );
    }
}

#[test]
fn wls_covariance_is_consistent_with_its_errors() {
    // Noisy ranges with per-satellite sigmas: the position error's NEES under the formal
    // covariance must average 3 (within the 95 % band over 200 fixes).
    let frame = site();
    let r = frame.origin_ecef();
    let runs = 200u64;
    let mut total = 0.0;
    for run in 0..runs {
        let trial = TrialRng::new(31, run);
        let mut sky_rng = trial.stream("test/wls/sky");
        let mut noise = trial.stream("test/wls/noise");
        let sats = sky(&frame, &MIXED_SKY, &mut sky_rng);
        let ms: Vec<RangeMeasurement> = sats
            .iter()
            .enumerate()
            .map(|(i, s)| {
                let (p, v) = s.pos_vel(0.0);
                let sigma = 1.0 + i as f64;
                let pr = (p - r).norm() + 40.0 + sigma * gauss(&mut noise);
                RangeMeasurement {
                    sigma_m: sigma,
                    ..range_meas(s.id, p, v, pr, None)
                }
            })
            .collect();
        let fix = wls::solve(&ms, &WlsOptions::default()).unwrap();
        let e = fix.pos_ecef_m - r;
        total += e.dot(&(fix.cov_pos_ecef_m2.try_inverse().unwrap() * e));
    }
    let mean = total / runs as f64;
    let lo = chi2::quantile(0.025, 3.0 * runs as f64) / runs as f64;
    let hi = chi2::quantile(0.975, 3.0 * runs as f64) / runs as f64;
    println!("WLS position NEES over {runs} fixes: {mean:.3} (95 % band [{lo:.3}, {hi:.3}])");
    assert!(mean > lo && mean < hi);
}

#[test]
fn ekf_refuses_work_before_initialisation_and_reports_idx_layout() {
    let mut ekf = Ekf11::new(Ekf11Config::default()).unwrap();
    let m = range_meas(
        EmitterId::new(System::Gps, 1),
        Vector3::new(2e7, 0.0, 0.0),
        Vector3::zeros(),
        2e7,
        None,
    );
    assert_eq!(
        ekf.update_pseudorange(&m).reject_reason(),
        Some(RejectReason::NotInitialised)
    );
    assert_eq!(idx::POS, [0, 3, 6]);
    assert_eq!(
        (idx::CLOCK_BIAS, idx::CLOCK_DRIFT, idx::ISB_BDS),
        (9, 10, 11)
    );
}
