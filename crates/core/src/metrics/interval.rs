//! Confidence intervals across Monte Carlo trials: Student's t interval of a mean and the
//! percentile bootstrap of any statistic, both at 95 %.
//!
//! The t quantile is computed, not tabulated: the CDF of Student's t with ν degrees of
//! freedom is `F(t) = 1 − ½ I_x(ν/2, ½)` for `t ≥ 0`, with `x = ν / (ν + t²)` and `I` the
//! regularised incomplete beta function (Abramowitz & Stegun 26.7.1), evaluated by its
//! continued fraction (A&S 26.5.8); the quantile is Newton's method on that tail inside a
//! shrinking bracket, as [`crate::core::stats::chi2::quantile`] does for χ².

use rand::Rng;

use super::quantile_sorted;
use crate::core::stats::chi2::{ln_gamma, normal_quantile};
use crate::core::TrialRng;

/// The two-sided confidence level of the intervals in this module.
pub const CONFIDENCE: f64 = 0.95;

/// The regularised incomplete beta function `I_x(a, b)` for `a, b > 0`, `0 ≤ x ≤ 1`.
///
/// The continued fraction converges quickly for `x < (a + 1)/(a + b + 2)`; above that the
/// symmetry `I_x(a, b) = 1 − I_{1−x}(b, a)` is used instead. NaN outside the domain.
pub fn beta_inc(a: f64, b: f64, x: f64) -> f64 {
    if !(a > 0.0 && b > 0.0 && (0.0..=1.0).contains(&x)) {
        return f64::NAN;
    }
    if x == 0.0 || x == 1.0 {
        return x;
    }
    let ln_front = ln_gamma(a + b) - ln_gamma(a) - ln_gamma(b) + a * x.ln() + b * (1.0 - x).ln();
    if x < (a + 1.0) / (a + b + 2.0) {
        ln_front.exp() * beta_continued_fraction(a, b, x) / a
    } else {
        1.0 - ln_front.exp() * beta_continued_fraction(b, a, 1.0 - x) / b
    }
}

/// The continued fraction of A&S 26.5.8, `1/(1+ d₁/(1+ d₂/(1+ …)))`, by the modified
/// Lentz method, with `d_{2m+1} = −(a+m)(a+b+m)x / ((a+2m)(a+2m+1))` and
/// `d_{2m} = m(b−m)x / ((a+2m−1)(a+2m))`.
fn beta_continued_fraction(a: f64, b: f64, x: f64) -> f64 {
    const TINY: f64 = 1e-300;
    let guard = |v: f64| if v.abs() < TINY { TINY } else { v };
    let mut c = 1.0;
    let mut d = 1.0 / guard(1.0 - (a + b) * x / (a + 1.0));
    let mut h = d;
    for m in 1..10_000 {
        let m = f64::from(m);
        let even = m * (b - m) * x / ((a + 2.0 * m - 1.0) * (a + 2.0 * m));
        d = 1.0 / guard(1.0 + even * d);
        c = guard(1.0 + even / c);
        h *= d * c;
        let odd = -(a + m) * (a + b + m) * x / ((a + 2.0 * m) * (a + 2.0 * m + 1.0));
        d = 1.0 / guard(1.0 + odd * d);
        c = guard(1.0 + odd / c);
        let delta = d * c;
        h *= delta;
        if (delta - 1.0).abs() < 1e-16 {
            break;
        }
    }
    h
}

/// The upper tail `P(T > t)` of Student's t with `dof` degrees of freedom, for `t ≥ 0`:
/// `½ I_{ν/(ν+t²)}(ν/2, ½)`. Working with the tail keeps its precision far out.
fn student_t_upper_tail(t: f64, dof: f64) -> f64 {
    0.5 * beta_inc(0.5 * dof, 0.5, dof / (dof + t * t))
}

