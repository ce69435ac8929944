//! The posterior Cramér–Rao lower bound of a world's estimators
//! ([`crate::fusion::pcrlb`]): their process model, the measurements the world gives them
//! at the truth, and the truth trajectories of the run's trials.
//!
//! # Seed 000's model
//!
//! An estimator on seed 000's 12-state model (`ekf11`, or the filter family without a
//! paper `[estimator.process]`) gets [`PvaClockBound`] with its own `[estimator.ekf]`
//! tuning. Its information at each instant is taken from the world's own receivers at the
//! true position, so that it is the information of the measurements the estimator is
//! actually given:
//!
//! - GNSS: the links [`GnssGeometry::epoch`] tracks at the truth — the broadcast
//!   ephemeris satellites of `[sensors.gnss]` systems above the mask, after the
//!   `[[shielding]]` windows, not lost in the scene, in lock at the scene's C/N0 — each a
//!   pseudorange with the σ the receiver reports (C/N0-dependent DLL noise, URE, the
//!   iono and tropo model residuals) and, when the receiver outputs them, a range rate
//!   with its C/N0-dependent FLL σ;
//! - DTMB: the towers the receiver holds at the truth, with the σ it reports
//!   ([`DtmbSource::noise_free_ranges`]: thermal σ at the correlation peak's SNR under
//!   the world's path loss, shadowing and scene, with the receiver's floor);
//! - TC-OFDM (seed 004): the base stations its receiver (the DTMB receiver on the
//!   stations' navigation signal) holds at the truth, with the σ it reports, the same way.
//!   Each station's synchronisation error (`sync_sigma_ns`) is a bias drawn once per
//!   trial and is left out, as the other persistent errors below.
//!
//! Those σ are the world's model evaluated at the truth (the C/N0 and SNR depend on where
//! the receiver is), and the errors are taken as white and independent with those σ — the
//! model every estimator here assumes. The world's actual errors are partly persistent
//! (the URE is a 30-minute Gauss–Markov process, the iono and tropo residual factors are
//! drawn once per trial) and carry NLOS biases the σ does not describe. Persistence keeps
//! information from accumulating over epochs, so the white model credits the estimator
//! with more than it has, which keeps the bound a floor; this is an argument, not a proof
//! (the trial-wide iono and tropo factors are correlated across satellites, and an
//! estimator that modelled them could absorb part of them in the clock), and the Monte
//! Carlo test in `tests/it/pcrlb000.rs` checks the result. The DTMB range shares the clock `b` with its tower's clock offset counted as known, and
//! every range of every tower and satellite is counted at every instant (a mode selection
//! or a DTMB clock calibration that withholds ranges, a χ² gate that rejects them, are
//! not modelled): both only add information, so both can only lower the bound.
//!
//! The PCRLB bounds the MSE averaged over the trajectories the process model draws; a
//! world's truth is one trajectory, and seed 000's (waypoint plans) is far gentler than a
//! white jerk of 1 m²/s⁵ on every ECEF axis. Where each epoch's own pseudoranges fix the
//! position and the clock, the bound is carried by the measurements; where they do not
//! (two or three satellites in a `[[shielding]]` window), it is carried by the model's
//! spread of trajectories, and an estimator on the gentler truth does far better (on the
//! Kehui world a GPS-only EKF has 31 m RMS during 150–180 s, the recursion 487 m). So
//! [`World::pcrlb`] reports the bound of an estimator only when every epoch, from its
//! first fix on, is determined by its own pseudoranges
//! ([`PvaClockBound::measurement_determined`]); [`World::pva_clock_pcrlb`] gives it either
//! way, flagged.
//!
//! What the bound cannot count it does not approximate: omitting information a
//! measurement carries would raise the "bound" above what an estimator that uses it can
//! reach, so it would no longer be a lower bound. An estimator that takes position fixes
//! (`fixes = ["fm"]`: a WKNN fingerprint fix is a nonlinear, database- and
//! aiding-dependent function of the RSSI scan, whose error is neither Gaussian nor of the
//! covariance it reports) therefore gets no bound (`None`). The ranges of
//! `[sensors.emitters]` are counted like the receivers' (each emitter's `‖r_j − r‖` with
//! its σ, at the emitters' instants `k/rate_hz`, `k ≥ 1`, outages excepted): their
//! noise is white and Gaussian with exactly that σ, and their clock terms are the
//! model's clock states.
//!
//! # The INS rows
//!
//! An INS estimator (`filter = "ins"`, seed 004's loosely and tightly coupled rows) gets
//! the bound of its own error model ([`crate::inertial::ins_bound`]: the 15- or 18-state
//! error dynamics evaluated along each trial's true attitude and specific force, driven by
//! the IMU noise the estimator assumes) with the information of the ranges its fixes take
//! from the same receivers held at the truth, the range rates when it uses them. Unlike
//! seed 000's model, whose white jerk stands for every trajectory and lets a gentle truth
//! beat the recursion, this model's randomness is the IMU's own noise along the given
//! trajectory, so the bound is computed trial by trial and needs no "determined" flag
//! beyond the first fix. The range rates describe the walker's path, while the IMU also
//! moves with the gait (a quarter of a metre per second vertically); the bound takes the
//! estimator's `fix_velocity_noise_mps` as the velocity they do not describe, as the
//! estimator does ([`InsBound::with_velocity_noise`]).

