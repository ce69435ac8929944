//! Error statistics of estimators against the truth.
//!
//! The σ-levels follow the convention of seed 000's tables: the 68.27 %, 95.45 % and
//! 99.73 % percentiles of the 3-D position error (the fractions of a Gaussian within 1, 2
//! and 3 σ). Percentiles use linear interpolation between order statistics (Hyndman & Fan
//! type 7, numpy's default), so a user can recompute them from `trials.parquet`.
//!
//! The submodules add the trajectory errors of the TUM benchmark ([`trajectory`]: ATE,
//! RPE, TUM files), filter consistency against χ² bands ([`consistency`]: NEES, NIS),
//! confidence intervals across trials ([`interval`]) and the empirical CDF ([`mod@ecdf`]).

pub mod consistency;
pub mod ecdf;
pub mod interval;
pub mod summary;
pub mod trajectory;

pub use consistency::{
    chi2_band, nees_epochs, nees_summary, nis_epochs, nis_summary, summary_of_samples,
    ConsistencySummary, EpochConsistency, EpochSamples,
};
pub use ecdf::{ecdf, ecdf_of};
pub use interval::{
    bootstrap_ci, mean_ci95, positive_ci95, student_t_cdf, student_t_quantile, unit_ci95, MeanCi95,
};
pub use trajectory::{
    ate, ate_errors, rigid_alignment, rpe, rpe_errors, write_tum, Alignment, TrajectoryStats,
};

use crate::io::spill::SortedSpill;
use serde::Serialize;

/// The probability masses of the 1σ, 2σ and 3σ levels.
pub const SIGMA_LEVELS: [f64; 3] = [0.6827, 0.9545, 0.9973];

/// Summary statistics of a set of errors (metres).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Default)]
pub struct ErrorStats {
    pub sigma1: f64,
    pub sigma2: f64,
    pub sigma3: f64,
    pub mean: f64,
    pub std: f64,
    pub rmse: f64,
    pub max: f64,
    /// Number of samples the statistics were computed from.
    pub count: usize,
}

/// The `p`-quantile (0 ≤ p ≤ 1) of sorted data, type 7 (linear interpolation).
///
/// # Panics
/// Never: an empty slice gives NaN.
pub fn quantile_sorted(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let (lo, hi, w) = quantile_ranks(sorted.len(), p);
    sorted[lo] + w * (sorted[hi] - sorted[lo])
}

/// The ranks `(lo, hi)` and weight of the type-7 `p`-quantile of `n ≥ 1` sorted values:
/// `x_lo + w (x_hi − x_lo)`.
fn quantile_ranks(n: usize, p: f64) -> (usize, usize, f64) {
    let h = (n - 1) as f64 * p.clamp(0.0, 1.0);
    let lo = h.floor() as usize;
    (lo, (lo + 1).min(n - 1), h - lo as f64)
}

/// Values in ascending `total_cmp` order that can be visited more than once: a sorted
/// slice, or a [`SortedSpill`] holding more than memory should.
pub trait SortedValues {
    /// How many values there are.
    fn count(&self) -> usize;
    /// Calls `f(rank, value)` for every value in order.
    ///
    /// # Errors
    /// When values kept on disk cannot be read back.
    fn pass(&mut self, f: &mut dyn FnMut(usize, f64)) -> std::io::Result<()>;
}

impl SortedValues for &[f64] {
    fn count(&self) -> usize {
        self.len()
    }
    fn pass(&mut self, f: &mut dyn FnMut(usize, f64)) -> std::io::Result<()> {
        for (i, &v) in self.iter().enumerate() {
            f(i, v);
        }
        Ok(())
    }
}

impl SortedValues for SortedSpill {
    fn count(&self) -> usize {
        self.len()
    }
    fn pass(&mut self, f: &mut dyn FnMut(usize, f64)) -> std::io::Result<()> {
        self.for_each_sorted(f)
    }
}

/// What [`sorted_moments`] gathers in two passes over sorted values.
pub(crate) struct SortedMoments {
    pub mean: f64,
    /// Σ (x − mean)².
    pub sq_dev: f64,
    /// Σ x².
    pub sq: f64,
    /// The values at the requested ranks, in the order asked.
    pub at: Vec<f64>,
}

/// Mean, squared deviations, squares and the values at `ranks` of `n ≥ 1` sorted values,
/// summed in ascending order (so a slice and a spill of the same values agree to the bit).
pub(crate) fn sorted_moments(
    v: &mut dyn SortedValues,
    ranks: &[usize],
) -> std::io::Result<SortedMoments> {
    let n = v.count();
    let (mut sum, mut sq) = (0.0, 0.0);
    let mut at = vec![f64::NAN; ranks.len()];
    v.pass(&mut |i, x| {
        sum += x;
        sq += x * x;
        for (slot, &r) in at.iter_mut().zip(ranks) {
            if r == i {
                *slot = x;
            }
        }
    })?;
    let mean = sum / n as f64;
    let mut sq_dev = 0.0;
    v.pass(&mut |_, x| sq_dev += (x - mean).powi(2))?;
    Ok(SortedMoments {
        mean,
        sq_dev,
        sq,
        at,
    })
}

