//! Overlapping Allan deviation of rate data (IEEE Std 952-1997, Annex C; Riley, NIST
//! SP 1065, eq. 14).
//!
//! For rate samples y_k at interval τ₀, the "phase" (integrated rate) is
//! x_0 = 0, x_{i+1} = x_i + τ₀ y_i (N = n + 1 points), and for τ = m τ₀
//!
//! ```text
//! σ_A²(τ) = Σ_{i=0}^{N−2m−1} (x_{i+2m} − 2 x_{i+m} + x_i)² / (2 (N − 2m) τ²)
//! ```
//!
//! which is exactly what the `allantools` Python package computes in `oadev` with
//! `data_type = "freq"` (the cross-check in `tests/inertial.rs`). For the noise terms of an
//! inertial sensor (IEEE 952 Table C.1): white rate noise of density N gives σ_A = N/√τ
//! (so σ_A(1 s) = N), rate random walk K gives K √(τ/3), and bias instability gives the
//! floor (see [`crate::inertial::imu`] for our Gauss–Markov calibration).

/// One point of an Allan deviation curve.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AllanPoint {
    /// Averaging time τ = m τ₀ (s).
    pub tau_s: f64,
    /// Cluster size m (samples).
    pub m: usize,
    /// Overlapping Allan deviation (units of the input).
    pub adev: f64,
    /// Number of second differences averaged, N − 2m.
    pub terms: usize,
}

/// Cluster sizes 1, 2, 4, … (octave spacing) with at least `min_terms` second differences
/// each, for a record of `n` samples.
pub fn octave_cluster_sizes(n: usize, min_terms: usize) -> Vec<usize> {
    let mut out = Vec::new();
    let mut m = 1usize;
    while n + 1 >= 2 * m + min_terms.max(1) {
        out.push(m);
        m *= 2;
    }
    out
}

/// Cluster sizes spaced `per_decade` to a decade (deduplicated), as allantools' "decade"
/// taus, with at least `min_terms` second differences each.
pub fn log_cluster_sizes(n: usize, per_decade: usize, min_terms: usize) -> Vec<usize> {
    let mut out: Vec<usize> = Vec::new();
    let per_decade = per_decade.max(1) as f64;
    let mut k = 0.0;
    loop {
        let m = 10f64.powf(k / per_decade).round() as usize;
        if n + 1 < 2 * m + min_terms.max(1) {
            break;
        }
        if out.last() != Some(&m) {
            out.push(m);
        }
        k += 1.0;
    }
    out
}

/// Overlapping Allan deviation of the rate series `y` sampled every `tau0_s`, at the
/// cluster sizes `ms` (sizes with fewer than one second difference are skipped).
/// Uses O(n) memory for the phase and O(n) time per cluster size.
pub fn overlapping_adev(y: &[f64], tau0_s: f64, ms: &[usize]) -> Vec<AllanPoint> {
    let mut x = Vec::with_capacity(y.len() + 1);
    let mut acc = 0.0;
    x.push(0.0);
    for v in y {
        acc += v * tau0_s;
        x.push(acc);
    }
    let big_n = x.len();
    ms.iter()
        .filter(|&&m| m >= 1 && big_n > 2 * m)
        .map(|&m| {
            let terms = big_n - 2 * m;
            let mut s = 0.0;
            for i in 0..terms {
                let d = x[i + 2 * m] - 2.0 * x[i + m] + x[i];
                s += d * d;
            }
            let tau_s = m as f64 * tau0_s;
            AllanPoint {
                tau_s,
                m,
                adev: (s / (2.0 * terms as f64)).sqrt() / tau_s,
                terms,
            }
        })
        .collect()
}

/// The Allan deviation at τ = 1 s read off a curve by log-log interpolation of the two
/// nearest points; with white noise of density N this is N (IEEE 952 Table C.1).
pub fn adev_at(curve: &[AllanPoint], tau_s: f64) -> Option<f64> {
    let i = curve.iter().position(|p| p.tau_s >= tau_s)?;
    if curve[i].tau_s == tau_s || i == 0 {
        return (curve[i].tau_s == tau_s).then_some(curve[i].adev);
    }
    let (a, b) = (curve[i - 1], curve[i]);
    let w = (tau_s.ln() - a.tau_s.ln()) / (b.tau_s.ln() - a.tau_s.ln());
    Some((a.adev.ln() * (1.0 - w) + b.adev.ln() * w).exp())
}

/// The white-noise density N fitted to the τ^{−1/2} region: the least-squares fit of
/// σ_A(τ) √τ over the points with `tau_lo_s ≤ τ ≤ tau_hi_s`, in log space.
pub fn fit_white_density(curve: &[AllanPoint], tau_lo_s: f64, tau_hi_s: f64) -> Option<f64> {
    let v: Vec<f64> = curve
        .iter()
        .filter(|p| p.tau_s >= tau_lo_s && p.tau_s <= tau_hi_s)
        .map(|p| (p.adev * p.tau_s.sqrt()).ln())
        .collect();
    (!v.is_empty()).then(|| (v.iter().sum::<f64>() / v.len() as f64).exp())
}

/// The flat floor: the smallest Allan deviation on the curve for τ ≥ `tau_min_s`.
pub fn floor(curve: &[AllanPoint], tau_min_s: f64) -> Option<AllanPoint> {
    curve
        .iter()
        .filter(|p| p.tau_s >= tau_min_s)
        .copied()
        .min_by(|a, b| a.adev.total_cmp(&b.adev))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::TrialRng;
    use rand::Rng;
    use rand_distr::StandardNormal;

    #[test]
    fn white_noise_gives_n_over_sqrt_tau() {
        // σ_A(τ) = σ √(τ₀/τ) for white noise of per-sample σ; with τ₀ = 0.01 s, σ = 0.1 the
        // density is N = σ √τ₀ = 0.01 and σ_A(1 s) = 0.01.
        let mut rng = TrialRng::new(3, 0).stream("allan/white");
        let y: Vec<f64> = (0..400_000)
            .map(|_| 0.1 * rng.sample::<f64, _>(StandardNormal))
            .collect();
        let curve = overlapping_adev(&y, 0.01, &log_cluster_sizes(y.len(), 10, 100));
        let at1 = adev_at(&curve, 1.0).unwrap();
        assert!((at1 / 0.01 - 1.0).abs() < 0.03, "{at1}");
        let n = fit_white_density(&curve, 0.01, 10.0).unwrap();
        assert!((n / 0.01 - 1.0).abs() < 0.02, "{n}");
    }

    #[test]
    fn hand_computed_small_series() {
        // y = [1, 3, 2, 6], τ₀ = 1: x = [0, 1, 4, 6, 12]. m = 1: second differences 2, −1, 4,
        // σ² = (4 + 1 + 16) / (2·3) = 3.5.
        let c = overlapping_adev(&[1.0, 3.0, 2.0, 6.0], 1.0, &[1, 2, 3]);
        assert_eq!(c.len(), 2);
        assert!((c[0].adev - 3.5f64.sqrt()).abs() < 1e-15);
        // m = 2: one difference 12 − 8 + 0 = 4, σ² = 16 / (2 · 4) = 2.
        assert!((c[1].adev - 2f64.sqrt()).abs() < 1e-15);
        assert_eq!(octave_cluster_sizes(4, 1), vec![1, 2]);
    }
}
