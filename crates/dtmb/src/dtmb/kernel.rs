//! The interpolation kernel that defines DTMB's continuous-time waveform, shared by the
//! exact time-domain channel ([`super::channel`]) and the fast frequency-domain one
//! (`fd_channel`).
//!
//! **Waveform.** The transmitted samples `x[m]` (7.56 Msps) define the continuous-time
//! signal
//!
//! ```text
//! x(u) = Σ_m x[m] φ(u − m),   φ(u) = sinc(u) · I0(β√(1 − (u/K)²)) / I0(β),  |u| < K,
//! ```
//!
//! with `u` in transmitter samples: a Kaiser-windowed sinc of half-width `K = 16` samples
//! and `β = 6`. `φ(m) = δ[m]` at integers, so the waveform passes through the samples,
//! and its spectrum is flat to within 0.1 dB up to 0.44 of the sample rate. Evaluating
//! `x(u)` at any real `u` is exact for this waveform (no table, no quantised delay); a
//! delay is therefore exact to floating-point precision. Relative to the ideal
//! band-limited (infinite sinc) interpolation, the window alters only the outermost
//! 6 % of the band.

/// Half-width of the interpolation kernel in samples.
pub const KERNEL_HALF_WIDTH: usize = 16;
/// Kaiser window parameter of the kernel.
pub const KAISER_BETA: f64 = 6.0;
/// `I0(β)` for β = 6, the window normalisation (checked against the series in a test).
const I0_BETA: f64 = 67.234_406_976_477_97;

/// `1/k²` for the Bessel series, so its loop multiplies instead of dividing.
const INV_SQ: [f64; 25] = {
    let mut t = [0.0; 25];
    let mut k = 1;
    while k < 25 {
        t[k] = 1.0 / ((k * k) as f64);
        k += 1;
    }
    t
};

/// Modified Bessel function of the first kind, order 0, by its power series
/// `Σ_k ((x/2)^k / k!)²`. For the arguments used here (`x ≤ β = 6`, `x²/4 ≤ 9`) the
/// 24th term is below 10⁻²⁴ of the sum, so 24 terms reach double precision.
fn bessel_i0(x: f64) -> f64 {
    let q = x * x / 4.0;
    let mut term = 1.0;
    let mut sum = 1.0;
    for inv in &INV_SQ[1..] {
        term *= q * inv;
        sum += term;
    }
    sum
}

/// The interpolation kernel `φ(u)` and its derivative `φ'(u)`, analytically:
///
/// ```text
/// φ(u)  = sinc(u) w(u),   w(u) = I0(β s)/I0(β),   s = √(1 − (u/K)²),
/// φ'(u) = sinc'(u) w(u) + sinc(u) w'(u),
/// sinc'(u) = (cos πu − sinc u)/u,   w'(u) = −(β² u/K²) · [I1(βs)/(βs)] / I0(β),
/// ```
///
/// with `I1(x)/x = ½ Σ_k (x²/4)^k / (k!(k+1)!)` summed with `I0`'s series in one loop,
/// so the derivative has no `1/s` singularity at the window's edge. Near `u = 0` the
/// sinc and its derivative use their Taylor series (error below 10⁻¹⁶). The frequency-
/// domain channel needs `φ'` for the first-order sampling-clock drift term; the analytic
/// form is exact to rounding, where a central difference loses half the digits.
pub fn kernel_with_derivative(u: f64) -> (f64, f64) {
    let (sn, cs) = (std::f64::consts::PI * u).sin_cos();
    kernel_with_derivative_given(u, sn, cs)
}

/// [`kernel_with_derivative`] at the `2K` arguments `u_i = first + i − d`, the taps of a
/// path at fractional delay `d` starting at integer `first`, into `out` (length `2K`).
///
/// The arguments are one integer apart, so `sin πu_i = −(−1)^m sin πf` and
/// `cos πu_i = (−1)^m cos πf` with `u_i = m − f`, `m = first + i − ⌊d⌋`, `f = d − ⌊d⌋`:
/// one `sincos` for the whole set instead of one per tap (the frequency-domain channel
/// rebuilds six paths' taps every few frames).
pub fn kernel_taps_with_derivative(d: f64, first: i64, out: &mut [(f64, f64)]) {
    let fl = d.floor();
    let (sf, cf) = (std::f64::consts::PI * (d - fl)).sin_cos();
    let fl = fl as i64;
    for (i, o) in out.iter_mut().enumerate() {
        let j = first + i as i64;
        let odd = (j - fl).rem_euclid(2) == 1;
        let (sn, cs) = if odd { (sf, -cf) } else { (-sf, cf) };
        *o = kernel_with_derivative_given(j as f64 - d, sn, cs);
    }
}

/// `½/(k + 1)` for `k = 1 … 24`: the factor that turns `I0`'s series term into `I1(x)/x`'s.
const HALF_INV_K1: [f64; 25] = {
    let mut t = [0.0; 25];
    let mut k = 1;
    while k < 25 {
        t[k] = 0.5 / ((k + 1) as f64);
        k += 1;
    }
    t
};