use super::World;
use crate::beacons::ResolvedEmitter;
use crate::core::{SimTime, System, TrialRng};
use crate::dtmb::DtmbSource;
use crate::engine::trial::truth_at;
use crate::fusion::ekf11::Ekf11Config;
use crate::fusion::paper::ProcessSpec;
use crate::fusion::pcrlb::{PaperBound, PvaClockBound, DETERMINED_POS_MSE_M2};
use crate::gnss::measurement::{GnssGeometry, LinkGeometry};
use crate::inertial::attitude::PlatformTruth;
use crate::inertial::imu::ImuConfig;
use crate::inertial::ins_bound::{truth_dynamics, BoundCoupling, EpochInfo, InsBound};
use crate::inertial::ins_ekf::InsEkfConfig;
use crate::inertial::ins_estimator::{InsCoupling, InsEstimator};
use crate::inertial::ins_tight::TightClockConfig;
use crate::inertial::source::local_earth_of;
use crate::inertial::LocalEarth;
use crate::measurement::SourceKind;
use crate::measurement::{RangeMeasurement, Truth};
use crate::tcofdm::TcofdmSource;
use crate::world::schema::EstimatorSpec;
use crate::world::schema::FilterKind;
use std::sync::Arc;

/// The PCRLB of one estimator's model over a run: its position-RMSE bound at every epoch
/// and over the run.
#[derive(Clone, Debug, PartialEq)]
pub struct PositionBound {
    /// The square root of the epoch-averaged trace of the bound's position block (m): the
    /// figure `summary.json` reports as `pcrlb_pos_rmse_m`.
    pub rmse_m: f64,
    /// `(t_s, bound_m)` at every epoch (paper models: `t_s = (k + 1)·Δt` of the emitters'
    /// rate; seed 000's model: every instant a GNSS or DTMB batch arrives, from the first
    /// at which the position is determined): the square
    /// root of the trace of the position block at that epoch, the floor under an RMSE
    /// taken across trials at that instant.
    pub by_epoch: Vec<(f64, f64)>,
}

impl PositionBound {
    /// The bound of `(t_s, bound_m)` epochs, its RMSE the root of their mean square;
    /// `None` for no epoch or a mean that is not finite.
    fn from_epochs(by_epoch: Vec<(f64, f64)>) -> Option<Self> {
        if by_epoch.is_empty() {
            return None;
        }
        let mean = by_epoch.iter().map(|(_, b)| b * b).sum::<f64>() / by_epoch.len() as f64;
        (mean.is_finite() && mean >= 0.0).then(|| PositionBound {
            rmse_m: mean.sqrt(),
            by_epoch,
        })
    }
}