/// The CDF of Student's t with `dof` (> 0, not necessarily integer) degrees of freedom.
pub fn student_t_cdf(t: f64, dof: f64) -> f64 {
    if dof.is_nan() || dof <= 0.0 || t.is_nan() {
        return f64::NAN;
    }
    let tail = student_t_upper_tail(t.abs(), dof);
    if t >= 0.0 {
        1.0 - tail
    } else {
        tail
    }
}

/// The quantile of Student's t with `dof` degrees of freedom at probability `p`
/// (0 < p < 1), accurate to about 1e-12 relative; NaN outside the domain.
///
/// The start is the normal quantile with the first Cornish–Fisher term,
/// `z + (z³ + z)/(4ν)` (A&S 26.7.5); Newton steps on the upper tail follow, with the
/// density `f(t) = Γ((ν+1)/2) / (√(νπ) Γ(ν/2)) · (1 + t²/ν)^{−(ν+1)/2}`.
pub fn student_t_quantile(p: f64, dof: f64) -> f64 {
    if !(p > 0.0 && p < 1.0 && dof > 0.0) {
        return f64::NAN;
    }
    if p == 0.5 {
        return 0.0;
    }
    // Solve for the upper tail q = P(T > t) with t > 0, then restore the sign.
    let q = if p > 0.5 { 1.0 - p } else { p };
    let ln_norm =
        ln_gamma(0.5 * (dof + 1.0)) - ln_gamma(0.5 * dof) - 0.5 * (dof * std::f64::consts::PI).ln();
    let pdf = |t: f64| (ln_norm - 0.5 * (dof + 1.0) * (t * t / dof).ln_1p()).exp();
    let z = normal_quantile(1.0 - q);
    let mut t = (z + (z * z * z + z) / (4.0 * dof)).max(1e-12);
    let (mut lo, mut hi) = (0.0_f64, f64::INFINITY);
    for _ in 0..300 {
        let g = student_t_upper_tail(t, dof) - q;
        if g == 0.0 {
            break;
        }
        // The tail decreases with t: a tail above q means t is too small.
        if g > 0.0 {
            lo = lo.max(t);
        } else {
            hi = hi.min(t);
        }
        let mut next = t + g / pdf(t);
        if !(next.is_finite() && next > lo && next < hi) {
            next = if hi.is_finite() {
                0.5 * (lo + hi)
            } else {
                2.0 * t.max(lo) + 1.0
            };
        }
        let converged = (next - t).abs() <= 1e-14 * t.abs();
        t = next;
        if converged {
            break;
        }
    }
    if p > 0.5 {
        t
    } else {
        -t
    }
}

/// The 95 % confidence interval of the mean of `values` (independent trials),
/// `x̄ ± t_{0.975, n−1} · s/√n` with `s` the sample standard deviation (divisor n − 1).
///
/// `None` with fewer than two values or a non-finite one.
pub fn mean_ci95(values: &[f64]) -> Option<(f64, f64)> {
    let mut acc = MeanCi95::default();
    for &v in values {
        acc.push(v);
    }
    acc.interval()
}

/// [`mean_ci95`] of values that arrive one at a time (one per Monte Carlo trial), in
/// constant memory: Welford's running mean and sum of squared deviations (Welford 1962,
/// "Note on a method for calculating corrected sums of squares and products",
/// Technometrics 4(3); Knuth, TAOCP vol. 2, §4.2.2), stable where the textbook
/// Σx² − n x̄² loses digits.
#[derive(Clone, Copy, Debug, Default)]
pub struct MeanCi95 {
    n: usize,
    mean: f64,
    m2: f64,
    non_finite: bool,
}

impl MeanCi95 {
    pub fn push(&mut self, v: f64) {
        if !v.is_finite() {
            self.non_finite = true;
            return;
        }
        self.n += 1;
        let d = v - self.mean;
        self.mean += d / self.n as f64;
        self.m2 += d * (v - self.mean);
    }

    /// Values pushed (finite ones).
    pub fn count(&self) -> usize {
        self.n
    }

