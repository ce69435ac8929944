//! One trial: the event loop that moves truth, sources and estimators forward together.

use super::queue::{EventKind, EventQueue};
use super::{SampleContext, Truth};
use crate::core::{SimTime, TrialRng};
use crate::fusion::estimator::Estimate;
use crate::fusion::measurement::MeasurementBatch;
use crate::world::World;
use nalgebra::Vector3;

/// One estimator's record at one measurement epoch.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EpochRecord {
    /// Seconds since the start of the trial.
    pub t_s: f64,
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
}

/// Everything one estimator did in one trial.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct EstimatorTrace {
    pub name: String,
    pub epochs: Vec<EpochRecord>,
}

/// The outcome of one trial.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct TrialResult {
    pub trial: u64,
    pub estimators: Vec<EstimatorTrace>,
}

/// Truth at a simulation time.
pub fn truth_at(world: &World, trajectory: &dyn crate::motion::Trajectory, sim: SimTime) -> Truth {
    let enu = trajectory.state_at(sim.seconds());
    Truth {
        sim,
        t: sim.to_gps(world.start),
        pos_ecef_m: world.frame.ecef_of_enu(&enu.pos_enu_m),
        vel_ecef_mps: world.frame.ecef_vector_of_enu(&enu.vel_enu_mps),
        enu,
    }
}

fn errors(world: &World, truth: &Truth, est: &Estimate) -> (f64, f64, Option<f64>) {
    let e: Vector3<f64> = est.pos_ecef_m - truth.pos_ecef_m;
    let e_enu = world.frame.enu_vector_of_ecef(&e);
    let nees = est.cov_pos_m2.try_inverse().map(|pinv| (e.transpose() * pinv * e)[(0, 0)]).filter(|v| v.is_finite());
    (e.norm(), (e_enu.x * e_enu.x + e_enu.y * e_enu.y).sqrt(), nees)
}

/// Runs trial `trial` of `world` under `seed`.
///
/// The trial depends only on `(world, seed, trial)`: every random draw comes from a
/// stream of [`TrialRng::new(seed, trial)`].
///
/// # Errors
/// When the world cannot build this trial's parts.
pub fn run_trial(world: &World, seed: u64, trial: u64) -> Result<TrialResult, String> {
    let rng = TrialRng::new(seed, trial);
    let mut setup = world.build_trial(&rng)?;
    let mut queue = EventQueue::with_capacity(setup.sources.len() + 1);
    for (i, s) in setup.sources.iter().enumerate() {
        queue.schedule(s.first_sample(), EventKind::Sample(i));
    }
    queue.schedule(setup.end, EventKind::End);

    let mut latest: Vec<Option<Estimate>> = vec![None; setup.estimators.len()];
    let mut traces: Vec<EstimatorTrace> = setup
        .estimators
        .iter()
        .map(|e| EstimatorTrace { name: e.name().to_string(), epochs: Vec::new() })
        .collect();
    let mut batch = MeasurementBatch::default();

    while let Some(ev) = queue.pop() {
        let source_idx = match ev.kind {
            EventKind::End => break,
            EventKind::Sample(i) => i,
        };
        let truth = truth_at(world, setup.trajectory.as_ref(), ev.t);
        batch.items.clear();
        let ctx = SampleContext { truth: &truth, estimates: &latest };
        let source = &mut setup.sources[source_idx];
        if let Some(next) = source.sample(&ctx, &mut batch) {
            queue.schedule(next, EventKind::Sample(source_idx));
        }
        let source_name = source.name();
        for (k, est) in setup.estimators.iter_mut().enumerate() {
            if !est.consumes(source_name) {
                continue;
            }
            let out = est.process(&batch);
            latest[k] = est.latest();
            let (err_3d_m, err_h_m, nees_pos) = match &out.estimate {
                Some(e) => {
                    let (e3, eh, n) = errors(world, &truth, e);
                    (Some(e3), Some(eh), n)
                }
                None => (None, None, None),
            };
            traces[k].epochs.push(EpochRecord {
                t_s: ev.t.seconds(),
                err_3d_m,
                err_h_m,
                nees_pos,
                used: out.used,
                rejected: out.rejected,
                gdop: out.gdop,
                numerical_failure: out.numerical_failure,
            });
        }
    }
    Ok(TrialResult { trial, estimators: traces })
}