/// The PCRLB of an estimator on seed 000's model ([`World::pva_clock_pcrlb`]).
#[derive(Clone, Debug, PartialEq)]
pub struct PvaClockPositionBound {
    pub bound: PositionBound,
    /// [`PvaClockBound::measurement_determined`]: every epoch's pseudoranges fix the
    /// position and the clock on their own, so the bound is carried by the measurements
    /// rather than by the process model's spread of trajectories.
    pub measurement_determined: bool,
}

impl World {
    /// The bound on the position RMSE (m) of each estimator, in the world's order
    /// ([`PositionBound::rmse_m`] of [`World::pcrlb`]).
    pub fn pcrlb_pos_rmse_m(&self, seed: u64, trials: u64) -> Vec<Option<f64>> {
        self.pcrlb(seed, trials)
            .into_iter()
            .map(|b| b.map(|b| b.rmse_m))
            .collect()
    }

    /// The PCRLB of each estimator's model, in the world's order, with the measurement
    /// information averaged over the truth trajectories of trials `0..trials` of `seed`.
    /// The paper models are bounded on the world's `[sensors.emitters]`
    /// ([`World::paper_pcrlb`]), seed 000's 12-state model on the world's GNSS and DTMB
    /// receivers ([`World::pva_clock_pcrlb`], see the module documentation), the INS error
    /// models along the truth on the same receivers ([`World::ins_pcrlb`]). `None` for an
    /// estimator whose model no bound covers (PDR, WLS) or whose measurements the bound
    /// cannot count.
    pub fn pcrlb(&self, seed: u64, trials: u64) -> Vec<Option<PositionBound>> {
        let mut out = self.paper_pcrlb(seed, trials);
        for (slot, b) in out.iter_mut().zip(self.pva_clock_pcrlb(seed, trials)) {
            if let Some(b) = b.filter(|b| b.measurement_determined) {
                if slot.is_none() {
                    *slot = Some(b.bound);
                }
            }
        }
        for (slot, b) in out.iter_mut().zip(self.ins_pcrlb(seed, trials)) {
            if slot.is_none() {
                *slot = b;
            }
        }
        out
    }

    /// The PCRLB of each paper estimator ([`PaperBound`]), `None` for the others or a
    /// world without `[sensors.emitters]`. Every emitter of the estimator's systems is
    /// counted at every epoch (outages excepted): a mode selection that drops ranges is
    /// not modelled.
    pub fn paper_pcrlb(&self, seed: u64, trials: u64) -> Vec<Option<PositionBound>> {
        let n_est = self.file.estimators.len();
        let Some(cfg) = self.file.sensors.emitters.as_ref() else {
            return vec![None; n_est];
        };
        let Ok(emitters) = cfg.resolve(&self.frame) else {
            return vec![None; n_est];
        };
        let dt_s = 1.0 / cfg.rate_hz;
        let epochs = (self.duration_s / dt_s + 1e-9).floor() as usize;
        let trajectories: Vec<_> = (0..trials.max(1))
            .filter_map(|i| self.build_trajectory(&TrialRng::new(seed, i)).ok())
            .collect();
        if trajectories.is_empty() || epochs == 0 {
            return vec![None; n_est];
        }
        let plane_up_m = trajectories[0].state_at(0.0).pos_enu_m.z;
        let mut ranges = Vec::with_capacity(emitters.len());
        self.file
            .estimators
            .iter()
            .map(|e| {
                let spec = e.process.as_ref()?;
                if *spec == (ProcessSpec::PvaClock {}) {
                    return None;
                }
                let mut bound = PaperBound::new(spec, dt_s, epochs, plane_up_m).ok()?;
                for traj in &trajectories {
                    for k in 0..epochs {
                        let t_s = SimTime::from_seconds((k + 1) as f64 * dt_s).seconds();
                        let truth = traj.state_at(t_s).pos_enu_m;
                        ranges.clear();
                        for em in &emitters {
                            let sys = em.id.system;
                            let out = em.in_outage(t_s);
                            if e.sources.contains(&sys) && !out {
                                ranges.push((em.pos_enu_m, sys, em.sigma_m));
                            }
                        }
                        bound.add(k, &truth, &ranges);
                    }
                }
                let mse = bound.position_mse_m2().ok()?;
                let mean = mse.iter().sum::<f64>() / mse.len() as f64;
                (mean.is_finite() && mean >= 0.0).then(|| PositionBound {
                    rmse_m: mean.sqrt(),
                    by_epoch: mse
                        .iter()
                        .enumerate()
                        .map(|(k, m)| {
                            let t_s = SimTime::from_seconds((k + 1) as f64 * dt_s).seconds();
                            (t_s, m.max(0.0).sqrt())
                        })
                        .collect(),
                })
            })
            .collect()
    }

