//! Filter consistency over Monte Carlo runs: the normalised estimation error squared
//! (NEES) and the normalised innovation squared (NIS) against their χ² acceptance bands
//! (Bar-Shalom, Li & Kirubarajan, "Estimation with Applications to Tracking and
//! Navigation", Wiley 2001, §5.4.2 and §5.4.3).
//!
//! For a consistent filter the NEES `ε = x̃ᵀ P⁻¹ x̃` of an n-dimensional state is χ²(n).
//! The average over N independent runs at one epoch, `ε̄ = (1/N) Σ_r ε_r`, satisfies
//! `N·ε̄ ~ χ²(N·n)`, so its two-sided 95 % acceptance band is
//!
//! `[χ²_{N·n}(0.025) / N, χ²_{N·n}(0.975) / N]`.
//!
//! The NIS `ν = rᵀ S⁻¹ r` of an m-dimensional innovation is χ²(m); its dimension may
//! change from sample to sample (the number of measurements used), and a sum of
//! independent χ² variables is χ² with the summed degrees of freedom, so the band of an
//! average over samples with dimensions `m_k` is `[χ²_{Σm}(0.025), χ²_{Σm}(0.975)] / N`
//! around the expectation `Σm / N`. The NEES is the special case of a constant dimension,
//! and both are summarised by [`ConsistencySummary`].
//!
//! Two bands are reported. The per-epoch band checks each epoch's average over the runs;
//! about 95 % of the epochs of a consistent filter fall inside it
//! (`share_of_epochs_inside_band`). The overall band checks the average over every epoch
//! and run; it treats all samples as independent, which the runs are but successive
//! epochs of one run are not (the errors of a filter are correlated in time), so it is
//! narrower than the truth and an overall `inside = false` is a hint, not a verdict.

use serde::Serialize;

use crate::core::stats::chi2;

/// The probability mass of the acceptance bands.
pub const BAND_PROBABILITY: f64 = 0.95;

/// The band `[χ²_{dof}(α/2), χ²_{dof}(1 − α/2)] / count` of an average of `count`
/// samples whose degrees of freedom sum to `dof`.
pub fn chi2_band(dof: f64, count: usize) -> (f64, f64) {
    let alpha = 1.0 - BAND_PROBABILITY;
    let n = count as f64;
    (
        chi2::quantile(0.5 * alpha, dof) / n,
        chi2::quantile(1.0 - 0.5 * alpha, dof) / n,
    )
}

/// The runs' average at one epoch and its acceptance band.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct EpochConsistency {
    /// The average of the statistic over the runs that have a value at this epoch.
    pub mean: f64,
    /// Its expectation for a consistent filter: the average degrees of freedom.
    pub dof: f64,
    pub band_lo: f64,
    pub band_hi: f64,
    /// The number of runs averaged.
    pub runs: usize,
}

impl EpochConsistency {
    /// True when the average lies inside its band (bounds included).
    pub fn inside(&self) -> bool {
        self.band_lo <= self.mean && self.mean <= self.band_hi
    }
}

/// Summary of the NEES or NIS of a Monte Carlo run set (see the module documentation).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ConsistencySummary {
    /// The average of the statistic over every epoch and run.
    pub mean: f64,
    /// Its expectation for a consistent filter: the average degrees of freedom per
    /// sample (the state dimension n for the NEES).
    pub dof: f64,
    /// The 95 % band of `mean`, `[χ²_{Σm}(0.025), χ²_{Σm}(0.975)] / samples`, which
    /// treats every sample as independent.
    pub band_lo: f64,
    pub band_hi: f64,
    /// Whether `mean` lies inside `[band_lo, band_hi]`.
    pub inside: bool,
    /// The largest number of runs at any epoch (N).
    pub runs: usize,
    /// The number of epochs with at least one run.
    pub epochs: usize,
    /// The number of samples averaged into `mean`.
    pub samples: usize,
    /// The per-epoch band for an average over `runs` runs with `dof` degrees of freedom
    /// each, `[χ²_{N·n}(0.025)/N, χ²_{N·n}(0.975)/N]`, to draw under a plot. (Each epoch
    /// is checked against its own band, which differs where runs are missing or the
    /// NIS dimension changes.)
    pub epoch_band_lo: f64,
    pub epoch_band_hi: f64,
    /// The share of epochs whose run average lies inside its own band; about 0.95 for
    /// a consistent filter.
    pub share_of_epochs_inside_band: f64,
}

/// The run average and band of one epoch's samples `(value, dof)`: `Ok(None)` for an
/// epoch without samples, `Err(())` when a value is negative or not finite or a dof is
/// not positive.
fn epoch_from_samples(
    samples: impl Iterator<Item = (f64, f64)>,
) -> Result<Option<EpochConsistency>, ()> {
    let mut acc = EpochSamples::default();
    for (v, m) in samples {
        acc.push(v, m);
    }
    acc.finish()
}

