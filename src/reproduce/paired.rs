//! Paired comparisons behind each claimed ordering: is `A < B` a property of the method or
//! of a few trials?
//!
//! An ordering is judged on the figures pooled over every trial ([`super::OrderingResult`]),
//! and a pooled tail (a 3σ level, an RMSE) can be carried by one or two bad trials. Every
//! estimator of a world runs on the same trials (the same truth and the same random
//! measurements), so each trial is a matched pair: this module takes each trial's own value
//! of the ordering's metric for the two estimators of each adjacent pair of the claim,
//! counts the trials in which the claim holds and those in which it is reversed (a
//! difference within [`super::TIE_RELATIVE`] of the larger is a tie and counts in
//! neither), and gives the two-sided exact sign test of the split (Dixon & Mood, "The
//! statistical sign test", *JASA* 41, 1946): the probability of a split at least as
//! uneven if neither estimator were better.

use super::papers::Metric;
use super::{OrderingResult, TIE_RELATIVE};
use crate::engine::trial::{EstimatorTrace, TrialResult};
use crate::metrics::{ate_errors, Alignment, ErrorStats, TrajectoryStats};
use nalgebra::Vector3;

/// The split of the trials for one adjacent pair `a < b` of a claimed ordering.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PairedSign {
    /// Trials in which `a`'s value is below `b`'s (the claim holds).
    pub holds: usize,
    /// Trials in which it is above.
    pub reversed: usize,
    /// Trials within [`TIE_RELATIVE`], or without a value for either.
    pub ties: usize,
    /// The two-sided exact sign test's p-value of `holds` against `reversed`.
    pub p: f64,
}

impl PairedSign {
    /// Counts the matched pairs `(a, b)` of per-trial values.
    pub fn of(pairs: impl IntoIterator<Item = (Option<f64>, Option<f64>)>) -> Self {
        let (mut holds, mut reversed, mut ties) = (0, 0, 0);
        for pair in pairs {
            match pair {
                (Some(a), Some(b)) if (b - a).abs() > TIE_RELATIVE * a.abs().max(b.abs()) => {
                    if a < b {
                        holds += 1;
                    } else {
                        reversed += 1;
                    }
                }
                _ => ties += 1,
            }
        }
        Self {
            holds,
            reversed,
            ties,
            p: sign_test_p(holds, holds + reversed),
        }
    }
}

impl PairedSign {
    /// The splits of independent runs (the same pair on several master seeds) taken
    /// together: their counts add, and the test is of the sum.
    pub fn pooled<'a>(parts: impl IntoIterator<Item = &'a PairedSign>) -> Self {
        let (mut holds, mut reversed, mut ties) = (0, 0, 0);
        for p in parts {
            holds += p.holds;
            reversed += p.reversed;
            ties += p.ties;
        }
        Self {
            holds,
            reversed,
            ties,
            p: sign_test_p(holds, holds + reversed),
        }
    }
}

/// The two-sided exact sign test: the probability, under `X ~ Binomial(n, ½)`, of a
/// split at least as uneven as `k` of `n`, `min(1, 2 · P(X ≤ min(k, n − k)))`; 1 for
/// `n = 0`.
pub fn sign_test_p(k: usize, n: usize) -> f64 {
    if n == 0 {
        return 1.0;
    }
    let m = k.min(n - k);
    // ln C(n, i) − n ln 2, built up term by term so no factorial overflows.
    let ln_half_n = n as f64 * std::f64::consts::LN_2;
    let mut ln_c = 0.0f64;
    let mut tail = (-ln_half_n).exp();
    for i in 1..=m {
        ln_c += ((n - i + 1) as f64).ln() - (i as f64).ln();
        tail += (ln_c - ln_half_n).exp();
    }
    (2.0 * tail).min(1.0)
}

