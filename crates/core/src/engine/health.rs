//! Divergence supervision shared by every estimator: the engine checks each epoch's
//! outcome, and an estimator that has diverged is reported and reset instead of writing
//! NaN or drifting on unnoticed.
//!
//! Two symptoms are watched (Bar-Shalom, Li & Kirubarajan 2001, "Estimation with
//! Applications to Tracking and Navigation", §5.4: a consistent filter's normalised
//! innovation squared, NIS = νᵀS⁻¹ν, is χ²-distributed with the innovation's dimension as
//! degrees of freedom):
//!
//! - **a non-finite number**: an estimate whose position, velocity or covariance, or an
//!   epoch whose NIS, is NaN or infinite;
//! - **an NIS persistently outside its bound**: [`HealthConfig::window_epochs`]
//!   consecutive epochs, each either with its NIS above the χ²_dof quantile at
//!   1 − [`HealthConfig::false_alarm`] or **locked out by its own gate**: more than half
//!   of the measurements offered refused, or half (or three and a quarter) refused with
//!   at least half of the refusals made against the filter's own greater doubt — its
//!   variance along the measurement, `H P Hᵀ`, at least the measurement's `R` (a gated
//!   filter that has diverged refuses everything, or keeps only the few lines of sight
//!   its error is blind to, so the NIS of what it accepts would never show it; a sound
//!   one refusing biased measurements noisier than itself is left alone). Epochs
//!   without measurements neither count nor break the run. For a consistent filter, the chance of a false alarm at a given epoch is
//!   `false_alarm^window_epochs` = 10⁻⁴⁰ with the defaults; a filter whose noise model is
//!   merely optimistic by a factor of a few stays well below the bound.
//!
//! The watch judges scoring instants, not batches: everything an estimator did since the
//! previous instant, summed over its sources (see [`HealthMonitor`]). A non-finite
//! outcome is caught at the batch that produced it ([`is_non_finite`]), so no NaN ever
//! reaches a source.
//!
//! On either, the engine sets `numerical_failure` on the epoch record (with its time and
//! the estimator's name), drops the epoch's estimate and calls
//! [`crate::measurement::Estimator::reset`].

use crate::core::stats::chi2;
use crate::measurement::EpochOutcome;

/// The divergence test's settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HealthConfig {
    /// Consecutive epochs out of bounds that declare a divergence.
    pub window_epochs: u32,
    /// The per-epoch tail probability of the NIS bound.
    pub false_alarm: f64,
}

impl Default for HealthConfig {
    fn default() -> Self {
        Self {
            window_epochs: 10,
            false_alarm: 1e-4,
        }
    }
}

/// The most NIS degrees of freedom whose bound is cached; larger ones are computed.
const CACHED_DOF: usize = 128;

/// What [`HealthMonitor::check`] found.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Verdict {
    Healthy,
    /// A non-finite estimate or NIS.
    NonFinite,
    /// The NIS was out of bounds, or the filter locked out by its own gate, for the whole
    /// window.
    Diverged,
}

/// One estimator's divergence watch over a trial.
///
/// The watch judges one **scoring instant** at a time (see
/// [`crate::engine::trial::Scoring`]): the outcome of every batch the estimator processed
/// since the previous instant, summed (measurements used and gated, NIS and its
/// dimension). An estimator that takes two sources (GNSS and a DTMB tower, say) is thus
/// judged on everything it saw: a tower it gates while the satellites fit is an outlier
/// rejected, not a divergence, and a divergence in what one source sees still shows in the
/// sum (its gated or out-of-bound measurements weigh as they did).
#[derive(Clone, Debug)]
pub struct HealthMonitor {
    cfg: HealthConfig,
    run: u32,
    /// χ²_dof(1 − false_alarm) for dof = index, NaN until first needed.
    bound: [f64; CACHED_DOF + 1],
}

/// Whether an outcome carries a non-finite number: a position, velocity or covariance of
/// its estimate, or its NIS. Such an outcome must never reach a source or a record.
pub fn is_non_finite(out: &EpochOutcome) -> bool {
    let finite_estimate = out.estimate.is_none_or(|e| {
        e.pos_ecef_m.iter().all(|v| v.is_finite())
            && e.cov_pos_m2.iter().all(|v| v.is_finite())
            && e.vel_ecef_mps
                .is_none_or(|v| v.iter().all(|x| x.is_finite()))
    });
    !finite_estimate || !out.nis_sum.is_finite()
}

impl HealthMonitor {
    pub fn new(cfg: HealthConfig) -> Self {
        Self {
            cfg,
            run: 0,
            bound: [f64::NAN; CACHED_DOF + 1],
        }
    }

