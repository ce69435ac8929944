//! The reduction of a run's trials to its summary, one trial at a time.
//!
//! A run of 10 000 trials must not hold 10 000 trials: [`RunReducer`] takes them in trial
//! order and keeps only what the summary needs. Sums and counts are accumulated in trial
//! order (so the result does not depend on how many trials were in memory at once); the
//! errors whose exact percentiles the summary reports go to a [`SortedSpill`], which keeps
//! a bounded number of them in memory and sorts the rest on disk; per-epoch NEES and NIS
//! keep one running sum per epoch time; the across-trial confidence intervals keep a
//! running mean and variance (Welford). Nothing grows with the number of trials.

use super::{AcrossTrials, EstimatorSummary, FailureEpoch, RunOptions, Summary};
use crate::engine::trial::{EstimatorTrace, TrialResult};
use crate::io::spill::SortedSpill;
use crate::metrics::summary::SegmentStats;
use crate::metrics::{
    ate_errors, ecdf_of, positive_ci95, rpe_errors, summary_of_samples, unit_ci95, Alignment,
    EpochSamples, ErrorStats, MeanCi95, TrajectoryStats,
};
use crate::world::World;
use nalgebra::Vector3;
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// Numerical-failure epochs listed per estimator in the summary (all are counted).
pub const FAILURES_LISTED: usize = 20;

/// Points of each error CDF kept for the report.
pub const CDF_POINTS: usize = 400;

/// What a finished reduction gives: the summary, and what the report draws besides it.
pub struct Reduced {
    pub summary: Summary,
    /// The first trial reduced (trial 0 of a whole run): the report draws its trajectories.
    pub first: Option<TrialResult>,
    /// The curves the report draws from every trial, not only the first.
    pub curves: crate::report::Curves,
}

/// Accumulates trials, in trial order, into a [`Summary`].
pub struct RunReducer {
    estimators: Vec<EstimatorAcc>,
    warnings: BTreeSet<String>,
    first: Option<TrialResult>,
    last_trial: Option<u64>,
    /// The world's RPE interval (s), which every estimator's RPE uses.
    rpe_delta_s: f64,
    /// Tells indoor truth from outdoor (worlds with a scene).
    places: Option<Places>,
}

/// Where the truth of an epoch was: indoors (inside a building or an indoor zone of the
/// world's scene) or outdoors. Papers that test indoors and out state their accuracy for
/// each (seed 004: "indoor better than 1 m, outdoor 0.5 m"), so each estimator's errors
/// are also reduced per place.
struct Places {
    scene: std::sync::Arc<crate::propagation::Scene>,
    frame: crate::core::geodesy::EnuFrame,
}

impl Places {
    /// The world's places, when it has a scene (a truth that never goes indoors gives
    /// no split, [`EstimatorAcc::finish`]).
    fn of(world: &World) -> Option<Self> {
        world.scene.as_ref().map(|scene| Self {
            scene: scene.clone(),
            frame: world.frame.clone(),
        })
    }

    fn indoor(&self, truth_ecef_m: &[f64; 3]) -> bool {
        let enu = self.frame.enu_of_ecef(&Vector3::from(*truth_ecef_m));
        self.scene.indoor_at(&enu).is_some()
    }
}

impl RunReducer {
    /// A reducer for `world`'s estimators whose spilled errors go to `spill_dir`.
    pub fn new(world: &World, spill_dir: &Path) -> Self {
        Self::with_chunk(world, spill_dir, crate::io::spill::DEFAULT_CHUNK)
    }

