//! One trial: the event loop that moves truth, sources and estimators forward together.

use super::queue::{EventKind, EventQueue};
use crate::core::{EnuFrame, GpsTime, SimTime, System};
use crate::engine::health::{is_non_finite, HealthConfig, HealthMonitor, Verdict};
use crate::measurement::{
    EpochOutcome, Estimate, Estimator, MeasurementBatch, SampleContext, Source, SourceKind, Truth,
};
use crate::motion::Trajectory;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};
use std::borrow::Cow;

/// Everything a trial needs, freshly built from the world and the trial's random streams.
pub struct TrialSetup {
    pub trajectory: Box<dyn Trajectory>,
    pub sources: Vec<Box<dyn Source>>,
    pub estimators: Vec<Box<dyn Estimator>>,
    pub end: SimTime,
    /// When the estimators are scored.
    pub scoring: Scoring,
    /// Each estimator's divergence watch (the world's `[comparison]`); an estimator
    /// without an entry gets the default.
    pub health: Vec<HealthConfig>,
}

/// The instants at which every estimator of a world is scored.
#[derive(Clone, Debug, PartialEq)]
pub enum ScoringInstants {
    /// Every instant at which a source of one of these kinds produced a scored batch
    /// (every kind when empty): the GNSS epochs, typically.
    Sources(Vec<SourceKind>),
    /// A fixed grid: `first`, `first + period`, … up to the end of the trial.
    Periodic { first: SimTime, period: SimTime },
}

/// How a trial's estimators are scored: **one record per estimator per scoring instant**,
/// the same instants for every estimator of the world, so that every statistic compares
/// the estimators epoch for epoch (paired), whatever sources each one consumes.
///
/// At an instant the record holds the estimate after every batch of that instant (all
/// sources' batches at one time are processed before the instant is scored); an estimator
/// that processed no batch since the previous instant is scored with its latest estimate
/// as it stands (a receiver's output held between its own updates). The record's counters
/// (measurements used and gated, NIS and its dimension, GDOP, numerical failures) sum or
/// take the last value over the batches since the previous instant, so nothing an
/// estimator did between two instants is lost.
#[derive(Clone, Debug, PartialEq)]
pub struct Scoring {
    pub instants: ScoringInstants,
    /// An estimate counts as *available* only while its estimator used a measurement
    /// within this many seconds; older ones are scored as coasting (see
    /// [`EpochRecord::since_update_s`]).
    pub coast_limit_s: f64,
    /// The interval Δ (s) of the relative pose error: each pair of scoring instants Δ
    /// apart gives one RPE sample (`metrics::trajectory::rpe_errors`).
    pub rpe_delta_s: f64,
}

impl Scoring {
    /// The default coast limit (s): a user's setting rather than a model parameter, set to
    /// the divergence watch's window (ten 1 Hz epochs), beyond which an estimate that has
    /// seen no measurement is a prediction, not a fix.
    pub const DEFAULT_COAST_LIMIT_S: f64 = 10.0;

    /// The default RPE interval (s): the TUM benchmark's usual one second, which seed 000
    /// also uses ("the time interval Δ was chosen as 1 second", §6.1).
    pub const DEFAULT_RPE_DELTA_S: f64 = 1.0;

    /// Scoring at every scored batch of any source (the engine's behaviour for worlds that
    /// name no anchor source), with the default coast limit.
    pub fn every_batch() -> Self {
        Self {
            instants: ScoringInstants::Sources(Vec::new()),
            coast_limit_s: Self::DEFAULT_COAST_LIMIT_S,
            rpe_delta_s: Self::DEFAULT_RPE_DELTA_S,
        }
    }

    /// The default for a trial with these sources: the GNSS epochs (or seeds 001/003's
    /// emitter epochs) when there are any, else every scored batch.
    pub fn default_for(kinds: impl IntoIterator<Item = SourceKind>) -> Self {
        let anchors: Vec<SourceKind> = kinds
            .into_iter()
            .filter(|k| matches!(k, SourceKind::Gnss | SourceKind::Emitters))
            .fold(Vec::new(), |mut v, k| {
                if !v.contains(&k) {
                    v.push(k);
                }
                v
            });
        Self {
            instants: ScoringInstants::Sources(anchors),
            coast_limit_s: Self::DEFAULT_COAST_LIMIT_S,
            rpe_delta_s: Self::DEFAULT_RPE_DELTA_S,
        }
    }

