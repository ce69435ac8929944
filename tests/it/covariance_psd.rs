//! Property tests: every filter's covariance stays symmetric positive semi-definite over
//! random linear-Gaussian models, including badly conditioned ones.
//!
//! Each case draws a state dimension's worth of random structure from its own named
//! stream: a transition `F = R_F · diag(ρ) · R_Fᵀ`-like mix with spectral radius up to 1.2,
//! a process noise `Q` and measurement noise `R` with eigenvalues spread over 10^±k (their
//! condition numbers reach 1e8–1e12), a random `H`, and a prior just as ill-conditioned.
//! The filter runs 40 predict/update cycles on measurements of a simulated truth; after
//! every step the covariance must be symmetric (‖P − Pᵀ‖ ≤ 1e-9 ‖P‖) and have no
//! eigenvalue below −1e-9 · trace P. The conventional update `P⁺ = (I − KH) P⁻` with the
//! same data breaks the property in some of these cases (counted below), which is why the
//! filters use the Joseph form and symmetrise. The seed-000 EKF (nonlinear pseudoranges and
//! rates) and the 15-state INS error-state filter get random models of their own kind:
//! random geometry, noise spanning decades, random intervals and motions.

use hybridnav::core::TrialRng;
use hybridnav::fusion::kalman::{Ekf, RelativeEntropyKf, SigmaPointKf, StrongTrackingFilter};
use hybridnav::fusion::models::{MeasurementModel, ProcessModel};
use hybridnav::fusion::particle::{ParticleBuffer, ParticleFilter, Resampling};
use nalgebra::{SMatrix, SVector};
use rand::Rng;
use rand_distr::StandardNormal;

const N: usize = 6;
const M: usize = 3;
const CASES: u64 = 300;
const STEPS: usize = 40;

struct Lin {
    f: SMatrix<f64, N, N>,
    q: SMatrix<f64, N, N>,
}

impl ProcessModel<N> for Lin {
    fn f(&self, x: &SVector<f64, N>, _dt_s: f64) -> SVector<f64, N> {
        self.f * x
    }
    fn jacobian(&self, _x: &SVector<f64, N>, _dt_s: f64) -> SMatrix<f64, N, N> {
        self.f
    }
    fn q(&self, _x: &SVector<f64, N>, _dt_s: f64) -> SMatrix<f64, N, N> {
        self.q
    }
}

struct Obs {
    h: SMatrix<f64, M, N>,
    r: SMatrix<f64, M, M>,
}

impl MeasurementModel<N, M> for Obs {
    fn h(&self, x: &SVector<f64, N>) -> SVector<f64, M> {
        self.h * x
    }
    fn jacobian(&self, _x: &SVector<f64, N>) -> SMatrix<f64, M, N> {
        self.h
    }
    fn r(&self) -> SMatrix<f64, M, M> {
        self.r
    }
}

fn gauss<R: Rng>(rng: &mut R) -> f64 {
    rng.sample(StandardNormal)
}

/// A random orthogonal matrix (QR of a Gaussian matrix).
fn rotation<const D: usize, R: Rng>(rng: &mut R) -> SMatrix<f64, D, D> {
    let q = nalgebra::DMatrix::<f64>::from_fn(D, D, |_, _| gauss(rng))
        .qr()
        .q();
    SMatrix::<f64, D, D>::from_fn(|i, j| q[(i, j)])
}

/// A random SPD matrix with eigenvalues `scale · 10^u`, `u` uniform in ±`decades`/2.
fn spd<const D: usize, R: Rng>(rng: &mut R, scale: f64, decades: f64) -> SMatrix<f64, D, D> {
    let u = rotation::<D, R>(rng);
    let d = SVector::<f64, D>::from_fn(|_, _| {
        scale * 10f64.powf(decades * (rng.random::<f64>() - 0.5))
    });
    let m = u * SMatrix::from_diagonal(&d) * u.transpose();
    (m + m.transpose()) * 0.5
}

struct Case {
    proc: Lin,
    obs: Obs,
    p0: SMatrix<f64, N, N>,
    truth: Vec<SVector<f64, N>>,
    z: Vec<SVector<f64, M>>,
}