    /// The PCRLB of each estimator on seed 000's 12-state model ([`PvaClockBound`], see
    /// the module documentation), whether or not its epochs' ranges determine the
    /// position ([`World::pcrlb`] reports it only when they do); `None` for the other
    /// estimators and for those whose measurements it cannot count. A deterministic truth
    /// (a waypoint plan) is the same in every trial, so its information is computed once.
    pub fn pva_clock_pcrlb(&self, seed: u64, trials: u64) -> Vec<Option<PvaClockPositionBound>> {
        let n_est = self.file.estimators.len();
        let end = SimTime::from_seconds(self.duration_s);
        let instants_ns = self.measurement_instants_ns(end);
        let instants_s: Vec<f64> = instants_ns.iter().map(|&t| SimTime(t).seconds()).collect();
        let mut bounds: Vec<Option<PvaClockBound>> = self
            .file
            .estimators
            .iter()
            .map(|e| {
                let cfg = self.pva_clock_config(e)?;
                PvaClockBound::new(cfg, &e.sources, instants_s.clone()).ok()
            })
            .collect();
        if instants_s.is_empty() || bounds.iter().all(Option::is_none) {
            return vec![None; n_est];
        }
        let n_traj = if self.truth_is_deterministic() {
            1
        } else {
            trials.max(1)
        };
        let mut mine: Vec<RangeMeasurement> = Vec::with_capacity(64);
        let mut used = 0usize;
        for i in 0..n_traj {
            let rng = TrialRng::new(seed, i);
            let Ok(trajectory) = self.build_trajectory(&rng) else {
                continue;
            };
            let Ok(mut rx) = self.truth_receivers(&rng, end) else {
                return vec![None; n_est];
            };
            for (k, &t_ns) in instants_ns.iter().enumerate() {
                let truth = truth_at(&self.frame, self.start, trajectory.as_ref(), SimTime(t_ns));
                rx.sample(t_ns, &truth);
                for (e, bound) in self.file.estimators.iter().zip(bounds.iter_mut()) {
                    let Some(bound) = bound.as_mut() else {
                        continue;
                    };
                    if rx.epoch_of(|s| e.sources.contains(&s), &mut mine) {
                        bound.add(k, &truth.pos_ecef_m, &truth.vel_ecef_mps, &mine);
                    }
                }
            }
            for bound in bounds.iter_mut().flatten() {
                bound.end_trial();
            }
            used += 1;
        }
        if used == 0 {
            return vec![None; n_est];
        }
        bounds
            .into_iter()
            .map(|b| {
                let b = b?;
                let determined = b.measurement_determined();
                let mse = b.position_mse_m2().ok()?;
                let by_epoch: Vec<(f64, f64)> = b
                    .instants_s()
                    .iter()
                    .zip(&mse)
                    .filter_map(|(t, m)| m.map(|m| (*t, m.max(0.0).sqrt())))
                    .collect();
                PositionBound::from_epochs(by_epoch).map(|bound| PvaClockPositionBound {
                    bound,
                    measurement_determined: determined,
                })
            })
            .collect()
    }