    fn scores_batches_of(&self, kind: SourceKind) -> bool {
        match &self.instants {
            ScoringInstants::Sources(kinds) => kinds.is_empty() || kinds.contains(&kind),
            ScoringInstants::Periodic { .. } => false,
        }
    }
}

/// One estimator's record at one measurement epoch.
///
/// Records are what a run keeps of a trial (`OUT/trials/trial-NNNNNN.json.gz`) and what every
/// output (`summary.json`, `epochs.csv`, `trials.parquet`, `report.html`) is computed from,
/// so a resumed or merged run reproduces an uninterrupted one from these alone.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EpochRecord {
    /// Seconds since the start of the trial.
    pub t_s: f64,
    /// The true antenna position (ECEF, m).
    pub truth_ecef_m: [f64; 3],
    /// The estimated position (ECEF, m), when the estimator had an estimate.
    pub est_ecef_m: Option<[f64; 3]>,
    /// GPS satellites whose ranges were in this epoch's batch: the ones the receiver
    /// tracked (visible, or received by reflection), whether or not the estimator used them.
    pub n_gps: u32,
    /// BeiDou satellites tracked, likewise.
    pub n_bds: u32,
    /// 3-D position error (m), when the estimator had an estimate.
    pub err_3d_m: Option<f64>,
    /// Horizontal position error (m) in the local frame at the truth.
    pub err_h_m: Option<f64>,
    /// Position NEES εᵀP⁻¹ε (3 degrees of freedom), when the covariance is invertible.
    pub nees_pos: Option<f64>,
    pub used: u32,
    pub rejected: u32,
    pub gdop: Option<f64>,
    pub numerical_failure: bool,
    /// √trace of the position covariance (m): the estimator's own 3-D σ.
    pub pos_sigma_m: Option<f64>,
    /// NIS of the updates used this epoch per degree of freedom, `Σ νᵀS⁻¹ν / Σ dim ν`:
    /// about 1 for a consistent filter, whether it updates range by range (the EKFs) or
    /// with the whole epoch at once (the particle filters).
    pub mean_nis: Option<f64>,
    /// Summed NIS of the updates used this epoch, χ² with `nis_dof` degrees of freedom
    /// for a consistent filter.
    pub nis: Option<f64>,
    pub nis_dof: u32,
    /// Measurements an innovation gate rejected as outliers.
    pub rejected_gate: u32,
    /// The integration mode chosen this epoch (mode-selecting estimators only). Borrowed
    /// from the selector's static labels while simulating, so recording allocates nothing.
    pub mode: Option<Cow<'static, str>>,
    /// Seconds since the estimator last used a measurement (0 when it used one at this
    /// instant; absent when it never has). An estimate counts as available only while this
    /// is within the world's coast limit ([`Scoring::coast_limit_s`]); one with a positive
    /// value is coasting on its own prediction or held since its last update.
    #[serde(default)]
    pub since_update_s: Option<f64>,
}

/// Everything one estimator did in one trial.
#[derive(Clone, Debug, PartialEq, Default, Serialize, Deserialize)]
pub struct EstimatorTrace {
    pub name: String,
    pub epochs: Vec<EpochRecord>,
}

/// The outcome of one trial.
#[derive(Clone, Debug, PartialEq, Default, Serialize, Deserialize)]
pub struct TrialResult {
    pub trial: u64,
    pub estimators: Vec<EstimatorTrace>,
    /// The sources' warnings (see [`crate::measurement::Source::warnings`]).
    pub warnings: Vec<String>,
}

/// Truth at a simulation time.
pub fn truth_at(
    frame: &EnuFrame,
    start: GpsTime,
    trajectory: &dyn Trajectory,
    sim: SimTime,
) -> Truth {
    let enu = trajectory.state_at(sim.seconds());
    Truth {
        sim,
        t: sim.to_gps(start),
        pos_ecef_m: frame.ecef_of_enu(&enu.pos_enu_m),
        vel_ecef_mps: frame.ecef_vector_of_enu(&enu.vel_enu_mps),
        enu,
    }
}