    /// As [`RunReducer::new`], keeping `chunk` errors per metric in memory before a
    /// sorted run is spilled to disk (tests use tiny chunks).
    pub fn with_chunk(world: &World, spill_dir: &Path, chunk: usize) -> Self {
        // The coast limit and the RPE interval do not depend on the trial's sources (only
        // the default instants do).
        let scoring = world.scoring(std::iter::empty());
        let (coast_limit_s, rpe_delta_s) = (scoring.coast_limit_s, scoring.rpe_delta_s);
        let segments = segments_of(world);
        Self {
            estimators: world
                .file
                .estimators
                .iter()
                .map(|e| {
                    let mut acc = EstimatorAcc::new(&e.name, spill_dir, chunk);
                    acc.coast_limit_s = coast_limit_s;
                    acc.rpe_delta_s = rpe_delta_s;
                    acc.nees_dof = e.process.as_ref().map_or(3, |p| p.position_dof()) as f64;
                    acc.nees_dof_restarted = e
                        .process
                        .as_ref()
                        .map_or(3, |p| p.position_dof_after_restart())
                        as f64;
                    acc.segments = segments
                        .iter()
                        .map(|(label, window_s)| SegmentAcc {
                            window_s: *window_s,
                            ..SegmentAcc::new(label, spill_dir, chunk)
                        })
                        .collect();
                    acc
                })
                .collect(),
            warnings: BTreeSet::new(),
            first: None,
            last_trial: None,
            rpe_delta_s,
            places: Places::of(world),
        }
    }

    /// Adds the next trial.
    ///
    /// # Errors
    /// When trials come out of order (a bug), or spilled errors cannot be written (a
    /// full disk: the message names the file).
    pub fn push(&mut self, t: &TrialResult) -> Result<(), String> {
        if self.last_trial.is_some_and(|l| t.trial <= l) {
            return Err(format!(
                "internal: trial {} reduced after trial {:?}; trials must come in order",
                t.trial, self.last_trial
            ));
        }
        self.last_trial = Some(t.trial);
        for (k, acc) in self.estimators.iter_mut().enumerate() {
            if let Some(trace) = t.estimators.get(k) {
                acc.push(t.trial, trace, self.places.as_ref())
                    .map_err(|e| e.to_string())?;
            }
        }
        self.warnings.extend(t.warnings.iter().cloned());
        if self.first.is_none() {
            self.first = Some(t.clone());
        }
        Ok(())
    }

    /// The summary of every trial pushed.
    ///
    /// # Errors
    /// When spilled errors cannot be read back.
    pub fn finish(self, world: &World, opts: &RunOptions) -> Result<Reduced, String> {
        let mut estimators = Vec::with_capacity(self.estimators.len());
        let mut curves = crate::report::Curves::default();
        // The PCRLB of each estimator's model over the run's truth trajectories
        // (world::bound), and each estimator's efficiency against it.
        let mut bounds = world.pcrlb(opts.seed, opts.trials);
        let rpe_delta_s = self.rpe_delta_s;
        let mut warnings = self.warnings;
        for (i, acc) in self.estimators.into_iter().enumerate() {
            if acc.ate.len() > 1 && acc.rpe.is_empty() {
                warnings.insert(format!(
                    "estimator \"{}\": no two of its scored estimates are {rpe_delta_s} s apart, \
                     so it has no RPE ([scoring] rpe_delta_s should be a multiple of the \
                     interval between scoring instants)",
                    acc.name
                ));
            }
            let (mut s, cdf, rmse_vs_time) = acc.finish().map_err(|e| e.to_string())?;
            if let Some(p) = world.comparison.protocols.get(i) {
                s.protocol = p.clone();
            }
            let bound = bounds.get_mut(i).and_then(Option::take);
            s.pcrlb_pos_rmse_m = bound.as_ref().map(|b| b.rmse_m);
            curves.pcrlb_vs_time.push(bound.map(|b| b.by_epoch));
            curves.rmse_vs_time.push(rmse_vs_time);
            s.efficiency = s
                .pcrlb_pos_rmse_m
                .zip(s.error_3d_m.as_ref().map(|x| x.rmse))
                .filter(|(b, _)| *b > 0.0)
                .map(|(b, rmse)| rmse / b);
            estimators.push(s);
            curves.cdfs.push(cdf);
        }
        Ok(Reduced {
            summary: Summary {
                hybridnav_version: env!("CARGO_PKG_VERSION").to_string(),
                world: world.file.world.name.clone(),
                world_file: world.path.display().to_string(),
                world_hash: world.hash.clone(),
                seed: opts.seed,
                trials: opts.trials,
                shard: (!opts.shard.is_whole()).then(|| opts.shard.to_string()),
                duration_s: world.duration_s,
                rpe_delta_s,
                estimators,
                warnings: warnings.into_iter().collect(),
            },
            first: self.first,
            curves,
        })
    }
}