    /// The interval; `None` with fewer than two values or after a non-finite one.
    pub fn interval(&self) -> Option<(f64, f64)> {
        if self.n < 2 || self.non_finite {
            return None;
        }
        let n = self.n as f64;
        let var = self.m2 / (n - 1.0);
        let half = student_t_quantile(0.5 + 0.5 * CONFIDENCE, n - 1.0) * (var / n).sqrt();
        Some((self.mean - half, self.mean + half))
    }
}

/// The 95 % interval of the mean of a positive statistic over trials, from the Student t
/// interval `[a, b]` (`x̄ ± h` with `h = t · s/√n`, [`MeanCi95::interval`]), taken on the log
/// scale: `x̄ · exp(∓ h / x̄)`.
///
/// By the delta method (Casella & Berger, "Statistical Inference", 2nd ed., §5.5.4) the
/// standard error of `ln x̄` is `s / (√n · x̄)`, so the t interval of `ln x̄` is
/// `ln x̄ ± h / x̄`; mapped back it is positive whatever the spread, where `x̄ ± h` falls
/// below zero for a skewed statistic over few trials. Its two ends multiply and divide
/// `x̄` by one factor; it is as wide as the t interval's to first order when `h ≪ x̄`.
/// `None` without an interval or with `x̄ ≤ 0`.
pub fn positive_ci95(t_interval: Option<[f64; 2]>) -> Option<[f64; 2]> {
    let [a, b] = t_interval?;
    let (mean, half) = (0.5 * (a + b), 0.5 * (b - a));
    if !(mean > 0.0 && half.is_finite() && half >= 0.0) {
        return None;
    }
    let f = (half / mean).exp();
    Some([mean / f, mean * f])
}

/// The 95 % interval of the mean of a share in [0, 1] (an availability) over trials, from
/// its Student t interval `[a, b]` (`p̄ ± h`), taken on the logit scale:
/// `expit(logit p̄ ∓ h / (p̄ (1 − p̄)))`.
///
/// By the delta method (as [`positive_ci95`]) the standard error of `logit p̄` is
/// `s / (√n · p̄ (1 − p̄))`; mapped back the interval stays inside (0, 1), where `p̄ ± h`
/// can pass 100 %. A share with no spread (`h = 0`, every trial 100 %) is its own
/// interval. `None` without an interval or with `p̄` outside [0, 1].
pub fn unit_ci95(t_interval: Option<[f64; 2]>) -> Option<[f64; 2]> {
    let [a, b] = t_interval?;
    let (p, half) = (0.5 * (a + b), 0.5 * (b - a));
    if !((0.0..=1.0).contains(&p) && half.is_finite() && half >= 0.0) {
        return None;
    }
    if half == 0.0 {
        return Some([p, p]);
    }
    if p == 0.0 || p == 1.0 {
        return None;
    }
    let logit = (p / (1.0 - p)).ln();
    let se = half / (p * (1.0 - p));
    let expit = |x: f64| 1.0 / (1.0 + (-x).exp());
    Some([expit(logit - se), expit(logit + se)])
}