fn errors(frame: &EnuFrame, truth: &Truth, est: &Estimate) -> (f64, f64, Option<f64>) {
    let e: Vector3<f64> = est.pos_ecef_m - truth.pos_ecef_m;
    let e_enu = frame.enu_vector_of_ecef(&e);
    let nees = est
        .cov_pos_m2
        .try_inverse()
        .map(|pinv| (e.transpose() * pinv * e)[(0, 0)])
        .filter(|v| v.is_finite());
    (
        e.norm(),
        (e_enu.x * e_enu.x + e_enu.y * e_enu.y).sqrt(),
        nees,
    )
}

/// The event loop of one trial: samples every source when it asks, hands each batch to
/// the estimators that consume it, records their errors against the truth, and makes each
/// estimator's latest estimate visible to every source at its next event.
pub fn simulate(frame: &EnuFrame, start: GpsTime, setup: &mut TrialSetup) -> Vec<EstimatorTrace> {
    simulate_observed(frame, start, setup, None)
}

/// Watches a trial's measurement stream: every batch a source produced, with the truth at
/// its time (dataset export records trials through it).
///
/// Observing does not perturb the trial: the observer sees each batch after the source
/// made it and before the estimators read it, and draws no random numbers, so an observed
/// trial's estimator traces are bit-identical to an unobserved one's.
pub trait BatchObserver {
    /// Whether the sources should also fill [`MeasurementBatch::raw`] with the raw
    /// observations a receiver would log (RINEX observables, FM RSSI).
    fn wants_raw(&self) -> bool {
        false
    }
    /// One batch, including the empty ones (an epoch with every satellite blocked).
    fn batch(&mut self, truth: &Truth, batch: &MeasurementBatch);
}

/// What one estimator did since the previous scoring instant.
#[derive(Default)]
struct Pending {
    /// The outcomes of its batches, summed (the estimate is the last one's).
    sum: EpochOutcome,
    /// Whether it processed any batch.
    processed: bool,
}

impl Pending {
    fn add(&mut self, out: &EpochOutcome) {
        let s = &mut self.sum;
        s.estimate = out.estimate;
        s.used += out.used;
        s.inputs += out.inputs;
        s.rejected += out.rejected;
        s.gdop = out.gdop.or(s.gdop);
        s.numerical_failure |= out.numerical_failure;
        s.nis_sum += out.nis_sum;
        s.nis_count += out.nis_count;
        s.nis_dof += out.nis_dof;
        s.rejected_gate += out.rejected_gate;
        s.rejected_gate_state_led += out.rejected_gate_state_led;
        s.mode = out.mode.or(s.mode);
        s.nis_unwatched |= out.nis_unwatched;
        self.processed = true;
    }
}

/// The satellites tracked at the current instant, from its last GNSS batch.
#[derive(Clone, Copy, Default)]
struct Tracked {
    n_gps: u32,
    n_bds: u32,
}