/// The errors of one segment of the time line ([`SegmentStats`]): the 3-D errors for
/// their percentiles, the horizontal ones as a running sum of squares.
struct SegmentAcc {
    label: String,
    window_s: Option<[f64; 2]>,
    e3: SortedSpill,
    n: usize,
    sum_eh_m2: f64,
}

impl SegmentAcc {
    fn new(label: &str, dir: &Path, chunk: usize) -> Self {
        Self {
            label: label.to_string(),
            window_s: None,
            e3: SortedSpill::with_chunk(dir, chunk),
            n: 0,
            sum_eh_m2: 0.0,
        }
    }

    fn contains(&self, t_s: f64) -> bool {
        self.window_s.is_some_and(|[a, b]| t_s >= a && t_s < b)
    }

    fn add(&mut self, e3: f64, eh: f64) -> std::io::Result<()> {
        self.n += 1;
        self.sum_eh_m2 += eh * eh;
        self.e3.push(e3)
    }

    fn finish(mut self) -> std::io::Result<SegmentStats> {
        // As for the whole run: a non-finite error withholds the statistics.
        let finite = self.e3.non_finite() == 0 && self.sum_eh_m2.is_finite();
        Ok(SegmentStats {
            error_3d_m: if finite {
                ErrorStats::from_sorted(&mut self.e3)?
            } else {
                None
            },
            rmse_h_m: (finite && self.n > 0).then(|| (self.sum_eh_m2 / self.n as f64).sqrt()),
            label: self.label,
            window_s: self.window_s,
            epochs: self.n,
        })
    }
}

/// The world's `[[shielding]]` windows in time order, then the epochs outside all of them
/// (labels and windows; none for a world without windows).
fn segments_of(world: &World) -> Vec<(String, Option<[f64; 2]>)> {
    let mut windows: Vec<_> = world.file.shielding.iter().collect();
    if windows.is_empty() {
        return Vec::new();
    }
    windows.sort_by(|a, b| {
        a.from_s
            .total_cmp(&b.from_s)
            .then(a.to_s.total_cmp(&b.to_s))
    });
    let mut v: Vec<(String, Option<[f64; 2]>)> = windows
        .iter()
        .map(|w| {
            let what = match (&w.keep_highest, &w.keep, &w.block) {
                (Some(n), _, _) => format!(" ({n} per system)"),
                (None, Some(k), _) => format!(" ({} kept)", k.len()),
                (None, None, Some(b)) => format!(" ({} blocked)", b.len()),
                _ => String::new(),
            };
            (
                format!("{}–{} s{what}", w.from_s, w.to_s),
                Some([w.from_s, w.to_s]),
            )
        })
        .collect();
    v.push(("outside shielding".to_string(), None));
    v
}

/// One estimator's running reduction.
struct EstimatorAcc {
    name: String,
    e3: SortedSpill,
    eh: SortedSpill,
    ate: SortedSpill,
    ate_al: SortedSpill,
    rpe: SortedSpill,
    rpe_al: SortedSpill,
    epochs: usize,
    without: usize,
    /// Epochs with an estimate whose estimator had used no measurement at that instant
    /// (within the coast limit), and epochs with one older than the limit.
    coasting: usize,
    stale: usize,
    coast_limit_s: f64,
    /// The RPE interval Δ (s), the world's `[scoring] rpe_delta_s`.
    rpe_delta_s: f64,
    failures: usize,
    gated: u64,
    first_failures: Vec<FailureEpoch>,
    nees_sum: f64,
    nees_n: usize,
    /// The degrees of freedom of the position NEES (1 for seed 001's plane, whose x is
    /// known), and after the estimator's first reset in a trial (a restart from least
    /// squares can leave an axis in error that the prior knew exactly).
    nees_dof: f64,
    nees_dof_restarted: f64,
    modes: BTreeMap<String, usize>,
    moded: usize,
    /// Per epoch time (its bits: positive times order as their bits do), across trials.
    nees_by_t: BTreeMap<u64, EpochSamples>,
    nis_by_t: BTreeMap<u64, EpochSamples>,
    /// Per epoch time (its bits), the sum of the squared 3-D errors across trials and
    /// the number of trials in it.
    sq_err_by_t: BTreeMap<u64, (f64, u32)>,
    per_trial: PerTrial,
    /// Scratch of one trial, reused.
    trial_errs: Vec<f64>,
    /// The shielding windows and the rest of the time line ([`segments_of`]).
    segments: Vec<SegmentAcc>,
    /// The epochs whose truth was outdoors and indoors ([`Places`]), and how many epochs
    /// (with an estimate or not) were indoors: a world whose truth never goes indoors
    /// reports no split.
    outdoor: SegmentAcc,
    indoor: SegmentAcc,
    indoor_epochs: usize,
}