    /// The instants (ns of simulation time) at which the GNSS, DTMB and TC-OFDM receivers
    /// sample, from 0 to `end`.
    fn measurement_instants_ns(&self, end: SimTime) -> Vec<i64> {
        let sensors = &self.file.sensors;
        let mut instants_ns: Vec<i64> = Vec::new();
        let mut add_grid = |step_ns: i64| {
            let mut t = 0i64;
            while t <= end.0 {
                instants_ns.push(t);
                t += step_ns.max(1);
            }
        };
        if let Some(g) = &sensors.gnss {
            add_grid(GnssGeometry::step_ns(g.rate_hz));
        }
        if let Some(d) = &sensors.dtmb {
            add_grid(((1e9 / d.rate_hz).round() as i64).max(1));
        }
        if let Some(tc) = &sensors.tcofdm {
            add_grid(((1e9 / tc.rate_hz).round() as i64).max(1));
        }
        if let Some(em) = &sensors.emitters {
            // The emitters' first sample is one period after the start.
            let step_ns = em.period_ns();
            let mut t = step_ns;
            while t <= end.0 {
                instants_ns.push(t);
                t += step_ns;
            }
        }
        instants_ns.sort_unstable();
        instants_ns.dedup();
        instants_ns
    }

    /// The world's GNSS, DTMB and TC-OFDM receivers and emitters of trial `rng`, to be
    /// held at the truth ([`TruthReceivers`]).
    fn truth_receivers(&self, rng: &TrialRng, end: SimTime) -> Result<TruthReceivers, String> {
        let sensors = &self.file.sensors;
        let gnss = sensors.gnss.as_ref().map(|g| {
            GnssGeometry::new(
                g,
                Arc::clone(&self.nav),
                self.shielding.clone(),
                self.gnss_scene_view(),
            )
        });
        let clock = Arc::new(self.receiver_clock(rng));
        let dtmb = self.dtmb_source(Arc::clone(&clock), None, rng, end)?;
        let tcofdm = self.tcofdm_source(clock, None, rng, end)?;
        let emitters = match &sensors.emitters {
            Some(cfg) => Some((
                cfg.resolve(&self.frame).map_err(|e| e.to_string())?,
                cfg.period_ns(),
            )),
            None => None,
        };
        Ok(TruthReceivers {
            gnss_step: sensors
                .gnss
                .as_ref()
                .map(|g| GnssGeometry::step_ns(g.rate_hz)),
            range_rates: sensors.gnss.as_ref().is_some_and(|g| g.range_rates),
            dtmb_step: dtmb.as_ref().map(DtmbSource::period_ns),
            tcofdm_step: tcofdm.as_ref().map(TcofdmSource::period_ns),
            gnss,
            dtmb,
            tcofdm,
            links: Vec::with_capacity(64),
            gnss_ranges: Vec::with_capacity(64),
            dtmb_ranges: Vec::with_capacity(8),
            tcofdm_ranges: Vec::with_capacity(8),
            emitter_ranges: Vec::with_capacity(emitters.as_ref().map_or(0, |e| e.0.len())),
            emitters,
            now: [false; 4],
        })
    }