/// [`simulate`] with an optional [`BatchObserver`].
pub fn simulate_observed(
    frame: &EnuFrame,
    start: GpsTime,
    setup: &mut TrialSetup,
    mut observer: Option<&mut dyn BatchObserver>,
) -> Vec<EstimatorTrace> {
    let mut queue = EventQueue::with_capacity(setup.sources.len() + 2);
    for (i, s) in setup.sources.iter().enumerate() {
        queue.schedule(s.first_sample(), EventKind::Sample(i));
    }
    queue.schedule(setup.end, EventKind::End);
    if let ScoringInstants::Periodic { first, .. } = setup.scoring.instants {
        queue.schedule(first, EventKind::Score);
    }

    let n_est = setup.estimators.len();
    let mut latest: Vec<Option<Estimate>> = vec![None; n_est];
    let mut health: Vec<HealthMonitor> = (0..n_est)
        .map(|k| HealthMonitor::new(setup.health.get(k).copied().unwrap_or_default()))
        .collect();
    let mut pending: Vec<Pending> = (0..n_est).map(|_| Pending::default()).collect();
    let mut last_update: Vec<Option<SimTime>> = vec![None; n_est];
    let mut traces: Vec<EstimatorTrace> = setup
        .estimators
        .iter()
        .map(|e| EstimatorTrace {
            name: e.name().to_string(),
            epochs: Vec::new(),
        })
        .collect();
    // The routing, decided once: which estimators consume each source's batches, in the
    // world's estimator order.
    let subscribers: Vec<Vec<usize>> = setup
        .sources
        .iter()
        .map(|s| {
            let kind = s.kind();
            (0..n_est)
                .filter(|&k| setup.estimators[k].consumes(kind))
                .collect()
        })
        .collect();
    let scoring_source: Vec<bool> = setup
        .sources
        .iter()
        .map(|s| setup.scoring.scores_batches_of(s.kind()))
        .collect();
    let mut batch = MeasurementBatch::default();
    if observer.as_ref().is_some_and(|o| o.wants_raw()) {
        batch.raw = Some(crate::measurement::RawLog::default());
    }
    // Whether the instant being processed is a scoring instant, and what it tracked.
    let mut score_now = false;
    let mut tracked = Tracked::default();

    while let Some(ev) = queue.pop() {
        match ev.kind {
            EventKind::End => break,
            EventKind::Score => {
                score_now = true;
                if let ScoringInstants::Periodic { period, .. } = setup.scoring.instants {
                    queue.schedule(SimTime(ev.t.0 + period.0.max(1)), EventKind::Score);
                }
            }
            EventKind::Sample(source_idx) => {
                let truth = truth_at(frame, start, setup.trajectory.as_ref(), ev.t);
                batch.items.clear();
                if let Some(raw) = batch.raw.as_mut() {
                    raw.clear();
                }
                batch.unscored = false;
                batch.source = setup.sources[source_idx].kind();
                let ctx = SampleContext {
                    truth: &truth,
                    estimates: &latest,
                };
                let source = &mut setup.sources[source_idx];
                if let Some(next) = source.sample(&ctx, &mut batch) {
                    queue.schedule(next, EventKind::Sample(source_idx));
                }
                if let Some(o) = observer.as_mut() {
                    o.batch(&truth, &batch);
                }
                // An empty batch is no epoch unless the source says so (a GNSS epoch with
                // every satellite blocked is one); it still ends its instant below.
                if !batch.items.is_empty() || source.empty_batches_are_epochs() {
                    if !batch.unscored && scoring_source[source_idx] {
                        score_now = true;
                    }
                    if matches!(batch.source, SourceKind::Gnss | SourceKind::Emitters) {
                        let count = |sys: System| {
                            batch.ranges().filter(|r| r.emitter.system == sys).count() as u32
                        };
                        tracked = Tracked {
                            n_gps: count(System::Gps),
                            n_bds: count(System::Bds),
                        };
                    }
                    for &k in &subscribers[source_idx] {
                        let est = &mut setup.estimators[k];
                        let mut out = est.process(&batch);
                        // A non-finite outcome is reported at once and the estimator reset: it
                        // never hands a NaN on to a source or a record.
                        if is_non_finite(&out) {
                            out = EpochOutcome {
                                numerical_failure: true,
                                ..EpochOutcome::default()
                            };
                            est.reset();
                        } else if out.used > 0 {
                            last_update[k] = Some(ev.t);
                        }
                        latest[k] = est.latest();
                        pending[k].add(&out);
                    }
                }
            }
        }
        // Score once every event of the instant has been processed.
        if !score_now || queue.peek_time() == Some(ev.t) {
            continue;
        }
        score_now = false;
        let truth = truth_at(frame, start, setup.trajectory.as_ref(), ev.t);
        let truth_ecef_m = [truth.pos_ecef_m.x, truth.pos_ecef_m.y, truth.pos_ecef_m.z];
        for k in 0..n_est {
            let p = std::mem::take(&mut pending[k]);
            let mut out = p.sum;
            if !p.processed {
                out.estimate = latest[k];
            }
            // The divergence watch judges the instant as a whole (see `engine::health`).
            if p.processed && health[k].check(&out) != Verdict::Healthy {
                out.numerical_failure = true;
                setup.estimators[k].reset();
                latest[k] = setup.estimators[k].latest();
            }
            if out.numerical_failure {
                out.estimate = None;
            }
            let (err_3d_m, err_h_m, nees_pos) = match &out.estimate {
                Some(e) => {
                    let (e3, eh, n) = errors(frame, &truth, e);
                    (Some(e3), Some(eh), n)
                }
                None => (None, None, None),
            };
            traces[k].epochs.push(EpochRecord {
                t_s: ev.t.seconds(),
                truth_ecef_m,
                est_ecef_m: out
                    .estimate
                    .map(|e| [e.pos_ecef_m.x, e.pos_ecef_m.y, e.pos_ecef_m.z]),
                n_gps: tracked.n_gps,
                n_bds: tracked.n_bds,
                err_3d_m,
                err_h_m,
                nees_pos,
                used: out.used,
                rejected: out.rejected,
                gdop: out.gdop,
                numerical_failure: out.numerical_failure,
                pos_sigma_m: out
                    .estimate
                    .map(|e| e.cov_pos_m2.trace().max(0.0).sqrt())
                    .filter(|v| v.is_finite()),
                mean_nis: (out.nis_dof > 0).then(|| out.nis_sum / f64::from(out.nis_dof)),
                nis: (out.nis_dof > 0).then_some(out.nis_sum),
                nis_dof: out.nis_dof,
                rejected_gate: out.rejected_gate,
                mode: out.mode.map(Cow::Borrowed),
                since_update_s: last_update[k].map(|u| (ev.t.0 - u.0) as f64 * 1e-9),
            });
        }
    }
    traces
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::{Geodetic, TrialRng};
    use crate::measurement::{
        EpochOutcome, Estimator, Measurement, PositionFix, Source, SourceKind,
    };
    use crate::motion::TrajectoryConfig;
    use nalgebra::Matrix3;
    use std::sync::{Arc, Mutex};

    /// A source that reports the truth as a position fix every second and records which
    /// estimate it saw at each of its events.
    struct Probe {
        seen: Arc<Mutex<Vec<Option<f64>>>>,
        period: i64,
    }

    impl Source for Probe {
        fn kind(&self) -> SourceKind {
            SourceKind::Fm
        }
        fn first_sample(&self) -> SimTime {
            SimTime(0)
        }
        fn sample(
            &mut self,
            ctx: &SampleContext<'_>,
            out: &mut MeasurementBatch,
        ) -> Option<SimTime> {
            self.seen
                .lock()
                .unwrap()
                .push(ctx.estimates[0].map(|e| e.t.seconds_since(GpsTime::from_ns(0))));
            out.t = ctx.truth.t;
            out.items.push(Measurement::Position(PositionFix {
                pos_ecef_m: ctx.truth.pos_ecef_m,
                cov_m2: Matrix3::identity(),
                support: 0,
            }));
            Some(SimTime(ctx.truth.sim.0 + self.period))
        }
    }

    /// An estimator that echoes the last fix it was given.
    struct Echo(Option<Estimate>);

    impl Estimator for Echo {
        fn name(&self) -> &str {
            "echo"
        }
        fn consumes(&self, source: SourceKind) -> bool {
            source == SourceKind::Fm
        }
        fn process(&mut self, batch: &MeasurementBatch) -> EpochOutcome {
            if let Some(Measurement::Position(f)) = batch.items.first() {
                self.0 = Some(Estimate {
                    t: batch.t,
                    pos_ecef_m: f.pos_ecef_m,
                    vel_ecef_mps: None,
                    cov_pos_m2: f.cov_m2,
                });
            }
            EpochOutcome {
                estimate: self.0,
                used: 1,
                ..EpochOutcome::default()
            }
        }
        fn latest(&self) -> Option<Estimate> {
            self.0
        }
        fn reset(&mut self) {}
    }

    /// A source of fixes every `period` until `stop`, then silence.
    struct Stopping {
        period: i64,
        stop: i64,
    }

    impl Source for Stopping {
        fn kind(&self) -> SourceKind {
            SourceKind::Fm
        }
        fn first_sample(&self) -> SimTime {
            SimTime(0)
        }
        fn sample(
            &mut self,
            ctx: &SampleContext<'_>,
            out: &mut MeasurementBatch,
        ) -> Option<SimTime> {
            out.t = ctx.truth.t;
            out.items.push(Measurement::Position(PositionFix {
                pos_ecef_m: ctx.truth.pos_ecef_m,
                cov_m2: Matrix3::identity(),
                support: 0,
            }));
            let next = ctx.truth.sim.0 + self.period;
            (next < self.stop).then_some(SimTime(next))
        }
    }

    /// Two estimators fed by sources of different rates (4 Hz and 1 Hz) are scored at the
    /// same periodic instants, once each, with the counters of every batch since the
    /// previous instant summed; once the sources stop, the held estimates age and say so.
    #[test]
    fn every_estimator_is_scored_once_per_instant_and_ages_after_its_last_update() {
        struct Named(Echo, &'static str, SourceKind);
        impl Estimator for Named {
            fn name(&self) -> &str {
                self.1
            }
            fn consumes(&self, source: SourceKind) -> bool {
                source == self.2
            }
            fn process(&mut self, batch: &MeasurementBatch) -> EpochOutcome {
                self.0.process(batch)
            }
            fn latest(&self) -> Option<Estimate> {
                self.0.latest()
            }
            fn reset(&mut self) {}
        }
        struct As(Stopping, SourceKind);
        impl Source for As {
            fn kind(&self) -> SourceKind {
                self.1
            }
            fn first_sample(&self) -> SimTime {
                self.0.first_sample()
            }
            fn sample(
                &mut self,
                ctx: &SampleContext<'_>,
                out: &mut MeasurementBatch,
            ) -> Option<SimTime> {
                self.0.sample(ctx, out)
            }
        }
        let traj = TrajectoryConfig::Static {
            position_enu_m: [0.0, 0.0, 0.0],
            duration_s: 10.0,
        };
        let s = 1_000_000_000;
        let mut setup = TrialSetup {
            trajectory: traj.build(&mut TrialRng::new(0, 0).stream("t")).unwrap(),
            sources: vec![
                Box::new(As(
                    Stopping {
                        period: s / 4,
                        stop: 3 * s,
                    },
                    SourceKind::Fm,
                )),
                Box::new(As(
                    Stopping {
                        period: s,
                        stop: 5 * s,
                    },
                    SourceKind::Magnetic,
                )),
            ],
            estimators: vec![
                Box::new(Named(Echo(None), "fast", SourceKind::Fm)),
                Box::new(Named(Echo(None), "slow", SourceKind::Magnetic)),
            ],
            end: SimTime::from_seconds(9.5),
            scoring: Scoring {
                instants: ScoringInstants::Periodic {
                    first: SimTime(0),
                    period: SimTime(s),
                },
                coast_limit_s: 2.0,
                rpe_delta_s: Scoring::DEFAULT_RPE_DELTA_S,
            },
            health: Vec::new(),
        };
        let traces = simulate(
            &EnuFrame::new(Geodetic::from_deg(40.0, 116.0, 0.0)),
            GpsTime::from_ns(0),
            &mut setup,
        );
        let times = |k: usize| -> Vec<f64> { traces[k].epochs.iter().map(|e| e.t_s).collect() };
        let expected: Vec<f64> = (0..10).map(f64::from).collect();
        assert_eq!(times(0), expected);
        assert_eq!(times(1), expected);
        // The 4 Hz estimator's instants after the first sum the batches since the last
        // (its source stops after 2.75 s).
        let used: Vec<u32> = traces[0].epochs.iter().map(|e| e.used).collect();
        assert_eq!(used, [1, 4, 4, 3, 0, 0, 0, 0, 0, 0]);
        // Its last update was at 2.75 s; the 1 Hz one's at 4 s.
        let age = |k: usize, i: usize| traces[k].epochs[i].since_update_s.unwrap();
        assert_eq!(age(0, 2), 0.0);
        assert!((age(0, 3) - 0.25).abs() < 1e-12 && (age(0, 9) - 6.25).abs() < 1e-12);
        assert_eq!(age(1, 4), 0.0);
        assert_eq!(age(1, 9), 5.0);
        // Held estimates keep their error records (the estimate exists) while they age.
        assert!(traces[0].epochs.iter().all(|e| e.err_3d_m == Some(0.0)));
    }

    #[test]
    fn estimates_close_the_loop_at_the_next_event() {
        let seen = Arc::new(Mutex::new(Vec::new()));
        let traj = TrajectoryConfig::Static {
            position_enu_m: [0.0, 0.0, 0.0],
            duration_s: 3.0,
        };
        let mut setup = TrialSetup {
            trajectory: traj.build(&mut TrialRng::new(0, 0).stream("t")).unwrap(),
            sources: vec![Box::new(Probe {
                seen: Arc::clone(&seen),
                period: 1_000_000_000,
            })],
            estimators: vec![Box::new(Echo(None))],
            end: SimTime::from_seconds(3.0),
            scoring: Scoring::every_batch(),
            health: Vec::new(),
        };
        let start = GpsTime::from_ns(0);
        let traces = simulate(
            &EnuFrame::new(Geodetic::from_deg(40.0, 116.0, 0.0)),
            start,
            &mut setup,
        );
        // Events at 0, 1, 2 and 3 s (the End event at 3 s was scheduled before the sample at
        // 3 s, so it comes first and the loop stops there).
        assert_eq!(traces[0].epochs.len(), 3);
        assert!(traces[0].epochs.iter().all(|e| e.err_3d_m == Some(0.0)));
        // At each event the source sees the estimate made from its previous sample.
        assert_eq!(*seen.lock().unwrap(), vec![None, Some(0.0), Some(1.0)]);
    }

    /// An estimator that goes wrong on purpose: a NaN estimate at 2 s, then innovations far
    /// outside their χ² bound from 4 s on, until its second reset.
    struct Faulty {
        resets: Arc<Mutex<Vec<f64>>>,
        t0: GpsTime,
        healthy_again: bool,
    }

    impl Estimator for Faulty {
        fn name(&self) -> &str {
            "faulty"
        }
        fn consumes(&self, source: SourceKind) -> bool {
            source == SourceKind::Fm
        }
        fn process(&mut self, batch: &MeasurementBatch) -> EpochOutcome {
            let t = batch.t.seconds_since(self.t0);
            let Some(Measurement::Position(f)) = batch.items.first() else {
                return EpochOutcome::default();
            };
            let nan = t == 2.0;
            let nis = if t >= 4.0 && !self.healthy_again {
                1e6
            } else {
                2.0
            };
            EpochOutcome {
                estimate: Some(Estimate {
                    t: batch.t,
                    pos_ecef_m: if nan {
                        Vector3::repeat(f64::NAN)
                    } else {
                        f.pos_ecef_m
                    },
                    vel_ecef_mps: None,
                    cov_pos_m2: f.cov_m2,
                }),
                used: 3,
                nis_sum: nis,
                nis_count: 1,
                nis_dof: 3,
                ..EpochOutcome::default()
            }
        }
        fn latest(&self) -> Option<Estimate> {
            None
        }
        fn reset(&mut self) {
            // The first reset answers the NaN; the second, the NIS run, cures it.
            let mut r = self.resets.lock().unwrap();
            r.push(0.0);
            self.healthy_again = r.len() >= 2;
        }
    }

    /// The engine's divergence watch: a NaN estimate and an NIS persistently beyond its
    /// bound are each reported at their epoch (no estimate, `numerical_failure`), the
    /// estimator is reset, and no record carries a non-finite number.
    #[test]
    fn a_nan_estimate_and_a_persistent_nis_are_reported_at_their_epochs_and_reset() {
        let resets = Arc::new(Mutex::new(Vec::new()));
        let start = GpsTime::from_ns(0);
        let traj = TrajectoryConfig::Static {
            position_enu_m: [0.0, 0.0, 0.0],
            duration_s: 30.0,
        };
        let mut setup = TrialSetup {
            trajectory: traj.build(&mut TrialRng::new(0, 0).stream("t")).unwrap(),
            sources: vec![Box::new(Probe {
                seen: Arc::new(Mutex::new(Vec::new())),
                period: 1_000_000_000,
            })],
            estimators: vec![Box::new(Faulty {
                resets: Arc::clone(&resets),
                t0: start,
                healthy_again: false,
            })],
            end: SimTime::from_seconds(30.0),
            scoring: Scoring::every_batch(),
            health: Vec::new(),
        };
        let traces = simulate(
            &EnuFrame::new(Geodetic::from_deg(40.0, 116.0, 0.0)),
            start,
            &mut setup,
        );
        let failures: Vec<f64> = traces[0]
            .epochs
            .iter()
            .filter(|e| e.numerical_failure)
            .map(|e| e.t_s)
            .collect();
        // The NaN at 2 s at once; the NIS run from 4 s after its 10th epoch, 13 s.
        assert_eq!(failures, [2.0, 13.0]);
        assert_eq!(resets.lock().unwrap().len(), 2);
        for e in &traces[0].epochs {
            assert_eq!(e.est_ecef_m.is_none(), e.numerical_failure, "t = {}", e.t_s);
            for v in [
                e.err_3d_m,
                e.err_h_m,
                e.nees_pos,
                e.pos_sigma_m,
                e.mean_nis,
                e.nis,
            ]
            .into_iter()
            .flatten()
            {
                assert!(v.is_finite(), "t = {}", e.t_s);
            }
        }
    }
}