/// One epoch's NEES or NIS values across runs, accumulated one run at a time so that a
/// Monte Carlo run need not keep every value (the sums are taken in push order).
#[derive(Clone, Copy, Debug, Default)]
pub struct EpochSamples {
    sum: f64,
    dof: f64,
    n: usize,
    invalid: bool,
}

impl EpochSamples {
    /// Adds run's value `v` with `m` degrees of freedom.
    pub fn push(&mut self, v: f64, m: f64) {
        if !(v.is_finite() && v >= 0.0 && m.is_finite() && m > 0.0) {
            self.invalid = true;
        }
        self.sum += v;
        self.dof += m;
        self.n += 1;
    }

    /// The epoch's consistency; `Ok(None)` without values, `Err` when a value was negative
    /// or not finite or a dimension not positive.
    #[allow(clippy::result_unit_err)]
    pub fn finish(&self) -> Result<Option<EpochConsistency>, ()> {
        if self.invalid {
            return Err(());
        }
        if self.n == 0 {
            return Ok(None);
        }
        let (band_lo, band_hi) = chi2_band(self.dof, self.n);
        Ok(Some(EpochConsistency {
            mean: self.sum / self.n as f64,
            dof: self.dof / self.n as f64,
            band_lo,
            band_hi,
            runs: self.n,
        }))
    }
}

/// The summary of epochs accumulated with [`EpochSamples`], in epoch order; `None` when a
/// value was invalid or there is none.
pub fn summary_of_samples<'a>(
    epochs: impl Iterator<Item = &'a EpochSamples>,
) -> Option<ConsistencySummary> {
    let mut out = Vec::new();
    for e in epochs {
        if let Some(c) = e.finish().ok()? {
            out.push(c);
        }
    }
    summarise(&out)
}

/// The summary of per-epoch results (`None` when there are none).
fn summarise(epochs: &[EpochConsistency]) -> Option<ConsistencySummary> {
    if epochs.is_empty() {
        return None;
    }
    let samples: usize = epochs.iter().map(|e| e.runs).sum();
    let sum: f64 = epochs.iter().map(|e| e.mean * e.runs as f64).sum();
    let dof_sum: f64 = epochs.iter().map(|e| e.dof * e.runs as f64).sum();
    let runs = epochs.iter().map(|e| e.runs).max().unwrap_or(0);
    let dof = dof_sum / samples as f64;
    let mean = sum / samples as f64;
    let (band_lo, band_hi) = chi2_band(dof_sum, samples);
    let (epoch_band_lo, epoch_band_hi) = chi2_band(dof * runs as f64, runs);
    let inside_count = epochs.iter().filter(|e| e.inside()).count();
    Some(ConsistencySummary {
        mean,
        dof,
        band_lo,
        band_hi,
        inside: band_lo <= mean && mean <= band_hi,
        runs,
        epochs: epochs.len(),
        samples,
        epoch_band_lo,
        epoch_band_hi,
        share_of_epochs_inside_band: inside_count as f64 / epochs.len() as f64,
    })
}

/// The NEES of each epoch: `per_epoch[k]` holds the NEES of every run that has an
/// estimate at epoch k (runs without one are left out, so the count may vary), `dof` is
/// the dimension n of the error. Epochs without a value are skipped. `None` when `dof` is
/// zero or a value is negative or not finite (a diverged run must be reported).
pub fn nees_epochs<E: AsRef<[f64]>>(per_epoch: &[E], dof: usize) -> Option<Vec<EpochConsistency>> {
    if dof == 0 {
        return None;
    }
    let dof = dof as f64;
    let mut out = Vec::with_capacity(per_epoch.len());
    for e in per_epoch {
        if let Some(epoch) = epoch_from_samples(e.as_ref().iter().map(|&v| (v, dof))).ok()? {
            out.push(epoch);
        }
    }
    Some(out)
}

/// The NEES summary of a Monte Carlo run set; arguments as [`nees_epochs`]. `None` also
/// when there is no value at all.
pub fn nees_summary<E: AsRef<[f64]>>(per_epoch: &[E], dof: usize) -> Option<ConsistencySummary> {
    summarise(&nees_epochs(per_epoch, dof)?)
}

/// The NIS of each epoch: `per_epoch[k]` holds `(nis, dim)` for every run with an
/// update at epoch k, `dim` the number of scalar measurements in that innovation.
/// `None` when a value is negative or not finite or a dimension is zero.
pub fn nis_epochs<E: AsRef<[(f64, usize)]>>(per_epoch: &[E]) -> Option<Vec<EpochConsistency>> {
    let mut out = Vec::with_capacity(per_epoch.len());
    for e in per_epoch {
        let samples = e.as_ref().iter().map(|&(v, m)| (v, m as f64));
        if let Some(epoch) = epoch_from_samples(samples).ok()? {
            out.push(epoch);
        }
    }
    Some(out)
}

