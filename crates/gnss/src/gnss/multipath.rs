//! What a delay-lock loop makes of a multipath channel: the code tracking error, the power
//! left at the prompt correlator and the carrier the frequency loop follows.
//!
//! The receiver correlates the incoming signal with a local replica. With the propagation
//! paths k (excess delay δ_k in chips, amplitude a_k relative to the unobstructed direct
//! signal, phase φ_k), the complex correlation at a replica offset τ (chips) is
//!
//! ```text
//! C(τ) = Σ_k a_k e^{jφ_k} R(τ − δ_k),      R(x) = max(0, 1 − |x|)
//! ```
//!
//! with R the autocorrelation of a PRN code of infinite bandwidth (the triangle; GPS C/A
//! and BeiDou B1I both have it to within their 1/1023 and 1/2046 side lobes). A
//! noncoherent early-minus-late power discriminator with spacing d chips
//!
//! ```text
//! D(τ) = |C(τ + d/2)|² − |C(τ − d/2)|²
//! ```
//!
//! steers the replica until D(τ*) = 0 with D falling through zero (a stable lock point).
//! τ* is the code multipath error in chips; multiplied by the chip length it is the
//! pseudorange error. With the direct path alone τ* = 0; a reflection in phase (φ = 0) pulls
//! the lock point late, one in antiphase early; over all phases the errors of one
//! reflection trace the classic multipath error envelope (Braasch, *Multipath effects*, in
//! Parkinson & Spilker, *GPS: Theory and Applications*, vol. I, ch. 14; Kaplan & Hegarty
//! §6.2), which shrinks with the correlator spacing. When the direct path is blocked,
//! the loop locks on what remains: a lone reflection gives τ* = δ, the whole excess path
//! (the NLOS bias).
//!
//! # Reflections that rotate against the direct path
//!
//! When the receiver moves, a path k arrives with its own Doppler f_k, so the cross term
//! of paths i and j in |C(τ)|² rotates at f_i − f_j. The DLL's loop filter passes a
//! disturbance of its discriminator at frequency f to the code estimate with gain |H(f)|;
//! for a first-order loop of noise bandwidth B_L (closed loop K/(s + K), B_L = K/4;
//! Kaplan & Hegarty, *Understanding GPS*, 2nd ed., §5.6)
//!
//! ```text
//! |H(f)| = 1 / √(1 + (π f / (2 B_L))²)
//! ```
//!
//! so a reflection whose relative phase turns faster than the loop can follow moves the
//! code estimate only by that fraction of its static error: fast-fading multipath
//! averages out in the code loop (Braasch, *Multipath effects*, in Parkinson & Spilker vol.
//! I, ch. 14), while its power terms |a_k|² R² still pull the lock point. The discriminator
//! therefore weighs each cross term by g_ij = |H(f_i − f_j)|:
//!
//! ```text
//! P(τ) = Σ_i |a_i|² R(τ − δ_i)² + 2 Σ_{i<j} g_ij Re(a_i a_j*) R(τ − δ_i) R(τ − δ_j)
//! D(τ) = P(τ + d/2) − P(τ − d/2)
//! ```
//!
//! To first order in the multipath amplitude, the lock point of D is the averaged lock
//! point plus g_ij times the excursion the static phase would give, taken at this epoch's
//! phase: an epoch samples the residual oscillation the loop lets through. Paths with equal
//! Doppler (g = 1: a static receiver, or a receiver moving parallel to the ground and to
//! the wall that reflects) keep the static discriminator exactly. The prompt power (for the
//! C/N0) stays the instantaneous |C(τ*)|².
//!
//! The receiver acquires the strongest correlation peak, so the lock point searched is the
//! stable zero of D nearest to the path with the largest |C(δ_k)|. The prompt power
//! |C(τ*)|² scales the C/N0; the frequency loop follows the path that contributes most to
//! the prompt correlation, so its Doppler replaces the direct path's.

use crate::propagation::Path;
use num_complex::Complex64;

/// The scan step (chips) used to bracket the lock point before bisection.
const SCAN_STEP_CHIPS: f64 = 1.0 / 32.0;

/// The DLL's view of a channel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DllLock {
    /// Code tracking error τ* (chips): positive when the replica lags the direct path.
    pub code_error_chips: f64,
    /// Prompt correlation power |C(τ*)|² relative to an unobstructed direct signal (a
    /// factor; 10·log10 of it is the C/N0 change in dB).
    pub prompt_power: f64,
    /// Index (into the path list) of the path the frequency loop follows.
    pub carrier_path: usize,
}

/// The triangle autocorrelation of an ideal PRN code (x in chips).
fn triangle(x: f64) -> f64 {
    (1.0 - x.abs()).max(0.0)
}