/// The 95 % percentile bootstrap interval (Efron & Tibshirani, "An Introduction to the
/// Bootstrap", 1993, §13.3) of `stat` over `values`: `resamples` samples of the same size
/// are drawn with replacement, `stat` is evaluated on each (it may reorder its argument,
/// e.g. to take a median), and the 2.5 % and 97.5 % quantiles of those values (type 7,
/// as [`quantile_sorted`]) are the interval.
///
/// The draws come from the named stream `"metrics/bootstrap"` of seed `rng_seed` (there
/// is no global generator), so the same inputs and seed always give the same interval.
/// `None` when `values` is empty or not finite, `resamples` is zero, or `stat` returns a
/// non-finite value.
pub fn bootstrap_ci(
    values: &[f64],
    stat: impl Fn(&mut [f64]) -> f64,
    resamples: usize,
    rng_seed: u64,
) -> Option<(f64, f64)> {
    if values.is_empty() || resamples == 0 || values.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let mut rng = TrialRng::new(rng_seed, 0).stream("metrics/bootstrap");
    let mut sample = vec![0.0; values.len()];
    let mut stats = Vec::with_capacity(resamples);
    for _ in 0..resamples {
        for s in sample.iter_mut() {
            *s = values[rng.random_range(0..values.len())];
        }
        let v = stat(&mut sample);
        if !v.is_finite() {
            return None;
        }
        stats.push(v);
    }
    stats.sort_by(f64::total_cmp);
    let alpha = 0.5 * (1.0 - CONFIDENCE);
    Some((
        quantile_sorted(&stats, alpha),
        quantile_sorted(&stats, 1.0 - alpha),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_positive_statistics_interval_stays_positive_and_keeps_the_mean_between() {
        // Seed 003's EKF over two trials: the t interval of the mean error is
        // −1.50 … 14.14 m; on the log scale it is positive, with the mean 6.32 m inside
        // and the same factor to either end.
        let [a, b] = positive_ci95(Some([-1.5043050758396426, 14.143090424694964])).unwrap();
        let mean = 0.5 * (-1.5043050758396426 + 14.143090424694964);
        assert!(a > 0.0 && a < mean && mean < b, "{a} {b}");
        assert!((mean / a - b / mean).abs() < 1e-9 * b);
        // A tight interval is left as it was to first order: 100 ± 1 → 99.005 … 101.005.
        let [a, b] = positive_ci95(Some([99.0, 101.0])).unwrap();
        assert!(
            (a - 99.005).abs() < 1e-3 && (b - 101.005).abs() < 1e-3,
            "{a} {b}"
        );
        // Nothing to transform: no interval, or a mean of zero.
        assert!(positive_ci95(None).is_none());
        assert!(positive_ci95(Some([-1.0, 1.0])).is_none());
    }

    #[test]
    fn a_share_interval_stays_inside_zero_and_one() {
        // 0.99 ± 0.02 passes 100 %; on the logit scale it stays below, with p̄ inside.
        let [a, b] = unit_ci95(Some([0.97, 1.01])).unwrap();
        assert!(0.0 < a && a < 0.99 && 0.99 < b && b < 1.0, "{a} {b}");
        // Its standard error on the logit scale is h/(p(1−p)): the ends are symmetric there.
        let logit = |x: f64| (x / (1.0 - x)).ln();
        assert!((logit(b) - logit(0.99) - (logit(0.99) - logit(a))).abs() < 1e-9);
        assert!((logit(b) - logit(0.99) - 0.02 / (0.99 * 0.01)).abs() < 1e-9);
        // A tight interval is left as it was to first order.
        let [a, b] = unit_ci95(Some([0.499, 0.501])).unwrap();
        assert!(
            (a - 0.499).abs() < 1e-6 && (b - 0.501).abs() < 1e-6,
            "{a} {b}"
        );
        // Every trial at 100 %: no spread, the interval is the point.
        assert_eq!(unit_ci95(Some([1.0, 1.0])), Some([1.0, 1.0]));
        assert!(unit_ci95(Some([0.5, 1.7])).is_none());
    }

    #[test]
    fn t_quantiles_match_tables() {
        // The tables quoted to three decimals, then SciPy's stats.t.ppf to 1e-9.
        assert!((student_t_quantile(0.975, 4.0) - 2.776).abs() < 1e-3);
        assert!((student_t_quantile(0.975, 9.0) - 2.262).abs() < 1e-3);
        assert!((student_t_quantile(0.975, 29.0) - 2.045).abs() < 1e-3);
        for (p, dof, want) in [
            (0.975, 1.0, 12.706_204_736_174_694),
            (0.975, 2.0, 4.302_652_729_749_462),
            (0.975, 4.0, 2.776_445_105_197_793),
            (0.975, 9.0, 2.262_157_162_798_205),
            (0.975, 29.0, 2.045_229_642_132_703),
            (0.975, 100.0, 1.983_971_518_523_552),
            (0.975, 3.5, 2.940_088_637_982_728),
            (0.995, 1.0, 63.656_741_162_871_526),
            (0.995, 9.0, 3.249_835_541_592_126),
            (0.995, 29.0, 2.756_385_903_670_605),
            (1e-10, 7.0, -53.835_579_484_673_74),
        ] {
            let got = student_t_quantile(p, dof);
            assert!(
                (got - want).abs() < 1e-9 * want.abs(),
                "t({p}, {dof}) = {got}, want {want}"
            );
        }
    }

    #[test]
    fn t_quantile_inverts_the_cdf_and_has_closed_forms() {
        for dof in [1.0, 2.0, 3.0, 7.5, 40.0] {
            for p in [0.001, 0.1, 0.3, 0.5, 0.7, 0.9, 0.999] {
                let t = student_t_quantile(p, dof);
                assert!((student_t_cdf(t, dof) - p).abs() < 1e-13, "{p} {dof}");
            }
        }
        // ν = 1 is Cauchy: tan(π(p − ½)); ν = 2: (2p − 1)/√(2p(1 − p)).
        for p in [0.05, 0.6, 0.975] {
            let cauchy = (std::f64::consts::PI * (p - 0.5)).tan();
            assert!((student_t_quantile(p, 1.0) - cauchy).abs() < 1e-12 * cauchy.abs().max(1.0));
            let two = (2.0 * p - 1.0) / (2.0 * p * (1.0 - p)).sqrt();
            assert!((student_t_quantile(p, 2.0) - two).abs() < 1e-12 * two.abs().max(1.0));
        }
        assert!(student_t_quantile(1.0, 3.0).is_nan() && student_t_quantile(0.5, 0.0).is_nan());
    }

    #[test]
    fn mean_interval_by_hand() {
        // Mean 3, s² = 2.5, n = 5: 3 ± 2.776445 · √0.5.
        let (lo, hi) = mean_ci95(&[1.0, 2.0, 3.0, 4.0, 5.0]).unwrap();
        let half = 2.776_445_105_197_793 * 0.5f64.sqrt();
        assert!((lo - (3.0 - half)).abs() < 1e-12 && (hi - (3.0 + half)).abs() < 1e-12);
        assert!(mean_ci95(&[1.0]).is_none());
        assert!(mean_ci95(&[1.0, f64::NAN]).is_none());
    }

    #[test]
    fn bootstrap_is_deterministic_and_sensible() {
        let mut rng = TrialRng::new(3, 0).stream("test/bootstrap");
        let values: Vec<f64> = (0..200).map(|_| rng.random::<f64>() * 10.0).collect();
        let mean = |v: &mut [f64]| v.iter().sum::<f64>() / v.len() as f64;
        let a = bootstrap_ci(&values, mean, 2000, 42).unwrap();
        let b = bootstrap_ci(&values, mean, 2000, 42).unwrap();
        assert_eq!(a, b);
        assert_ne!(a, bootstrap_ci(&values, mean, 2000, 43).unwrap());
        // For a mean of 200 values the bootstrap and the t interval nearly agree.
        let (lo, hi) = mean_ci95(&values).unwrap();
        assert!(a.0 < a.1);
        assert!((a.0 - lo).abs() < 0.1 * (hi - lo) && (a.1 - hi).abs() < 0.1 * (hi - lo));
        // A median statistic may sort its resample.
        let median = |v: &mut [f64]| {
            v.sort_by(f64::total_cmp);
            quantile_sorted(v, 0.5)
        };
        let (mlo, mhi) = bootstrap_ci(&values, median, 500, 1).unwrap();
        assert!(mlo < mhi);
        assert!(bootstrap_ci(&[], mean, 10, 1).is_none());
        assert!(bootstrap_ci(&values, mean, 0, 1).is_none());
    }
}