    fn bound(&mut self, dof: u32) -> f64 {
        let p = 1.0 - self.cfg.false_alarm;
        match self.bound.get_mut(dof as usize) {
            Some(b) => {
                if b.is_nan() {
                    *b = chi2::quantile(p, f64::from(dof));
                }
                *b
            }
            None => chi2::quantile(p, f64::from(dof)),
        }
    }

    /// Checks one scoring instant's outcome (every batch since the previous instant,
    /// summed); after a verdict other than `Healthy` the watch starts afresh (the
    /// estimator is reset).
    pub fn check(&mut self, out: &EpochOutcome) -> Verdict {
        if is_non_finite(out) {
            self.run = 0;
            return Verdict::NonFinite;
        }
        // A filter that has drifted far enough can still fit a few of the measurements it
        // is given (those whose lines of sight are blind to its error) and refuse the
        // rest: the NIS of what it accepts looks normal, so persistent gating must count
        // too. But a sound filter also refuses outliers for long stretches: seed 004's
        // loosely coupled INS on track (0.85 m off, σ 0.76 m) refuses the three position
        // components of each biased fix and accepts its velocity, 3 of 6, and the tightly
        // coupled filters refuse 14-17 of 45 NLOS ranges and rates at the start. Two
        // things tell the lost filter apart:
        // - the share: an over-confident filter gone astray refuses most of what it is
        //   offered (an EKF told the car never accelerates fits 1-3 of 14 ranges while
        //   hundreds of metres off), so a strict majority of refusals (at least two)
        //   counts on its own;
        // - where the refused innovation's variance, S = H P Hᵀ + R, comes from: a sound
        //   filter refuses measurements noisier than its state along them (H P Hᵀ < R), a
        //   lost but honest one refuses measurements more certain than itself (seed 000's
        //   Kehui filters leave a shielding window 300-500 m off with σ 50-80 m and refuse
        //   3 ranges and a rate of 13 for ten seconds). So a smaller share (half, or three
        //   and a quarter) counts when at least half of the refusals had H P Hᵀ ≥ R.
        // A consistent filter gates 0.1 % of its measurements (the χ²(1) gate at 0.999); a
        // run of ten such instants is what a wrong state does. One measurement refused is
        // never enough: with two DTMB towers and one of them NLOS-biased, refusing the
        // biased one is the gate doing its job, and a filter whose state had gone wrong
        // would refuse both.
        // An INS's IMU samples are counted as used but never offered to a gate: a hundred
        // of them a second would otherwise dilute a tightly coupled filter's gated ranges
        // below any fraction (seed 004's STF ran 300 km away with every range gated).
        let offered = out.used.saturating_sub(out.inputs) + out.rejected_gate;
        let gated = out.rejected_gate;
        let many_gated = gated >= 2 && 2 * gated >= offered || gated >= 3 && 4 * gated >= offered;
        let locked_out = gated >= 2 && 2 * gated > offered
            || many_gated && 2 * out.rejected_gate_state_led >= gated;
        let nis_outside =
            !out.nis_unwatched && out.nis_dof > 0 && out.nis_sum > self.bound(out.nis_dof);
        let outside = nis_outside || locked_out;
        let informative = out.nis_dof > 0 || out.rejected_gate > 0;
        if outside {
            self.run += 1;
        } else if informative {
            self.run = 0;
        }
        if self.run >= self.cfg.window_epochs.max(1) {
            self.run = 0;
            return Verdict::Diverged;
        }
        Verdict::Healthy
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::TrialRng;
    use rand_distr::{ChiSquared, Distribution};

    fn epoch(nis: f64, dof: u32) -> EpochOutcome {
        EpochOutcome {
            used: dof,
            nis_sum: nis,
            nis_count: dof,
            nis_dof: dof,
            ..EpochOutcome::default()
        }
    }

    /// A consistent filter (NIS drawn from χ²_dof) over 10⁵ epochs raises no alarm; an
    /// optimistic one (NIS 3× too large) neither; a diverged one (NIS 1000× too large) is
    /// caught after exactly the window.
    #[test]
    fn consistent_and_mildly_optimistic_filters_pass_and_a_diverged_one_is_caught() {
        let mut rng = TrialRng::new(3, 0).stream("test/health");
        for scale in [1.0, 3.0] {
            let mut m = HealthMonitor::new(HealthConfig::default());
            for k in 0..100_000u32 {
                let dof = 1 + k % 12;
                let nis = scale * ChiSquared::new(f64::from(dof)).unwrap().sample(&mut rng);
                assert_eq!(m.check(&epoch(nis, dof)), Verdict::Healthy, "scale {scale}");
            }
        }
        let mut m = HealthMonitor::new(HealthConfig::default());
        for k in 1..=10 {
            let nis = 1000.0 * ChiSquared::new(8.0).unwrap().sample(&mut rng);
            let v = m.check(&epoch(nis, 8));
            assert_eq!(v == Verdict::Diverged, k == 10, "epoch {k}");
        }
    }

    /// A NIS marked for the records only (`nis_unwatched`) is not judged, however large,
    /// but its epochs still break a run of gated ones, and gated epochs still count.
    #[test]
    fn an_unwatched_nis_is_not_judged_but_gating_still_is() {
        let mut m = HealthMonitor::new(HealthConfig {
            window_epochs: 3,
            false_alarm: 1e-4,
        });
        let huge = EpochOutcome {
            nis_unwatched: true,
            ..epoch(1e9, 6)
        };
        for _ in 0..10 {
            assert_eq!(m.check(&huge), Verdict::Healthy);
        }
        let gated = EpochOutcome {
            rejected: 6,
            rejected_gate: 6,
            ..EpochOutcome::default()
        };
        assert_eq!(m.check(&gated), Verdict::Healthy);
        assert_eq!(m.check(&gated), Verdict::Healthy);
        assert_eq!(m.check(&huge), Verdict::Healthy);
        assert_eq!(m.check(&gated), Verdict::Healthy);
        assert_eq!(m.check(&gated), Verdict::Healthy);
        assert_eq!(m.check(&gated), Verdict::Diverged);
        // The same NIS, watched, is caught.
        for k in 1..=3 {
            assert_eq!(m.check(&epoch(1e9, 6)) == Verdict::Diverged, k == 3);
        }
    }

    #[test]
    fn gated_out_epochs_count_and_empty_epochs_do_not_break_the_run() {
        let mut m = HealthMonitor::new(HealthConfig {
            window_epochs: 3,
            false_alarm: 1e-4,
        });
        let gated = EpochOutcome {
            rejected: 7,
            rejected_gate: 7,
            ..EpochOutcome::default()
        };
        assert_eq!(m.check(&gated), Verdict::Healthy);
        assert_eq!(m.check(&EpochOutcome::default()), Verdict::Healthy);
        assert_eq!(m.check(&gated), Verdict::Healthy);
        assert_eq!(m.check(&gated), Verdict::Diverged);
        // A healthy update in between breaks the run.
        assert_eq!(m.check(&gated), Verdict::Healthy);
        assert_eq!(m.check(&epoch(1.0, 4)), Verdict::Healthy);
        assert_eq!(m.check(&gated), Verdict::Healthy);
        assert_eq!(m.check(&gated), Verdict::Healthy);
        assert_eq!(m.check(&epoch(f64::NAN, 4)), Verdict::NonFinite);
    }

    /// One NLOS-biased tower of two refused, instant after instant, while the other fits:
    /// the gate at work, never a divergence. Both refused: caught after the window.
    #[test]
    fn one_gated_tower_of_two_is_not_a_divergence_but_both_are() {
        let mut m = HealthMonitor::new(HealthConfig {
            window_epochs: 3,
            false_alarm: 1e-4,
        });
        let one_of_two = EpochOutcome {
            rejected: 1,
            rejected_gate: 1,
            ..epoch(0.4, 1)
        };
        for _ in 0..100 {
            assert_eq!(m.check(&one_of_two), Verdict::Healthy);
        }
        let both = EpochOutcome {
            rejected: 2,
            rejected_gate: 2,
            ..EpochOutcome::default()
        };
        assert_eq!(m.check(&both), Verdict::Healthy);
        assert_eq!(m.check(&both), Verdict::Healthy);
        assert_eq!(m.check(&both), Verdict::Diverged);
    }

    /// A filter that fits three of its eight ranges and gates the other five has an NIS
    /// that looks normal; the epochs count against it all the same (a strict majority
    /// refused), and so do epochs with half, or three of twelve, refused against its own
    /// greater doubt. One that gates two of twelve (NLOS ranges in a canyon) does not.
    #[test]
    fn epochs_with_half_the_measurements_gated_against_the_state_count() {
        let mut m = HealthMonitor::new(HealthConfig {
            window_epochs: 3,
            false_alarm: 1e-4,
        });
        let fits_few = EpochOutcome {
            rejected: 5,
            rejected_gate: 5,
            rejected_gate_state_led: 5,
            ..epoch(2.5, 3)
        };
        let half = EpochOutcome {
            rejected: 4,
            rejected_gate: 4,
            rejected_gate_state_led: 2,
            ..epoch(3.0, 4)
        };
        // Two NLOS ranges of twelve: healthy however long it lasts.
        let minority = EpochOutcome {
            rejected: 2,
            rejected_gate: 2,
            ..epoch(5.0, 10)
        };
        assert_eq!(m.check(&fits_few), Verdict::Healthy);
        assert_eq!(m.check(&half), Verdict::Healthy);
        assert_eq!(m.check(&fits_few), Verdict::Diverged);
        for _ in 0..100 {
            assert_eq!(m.check(&minority), Verdict::Healthy);
        }
        // Three of twelve, epoch after epoch, two of them against a state less certain
        // than they are: a state stuck off the truth (seed 000's Kehui filters leaving a
        // shielding window hundreds of metres off refuse three ranges and a rate of 13).
        let stuck = EpochOutcome {
            rejected: 3,
            rejected_gate: 3,
            rejected_gate_state_led: 2,
            ..epoch(4.0, 9)
        };
        assert_eq!(m.check(&stuck), Verdict::Healthy);
        assert_eq!(m.check(&stuck), Verdict::Healthy);
        assert_eq!(m.check(&stuck), Verdict::Diverged);
    }

    /// Half, or a quarter, refused, but most of the refused measurements noisier than the
    /// state along them (`H P Hᵀ < R`): a sound filter removing biased measurements,
    /// never a divergence — seed 004's loosely coupled INS refusing the three position
    /// components of fixes whose σ exceeds its own, ten instants running. A strict
    /// majority refused still counts, whoever is the less certain.
    #[test]
    fn measurements_noisier_than_the_state_may_be_gated_for_ever() {
        let mut m = HealthMonitor::new(HealthConfig {
            window_epochs: 3,
            false_alarm: 1e-4,
        });
        let half_of_a_fix = EpochOutcome {
            rejected: 3,
            rejected_gate: 3,
            rejected_gate_state_led: 1,
            ..epoch(2.0, 3)
        };
        let a_quarter_of_the_sky = EpochOutcome {
            rejected: 4,
            rejected_gate: 4,
            rejected_gate_state_led: 1,
            ..epoch(9.0, 12)
        };
        for _ in 0..100 {
            assert_eq!(m.check(&half_of_a_fix), Verdict::Healthy);
            assert_eq!(m.check(&a_quarter_of_the_sky), Verdict::Healthy);
        }
        // Four of six refused, every one of them noisier than the state: an over-confident
        // filter that has left its measurements behind.
        let most_of_it = EpochOutcome {
            rejected: 4,
            rejected_gate: 4,
            ..epoch(1.0, 2)
        };
        assert_eq!(m.check(&most_of_it), Verdict::Healthy);
        assert_eq!(m.check(&most_of_it), Verdict::Healthy);
        assert_eq!(m.check(&most_of_it), Verdict::Diverged);
    }

    /// An INS's IMU samples count as used but are no measurements a gate could refuse:
    /// a tightly coupled filter whose every range is gated while a hundred IMU samples a
    /// second propagate it is out of bounds, as it would be without the IMU; the same
    /// epochs with the samples counted as measurements would hide it.
    #[test]
    fn imu_samples_do_not_dilute_the_gated_share() {
        let window = HealthConfig {
            window_epochs: 3,
            false_alarm: 1e-4,
        };
        let coasting = EpochOutcome {
            used: 100,
            inputs: 100,
            rejected: 6,
            rejected_gate: 6,
            ..EpochOutcome::default()
        };
        let mut m = HealthMonitor::new(window);
        assert_eq!(m.check(&coasting), Verdict::Healthy);
        assert_eq!(m.check(&coasting), Verdict::Healthy);
        assert_eq!(m.check(&coasting), Verdict::Diverged);
        let as_measurements = EpochOutcome {
            inputs: 0,
            ..coasting
        };
        let mut m = HealthMonitor::new(window);
        for _ in 0..10 {
            assert_eq!(m.check(&as_measurements), Verdict::Healthy);
        }
        // Two ranges of six accepted with a normal NIS, four gated against the state: still
        // two thirds gated.
        let mostly = EpochOutcome {
            used: 102,
            inputs: 100,
            rejected: 4,
            rejected_gate: 4,
            rejected_gate_state_led: 4,
            nis_sum: 1.5,
            nis_count: 2,
            nis_dof: 2,
            ..EpochOutcome::default()
        };
        let mut m = HealthMonitor::new(window);
        assert_eq!(m.check(&mostly), Verdict::Healthy);
        assert_eq!(m.check(&mostly), Verdict::Healthy);
        assert_eq!(m.check(&mostly), Verdict::Diverged);
    }
}
