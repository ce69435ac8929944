//! The posterior Cramér–Rao lower bound of a world's paper estimators
//! ([`crate::fusion::pcrlb`]): their process model, the world's emitters, and the truth
//! trajectories of the run's trials.

use super::World;
use crate::core::{SimTime, TrialRng};
use crate::fusion::paper::ProcessSpec;
use crate::fusion::pcrlb::PaperBound;

/// The PCRLB of one estimator's model over a run: its position-RMSE bound at every epoch
/// and over the run.
#[derive(Clone, Debug, PartialEq)]
pub struct PositionBound {
    /// The square root of the epoch-averaged trace of the bound's position block (m): the
    /// figure `summary.json` reports as `pcrlb_pos_rmse_m`.
    pub rmse_m: f64,
    /// `(t_s, bound_m)` at every epoch `t_s = (k + 1)·Δt` of the emitters' rate: the square
    /// root of the trace of the position block at that epoch, the floor under an RMSE
    /// taken across trials at that instant.
    pub by_epoch: Vec<(f64, f64)>,
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
    /// `None` for an estimator whose model the bound does not cover (seed 000's 12-state
    /// model, the INS, PDR, WLS) or a world without `[sensors.emitters]`. Every emitter of
    /// the estimator's systems is counted at every epoch (outages excepted): a mode
    /// selection that drops ranges is not modelled.
    pub fn pcrlb(&self, seed: u64, trials: u64) -> Vec<Option<PositionBound>> {
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
                            let out = em.outages_s.iter().any(|w| t_s >= w[0] && t_s < w[1]);
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
}