/// C(τ) for paths given as (delay chips, complex amplitude).
fn correlation(paths: &[(f64, Complex64)], tau_chips: f64) -> Complex64 {
    paths
        .iter()
        .map(|(delay, a)| a * triangle(tau_chips - delay))
        .sum()
}

/// |H(f)| of a first-order loop of noise bandwidth `bandwidth_hz` (see the module
/// documentation); 1 for an infinite bandwidth.
pub fn loop_response(f_hz: f64, bandwidth_hz: f64) -> f64 {
    let x = std::f64::consts::PI * f_hz / (2.0 * bandwidth_hz);
    1.0 / (1.0 + x * x).sqrt()
}

const N_TAPS: usize = crate::propagation::MAX_PATHS;

/// The taps of one channel and, when their Dopplers differ, the loop's weights g_ij of
/// their cross terms (see the module documentation). Lives on the stack.
struct Channel<'a> {
    taps: &'a [(f64, Complex64)],
    /// `None`: every g_ij is 1 and P(τ) = |C(τ)|².
    weights: Option<[[f64; N_TAPS]; N_TAPS]>,
}

impl Channel<'_> {
    /// P(τ), the loop-averaged correlation power.
    fn power(&self, tau_chips: f64) -> f64 {
        let Some(g) = &self.weights else {
            return correlation(self.taps, tau_chips).norm_sqr();
        };
        let mut r = [0.0; N_TAPS];
        for (rk, (delay, _)) in r.iter_mut().zip(self.taps) {
            *rk = triangle(tau_chips - delay);
        }
        let mut p = 0.0;
        for (i, (_, ai)) in self.taps.iter().enumerate() {
            if r[i] == 0.0 {
                continue;
            }
            p += ai.norm_sqr() * r[i] * r[i];
            for (j, (_, aj)) in self.taps.iter().enumerate().skip(i + 1) {
                p += 2.0 * g[i][j] * (ai * aj.conj()).re * r[i] * r[j];
            }
        }
        p
    }

    fn discriminator(&self, tau_chips: f64, spacing_chips: f64) -> f64 {
        let h = 0.5 * spacing_chips;
        self.power(tau_chips + h) - self.power(tau_chips - h)
    }
}

/// The lock point of a noncoherent early-minus-late DLL on `paths` (see the module
/// documentation). `chip_length_m` converts the paths' excess delays (seconds × c, i.e.
/// metres) to chips; `spacing_chips` is the early–late spacing d in (0, 1];
/// `dll_bandwidth_hz` is the loop's noise bandwidth B_L, which weighs the cross terms of
/// paths whose Dopplers differ (`f64::INFINITY`: the static discriminator whatever the
/// Dopplers).
///
/// Returns `None` when there is no signal (every amplitude zero or non-finite).
/// No allocation: at most [`crate::propagation::MAX_PATHS`] paths are read into a stack
/// array.
pub fn dll_lock(
    paths: &[Path],
    chip_length_m: f64,
    spacing_chips: f64,
    dll_bandwidth_hz: f64,
) -> Option<DllLock> {
    let mut buf = [(0.0, Complex64::new(0.0, 0.0)); N_TAPS];
    let n = paths.len().min(N_TAPS);
    for (slot, p) in buf.iter_mut().zip(paths.iter()) {
        let delay_chips = p.excess_delay_s * crate::core::C_MPS / chip_length_m;
        *slot = (delay_chips, Complex64::from_polar(p.amplitude, p.phase_rad));
    }
    let taps = &buf[..n];
    if taps
        .iter()
        .any(|(d, a)| !(d.is_finite() && a.re.is_finite() && a.im.is_finite()))
    {
        return None;
    }
    let paths = &paths[..n];
    let rotating = paths
        .iter()
        .any(|p| (p.doppler_hz - paths[0].doppler_hz).abs() > 1e-9);
    let weights = (rotating && dll_bandwidth_hz.is_finite()).then(|| {
        let mut g = [[1.0; N_TAPS]; N_TAPS];
        for (i, pi) in paths.iter().enumerate() {
            for (j, pj) in paths.iter().enumerate() {
                g[i][j] = loop_response(pi.doppler_hz - pj.doppler_hz, dll_bandwidth_hz);
            }
        }
        g
    });
    let ch = Channel { taps, weights };
    // The receiver acquires the strongest peak: start from the path whose delay carries
    // the largest (loop-averaged) correlation power.
    let (start, peak) =
        taps.iter()
            .map(|(d, _)| (*d, ch.power(*d)))
            .fold(
                (0.0, 0.0),
                |best, cur| if cur.1 > best.1 { cur } else { best },
            );
    if peak <= 0.0 {
        return None;
    }
    let d = spacing_chips.clamp(1e-3, 1.0);
    // Scan outwards from the peak for the nearest + → − crossing of D, alternating sides
    // so that the nearest crossing wins, then bisect inside it.
    let mut lock = None;
    let steps = (1.5 / SCAN_STEP_CHIPS) as i32;
    'scan: for i in 0..steps {
        for side in [1.0, -1.0] {
            let a = start + side * f64::from(i) * SCAN_STEP_CHIPS;
            let b = a + side * SCAN_STEP_CHIPS;
            let (lo, hi) = if a < b { (a, b) } else { (b, a) };
            let (d_lo, d_hi) = (ch.discriminator(lo, d), ch.discriminator(hi, d));
            if d_lo >= 0.0 && d_hi < 0.0 {
                lock = Some(bisect(&ch, lo, hi, d));
                break 'scan;
            }
        }
    }
    let tau = lock?;
    let prompt = correlation(taps, tau);
    let carrier_path = taps
        .iter()
        .enumerate()
        .map(|(k, (delay, a))| (k, a.norm() * triangle(tau - delay)))
        .fold(
            (0, -1.0),
            |best, cur| if cur.1 > best.1 { cur } else { best },
        )
        .0;
    Some(DllLock {
        code_error_chips: tau,
        prompt_power: prompt.norm_sqr(),
        carrier_path,
    })
}