impl EstimatorAcc {
    fn new(name: &str, dir: &Path, chunk: usize) -> Self {
        let spill = || SortedSpill::with_chunk(dir, chunk);
        Self {
            name: name.to_string(),
            e3: spill(),
            eh: spill(),
            ate: spill(),
            ate_al: spill(),
            rpe: spill(),
            rpe_al: spill(),
            epochs: 0,
            without: 0,
            coasting: 0,
            stale: 0,
            coast_limit_s: crate::engine::trial::Scoring::DEFAULT_COAST_LIMIT_S,
            rpe_delta_s: crate::engine::trial::Scoring::DEFAULT_RPE_DELTA_S,
            failures: 0,
            gated: 0,
            first_failures: Vec::new(),
            nees_sum: 0.0,
            nees_n: 0,
            nees_dof: 3.0,
            nees_dof_restarted: 3.0,
            modes: BTreeMap::new(),
            moded: 0,
            nees_by_t: BTreeMap::new(),
            nis_by_t: BTreeMap::new(),
            sq_err_by_t: BTreeMap::new(),
            per_trial: PerTrial::default(),
            trial_errs: Vec::new(),
            segments: Vec::new(),
            outdoor: SegmentAcc::new("outdoor", dir, chunk),
            indoor: SegmentAcc::new("indoor", dir, chunk),
            indoor_epochs: 0,
        }
    }

