//! Small statistical functions shared by the filters and the propagation models.

/// The standard normal quantile Φ⁻¹(p): P. J. Acklam's rational approximation, relative
/// error below 1.2e-9 over (0, 1); −∞ at p ≤ 0 and +∞ at p ≥ 1.
pub fn normal_quantile(p: f64) -> f64 {
    const A: [f64; 6] = [
        -3.969_683_028_665_376e1,
        2.209_460_984_245_205e2,
        -2.759_285_104_469_687e2,
        1.383_577_518_672_69e2,
        -3.066_479_806_614_716e1,
        2.506_628_277_459_239,
    ];
    const B: [f64; 5] = [
        -5.447_609_879_822_406e1,
        1.615_858_368_580_409e2,
        -1.556_989_798_598_866e2,
        6.680_131_188_771_972e1,
        -1.328_068_155_288_572e1,
    ];
    const C: [f64; 6] = [
        -7.784_894_002_430_293e-3,
        -3.223_964_580_411_365e-1,
        -2.400_758_277_161_838,
        -2.549_732_539_343_734,
        4.374_664_141_464_968,
        2.938_163_982_698_783,
    ];
    const D: [f64; 4] = [
        7.784_695_709_041_462e-3,
        3.224_671_290_700_398e-1,
        2.445_134_137_142_996,
        3.754_408_661_907_416,
    ];
    const P_LOW: f64 = 0.024_25;
    if p <= 0.0 {
        return f64::NEG_INFINITY;
    }
    if p >= 1.0 {
        return f64::INFINITY;
    }
    let tail = |q: f64| {
        let q = (-2.0 * q.ln()).sqrt();
        (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    };
    if p < P_LOW {
        tail(p)
    } else if p > 1.0 - P_LOW {
        -tail(1.0 - p)
    } else {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    }
}

/// χ² distribution functions for filter-consistency tests (NEES, NIS).
///
/// The CDF is the regularised lower incomplete gamma function `P(k/2, x/2)`, evaluated by
/// its power series for `x < a + 1` and by Lentz's continued fraction for its complement
/// otherwise (Press et al., *Numerical Recipes*, 3rd ed., §6.2); `ln Γ` is Lanczos'
/// approximation with g = 7, n = 9 (error below 1e-15). The quantile starts from the
/// Wilson–Hilferty approximation and is polished by safeguarded Newton steps on the CDF.
///
/// Wilson–Hilferty (1931): `(X/k)^{1/3}` is nearly normal with mean `1 − 2/(9k)` and
/// variance `2/(9k)`, so `χ²_p(k) ≈ k·(1 − 2/(9k) + z_p·√(2/(9k)))³` with `z_p` the
/// standard normal quantile. Its relative error is below 1 % for k ≥ 3 and shrinks as
/// k grows; at k = 1 it is a few per cent in the tails.
pub mod chi2 {
    /// Natural log of the gamma function for `x > 0` (Lanczos, g = 7, n = 9).
    pub fn ln_gamma(x: f64) -> f64 {
        const G: f64 = 7.0;
        const COEF: [f64; 9] = [
            0.999_999_999_999_809_9,
            676.520_368_121_885_1,
            -1_259.139_216_722_402_8,
            771.323_428_777_653_1,
            -176.615_029_162_140_6,
            12.507_343_278_686_905,
            -0.138_571_095_265_720_12,
            9.984_369_578_019_572e-6,
            1.505_632_735_149_311_6e-7,
        ];
        if x < 0.5 {
            // Reflection: Γ(x)Γ(1 − x) = π / sin(πx).
            let pi = std::f64::consts::PI;
            return (pi / (pi * x).sin()).abs().ln() - ln_gamma(1.0 - x);
        }
        let x = x - 1.0;
        let mut a = COEF[0];
        for (i, &c) in COEF.iter().enumerate().skip(1) {
            a += c / (x + i as f64);
        }
        let t = x + G + 0.5;
        0.5 * (2.0 * std::f64::consts::PI).ln() + (x + 0.5) * t.ln() - t + a.ln()
    }

    /// Regularised lower incomplete gamma function `P(a, x)`, `a > 0`, `x ≥ 0`.
    pub fn gamma_p(a: f64, x: f64) -> f64 {
        if x <= 0.0 {
            return 0.0;
        }
        let log_prefactor = -x + a * x.ln() - ln_gamma(a);
        if x < a + 1.0 {
            // Series: P = e^{−x} x^a / Γ(a) · Σ x^n / (a (a+1) … (a+n)).
            let (mut term, mut sum, mut ap) = (1.0 / a, 1.0 / a, a);
            for _ in 0..10_000 {
                ap += 1.0;
                term *= x / ap;
                sum += term;
                if term.abs() < sum.abs() * 1e-17 {
                    break;
                }
            }
            (sum.ln() + log_prefactor).exp().min(1.0)
        } else {
            // Continued fraction for Q = 1 − P (modified Lentz).
            let tiny = 1e-300;
            let mut b = x + 1.0 - a;
            let mut c = 1.0 / tiny;
            let mut d = 1.0 / b;
            let mut h = d;
            for i in 1..10_000 {
                let an = -(i as f64) * (i as f64 - a);
                b += 2.0;
                d = an * d + b;
                if d.abs() < tiny {
                    d = tiny;
                }
                c = b + an / c;
                if c.abs() < tiny {
                    c = tiny;
                }
                d = 1.0 / d;
                let delta = d * c;
                h *= delta;
                if (delta - 1.0).abs() < 1e-16 {
                    break;
                }
            }
            (1.0 - (log_prefactor.exp() * h)).max(0.0)
        }
    }

    /// CDF of χ²(k) at `x`.
    pub fn cdf(x: f64, dof: f64) -> f64 {
        gamma_p(0.5 * dof, 0.5 * x)
    }

    /// Standard normal quantile, used for the Wilson–Hilferty start (see
    /// [`super::normal_quantile`]).
    pub use super::normal_quantile;

    /// Wilson–Hilferty approximation of the χ²(k) quantile at probability `p`.
    pub fn quantile_wilson_hilferty(p: f64, dof: f64) -> f64 {
        let v = 2.0 / (9.0 * dof);
        let c = 1.0 - v + normal_quantile(p) * v.sqrt();
        dof * (c.max(0.0)).powi(3)
    }

    /// The χ²(k) quantile at probability `p` (0 < p < 1), accurate to about 1e-12
    /// relative: Wilson–Hilferty, then Newton on the CDF inside a shrinking bracket.
    pub fn quantile(p: f64, dof: f64) -> f64 {
        if !(p > 0.0 && p < 1.0 && dof > 0.0) {
            return f64::NAN;
        }
        let a = 0.5 * dof;
        let ln_norm = a * 2f64.ln() + ln_gamma(a);
        let pdf = |x: f64| ((a - 1.0) * x.ln() - 0.5 * x - ln_norm).exp();
        let (mut lo, mut hi) = (0.0_f64, f64::INFINITY);
        let mut x = quantile_wilson_hilferty(p, dof).max(1e-300);
        for _ in 0..200 {
            let f = cdf(x, dof) - p;
            if f == 0.0 {
                return x;
            }
            if f < 0.0 {
                lo = lo.max(x);
            } else {
                hi = hi.min(x);
            }
            let step = f / pdf(x);
            let mut next = x - step;
            // Keep the iterate inside the bracket: bisect (or expand) when Newton leaves it.
            if !(next.is_finite() && next > lo && next < hi) {
                next = if hi.is_finite() {
                    0.5 * (lo + hi)
                } else {
                    2.0 * x.max(lo) + 1.0
                };
            }
            if (next - x).abs() <= 1e-14 * x.abs() {
                return next;
            }
            x = next;
        }
        x
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tabulated_values() {
        // Φ⁻¹(0.975) = 1.959963985, Φ⁻¹(0.5) = 0, Φ⁻¹(0.001) = −3.090232306 (tables).
        assert!((normal_quantile(0.975) - 1.959_963_985).abs() < 1e-8);
        assert_eq!(normal_quantile(0.5), 0.0);
        assert!((normal_quantile(0.001) + 3.090_232_306).abs() < 1e-8);
        assert_eq!(normal_quantile(0.0), f64::NEG_INFINITY);
    }
}