impl ErrorStats {
    /// Statistics of `errors`; the slice is sorted in place. Returns `None` when empty or
    /// when any error is not finite (a filter that diverged must be reported, not averaged).
    pub fn from_errors(errors: &mut [f64]) -> Option<Self> {
        if errors.iter().any(|e| !e.is_finite()) {
            return None;
        }
        errors.sort_by(f64::total_cmp);
        let mut sorted: &[f64] = errors;
        Self::from_sorted(&mut sorted).ok().flatten()
    }

    /// Statistics of finite values already in ascending order (`None` when there are
    /// none); the caller checks finiteness, as [`SortedSpill::non_finite`] allows.
    ///
    /// # Errors
    /// When values kept on disk cannot be read back.
    pub fn from_sorted(v: &mut dyn SortedValues) -> std::io::Result<Option<Self>> {
        let n = v.count();
        if n == 0 {
            return Ok(None);
        }
        let q = SIGMA_LEVELS.map(|p| quantile_ranks(n, p));
        let ranks: Vec<usize> = q
            .iter()
            .flat_map(|&(lo, hi, _)| [lo, hi])
            .chain([n - 1])
            .collect();
        let m = sorted_moments(v, &ranks)?;
        let level = |k: usize| {
            let (lo, hi) = (m.at[2 * k], m.at[2 * k + 1]);
            lo + q[k].2 * (hi - lo)
        };
        let nf = n as f64;
        Ok(Some(Self {
            sigma1: level(0),
            sigma2: level(1),
            sigma3: level(2),
            mean: m.mean,
            std: if n > 1 {
                (m.sq_dev / (nf - 1.0)).sqrt()
            } else {
                0.0
            },
            rmse: (m.sq / nf).sqrt(),
            max: m.at[6],
            count: n,
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_match_numpy_type7() {
        // numpy.percentile([1, 2, 3, 4, 5], [68.27, 95.45, 99.73]) = 3.7308, 4.818, 4.9892.
        let v = [1.0, 2.0, 3.0, 4.0, 5.0];
        assert!((quantile_sorted(&v, 0.6827) - 3.7308).abs() < 1e-12);
        assert!((quantile_sorted(&v, 0.9545) - 4.818).abs() < 1e-12);
        assert!((quantile_sorted(&v, 0.9973) - 4.9892).abs() < 1e-12);
    }

    #[test]
    fn rayleigh_sigma_levels() {
        // The 3-D error of an isotropic Gaussian with σ = 1 per axis follows a Maxwell
        // distribution whose 68.27 % point is 1.8776 (chi with 3 degrees of freedom).
        // Build a large deterministic sample from its inverse CDF by bisection.
        let cdf = |r: f64| {
            use std::f64::consts::PI;
            libm_erf(r / 2f64.sqrt()) - (2.0 / PI).sqrt() * r * (-r * r / 2.0).exp()
        };
        let n = 20_000;
        let mut samples: Vec<f64> = (0..n)
            .map(|i| {
                let u = (i as f64 + 0.5) / n as f64;
                let (mut lo, mut hi) = (0.0, 10.0);
                for _ in 0..60 {
                    let mid = 0.5 * (lo + hi);
                    if cdf(mid) < u {
                        lo = mid
                    } else {
                        hi = mid
                    }
                }
                0.5 * (lo + hi)
            })
            .collect();
        let s = ErrorStats::from_errors(&mut samples).unwrap();
        assert!((s.sigma1 - 1.8776).abs() < 2e-3, "{}", s.sigma1);
        // Mean of the Maxwell distribution: 2·√(2/π) = 1.59577.
        assert!((s.mean - 1.59577).abs() < 1e-3, "{}", s.mean);
        // RMS of a 3-D unit Gaussian: √3.
        assert!((s.rmse - 3f64.sqrt()).abs() < 2e-3, "{}", s.rmse);
    }

    /// erf by Abramowitz & Stegun 7.1.26 refined with a series; accurate to 1e-9 here.
    fn libm_erf(x: f64) -> f64 {
        // Series for |x| < 3, continued fraction beyond.
        if x.abs() < 3.0 {
            let mut sum = x;
            let mut term = x;
            let x2 = x * x;
            for n in 1..200 {
                term *= -x2 / n as f64;
                let add = term / (2 * n + 1) as f64;
                sum += add;
                if add.abs() < 1e-17 {
                    break;
                }
            }
            2.0 / std::f64::consts::PI.sqrt() * sum
        } else {
            1.0f64.copysign(x)
        }
    }

    #[test]
    fn non_finite_is_refused() {
        assert!(ErrorStats::from_errors(&mut [1.0, f64::NAN]).is_none());
        assert!(ErrorStats::from_errors(&mut []).is_none());
    }
}