fn bisect(ch: &Channel<'_>, mut lo: f64, mut hi: f64, d: f64) -> f64 {
    // 40 halvings of a 1/32-chip bracket leave ~3e-14 chips: far below any effect.
    for _ in 0..40 {
        let mid = 0.5 * (lo + hi);
        if ch.discriminator(mid, d) >= 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::propagation::PathKind;
    use nalgebra::Vector3;

    const CHIP_M: f64 = 293.052_256;

    fn path(kind: PathKind, delay_chips: f64, amplitude: f64, phase_rad: f64) -> Path {
        Path {
            kind,
            excess_delay_s: delay_chips * CHIP_M / crate::core::C_MPS,
            amplitude,
            phase_rad,
            doppler_hz: 0.0,
            arrival_enu: Vector3::z(),
        }
    }

    #[test]
    fn direct_path_alone_has_no_error() {
        let l = dll_lock(
            &[path(PathKind::Direct, 0.0, 1.0, 0.0)],
            CHIP_M,
            1.0,
            f64::INFINITY,
        )
        .unwrap();
        assert!(l.code_error_chips.abs() < 1e-9);
        assert!((l.prompt_power - 1.0).abs() < 1e-9);
    }

    /// A single in-phase or antiphase reflection, solved by hand on the piecewise-linear
    /// correlation triangles.
    #[test]
    fn single_reflection_matches_the_error_envelope() {
        let d = 1.0;
        let alpha = 0.5;
        for (phase, sign) in [(0.0, 1.0), (std::f64::consts::PI, -1.0)] {
            let paths = [
                path(PathKind::Direct, 0.0, 1.0, 0.0),
                path(PathKind::Wall { building: 0 }, 0.6, alpha, phase),
            ];
            let l = dll_lock(&paths, CHIP_M, d, f64::INFINITY).unwrap();
            // Hand solution for δ = 0.6, d = 1: early at τ − 0.5, late at τ + 0.5.
            // In phase, for 0.1 < τ < 0.5: early = (0.5 + τ) + α R(τ − 1.1)
            // = 0.5 + τ + α(τ − 0.1) and late = (0.5 − τ) + α R(τ − 0.1)
            // = 0.5 − τ + α(1.1 − τ); equal when τ = 0.6α / (1 + α) (0.2 for α = 0.5).
            // In antiphase, for τ < 0.1: early = 0.5 + τ (the reflection's early tap is
            // outside its triangle) and late = 0.5 − τ − α(0.9 + τ); equal when
            // τ = −0.9α / (2 + α) (−0.18 for α = 0.5).
            let expect = if sign > 0.0 {
                0.6 * alpha / (1.0 + alpha)
            } else {
                -0.9 * alpha / (2.0 + alpha)
            };
            assert!(
                (l.code_error_chips - expect).abs() < 1e-9,
                "phase {phase}: {} vs {expect}",
                l.code_error_chips
            );
        }
    }

    /// Narrow correlators are less sensitive: the error for the same in-phase reflection
    /// shrinks with the spacing.
    #[test]
    fn narrow_correlator_reduces_the_error() {
        let paths = [
            path(PathKind::Direct, 0.0, 1.0, 0.0),
            path(PathKind::Wall { building: 0 }, 0.3, 0.5, 0.0),
        ];
        let wide = dll_lock(&paths, CHIP_M, 1.0, f64::INFINITY)
            .unwrap()
            .code_error_chips;
        let narrow = dll_lock(&paths, CHIP_M, 0.1, f64::INFINITY)
            .unwrap()
            .code_error_chips;
        assert!(
            wide > 0.0 && narrow > 0.0 && narrow < 0.5 * wide,
            "{wide} {narrow}"
        );
    }

    /// A blocked direct path leaves the reflection: the receiver tracks it with the whole
    /// excess delay as its bias and the reflection's power.
    #[test]
    fn lone_reflection_gives_the_nlos_bias() {
        let paths = [
            path(PathKind::Direct, 0.0, 1e-4, 0.0),
            path(PathKind::Wall { building: 0 }, 0.137, 0.3, 1.0),
        ];
        let l = dll_lock(&paths, CHIP_M, 0.5, f64::INFINITY).unwrap();
        assert!(
            (l.code_error_chips - 0.137).abs() < 2e-3,
            "{}",
            l.code_error_chips
        );
        assert!((l.prompt_power / 0.09 - 1.0).abs() < 0.01);
        assert_eq!(l.carrier_path, 1);
    }

    /// A reflection rotating far faster than the loop leaves only its power: the lock
    /// point is that of P(τ) = R(τ)² + α² R(τ − δ)², solved by hand for δ = 0.6, d = 1
    /// (as above: early (0.5 + τ)² + α²(τ − 0.1)², late (0.5 − τ)² + α²(1.1 − τ)², equal
    /// when τ = 0.6α² / (1 + α²), 0.12 for α = 0.5), whatever the phase.
    #[test]
    fn a_fast_rotating_reflection_leaves_only_its_power() {
        let alpha = 0.5;
        for phase in [0.0, 1.0, std::f64::consts::PI] {
            let mut refl = path(PathKind::Wall { building: 0 }, 0.6, alpha, phase);
            refl.doppler_hz = 1e6;
            let paths = [path(PathKind::Direct, 0.0, 1.0, 0.0), refl];
            let l = dll_lock(&paths, CHIP_M, 1.0, 2.0).unwrap();
            let expect = 0.6 * alpha * alpha / (1.0 + alpha * alpha);
            assert!(
                (l.code_error_chips - expect).abs() < 1e-5,
                "phase {phase}: {} vs {expect}",
                l.code_error_chips
            );
        }
    }

    /// Between the two limits the loop lets through its response's share of the static
    /// excursion: with g = |H(Δf)| the lock point is, to first order in α, the averaged one
    /// plus g times (static − averaged); here 12.5 Hz against a 2 Hz loop (g = 0.101), the
    /// in-phase and antiphase cases of the hand-solved channel above.
    #[test]
    fn a_rotating_reflection_moves_the_lock_by_the_loops_response() {
        let (alpha, f_hz, bl_hz) = (0.2, 12.5, 2.0);
        let g = loop_response(f_hz, bl_hz);
        assert!(
            (g - 1.0 / (1.0 + (std::f64::consts::PI * 12.5 / 4.0).powi(2)).sqrt()).abs() < 1e-15
        );
        let averaged = 0.6 * alpha * alpha / (1.0 + alpha * alpha);
        for (phase, static_tau) in [
            (0.0, 0.6 * alpha / (1.0 + alpha)),
            (std::f64::consts::PI, -0.9 * alpha / (2.0 + alpha)),
        ] {
            let mut refl = path(PathKind::Wall { building: 0 }, 0.6, alpha, phase);
            refl.doppler_hz = f_hz;
            let paths = [path(PathKind::Direct, 0.0, 1.0, 0.0), refl];
            let tau = dll_lock(&paths, CHIP_M, 1.0, bl_hz)
                .unwrap()
                .code_error_chips;
            let first_order = averaged + g * (static_tau - averaged);
            assert!(
                (tau - first_order).abs() < 0.1 * (static_tau - averaged).abs(),
                "phase {phase}: {tau} vs {first_order} (static {static_tau}, averaged {averaged})"
            );
        }
    }

    /// Paths with one Doppler (a receiver moving parallel to the reflectors) keep the
    /// static discriminator exactly, whatever the loop bandwidth.
    #[test]
    fn equal_dopplers_keep_the_static_lock_point() {
        let mut paths = [
            path(PathKind::Direct, 0.0, 1.0, 0.0),
            path(PathKind::Ground, 0.2, 0.4, 2.0),
            path(PathKind::Wall { building: 0 }, 0.5, 0.3, -1.0),
        ];
        for p in &mut paths {
            p.doppler_hz = 37.5;
        }
        let a = dll_lock(&paths, CHIP_M, 0.5, 2.0).unwrap();
        let b = dll_lock(&paths, CHIP_M, 0.5, f64::INFINITY).unwrap();
        assert_eq!(a, b);
    }

    #[test]
    fn no_signal_is_none() {
        assert!(dll_lock(
            &[path(PathKind::Direct, 0.0, 0.0, 0.0)],
            CHIP_M,
            1.0,
            f64::INFINITY
        )
        .is_none());
        assert!(dll_lock(&[], CHIP_M, 1.0, f64::INFINITY).is_none());
    }
}