    /// The PCRLB of each INS estimator ([`InsBound`], see its module documentation), in
    /// the world's order; `None` for the other estimators, for an INS that takes fixes the
    /// bound cannot count (FM, magnetic landmarks) and for a world without an IMU. The
    /// bound is computed along each trial's truth (the walker's gait differs from trial to
    /// trial) and its mean square averaged over trials `0..trials` of `seed`; it is
    /// reported from the first instant at which the position is determined
    /// ([`DETERMINED_POS_MSE_M2`]). Estimators with one error model, coupling and set of
    /// ranges (seed 004's four Kalman filters) share one computation.
    pub fn ins_pcrlb(&self, seed: u64, trials: u64) -> Vec<Option<PositionBound>> {
        let n_est = self.file.estimators.len();
        let Some(imu) = self.file.sensors.imu.as_ref() else {
            return vec![None; n_est];
        };
        let Ok(spec) = imu.resolve() else {
            return vec![None; n_est];
        };
        let earth = local_earth_of(&self.frame);
        // One model per distinct bound; each estimator points at its model.
        let mut models: Vec<InsModel> = Vec::new();
        let slots: Vec<Option<usize>> = self
            .file
            .estimators
            .iter()
            .map(|e| {
                let model = self.ins_model(e, imu, earth)?;
                let at = models.iter().position(|m| m.same_bound(&model));
                Some(at.unwrap_or_else(|| {
                    models.push(model);
                    models.len() - 1
                }))
            })
            .collect();
        if models.is_empty() {
            return vec![None; n_est];
        }
        let end = SimTime::from_seconds(self.duration_s);
        let instants_ns = self.measurement_instants_ns(end);
        let mut mse_sum = vec![vec![0.0f64; instants_ns.len()]; models.len()];
        let mut used = 0usize;
        let mut mine: Vec<RangeMeasurement> = Vec::with_capacity(64);
        let imu_step_s = 1.0 / spec.rate_hz;
        for i in 0..trials.max(1) {
            let rng = TrialRng::new(seed, i);
            // The body truth owns the trial's trajectory; the engine's truth is its path.
            let Ok(path) = self.build_trajectory(&rng) else {
                continue;
            };
            let Ok(body) = PlatformTruth::of_trial(path, &self.file.platform.attitude(), &rng)
            else {
                continue;
            };
            let Ok(mut rx) = self.truth_receivers(&rng, end) else {
                return vec![None; n_est];
            };
            let mut states: Vec<_> = models.iter().map(|m| m.bound.start(0.0)).collect();
            let mut k_imu = 1u64;
            for (k, &t_ns) in instants_ns.iter().enumerate() {
                let t_s = SimTime(t_ns).seconds();
                // The IMU samples up to this instant, then the rest of the way to it.
                loop {
                    let t_imu = (k_imu as f64 * imu_step_s).min(t_s);
                    if t_imu <= states[0].t_s {
                        break;
                    }
                    let b = body.sample(t_imu);
                    let (c, f_n) = truth_dynamics(&earth, &b);
                    for (m, st) in models.iter().zip(states.iter_mut()) {
                        m.bound.predict(st, t_imu, &c, &f_n, b.pos_enu_m.z);
                    }
                    if k_imu as f64 * imu_step_s <= t_s {
                        k_imu += 1;
                    }
                }
                let truth = truth_at(&self.frame, self.start, body.trajectory(), SimTime(t_ns));
                rx.sample(t_ns, &truth);
                for ((m, st), sum) in models.iter().zip(states.iter_mut()).zip(mse_sum.iter_mut()) {
                    if rx.epoch_of(|s| m.ranges.contains(&s), &mut mine) {
                        let mut info = EpochInfo::zeros();
                        m.bound.add_epoch_information(
                            &mut info,
                            &truth.pos_ecef_m,
                            &truth.vel_ecef_mps,
                            &mine,
                            m.rates,
                        );
                        m.bound.update(st, &m.bound.information(&info));
                    }
                    sum[k] += st.position_mse_m2();
                }
            }
            used += 1;
        }
        if used == 0 {
            return vec![None; n_est];
        }
        let bounds: Vec<Option<PositionBound>> = mse_sum
            .iter()
            .map(|sum| {
                let mut determined = false;
                let by_epoch = instants_ns
                    .iter()
                    .zip(sum)
                    .filter_map(|(&t, &s)| {
                        let mse = s / used as f64;
                        determined |= mse < DETERMINED_POS_MSE_M2;
                        determined.then(|| (SimTime(t).seconds(), mse.max(0.0).sqrt()))
                    })
                    .collect();
                PositionBound::from_epochs(by_epoch)
            })
            .collect();
        slots
            .iter()
            .map(|s| s.and_then(|i| bounds[i].clone()))
            .collect()
    }