/// The NIS summary of a Monte Carlo run set; arguments as [`nis_epochs`]. `None` also
/// when there is no value at all.
pub fn nis_summary<E: AsRef<[(f64, usize)]>>(per_epoch: &[E]) -> Option<ConsistencySummary> {
    summarise(&nis_epochs(per_epoch)?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::TrialRng;
    use rand::Rng;
    use rand_distr::StandardNormal;

    #[test]
    fn band_matches_chi2_tables() {
        // Bar-Shalom et al. (2001) §5.4.2: N = 50 runs, n = 3 gives the 95 % band
        // [2.36, 3.72] (χ²_150 = 117.98, 185.80). SciPy, stats.chi2.ppf / N:
        // 2.359690308058058, 3.716008940075865; N = 100: 2.539123226, 3.498744688.
        let (lo, hi) = chi2_band(150.0, 50);
        assert!((lo - 2.36).abs() < 5e-3 && (hi - 3.72).abs() < 5e-3);
        assert!((lo - 2.359_690_308_058_058).abs() < 1e-9);
        assert!((hi - 3.716_008_940_075_865).abs() < 1e-9);
        let (lo, hi) = chi2_band(300.0, 100);
        assert!((lo - 2.539_123_226_024_897_5).abs() < 1e-9);
        assert!((hi - 3.498_744_688_299_152_6).abs() < 1e-9);
        // One run, n = 2: χ²_2 quantiles −2 ln(1 − p) = 0.050636, 7.377759.
        let (lo, hi) = chi2_band(2.0, 1);
        assert!((lo + 2.0 * 0.975f64.ln()).abs() < 1e-12);
        assert!((hi + 2.0 * 0.025f64.ln()).abs() < 1e-9);
    }

    /// NEES of `runs` runs × `epochs` epochs of a consistent n = 3 "filter": the errors
    /// are drawn from the covariance the filter claims, scaled by `scale`.
    fn simulated_nees(runs: usize, epochs: usize, scale: f64) -> Vec<Vec<f64>> {
        let mut rng = TrialRng::new(11, 0).stream("test/nees");
        (0..epochs)
            .map(|_| {
                (0..runs)
                    .map(|_| {
                        (0..3)
                            .map(|_| (scale * rng.sample::<f64, _>(StandardNormal)).powi(2))
                            .sum()
                    })
                    .collect()
            })
            .collect()
    }

    #[test]
    fn consistent_filter_passes_and_overconfident_one_fails() {
        let good = nees_summary(&simulated_nees(50, 400, 1.0), 3).unwrap();
        assert_eq!((good.runs, good.epochs, good.samples), (50, 400, 20_000));
        assert_eq!(good.dof, 3.0);
        assert!((good.mean - 3.0).abs() < 0.1, "{good:?}");
        assert!(good.inside, "{good:?}");
        assert!((good.epoch_band_lo - 2.359_690_308).abs() < 1e-8);
        // About 95 % of the epochs inside (binomial sd over 400 epochs ≈ 1.1 %).
        assert!(
            (good.share_of_epochs_inside_band - 0.95).abs() < 0.04,
            "{good:?}"
        );
        // Errors 30 % larger than the covariance claims.
        let bad = nees_summary(&simulated_nees(50, 400, 1.3), 3).unwrap();
        assert!(!bad.inside && bad.mean > bad.band_hi, "{bad:?}");
        assert!(bad.share_of_epochs_inside_band < 0.5, "{bad:?}");
    }

    #[test]
    fn missing_runs_and_varying_nis_dimensions() {
        // Epoch 0: two runs; epoch 1: none (skipped); epoch 2: one run.
        let per_epoch: Vec<Vec<f64>> = vec![vec![1.0, 5.0], vec![], vec![2.0]];
        let e = nees_epochs(&per_epoch, 2).unwrap();
        assert_eq!(e.len(), 2);
        assert_eq!((e[0].mean, e[0].runs, e[1].runs), (3.0, 2, 1));
        assert_eq!((e[0].band_lo, e[0].band_hi), chi2_band(4.0, 2));
        let s = nees_summary(&per_epoch, 2).unwrap();
        assert_eq!((s.mean, s.samples, s.runs, s.epochs), (8.0 / 3.0, 3, 2, 2));
        assert_eq!((s.band_lo, s.band_hi), chi2_band(6.0, 3));
        // NIS with 4 and 6 measurements: expectation 5, band from χ²_10 / 2.
        let nis = vec![vec![(3.0, 4), (8.0, 6)]];
        let s = nis_summary(&nis).unwrap();
        assert_eq!((s.mean, s.dof), (5.5, 5.0));
        assert_eq!((s.band_lo, s.band_hi), chi2_band(10.0, 2));
        assert!(s.inside);
    }

    #[test]
    fn bad_input_is_refused() {
        assert!(nees_summary(&[vec![1.0, f64::NAN]], 3).is_none());
        assert!(nees_summary(&[vec![-1.0]], 3).is_none());
        assert!(nees_summary(&[vec![1.0]], 0).is_none());
        assert!(nees_summary::<Vec<f64>>(&[], 3).is_none());
        assert!(nis_summary(&[vec![(1.0, 0)]]).is_none());
    }
}