    fn push(
        &mut self,
        trial: u64,
        trace: &EstimatorTrace,
        places: Option<&Places>,
    ) -> std::io::Result<()> {
        self.trial_errs.clear();
        // One NEES per time per trial: the last record of an instant with several batches
        // (GNSS and FM at the same second), as the TUM tracks below keep.
        let mut trial_nees: BTreeMap<u64, (f64, f64)> = BTreeMap::new();
        let mut nees_dof = self.nees_dof;
        let mut trial_nis: BTreeMap<u64, (f64, usize)> = BTreeMap::new();
        let mut trial_sq: BTreeMap<u64, f64> = BTreeMap::new();
        for ep in &trace.epochs {
            if ep.numerical_failure {
                nees_dof = self.nees_dof_restarted;
            }
            self.epochs += 1;
            self.gated += u64::from(ep.rejected_gate);
            let indoor = places.map(|p| p.indoor(&ep.truth_ecef_m));
            if indoor == Some(true) {
                self.indoor_epochs += 1;
            }
            if ep.numerical_failure {
                self.failures += 1;
                if self.first_failures.len() < FAILURES_LISTED {
                    self.first_failures
                        .push(FailureEpoch { trial, t_s: ep.t_s });
                }
            }
            match (ep.err_3d_m, ep.err_h_m) {
                (Some(a), Some(b)) => {
                    self.e3.push(a)?;
                    self.eh.push(b)?;
                    self.trial_errs.push(a);
                    trial_sq.insert(ep.t_s.to_bits(), a * a);
                    if let Some((outside, windows)) = self.segments.split_last_mut() {
                        let mut inside = false;
                        for g in windows.iter_mut().filter(|g| g.contains(ep.t_s)) {
                            g.add(a, b)?;
                            inside = true;
                        }
                        if !inside {
                            outside.add(a, b)?;
                        }
                    }
                    match indoor {
                        Some(true) => self.indoor.add(a, b)?,
                        Some(false) => self.outdoor.add(a, b)?,
                        None => {}
                    }
                    match ep.since_update_s {
                        Some(age) if age <= self.coast_limit_s => {
                            if age > 0.0 {
                                self.coasting += 1;
                            }
                        }
                        _ => self.stale += 1,
                    }
                }
                _ => self.without += 1,
            }
            if let Some(n) = ep.nees_pos {
                self.nees_sum += n;
                self.nees_n += 1;
                trial_nees.insert(ep.t_s.to_bits(), (n, nees_dof));
            }
            if let Some(n) = ep.nis {
                // Several batches at one instant: their NIS add, as do their dimensions.
                let slot = trial_nis.entry(ep.t_s.to_bits()).or_insert((0.0, 0));
                slot.0 += n;
                slot.1 += ep.nis_dof as usize;
            }
            if let Some(m) = &ep.mode {
                *self.modes.entry(m.to_string()).or_default() += 1;
                self.moded += 1;
            }
        }
        for (t, (n, dof)) in trial_nees {
            self.nees_by_t.entry(t).or_default().push(n, dof);
        }
        for (t, (n, dof)) in trial_nis {
            self.nis_by_t.entry(t).or_default().push(n, dof as f64);
        }
        for (t, e2) in trial_sq {
            let slot = self.sq_err_by_t.entry(t).or_default();
            slot.0 += e2;
            slot.1 += 1;
        }
        let tr = track(trace);
        let a = ate_errors(&tr.truth, &tr.est, Alignment::None);
        let r = rpe_errors(
            &tr.t_s,
            &tr.truth,
            &tr.est,
            self.rpe_delta_s,
            Alignment::None,
        );
        if let Some(v) = &a {
            self.ate.extend(v)?;
        }
        if let Some(v) = &r {
            self.rpe.extend(v)?;
        }
        if let Some(v) = ate_errors(&tr.truth, &tr.est, Alignment::Rigid) {
            self.ate_al.extend(&v)?;
        }
        if let Some(v) = rpe_errors(
            &tr.t_s,
            &tr.truth,
            &tr.est,
            self.rpe_delta_s,
            Alignment::Rigid,
        ) {
            self.rpe_al.extend(&v)?;
        }
        let pt = &mut self.per_trial;
        if let Some(st) = ErrorStats::from_errors(&mut self.trial_errs) {
            pt.sigma1.push(st.sigma1);
            pt.sigma2.push(st.sigma2);
            pt.sigma3.push(st.sigma3);
            pt.mean.push(st.mean);
            pt.rmse.push(st.rmse);
            if let Some(v) = a.and_then(|mut v| TrajectoryStats::from_errors(&mut v)) {
                pt.ate_rmse.push(v.rmse);
            }
            if let Some(v) = r.and_then(|mut v| TrajectoryStats::from_errors(&mut v)) {
                pt.rpe_rmse.push(v.rmse);
            }
        }
        let n_ep = trace.epochs.len();
        if n_ep > 0 {
            let limit = self.coast_limit_s;
            let with = trace.epochs.iter().filter(|e| available(e, limit)).count();
            pt.availability.push(with as f64 / n_ep as f64);
        }
        Ok(())
    }