    /// The bound model of an INS estimator, or `None` for another estimator or an INS
    /// whose fixes the bound cannot count.
    fn ins_model(&self, e: &EstimatorSpec, imu: &ImuConfig, earth: LocalEarth) -> Option<InsModel> {
        if e.filter != FilterKind::Ins {
            return None;
        }
        let est = InsEstimator::new(
            &e.name,
            &e.ins.clone().unwrap_or_default(),
            imu,
            &e.sources,
            &self.frame,
            self.start,
        )
        .ok()?;
        let cfg = est.config();
        let mut ranges = Vec::new();
        for kind in &cfg.fix_sources {
            let systems: &[System] = match kind {
                SourceKind::Gnss => &[System::Gps, System::Bds],
                SourceKind::Dtmb => &[System::Dtmb],
                SourceKind::Tcofdm => &[System::Tcofdm],
                _ => return None,
            };
            ranges.extend(systems.iter().filter(|s| e.sources.contains(s)));
        }
        let coupling = match cfg.coupling {
            InsCoupling::Loose => BoundCoupling::Loose,
            InsCoupling::Tight => BoundCoupling::Tight(TightClockConfig::default()),
        };
        let tilt_rad = cfg.init_tilt_sigma_deg.to_radians();
        Some(InsModel {
            bound: InsBound::new(
                est.error_model(),
                tilt_rad,
                coupling,
                earth,
                *self.frame.rotation(),
            )
            .with_velocity_noise(cfg.fix_velocity_noise_mps),
            key: (
                *est.error_model(),
                tilt_rad,
                coupling,
                cfg.fix_velocity_noise_mps,
            ),
            ranges,
            rates: cfg.use_gnss_velocity,
        })
    }

    /// The tuning of seed 000's model an estimator runs, or `None` when it does not run
    /// that model or takes position fixes, which the bound cannot count (see the module
    /// documentation).
    fn pva_clock_config(&self, e: &EstimatorSpec) -> Option<Ekf11Config> {
        (e.runs_pva_clock() && e.fixes.is_empty()).then(|| e.ekf.unwrap_or_default())
    }
}

/// The world's GNSS, DTMB and TC-OFDM receivers and emitters of one trial held at the
/// truth: at each instant, the ranges each gives there with the σ it reports (see the
/// module documentation), and whether each had a batch. Reuses its buffers.
struct TruthReceivers {
    gnss: Option<GnssGeometry>,
    gnss_step: Option<i64>,
    range_rates: bool,
    dtmb: Option<DtmbSource>,
    dtmb_step: Option<i64>,
    tcofdm: Option<TcofdmSource>,
    tcofdm_step: Option<i64>,
    links: Vec<LinkGeometry>,
    gnss_ranges: Vec<RangeMeasurement>,
    dtmb_ranges: Vec<RangeMeasurement>,
    tcofdm_ranges: Vec<RangeMeasurement>,
    /// `[sensors.emitters]`, resolved, and their period (ns).
    emitters: Option<(Vec<ResolvedEmitter>, i64)>,
    emitter_ranges: Vec<RangeMeasurement>,
    /// Whether the GNSS, DTMB and TC-OFDM receivers and the emitters had a batch at the
    /// last instant.
    now: [bool; 4],
}