/// The body of [`kernel_with_derivative`] with `sin πu` and `cos πu` supplied.
#[inline(always)]
fn kernel_with_derivative_given(u: f64, sin_pi_u: f64, cos_pi_u: f64) -> (f64, f64) {
    let k = KERNEL_HALF_WIDTH as f64;
    if u.abs() >= k {
        return (0.0, 0.0);
    }
    let pi = std::f64::consts::PI;
    let (s, ds) = if u.abs() < 1e-4 {
        let x2 = (pi * u) * (pi * u);
        (
            1.0 - x2 / 6.0 + x2 * x2 / 120.0,
            pi * pi * u * (-1.0 / 3.0 + x2 / 30.0),
        )
    } else {
        let sinc = sin_pi_u / (pi * u);
        (sinc, (cos_pi_u - sinc) / u)
    };
    let r = u / k;
    // (x/2)² with x = β√(1 − r²), without the square root.
    let q = 0.25 * KAISER_BETA * KAISER_BETA * (1.0 - r * r).max(0.0);
    let (mut term, mut i0, mut i1x) = (1.0, 1.0, 0.5);
    for (inv, half) in INV_SQ[1..].iter().zip(&HALF_INV_K1[1..]) {
        term *= q * inv;
        i0 += term;
        // The series of I1(x)/x: term_k / (k + 1), halved.
        i1x += term * half;
    }
    let w = i0 / I0_BETA;
    let dw = -(KAISER_BETA * KAISER_BETA * u / (k * k)) * i1x / I0_BETA;
    (s * w, ds * w + s * dw)
}

/// The interpolation kernel `φ(u)` of the module documentation.
pub fn kernel(u: f64) -> f64 {
    let k = KERNEL_HALF_WIDTH as f64;
    if u.abs() >= k {
        return 0.0;
    }
    let s = if u.abs() < 1e-12 {
        1.0
    } else {
        (std::f64::consts::PI * u).sin() / (std::f64::consts::PI * u)
    };
    let r = u / k;
    s * bessel_i0(KAISER_BETA * (1.0 - r * r).sqrt()) / I0_BETA
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kaiser_normalisation_matches_the_series() {
        assert!((bessel_i0(KAISER_BETA) / I0_BETA - 1.0).abs() < 1e-14);
        assert!((bessel_i0(1.0) - 1.266_065_877_752_008_4).abs() < 1e-15);
    }

    #[test]
    fn kernel_derivative_matches_a_central_difference() {
        // The analytic φ' against a central difference of φ (truncation h²|φ‴|/6 with
        // h = 1e-4, about 1e-8 here) over the whole support, the window edge included.
        let mut worst = 0.0f64;
        let mut u = -16.0;
        while u <= 16.0 {
            let (phi, dphi) = kernel_with_derivative(u);
            assert!((phi - kernel(u)).abs() < 1e-15, "φ({u})");
            let h = 1e-4;
            let fd = (kernel(u + h) - kernel(u - h)) / (2.0 * h);
            if u.abs() < 16.0 - h {
                worst = worst.max((dphi - fd).abs());
            }
            u += 0.013_7;
        }
        assert!(worst < 1e-7, "worst |φ' − central difference| {worst}");
        // φ'(0) = 0 by symmetry, and φ'(m) = cos(πm)/m · w(m) at integers m ≠ 0.
        assert!(kernel_with_derivative(0.0).1.abs() < 1e-15);
        let w3 = bessel_i0(KAISER_BETA * (1.0f64 - (3.0f64 / 16.0).powi(2)).sqrt()) / I0_BETA;
        assert!((kernel_with_derivative(3.0).1 - (-1.0 / 3.0) * w3).abs() < 1e-14);
    }

    #[test]
    fn kernel_taps_match_the_kernel_tap_by_tap() {
        // The taps of a set from one sincos against the kernel evaluated at each argument,
        // for delays on both sides of integers, at integers and near them (the Taylor branch).
        let k = KERNEL_HALF_WIDTH as i64;
        let mut taps = [(0.0, 0.0); 2 * KERNEL_HALF_WIDTH];
        for d in [
            37.8f64,
            38.0,
            38.00002,
            -3.25,
            0.5,
            1_234.999_99,
            7.3e4 + 0.61,
        ] {
            let first = d.floor() as i64 - k + 1;
            kernel_taps_with_derivative(d, first, &mut taps);
            for (i, &(h, dh)) in taps.iter().enumerate() {
                let u = (first + i as i64) as f64 - d;
                let (h0, dh0) = kernel_with_derivative(u);
                assert!(
                    (h - h0).abs() < 1e-13 && (dh - dh0).abs() < 1e-12,
                    "d {d} u {u}"
                );
                assert!((h - kernel(u)).abs() < 1e-13, "d {d} u {u}");
            }
        }
    }

    #[test]
    fn kernel_interpolates_through_samples() {
        assert!((kernel(0.0) - 1.0).abs() < 1e-15);
        for m in 1..20 {
            assert!(kernel(m as f64).abs() < 1e-15 && kernel(-(m as f64)).abs() < 1e-15);
        }
    }
}