fn case(k: u64) -> Case {
    let mut rng = TrialRng::new(20261122, k).stream("test/psd");
    let decades = [4.0, 8.0, 12.0][(k % 3) as usize];
    let rot = rotation::<N, _>(&mut rng);
    let rho = SVector::<f64, N>::from_fn(|_, _| 0.2 + rng.random::<f64>());
    let f = rot * SMatrix::from_diagonal(&rho) * rot.transpose()
        + SMatrix::<f64, N, N>::from_fn(|_, _| 0.05 * gauss(&mut rng));
    let proc = Lin {
        f,
        q: spd::<N, _>(&mut rng, 1e-2, decades),
    };
    let obs = Obs {
        h: SMatrix::<f64, M, N>::from_fn(|_, _| gauss(&mut rng)),
        r: spd::<M, _>(&mut rng, 1.0, decades),
    };
    let p0 = spd::<N, _>(&mut rng, 10.0, decades);
    let mut x = SVector::<f64, N>::from_fn(|_, _| gauss(&mut rng));
    let (lq, lr) = (
        proc.q.cholesky().expect("SPD").l(),
        obs.r.cholesky().expect("SPD").l(),
    );
    let mut truth = Vec::with_capacity(STEPS);
    let mut z = Vec::with_capacity(STEPS);
    for _ in 0..STEPS {
        x = proc.f * x + lq * SVector::<f64, N>::from_fn(|_, _| gauss(&mut rng));
        truth.push(x);
        z.push(obs.h * x + lr * SVector::<f64, M>::from_fn(|_, _| gauss(&mut rng)));
    }
    Case {
        proc,
        obs,
        p0,
        truth,
        z,
    }
}

/// Why `p` is not a symmetric PSD covariance, if it is not.
fn not_psd<const D: usize>(p: &SMatrix<f64, D, D>) -> Option<String> {
    let norm = p.norm();
    let asym = (p - p.transpose()).norm();
    if !(norm.is_finite() && asym <= 1e-9 * norm) {
        return Some(format!("asymmetry {asym:e} of norm {norm:e}"));
    }
    let min = nalgebra::DMatrix::from_iterator(D, D, p.iter().copied())
        .symmetric_eigen()
        .eigenvalues
        .min();
    if min < -1e-9 * p.trace() {
        return Some(format!("eigenvalue {min:e} of trace {:e}", p.trace()));
    }
    None
}

fn check_all(name: &str, mut step: impl FnMut(&Case, usize) -> SMatrix<f64, N, N>) {
    for k in 0..CASES {
        let c = case(k);
        for s in 0..STEPS {
            let p = step(&c, s);
            if let Some(why) = not_psd(&p) {
                panic!("{name}, case {k}, step {s}: {why}");
            }
        }
    }
}

#[test]
fn kalman_filter_covariances_stay_symmetric_psd() {
    let mut f = None;
    let mut used = 0u64;
    check_all("EKF (Joseph)", |c, s| {
        if s == 0 {
            f = Some(Ekf::new(SVector::zeros(), c.p0).unwrap());
        }
        let kf = f.as_mut().unwrap();
        kf.predict(&c.proc, 1.0).unwrap();
        used += u64::from(kf.update(&c.obs, &c.z[s]).used);
        *kf.covariance()
    });
    // Every update was used: the property is tested on real updates.
    assert_eq!(used, CASES * STEPS as u64 * M as u64);
}

#[test]
fn sigma_point_filter_covariances_stay_symmetric_psd() {
    for cubature in [false, true] {
        let mut f = None;
        let mut used = 0u64;
        check_all(if cubature { "CKF" } else { "UKF" }, |c, s| {
            if s == 0 {
                f = Some(if cubature {
                    SigmaPointKf::cubature(SVector::zeros(), c.p0).unwrap()
                } else {
                    SigmaPointKf::unscented(SVector::zeros(), c.p0, 1.0, 2.0, 0.0).unwrap()
                });
            }
            let kf = f.as_mut().unwrap();
            kf.predict(&c.proc, 1.0).unwrap();
            used += u64::from(kf.update(&c.obs, &c.z[s]).used);
            *kf.covariance()
        });
        assert_eq!(used, CASES * STEPS as u64 * M as u64);
    }
}

#[test]
fn strong_tracking_and_relative_entropy_covariances_stay_symmetric_psd() {
    let mut stf = None;
    check_all("STF", |c, s| {
        if s == 0 {
            stf =
                Some(StrongTrackingFilter::<N, M>::new(SVector::zeros(), c.p0, 0.95, 1.0).unwrap());
        }
        let kf = stf.as_mut().unwrap();
        kf.predict(&c.proc, 1.0).unwrap();
        let _ = kf.update(&c.obs, &c.z[s]);
        *kf.covariance()
    });
    let mut re = None;
    check_all("RE-KF", |c, s| {
        if s == 0 {
            re = Some(
                RelativeEntropyKf::new(
                    SVector::zeros(),
                    c.p0,
                    hybridnav::fusion::kalman::DEFAULT_ALEPH_THRESHOLD,
                    None,
                )
                .unwrap(),
            );
        }
        let kf = re.as_mut().unwrap();
        kf.predict(&c.proc, 1.0).unwrap();
        let _ = kf.update(&c.obs, &c.z[s]);
        *kf.covariance()
    });
}