/// One trial's value of `metric` for one estimator: the statistic the summary pools over
/// every trial, taken over this trial's scored epochs alone. `None` without an estimate,
/// and for the RPE (no paper claims an ordering in it).
pub fn trial_metric(trace: &EstimatorTrace, metric: Metric) -> Option<f64> {
    let mut e3: Vec<f64> = trace.epochs.iter().filter_map(|e| e.err_3d_m).collect();
    match metric {
        Metric::Sigma1
        | Metric::Sigma2
        | Metric::Sigma3
        | Metric::Mean
        | Metric::Std
        | Metric::Rmse => {
            let s = ErrorStats::from_errors(&mut e3)?;
            Some(match metric {
                Metric::Sigma1 => s.sigma1,
                Metric::Sigma2 => s.sigma2,
                Metric::Sigma3 => s.sigma3,
                Metric::Mean => s.mean,
                Metric::Std => s.std,
                _ => s.rmse,
            })
        }
        Metric::Horizontal1 | Metric::Horizontal2 => {
            let mut eh: Vec<f64> = trace.epochs.iter().filter_map(|e| e.err_h_m).collect();
            let s = ErrorStats::from_errors(&mut eh)?;
            Some(if metric == Metric::Horizontal1 {
                s.sigma1
            } else {
                s.sigma2
            })
        }
        Metric::AteMean | Metric::AteRmse => {
            let (truth, est): (Vec<Vector3<f64>>, Vec<Vector3<f64>>) = trace
                .epochs
                .iter()
                .filter_map(|e| Some((Vector3::from(e.truth_ecef_m), Vector3::from(e.est_ecef_m?))))
                .unzip();
            let mut ate = ate_errors(&truth, &est, Alignment::None)?;
            let s = TrajectoryStats::from_errors(&mut ate)?;
            Some(if metric == Metric::AteMean {
                s.mean
            } else {
                s.rmse
            })
        }
        Metric::RpeMean | Metric::RpeRmse => None,
    }
}

/// Fills each ordering's [`OrderingResult::paired`] from the run's trials (`names` are the
/// world's estimator names, in the order of each trial's traces).
pub fn pair(orderings: &mut [OrderingResult], trials: &[TrialResult], names: &[String]) {
    for o in orderings {
        if o.metric == Metric::RpeMean || o.metric == Metric::RpeRmse {
            o.paired = vec![None; o.values.len().saturating_sub(1)];
            continue;
        }
        // Each estimator of the claim, its value in every trial (`None` for a name the
        // world lacks), taken once though the middle one of `a < b < c` is in two pairs.
        let per_trial: Vec<Option<Vec<Option<f64>>>> = o
            .values
            .iter()
            .map(|(name, _)| {
                let k = names.iter().position(|x| x == name)?;
                Some(
                    trials
                        .iter()
                        .map(|t| t.estimators.get(k).and_then(|e| trial_metric(e, o.metric)))
                        .collect(),
                )
            })
            .collect();
        o.paired = per_trial
            .windows(2)
            .map(|w| {
                let (a, b) = (w[0].as_ref()?, w[1].as_ref()?);
                Some(PairedSign::of(a.iter().copied().zip(b.iter().copied())))
            })
            .collect();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The exact two-sided sign test against its closed forms: 20 of 20 is `2 · 2⁻²⁰`;
    /// 15 of 20 is `2 · Σ_{i ≤ 5} C(20, i) / 2²⁰ = 2 · 21 700 / 1 048 576`; an even split
    /// and no pair give 1; 0 of n is the same as n of n.
    #[test]
    fn the_sign_test_has_its_binomial_tails() {
        assert!((sign_test_p(20, 20) - 2.0 * 0.5f64.powi(20)).abs() < 1e-18);
        assert!((sign_test_p(15, 20) - 2.0 * 21_700.0 / 1_048_576.0).abs() < 1e-14);
        assert_eq!(sign_test_p(10, 20), 1.0);
        assert_eq!(sign_test_p(0, 0), 1.0);
        assert_eq!(sign_test_p(0, 7), sign_test_p(7, 7));
        // Large n stays finite: 600 of 1000 is far out in the tail (normal approximation
        // z = 6.3, two-sided ≈ 2.5e-10).
        let p = sign_test_p(600, 1000);
        assert!(p > 1e-10 && p < 5e-10, "{p}");
    }

    /// Ties (within 0.1 %) and missing values count in neither direction.
    #[test]
    fn pairs_split_into_holds_reversed_and_ties() {
        let s = PairedSign::of([
            (Some(1.0), Some(2.0)),
            (Some(3.0), Some(2.0)),
            (Some(1.0), Some(1.0005)),
            (None, Some(1.0)),
            (Some(0.5), Some(0.9)),
        ]);
        assert_eq!((s.holds, s.reversed, s.ties), (2, 1, 2));
        assert_eq!(s.p, sign_test_p(2, 3));
        let t = PairedSign::of([(Some(1.0), Some(2.0)), (Some(1.0), Some(3.0))]);
        let both = PairedSign::pooled([&s, &t]);
        assert_eq!((both.holds, both.reversed, both.ties), (4, 1, 2));
        assert_eq!(both.p, sign_test_p(4, 5));
    }
}