impl TruthReceivers {
    /// The receivers at simulation time `t_ns` and the truth there.
    fn sample(&mut self, t_ns: i64, truth: &Truth) {
        let due = |step: Option<i64>| step.is_some_and(|s| t_ns % s == 0);
        self.now = [
            due(self.gnss_step),
            due(self.dtmb_step),
            due(self.tcofdm_step),
            t_ns > 0 && due(self.emitters.as_ref().map(|e| e.1)),
        ];
        self.gnss_ranges.clear();
        if let (Some(geo), true) = (self.gnss.as_mut(), self.now[0]) {
            self.links.clear();
            geo.epoch(truth, &mut self.links);
            let rates = self.range_rates;
            self.gnss_ranges
                .extend(self.links.iter().map(|l| RangeMeasurement {
                    emitter: geo.satellites()[l.channel as usize],
                    emitter_pos_ecef_m: l.pos_ecef_m,
                    emitter_vel_ecef_mps: l.vel_ecef_mps,
                    pseudorange_m: l.range_m,
                    sigma_m: l.sigma_m,
                    range_rate_mps: rates.then_some(l.geometric_rate_mps),
                    sigma_rate_mps: l.sigma_rate_mps,
                    cn0_dbhz: l.cn0_dbhz,
                    elevation_rad: l.el_rad,
                }));
        }
        self.dtmb_ranges.clear();
        if let (Some(d), true) = (self.dtmb.as_mut(), self.now[1]) {
            d.noise_free_ranges(truth, &mut self.dtmb_ranges);
        }
        self.tcofdm_ranges.clear();
        if let (Some(tc), true) = (self.tcofdm.as_mut(), self.now[2]) {
            tc.noise_free_ranges(truth, &mut self.tcofdm_ranges);
        }
        self.emitter_ranges.clear();
        if let (Some((emitters, _)), true) = (self.emitters.as_ref(), self.now[3]) {
            let t_s = SimTime(t_ns).seconds();
            // Only the geometry and σ enter the information: the geometric range stands
            // for the pseudorange, without the source's clock terms and noise.
            self.emitter_ranges
                .extend(emitters.iter().filter(|e| !e.in_outage(t_s)).map(|e| {
                    let range_m = (e.pos_ecef_m - truth.pos_ecef_m).norm();
                    e.range_measurement(&truth.pos_ecef_m, range_m)
                }));
        }
    }

    /// Whether the last instant is an epoch of an estimator that uses the systems `uses`
    /// accepts (a batch of one of its sources arrived, even an empty one); its ranges of
    /// those systems into `out`.
    fn epoch_of(&self, uses: impl Fn(System) -> bool, out: &mut Vec<RangeMeasurement>) -> bool {
        let epoch = (self.now[0] && (uses(System::Gps) || uses(System::Bds)))
            || (self.now[1] && uses(System::Dtmb))
            || (self.now[2] && uses(System::Tcofdm))
            || (self.now[3]
                && self
                    .emitters
                    .as_ref()
                    .is_some_and(|(emitters, _)| emitters.iter().any(|e| uses(e.id.system))));
        out.clear();
        if epoch {
            out.extend(
                self.gnss_ranges
                    .iter()
                    .chain(&self.dtmb_ranges)
                    .chain(&self.tcofdm_ranges)
                    .chain(&self.emitter_ranges)
                    .filter(|m| uses(m.system()))
                    .copied(),
            );
        }
        epoch
    }
}

/// An INS estimator's bound ([`World::ins_pcrlb`]): the model, what distinguishes it from
/// another, and the ranges it counts.
struct InsModel {
    bound: InsBound,
    key: (InsEkfConfig, f64, BoundCoupling, [f64; 2]),
    /// The systems whose ranges the estimator's fixes (or tight updates) take.
    ranges: Vec<System>,
    /// Whether it takes the GNSS range rates.
    rates: bool,
}

impl InsModel {
    fn same_bound(&self, other: &InsModel) -> bool {
        self.key == other.key && self.ranges == other.ranges && self.rates == other.rates
    }
}