/// The particle filter's weighted covariance is PSD by construction (a weighted sum of
/// outer products); checked all the same, with fewer cases as each step costs more.
#[test]
fn particle_filter_covariances_stay_symmetric_psd() {
    for k in 0..40 {
        let c = case(k);
        let mut rng = TrialRng::new(5, k).stream("test/psd/pf");
        let buf = ParticleBuffer::<N>::new(500).unwrap();
        let mut pf = ParticleFilter::new(buf, Resampling::Systematic, 0.5).unwrap();
        pf.init_gaussian(&c.truth[0], &c.p0, &mut rng).unwrap();
        for s in 0..STEPS {
            let _ = pf.predict(&c.proc, 1.0, &mut rng);
            let _ = pf.update(&c.obs, &c.z[s], &mut rng);
            if let Some(why) = not_psd(&pf.covariance()) {
                panic!("PF, case {k}, step {s}: {why}");
            }
        }
    }
}

/// The property is not vacuous: the conventional update `P⁺ = (I − KH) P⁻`, without the
/// Joseph form or symmetrisation, loses it on some of the same cases.
#[test]
fn the_conventional_update_fails_where_the_joseph_form_holds() {
    let mut broken = 0;
    for k in 0..CASES {
        let c = case(k);
        let mut p = c.p0;
        for _ in 0..STEPS {
            p = c.proc.f * p * c.proc.f.transpose() + c.proc.q;
            let s = c.obs.h * p * c.obs.h.transpose() + c.obs.r;
            let Some(s_inv) = s.try_inverse() else {
                break;
            };
            let k_gain = p * c.obs.h.transpose() * s_inv;
            p = (SMatrix::<f64, N, N>::identity() - k_gain * c.obs.h) * p;
            if not_psd(&p).is_some() {
                broken += 1;
                break;
            }
        }
    }
    eprintln!("conventional update: {broken} of {CASES} cases lost symmetry or PSD");
    assert!(
        broken > 0,
        "the random models are too benign to test anything"
    );
}

/// A random unit vector in the upper half-space of `up`.
fn above<R: Rng>(rng: &mut R, up: &nalgebra::Vector3<f64>) -> nalgebra::Vector3<f64> {
    loop {
        let v = nalgebra::Vector3::from_fn(|_, _| gauss(rng)).normalize();
        if v.dot(up) > 0.05 {
            return v;
        }
    }
}

/// The seed-000 EKF (12 states: position, velocity, acceleration, clock bias and drift,
/// BeiDou inter-system bias) over 200 random cases: random jerk and clock PSDs over six
/// decades, random receiver site, 4–12 satellites of both systems in random directions,
/// pseudorange σ from 0.1 m to 1 km and rate σ from 1 mm/s to 10 m/s, random intervals
/// from 10 ms to 30 s, occasional position fixes with random covariances, no gates.
#[test]
fn the_seed000_ekf_covariance_stays_symmetric_psd() {
    use hybridnav::core::{EmitterId, System};
    use hybridnav::fusion::ekf11::{Ekf11, Ekf11Config, IsbConfig};
    use hybridnav::measurement::{PositionFix, RangeMeasurement};
    use nalgebra::Vector3;
    let (mut total, mut accepted) = (0usize, 0usize);
    for k in 0..200u64 {
        let mut rng = TrialRng::new(77, k).stream("test/psd/ekf11");
        let decade = |rng: &mut hybridnav::core::rng::StreamRng, lo: f64, hi: f64| {
            10f64.powf(lo + (hi - lo) * rng.random::<f64>())
        };
        let cfg = Ekf11Config {
            accel_psd_m2ps5: [0; 3].map(|_| decade(&mut rng, -4.0, 2.0)),
            clock_bias_psd_m2ps: decade(&mut rng, -3.0, 3.0),
            clock_drift_psd_m2ps3: decade(&mut rng, -3.0, 3.0),
            isb_bds: Some(IsbConfig::default()),
            gate_chi2: None,
            gate_chi2_position: None,
            ..Ekf11Config::default()
        };
        let mut f = Ekf11::new(cfg).unwrap();
        let up = Vector3::from_fn(|_, _| gauss(&mut rng)).normalize();
        let mut pos = up * 6.37e6;
        let vel = Vector3::from_fn(|_, _| 10.0 * gauss(&mut rng));
        f.initialise(pos, 3e4, decade(&mut rng, 0.0, 4.0), 1e5)
            .unwrap();
        for step in 0..40 {
            let dt = decade(&mut rng, -2.0, 1.5);
            pos += vel * dt;
            f.predict(dt).unwrap();
            if let Some(why) = not_psd(f.covariance()) {
                panic!("EKF11, case {k}, step {step}, predict: {why}");
            }
            let n = rng.random_range(4..=12);
            for j in 0..n {
                let los = above(&mut rng, &up);
                let sat = pos + 2.0e7 * los;
                let system = if j % 2 == 0 { System::Gps } else { System::Bds };
                let sigma_m = decade(&mut rng, -1.0, 3.0);
                let m = RangeMeasurement {
                    emitter: EmitterId::new(system, j as u16 + 1),
                    emitter_pos_ecef_m: sat,
                    emitter_vel_ecef_mps: Vector3::from_fn(|_, _| 3000.0 * gauss(&mut rng)),
                    pseudorange_m: (sat - pos).norm() + 3e4 + sigma_m * gauss(&mut rng),
                    sigma_m,
                    range_rate_mps: rng.random_bool(0.5).then(|| gauss(&mut rng)),
                    sigma_rate_mps: decade(&mut rng, -3.0, 1.0),
                    cn0_dbhz: 40.0,
                    elevation_rad: 0.5,
                };
                let out = f.update_range(&m);
                total += 1;
                accepted += usize::from(out.range.is_accepted());
                if let Some(why) = not_psd(f.covariance()) {
                    panic!("EKF11, case {k}, step {step}, range {j}: {why}");
                }
            }
            if rng.random_bool(0.3) {
                let fix = PositionFix {
                    pos_ecef_m: pos + Vector3::from_fn(|_, _| 5.0 * gauss(&mut rng)),
                    cov_m2: spd::<3, _>(&mut rng, 25.0, 6.0),
                    support: 0,
                };
                let _ = f.update_position(&fix);
                if let Some(why) = not_psd(f.covariance()) {
                    panic!("EKF11, case {k}, step {step}, fix: {why}");
                }
            }
        }
    }
    // The property is only tested if the updates happen.
    assert!(
        accepted * 10 > total * 9,
        "{accepted} of {total} ranges used"
    );
}