    fn finish(
        mut self,
    ) -> std::io::Result<(EstimatorSummary, crate::report::Curve, crate::report::Curve)> {
        // A diverged estimate (non-finite error) withholds the statistics rather than
        // averaging NaN; the failure count and epochs say what happened.
        fn error_stats(s: &mut SortedSpill) -> std::io::Result<Option<ErrorStats>> {
            if s.non_finite() > 0 {
                return Ok(None);
            }
            ErrorStats::from_sorted(s)
        }
        fn traj_stats(s: &mut SortedSpill) -> std::io::Result<Option<TrajectoryStats>> {
            if s.non_finite() > 0 {
                return Ok(None);
            }
            TrajectoryStats::from_sorted(s)
        }
        let cdf = ecdf_of(&mut self.e3, CDF_POINTS)?;
        let summary = EstimatorSummary {
            error_3d_m: error_stats(&mut self.e3)?,
            error_h_m: error_stats(&mut self.eh)?,
            availability: if self.epochs > 0 {
                (self.epochs - self.without - self.stale) as f64 / self.epochs as f64
            } else {
                0.0
            },
            epochs: self.epochs,
            epochs_without_fix: self.without,
            coasting_epochs: self.coasting,
            stale_epochs: self.stale,
            mean_nees_pos: (self.nees_n > 0).then(|| self.nees_sum / self.nees_n as f64),
            numerical_failures: self.failures,
            reset_share: self.failures as f64 / self.epochs.max(1) as f64,
            gated_measurements: self.gated,
            protocol: Default::default(),
            first_failures: self.first_failures,
            ate_m: traj_stats(&mut self.ate)?,
            ate_aligned_m: traj_stats(&mut self.ate_al)?,
            rpe_m: traj_stats(&mut self.rpe)?,
            rpe_aligned_m: traj_stats(&mut self.rpe_al)?,
            nees: summary_of_samples(self.nees_by_t.values()),
            nis: summary_of_samples(self.nis_by_t.values()),
            modes: self
                .modes
                .into_iter()
                .map(|(m, n)| (m, n as f64 / self.moded.max(1) as f64))
                .collect(),
            across_trials: self.per_trial.intervals(),
            name: self.name,
            pcrlb_pos_rmse_m: None,
            efficiency: None,
            segments: self
                .segments
                .into_iter()
                .map(SegmentAcc::finish)
                .collect::<std::io::Result<_>>()?,
            environments: if self.indoor_epochs > 0 {
                vec![self.outdoor.finish()?, self.indoor.finish()?]
            } else {
                Vec::new()
            },
        };
        let rmse_vs_time = self
            .sq_err_by_t
            .iter()
            .map(|(t, (sum, n))| (f64::from_bits(*t), (sum / f64::from(*n)).sqrt()))
            .collect();
        Ok((summary, cdf, rmse_vs_time))
    }
}

/// Whether an epoch's estimate counts as available: there is one, and its estimator used a
/// measurement within the coast limit (an estimate that has only been predicted or held
/// for longer is not a fix, however close it happens to be).
fn available(ep: &crate::engine::trial::EpochRecord, coast_limit_s: f64) -> bool {
    ep.err_3d_m.is_some() && ep.since_update_s.is_some_and(|a| a <= coast_limit_s)
}

/// The trajectory of one trial's estimator: times, truth and estimate of the epochs with
/// an estimate.
struct Track {
    t_s: Vec<f64>,
    truth: Vec<Vector3<f64>>,
    est: Vec<Vector3<f64>>,
}

fn track(trace: &EstimatorTrace) -> Track {
    let mut tr = Track {
        t_s: Vec::new(),
        truth: Vec::new(),
        est: Vec::new(),
    };
    for ep in &trace.epochs {
        if let Some(e) = ep.est_ecef_m {
            // Two batches at one instant (e.g. GNSS and FM) give two records with the
            // same time; the TUM metrics need one pose per time, the last one.
            if tr.t_s.last() == Some(&ep.t_s) {
                tr.t_s.pop();
                tr.truth.pop();
                tr.est.pop();
            }
            tr.t_s.push(ep.t_s);
            tr.truth.push(Vector3::from(ep.truth_ecef_m));
            tr.est.push(Vector3::from(e));
        }
    }
    tr
}

/// Each trial's own value of the statistics [`AcrossTrials`] gives intervals of, reduced
/// as they come.
#[derive(Default)]
struct PerTrial {
    sigma1: MeanCi95,
    sigma2: MeanCi95,
    sigma3: MeanCi95,
    mean: MeanCi95,
    rmse: MeanCi95,
    ate_rmse: MeanCi95,
    rpe_rmse: MeanCi95,
    availability: MeanCi95,
}

impl PerTrial {
    fn intervals(&self) -> AcrossTrials {
        // Each statistic's interval respects its support: errors are positive (log scale),
        // availability a share (logit scale).
        let t = |m: &MeanCi95| m.interval().map(|(a, b)| [a, b]);
        let ci = |m: &MeanCi95| positive_ci95(t(m));
        AcrossTrials {
            trials: self.sigma1.count(),
            sigma1_ci95_m: ci(&self.sigma1),
            sigma2_ci95_m: ci(&self.sigma2),
            sigma3_ci95_m: ci(&self.sigma3),
            mean_ci95_m: ci(&self.mean),
            rmse_ci95_m: ci(&self.rmse),
            ate_rmse_ci95_m: ci(&self.ate_rmse),
            rpe_rmse_ci95_m: ci(&self.rpe_rmse),
            availability_ci95: unit_ci95(t(&self.availability)),
        }
    }
}