/// The INS error-state filter (15 states) over 100 random cases: an IMU grade from phone
/// to navigation grade, 20 s of random rotation (up to 2 rad/s) and specific force (up to
/// 3 g) at 100 Hz, a position, velocity or joint fix every second with a random SPD
/// covariance whose eigenvalues span four decades.
#[test]
fn the_ins_error_state_covariance_stays_symmetric_psd() {
    use hybridnav::inertial::imu::{ImuConfig, ImuGrade};
    use hybridnav::inertial::ins_ekf::{InsEkf, InsEkfConfig};
    use hybridnav::inertial::strapdown::NavState;
    use hybridnav::inertial::LocalEarth;
    use hybridnav::measurement::ImuSample;
    use nalgebra::{UnitQuaternion, Vector3};
    for k in 0..100u64 {
        let mut rng = TrialRng::new(78, k).stream("test/psd/ins");
        let grade = [ImuGrade::Low, ImuGrade::Mid, ImuGrade::High][(k % 3) as usize];
        let cfg = InsEkfConfig::from_imu(&ImuConfig::grade(grade).resolve().unwrap());
        let earth = LocalEarth::new(rng.random::<f64>() * 1.4 - 0.7, 0.0);
        let start = NavState {
            t_s: 0.0,
            pos_enu_m: Vector3::zeros(),
            vel_enu_mps: Vector3::from_fn(|_, _| 5.0 * gauss(&mut rng)),
            q_nb: UnitQuaternion::from_euler_angles(
                0.2 * gauss(&mut rng),
                0.2 * gauss(&mut rng),
                3.0 * gauss(&mut rng),
            ),
        };
        let mut f = InsEkf::new(start, earth, &cfg);
        for step in 1..=2000 {
            let s = ImuSample {
                t_s: step as f64 * 0.01,
                gyro_rps: Vector3::from_fn(|_, _| 2.0 * (rng.random::<f64>() - 0.5) * 2.0),
                accel_mps2: Vector3::new(0.0, 0.0, 9.8)
                    + Vector3::from_fn(|_, _| 30.0 * (rng.random::<f64>() - 0.5)),
            };
            f.propagate(&s);
            if step % 100 != 0 {
                continue;
            }
            let cov = spd::<3, _>(&mut rng, 4.0, 4.0);
            let z = Vector3::from_fn(|_, _| 3.0 * gauss(&mut rng));
            let out = match step / 100 % 3 {
                0 => f.update_position(&(f.state().pos_enu_m + z), &cov),
                1 => f.update_velocity(&(f.state().vel_enu_mps + 0.1 * z), &(0.01 * cov)),
                _ => f.update_position_velocity(
                    &(f.state().pos_enu_m + z),
                    &cov,
                    &(f.state().vel_enu_mps + 0.1 * z),
                    &(0.01 * cov),
                ),
            };
            assert!(out.is_ok_and(|o| o.accepted), "case {k}, step {step}");
            if let Some(why) = not_psd(f.covariance()) {
                panic!("INS, case {k}, step {step}: {why}");
            }
        }
    }
}
