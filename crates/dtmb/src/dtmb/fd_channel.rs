//! The frequency-domain implementation of the multipath channel ([`super::Channel`]).
//!
//! **What it computes.** The channel of [`super::channel`] gives receiver sample `n`
//!
//! ```text
//! y[n] = Σ_p g_p e^{j2π(f_p + Δf) n r / f_s} x(n r − τ_p f_s),   r = 1/(1 + ε),
//! ```
//!
//! with `x(u) = Σ_m x[m] φ(u − m)` the windowed-sinc waveform. Write `d_p(n) = n − (n r −
//! τ_p f_s) = n ε' + τ_p f_s` (`ε' = 1 − r`) for the delay in samples; then
//! `x(n − d_p) = Σ_j h_p[j] x[n − j]` with the FIR `h_p[j] = φ(j − d_p)` (32 taps).
//!
//! **Block algorithm (overlap-save with boundary spectra).** The output is cut into
//! sub-blocks of a fixed length `B`; sub-block `s` covers samples `a_s … a_s + B − 1` and
//! has boundaries `b_s = a_s − ½` and `b_s + B`. A common rotation at `f_c` (the CFO plus
//! the middle of the paths' Doppler range) is taken out exactly per sample; what remains
//! of path `p`'s carrier is `c_p(t) = g_p e^{j2π f_p,res r t / f_s}`,
//! `f_p,res = f_p + Δf − f_c`. Against a base instant `n_b` at which the FIR taps are
//! built, the delay is `d_p(n) = d_p(n_b) + δ(n)`, `δ(n) = ε'(n − n_b)`, common to all
//! paths. At a boundary `b` the whole channel is then, to first order in `δ`, the LTI
//! filter
//!
//! ```text
//! H(b) = Σ_p c_p(b) [D_p − δ(b) D'_p],
//! ```
//!
//! with `D_p`, `D'_p` the exact DFTs of the taps `φ(j − d_p(n_b))` and of their
//! derivative taps `φ'(j − d_p(n_b))` (computed once per base; the derivative
//! analytically, [`crate::dtmb::kernel::kernel_taps_with_derivative`]). Inside the sub-block the
//! output is the linear interpolation in time of the two boundary filters' outputs,
//!
//! ```text
//! y[n] = e^{j2π f_c n r/f_s} { (1 − w) IDFT(X·H(b_s)) + w IDFT(X·H(b_s + B)) },
//! w = (n − b_s)/B,
//! ```
//!
//! `X` the DFT of the input segment: one forward and two inverse FFTs per sub-block, and
//! the end filter of one sub-block is the start filter of the next. Both the residual
//! Doppler phasor `e^{jω_p n}` and the delay drift `δ(n)` are thereby interpolated
//! linearly between exact values at the boundaries. The drift is linear in `n`, so its
//! interpolation is exact and only the first-order expansion in `δ` remains,
//! `δ²|x''|/2` with `|δ| ≤ 0.04` samples (the base is moved when the drift would exceed
//! it); the phasor's linear interpolation errs by at most `ω_p² B²/8 ≤ 1.25·10⁻³` (the
//! sub-block is shortened until it holds). Both are near −60 dB relative to the signal,
//! tested against the time-domain reference. Because the per-path spectra are exact DFTs
//! of finite FIRs, the overlap-save has no circular-wrap error: the delays are exact.
//!
//! **Cost.** Per sub-block (B = 1788 samples for a 30 µs delay spread, FFT 2048): three
//! FFTs and one pass over the bins accumulating `Σ_p c_p D_p + (−δ c_p) D'_p`. The taps are
//! real, so only bins `0 … N/2` of each spectrum are stored and one pass over them yields
//! both bins `k` and `N − k` (eight fused multiply–adds per path and pair of bins; the
//! spectra interleaved in blocks of sixteen so the pass streams through memory). The
//! common rotation is applied in the same pass as the interpolation. Output computed past
//! the end of a call is kept and served to the next call that continues where this one
//! stopped, so a stream read frame by frame costs the same as one read in one piece.

// The one kind of unsafe code hybridnav has: its AVX2 intrinsics, `#[target_feature]`
// functions called only after run-time CPU detection, each with a same-bits test against
// the portable code.
#![allow(unsafe_code)]

use super::pn::SAMPLE_RATE_HZ;
use super::transmitter::SampleSource;
use crate::dtmb::kernel::{kernel_taps_with_derivative, KERNEL_HALF_WIDTH};
use crate::dtmb::multipath::ChannelConfig;
use num_complex::{Complex32, Complex64};
use rustfft::{Fft, FftPlanner};
use std::f64::consts::PI;
use std::sync::Arc;

/// Largest error of the linear interpolation of a residual Doppler phasor over a
/// sub-block, `ω² B² / 8` (relative amplitude).
const MAX_INTERP_ERROR: f64 = 1.25e-3;
/// Largest SFO delay drift from the base before the per-path spectra are rebuilt (samples).
const MAX_DRIFT_SAMPLES: f64 = 0.04;
/// Below this many outputs per sub-block the frequency-domain path is not worth it.
pub(crate) const MIN_SUB_BLOCK: usize = 32;
/// Lanes of the vectorised loops: sixteen f32, two AVX2 registers (the FFT sizes are
/// powers of two ≥ 512, so half of one is a multiple of it).
const LANES: usize = 16;
/// Floats per path and block of sixteen bin pairs: Re D, Im D, Re D', Im D' (sixteen
/// lanes each).
const PATH_STRIDE: usize = 4 * LANES;
/// Most paths the frequency-domain engine takes (more use the time-domain reference).
pub(crate) const MAX_FD_PATHS: usize = 32;
/// Samples between restarts of the f32 phasors from f64.
const ROT_RESTART: usize = 512;

/// The size of the engine for one configuration.
#[derive(Clone, Debug, PartialEq)]
struct Plan {
    /// FFT size.
    n: usize,
    /// Taps of the combined filter (its support in samples).
    taps: usize,
    /// Sub-block length.
    b_len: usize,
    /// Common rotation (Hz) and per-path residual Doppler (Hz).
    f_common_hz: f64,
    f_res_hz: Vec<f64>,
}

impl Plan {
    /// The plan for `cfg`, or `None` when the paths' Doppler spread or the SFO would force
    /// sub-blocks too short for the frequency domain to pay.
    fn new(cfg: &ChannelConfig) -> Option<Self> {
        // Paths whose delays drift at their own rates would stretch the combined filter
        // without bound: the time-domain reference runs them.
        if cfg.paths.len() > MAX_FD_PATHS || cfg.paths.iter().any(|p| p.delay_rate != 0.0) {
            return None;
        }
        let (dmin, dmax) = cfg.paths.iter().fold((f64::MAX, f64::MIN), |(a, b), p| {
            (a.min(p.delay_s), b.max(p.delay_s))
        });
        // The combined filter spans floor(d_max) − floor(d_min) + 2K taps at any base,
        // which never exceeds ceil(d_max − d_min) + 2K.
        let span = ((dmax - dmin) * SAMPLE_RATE_HZ).ceil() as usize;
        let taps = span + 2 * KERNEL_HALF_WIDTH;
        let (fmin, fmax) = cfg.paths.iter().fold((f64::MAX, f64::MIN), |(a, b), p| {
            (a.min(p.doppler_hz), b.max(p.doppler_hz))
        });
        let f_mid = 0.5 * (fmin + fmax);
        let f_common_hz = cfg.cfo_hz + f_mid;
        let f_res_hz: Vec<f64> = cfg.paths.iter().map(|p| p.doppler_hz - f_mid).collect();
        let r = 1.0 / (1.0 + cfg.sfo_ppm * 1e-6);
        let eps = (1.0 - r).abs();
        let w_max =
            f_res_hz.iter().fold(0.0f64, |a, f| a.max(f.abs())) * 2.0 * PI * r / SAMPLE_RATE_HZ;
        // The longest sub-block the Doppler and drift bounds allow.
        let mut limit = usize::MAX;
        if w_max > 0.0 {
            limit = limit.min(((8.0 * MAX_INTERP_ERROR).sqrt() / w_max) as usize);
        }
        if eps > 0.0 {
            limit = limit.min((2.0 * MAX_DRIFT_SAMPLES / eps) as usize);
        }
        // FFT size: four times the filter, or less when the bounds cap the sub-block
        // anyway (a larger FFT would only cost more per output sample).
        let mut n = (4 * taps).next_power_of_two().clamp(512, 1 << 16);
        let b_of = |n: usize| n.checked_sub(taps).map(|m| (m + 1).min(limit));
        while n > 512 && b_of(n / 2).is_some() && b_of(n / 2) == b_of(n) {
            n /= 2;
        }
        let b_len = b_of(n)?;
        (b_len >= MIN_SUB_BLOCK).then_some(Self {
            n,
            taps,
            b_len,
            f_common_hz,
            f_res_hz,
        })
    }

    /// The common carrier rotation at the receiver's sample rate, `f_c r / f_s` cycles
    /// per sample.
    fn rotator(&self, cfg: &ChannelConfig) -> Rotator {
        Rotator::new(self.f_common_hz * sfo_ratio(cfg) / SAMPLE_RATE_HZ)
    }
}

/// State of the frequency-domain channel: plans, per-path spectra and work buffers.
pub(crate) struct FdChannel {
    plan: Plan,
    fwd: Arc<dyn Fft<f32>>,
    inv: Arc<dyn Fft<f32>>,
    scratch: Vec<Complex32>,
    /// The base receiver sample `n_b` of the spectra (`None` before the first build) and
    /// a counter that tells spectra of different builds apart.
    base: Option<f64>,
    builds: u64,
    /// First tap index (delay in samples) of the combined filter at the base.
    j_lo: i64,
    /// Per-path spectra of bins `0 … N/2 − 1` (the taps are real, so bin `N − k` is the
    /// conjugate of bin `k`), interleaved: block of sixteen bins `k`, path `p`, then
    /// `[Re D; 16] [Im D; 16] [Re D'; 16] [Im D'; 16]` at `(k·P + p)·64`.
    spectra: Vec<f32>,
    /// Bin `N/2` of every path: `Re D, Im D, Re D', Im D'` at `4p`.
    nyquist: Vec<f32>,
    /// The common carrier rotation.
    rot: Rotator,
    /// The input segment (and, after the products, the start filter's output).
    seg: Vec<Complex32>,
    /// The end filter's output.
    y_end: Vec<Complex32>,
    /// The combined filter at the start and end boundaries.
    h_start: Vec<Complex32>,
    h_end: Vec<Complex32>,
    /// Boundary and build of `h_start`, when it is valid.
    h_start_at: Option<(f64, u64)>,
    /// Output computed past the end of the last call: receiver sample of `carry[off]` and
    /// how many samples remain.
    carry: Vec<Complex32>,
    carry_start: i64,
    carry_off: usize,
    carry_len: usize,
}

impl std::fmt::Debug for FdChannel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FdChannel")
            .field("plan", &self.plan)
            .finish_non_exhaustive()
    }
}

impl Clone for FdChannel {
    fn clone(&self) -> Self {
        Self {
            plan: self.plan.clone(),
            fwd: Arc::clone(&self.fwd),
            inv: Arc::clone(&self.inv),
            scratch: self.scratch.clone(),
            base: self.base,
            builds: self.builds,
            j_lo: self.j_lo,
            spectra: self.spectra.clone(),
            nyquist: self.nyquist.clone(),
            rot: self.rot.clone(),
            seg: self.seg.clone(),
            y_end: self.y_end.clone(),
            h_start: self.h_start.clone(),
            h_end: self.h_end.clone(),
            h_start_at: self.h_start_at,
            carry: self.carry.clone(),
            carry_start: self.carry_start,
            carry_off: self.carry_off,
            carry_len: self.carry_len,
        }
    }
}

impl FdChannel {
    /// Plans the engine for `cfg` (see [`Plan::new`]).
    pub(crate) fn new(cfg: &ChannelConfig) -> Option<Self> {
        let plan = Plan::new(cfg)?;
        let n = plan.n;
        let mut planner = FftPlanner::<f32>::new();
        let fwd = planner.plan_fft_forward(n);
        let inv = planner.plan_fft_inverse(n);
        let scratch_len = fwd
            .get_inplace_scratch_len()
            .max(inv.get_inplace_scratch_len());
        let zeros = vec![Complex32::default(); n];
        Some(Self {
            fwd,
            inv,
            scratch: vec![Complex32::default(); scratch_len],
            base: None,
            builds: 0,
            j_lo: 0,
            spectra: vec![0.0; 2 * n * cfg.paths.len()],
            nyquist: vec![0.0; 4 * cfg.paths.len()],
            rot: plan.rotator(cfg),
            seg: zeros.clone(),
            y_end: zeros,
            // One bin more than the FFT: index N holds a copy of bin 0 that the pairwise
            // combine writes as the mirror of bin 0 (see `combine`); nothing reads it.
            h_start: vec![Complex32::default(); n + 1],
            h_end: vec![Complex32::default(); n + 1],
            h_start_at: None,
            carry: vec![Complex32::default(); plan.b_len],
            carry_start: 0,
            carry_off: 0,
            carry_len: 0,
            plan,
        })
    }

    /// Adapts the engine to new paths (a moving receiver), keeping the FFT plans and
    /// buffers when the FFT size is unchanged; returns `false` when the frequency domain
    /// does not suit `cfg` (the caller then uses the time-domain reference).
    pub(crate) fn reconfigure(&mut self, cfg: &ChannelConfig) -> bool {
        let Some(plan) = Plan::new(cfg) else {
            return false;
        };
        if plan.n != self.plan.n {
            match Self::new(cfg) {
                Some(fresh) => *self = fresh,
                None => return false,
            }
            return true;
        }
        self.spectra.resize(2 * plan.n * cfg.paths.len(), 0.0);
        self.nyquist.resize(4 * cfg.paths.len(), 0.0);
        self.rot = plan.rotator(cfg);
        self.carry.resize(plan.b_len, Complex32::default());
        self.plan = plan;
        self.base = None;
        self.h_start_at = None;
        self.carry_len = 0;
        true
    }

    /// Rebuilds the per-path tap spectra at base receiver sample `n_b`.
    fn rebuild(&mut self, cfg: &ChannelConfig, n_b: f64) {
        let eps = 1.0 - sfo_ratio(cfg);
        let k = KERNEL_HALF_WIDTH as i64;
        let n = self.plan.n;
        let np = cfg.paths.len();
        let dmin = cfg
            .paths
            .iter()
            .map(|p| n_b * eps + p.delay_s * SAMPLE_RATE_HZ)
            .fold(f64::MAX, f64::min);
        self.j_lo = dmin.floor() as i64 - k + 1;
        for (p, path) in cfg.paths.iter().enumerate() {
            let d = n_b * eps + path.delay_s * SAMPLE_RATE_HZ;
            // One complex FFT carries both real tap sets: F = DFT(h + j h'), and by
            // Hermitian symmetry D = (F[k] + F*[−k])/2, D' = (F[k] − F*[−k])/(2j).
            let buf = &mut self.seg;
            buf.iter_mut().for_each(|x| *x = Complex32::default());
            let first = d.floor() as i64 - k + 1;
            let mut taps = [(0.0, 0.0); 2 * KERNEL_HALF_WIDTH];
            kernel_taps_with_derivative(d, first, &mut taps);
            let at = (first - self.j_lo) as usize;
            for (b, &(h, dh)) in buf[at..].iter_mut().zip(&taps) {
                *b = Complex32::new(h as f32, dh as f32);
            }
            self.fwd.process_with_scratch(buf, &mut self.scratch);
            let split = |kk: usize| {
                let a = buf[kk];
                let b = buf[if kk == 0 { 0 } else { n - kk }].conj();
                let dd = (a + b) * 0.5;
                let diff = (a - b) * 0.5;
                [dd.re, dd.im, diff.im, -diff.re]
            };
            for (blk, dst) in self
                .spectra
                .chunks_exact_mut(np * PATH_STRIDE)
                .map(|c| &mut c[p * PATH_STRIDE..(p + 1) * PATH_STRIDE])
                .enumerate()
            {
                for l in 0..LANES {
                    let v = split(blk * LANES + l);
                    for (q, x) in v.into_iter().enumerate() {
                        dst[q * LANES + l] = x;
                    }
                }
            }
            self.nyquist[4 * p..4 * p + 4].copy_from_slice(&split(n / 2));
        }
        self.base = Some(n_b);
        self.builds += 1;
        self.h_start_at = None;
    }

    /// Fills `out` with the noiseless channel output for receiver samples
    /// `rx_start .. rx_start + out.len()`.
    pub(crate) fn process<S: SampleSource + ?Sized>(
        &mut self,
        cfg: &ChannelConfig,
        src: &mut S,
        rx_start: i64,
        out: &mut [Complex32],
    ) {
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx2")
                && std::arch::is_x86_feature_detected!("fma")
            {
                // SAFETY: the CPU supports AVX2 and FMA, checked just above.
                unsafe { self.process_avx2(cfg, src, rx_start, out) };
                return;
            }
        }
        // SAFETY: the portable build (`AVX2 = false`) uses no intrinsics.
        unsafe { self.process_impl::<false, S>(cfg, src, rx_start, out) };
    }

    /// [`FdChannel::process_impl`] compiled for AVX2 and FMA: the spectral loops run in
    /// pairs of eight-lane registers. Every multiply–add is written as `mul_add`, which
    /// rounds once both in hardware and in the portable build's software fallback, and the
    /// arithmetic is element-wise, so results equal the portable build's bit for bit.
    ///
    /// # Safety
    /// The CPU must support AVX2 and FMA.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn process_avx2<S: SampleSource + ?Sized>(
        &mut self,
        cfg: &ChannelConfig,
        src: &mut S,
        rx_start: i64,
        out: &mut [Complex32],
    ) {
        self.process_impl::<true, S>(cfg, src, rx_start, out);
    }

    /// The engine; `AVX2` selects the intrinsics of the per-bin and interpolation passes
    /// and is true only inside [`FdChannel::process_avx2`], whose caller checked the CPU.
    ///
    /// # Safety
    /// With `AVX2 = true` the CPU must support AVX2 and FMA; with `false` it is safe.
    #[inline(always)]
    unsafe fn process_impl<const AVX2: bool, S: SampleSource + ?Sized>(
        &mut self,
        cfg: &ChannelConfig,
        src: &mut S,
        rx_start: i64,
        out: &mut [Complex32],
    ) {
        let mut pos = 0usize;
        // Continue from the output a previous call computed ahead.
        if self.carry_len > 0 && self.carry_start == rx_start {
            let take = self.carry_len.min(out.len());
            out[..take].copy_from_slice(&self.carry[self.carry_off..self.carry_off + take]);
            self.carry_off += take;
            self.carry_len -= take;
            self.carry_start += take as i64;
            pos = take;
        }
        if pos < out.len() {
            self.carry_len = 0;
        }
        let b_len = self.plan.b_len;
        while pos < out.len() {
            let a = rx_start + pos as i64;
            if out.len() - pos >= b_len {
                self.sub_block::<AVX2, S>(cfg, src, a, &mut out[pos..pos + b_len]);
                pos += b_len;
            } else {
                // The last, partial sub-block: compute it whole and keep the rest.
                let mut carry = std::mem::take(&mut self.carry);
                self.sub_block::<AVX2, S>(cfg, src, a, &mut carry[..b_len]);
                let take = out.len() - pos;
                out[pos..].copy_from_slice(&carry[..take]);
                self.carry = carry;
                self.carry_start = a + take as i64;
                self.carry_off = take;
                self.carry_len = b_len - take;
                pos = out.len();
            }
        }
    }

    /// The combined filter `H(b)` at boundary `b` (receiver samples) into `h`, with the
    /// `1/N` of the inverse FFT folded in.
    ///
    /// The taps are real, so `D_p[N − k] = D_p[k]*` (and the same for `D'_p`): with
    /// `D = a + jb`, `D' = a' + jb'` and the per-path coefficients `c = c_r + jc_i`,
    /// `d = −δ c`, the four sums
    ///
    /// ```text
    /// A = Σ_p c_r a + d_r a',  B = Σ_p c_i b + d_i b',
    /// C = Σ_p c_r b + d_r b',  E = Σ_p c_i a + d_i a'
    /// ```
    ///
    /// give both bins of a pair, `H[k] = (A − B) + j(C + E)` and
    /// `H[N − k] = (A + B) + j(E − C)`: eight multiply–adds per path and pair of bins,
    /// half the work and half the stored spectra of evaluating every bin.
    #[inline(always)]
    fn combine(
        spectra: &[f32],
        nyquist: &[f32],
        plan: &Plan,
        cfg: &ChannelConfig,
        base: f64,
        b: f64,
        h: &mut [Complex32],
    ) {
        let r = sfo_ratio(cfg);
        let delta = (1.0 - r) * (b - base);
        let n = plan.n;
        let inv_n = 1.0 / n as f64;
        let np = cfg.paths.len();
        // Per path: c_p(b)/N and −δ(b) c_p(b)/N.
        let mut coef = [(0f32, 0f32, 0f32, 0f32); MAX_FD_PATHS];
        for (p, path) in cfg.paths.iter().enumerate() {
            let cycles = (plan.f_res_hz[p] * r * b / SAMPLE_RATE_HZ).fract();
            let c = path.gain * Complex64::from_polar(inv_n, 2.0 * PI * cycles);
            let d = -delta * c;
            coef[p] = (c.re as f32, c.im as f32, d.re as f32, d.im as f32);
        }
        let coef = &coef[..np];
        for (blk, s_blk) in spectra.chunks_exact(np * PATH_STRIDE).enumerate() {
            let mut acc_a = [0f32; LANES];
            let mut acc_b = [0f32; LANES];
            let mut acc_c = [0f32; LANES];
            let mut acc_e = [0f32; LANES];
            for (s, &(cr, ci, dr, di)) in s_blk.chunks_exact(PATH_STRIDE).zip(coef) {
                let (sa, rest) = s.split_at(LANES);
                let (sb, rest) = rest.split_at(LANES);
                let (sa1, sb1) = rest.split_at(LANES);
                for l in 0..LANES {
                    acc_a[l] = dr.mul_add(sa1[l], cr.mul_add(sa[l], acc_a[l]));
                    acc_b[l] = di.mul_add(sb1[l], ci.mul_add(sb[l], acc_b[l]));
                    acc_c[l] = dr.mul_add(sb1[l], cr.mul_add(sb[l], acc_c[l]));
                    acc_e[l] = di.mul_add(sa1[l], ci.mul_add(sa[l], acc_e[l]));
                }
            }
            // Bins k0 … k0 + 15 forwards, and their mirrors N − k0 … N − k0 − 15, which
            // are the contiguous range below N − k0 + 1 in reverse order (for k0 = 0 the
            // mirror of bin 0 lands on the spare index N).
            let k0 = blk * LANES;
            let fwd = k0..k0 + LANES;
            let mirror = n - k0 + 1 - LANES..n - k0 + 1;
            for (l, x) in h[fwd].iter_mut().enumerate() {
                *x = Complex32::new(acc_a[l] - acc_b[l], acc_c[l] + acc_e[l]);
            }
            for (l, x) in h[mirror].iter_mut().rev().enumerate() {
                *x = Complex32::new(acc_a[l] + acc_b[l], acc_e[l] - acc_c[l]);
            }
        }
        // Bin N/2 is its own mirror: evaluated directly.
        let (mut re, mut im) = (0f32, 0f32);
        for (s, &(cr, ci, dr, di)) in nyquist.chunks_exact(4).zip(coef) {
            re = (-di).mul_add(
                s[3],
                dr.mul_add(s[2], (-ci).mul_add(s[1], cr.mul_add(s[0], re))),
            );
            im = di.mul_add(
                s[2],
                dr.mul_add(s[3], ci.mul_add(s[0], cr.mul_add(s[1], im))),
            );
        }
        h[n / 2] = Complex32::new(re, im);
    }

    /// Computes the `B` outputs of the sub-block starting at receiver sample `a` into `dst`.
    ///
    /// # Safety
    /// As [`FdChannel::process_impl`]: with `AVX2 = true` the CPU must support AVX2 and FMA.
    #[inline(always)]
    unsafe fn sub_block<const AVX2: bool, S: SampleSource + ?Sized>(
        &mut self,
        cfg: &ChannelConfig,
        src: &mut S,
        a: i64,
        dst: &mut [Complex32],
    ) {
        let eps = 1.0 - sfo_ratio(cfg);
        let b_len = self.plan.b_len;
        let b_start = a as f64 - 0.5;
        let b_end = b_start + b_len as f64;
        let valid = self.base.is_some_and(|nb| {
            (eps * (b_start - nb)).abs() <= MAX_DRIFT_SAMPLES
                && (eps * (b_end - nb)).abs() <= MAX_DRIFT_SAMPLES
        });
        if !valid {
            // Place the base so the drift runs from −max to +max from here on: a stream
            // read forwards rebuilds once every 2·max/|ε'| samples.
            let ahead = if eps == 0.0 {
                0.0
            } else {
                MAX_DRIFT_SAMPLES / eps.abs()
            };
            self.rebuild(cfg, b_start + ahead);
        }
        let base = self.base.unwrap_or(b_start);
        if self.h_start_at != Some((b_start, self.builds)) {
            Self::combine(
                &self.spectra,
                &self.nyquist,
                &self.plan,
                cfg,
                base,
                b_start,
                &mut self.h_start,
            );
        }
        Self::combine(
            &self.spectra,
            &self.nyquist,
            &self.plan,
            cfg,
            base,
            b_end,
            &mut self.h_end,
        );
        let taps = self.plan.taps;
        let j_hi = self.j_lo + taps as i64 - 1;
        src.generate(a - j_hi, &mut self.seg);
        self.fwd
            .process_with_scratch(&mut self.seg, &mut self.scratch);
        // Y_start = X·H(b_s) in place, Y_end = X·H(b_e).
        #[cfg(target_arch = "x86_64")]
        if AVX2 {
            // SAFETY: `AVX2` is true only in `process_avx2`, whose caller checked the CPU.
            unsafe { filter_avx2(&mut self.seg, &mut self.y_end, &self.h_start, &self.h_end) };
        } else {
            filter(&mut self.seg, &mut self.y_end, &self.h_start, &self.h_end);
        }
        #[cfg(not(target_arch = "x86_64"))]
        filter(&mut self.seg, &mut self.y_end, &self.h_start, &self.h_end);
        self.inv
            .process_with_scratch(&mut self.seg, &mut self.scratch);
        self.inv
            .process_with_scratch(&mut self.y_end, &mut self.scratch);
        // Linear interpolation between the two boundary outputs, w = (i + ½)/B, and the
        // common carrier rotation, in one pass.
        let first = taps - 1;
        let ys = &self.seg[first..first + b_len];
        let ye = &self.y_end[first..first + b_len];
        if self.plan.f_common_hz != 0.0 {
            #[cfg(target_arch = "x86_64")]
            if AVX2 {
                // SAFETY: `AVX2` is true only in `process_avx2`, whose caller checked the
                // CPU.
                unsafe { self.rot.interpolate_avx2(dst, ys, ye, a) };
            } else {
                self.rot.interpolate(dst, ys, ye, a);
            }
            #[cfg(not(target_arch = "x86_64"))]
            self.rot.interpolate(dst, ys, ye, a);
        } else {
            let inv_b = 1.0 / b_len as f32;
            for (i, ((o, s), e)) in dst.iter_mut().zip(ys).zip(ye).enumerate() {
                *o = lerp(*s, *e, weight(i, inv_b));
            }
        }
        std::mem::swap(&mut self.h_start, &mut self.h_end);
        self.h_start_at = Some((b_end, self.builds));
    }
}

/// `x·h` as `(x_r h_r − x_i h_i, x_r h_i + x_i h_r)` with each component's first product
/// fused into the sum (one multiply, one multiply–add), the rounding the AVX2 build
/// reproduces.
#[inline(always)]
fn filter_bin(x: Complex32, h: Complex32) -> Complex32 {
    Complex32::new(
        x.re.mul_add(h.re, -(x.im * h.im)),
        x.re.mul_add(h.im, x.im * h.re),
    )
}

/// The two products of a sub-block, `Y_start = X·H(b_s)` into `x` (in place) and
/// `Y_end = X·H(b_e)` into `y_end`.
#[inline(always)]
fn filter(x: &mut [Complex32], y_end: &mut [Complex32], h_s: &[Complex32], h_e: &[Complex32]) {
    for (((v, ye), &hs), &he) in x.iter_mut().zip(y_end.iter_mut()).zip(h_s).zip(h_e) {
        let xv = *v;
        *v = filter_bin(xv, hs);
        *ye = filter_bin(xv, he);
    }
}

/// [`filter`] in AVX2 intrinsics on the interleaved samples: with `t = dup(x_i)·swap(h)`
/// (one rounded product per component), `fmaddsub(dup(x_r), h, t)` is
/// `(fma(x_r, h_r, −t_r), fma(x_r, h_i, t_i))`, the portable [`filter_bin`] bit for bit
/// (tested).
///
/// # Safety
/// The CPU must support AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn filter_avx2(
    x: &mut [Complex32],
    y_end: &mut [Complex32],
    h_s: &[Complex32],
    h_e: &[Complex32],
) {
    use std::arch::x86_64::*;
    let len = x.len().min(y_end.len()).min(h_s.len()).min(h_e.len());
    let mut i = 0;
    while i + 4 <= len {
        // SAFETY: i + 3 < len, within every slice; four Complex32 are eight f32.
        let v = _mm256_loadu_ps(x.as_ptr().add(i) as *const f32);
        let vr = _mm256_moveldup_ps(v);
        let vi = _mm256_movehdup_ps(v);
        let prod = |h: __m256| {
            let t = _mm256_mul_ps(vi, _mm256_permute_ps(h, 0b1011_0001));
            _mm256_fmaddsub_ps(vr, h, t)
        };
        let ys = prod(_mm256_loadu_ps(h_s.as_ptr().add(i) as *const f32));
        let ye = prod(_mm256_loadu_ps(h_e.as_ptr().add(i) as *const f32));
        _mm256_storeu_ps(x.as_mut_ptr().add(i) as *mut f32, ys);
        _mm256_storeu_ps(y_end.as_mut_ptr().add(i) as *mut f32, ye);
        i += 4;
    }
    for k in i..len {
        let xv = x[k];
        x[k] = filter_bin(xv, h_s[k]);
        y_end[k] = filter_bin(xv, h_e[k]);
    }
}

/// The resampling ratio `r = 1/(1 + ε)` of a configuration's sampling-frequency offset.
fn sfo_ratio(cfg: &ChannelConfig) -> f64 {
    1.0 / (1.0 + cfg.sfo_ppm * 1e-6)
}

/// The interpolation weight `w = (i + ½)/B` of output `i` of a sub-block (`inv_b = 1/B`).
#[inline(always)]
fn weight(i: usize, inv_b: f32) -> f32 {
    // Through i32, which converts to f32 in vector registers (usize does not).
    (i as i32 as f32 + 0.5) * inv_b
}

/// `s + w (e − s)`, one rounding per component.
#[inline(always)]
fn lerp(s: Complex32, e: Complex32, w: f32) -> Complex32 {
    Complex32::new(w.mul_add(e.re - s.re, s.re), w.mul_add(e.im - s.im, s.im))
}

/// A carrier rotation `e^{j2π f n}` (`f` in cycles per sample) applied to runs of samples.
///
/// Sixteen phasors, one per lane, advance by `e^{j2π·16f}` so the loops vectorise; every
/// 512 samples they restart from an f64 phasor, so the f32 rounding never accumulates
/// beyond 32 steps (relative error ~1e-6). A restart costs one f64 `sincos` (the phase of
/// its first sample) and sixteen complex products with lane offsets `e^{j2π f l}` computed
/// once (by products of `e^{j2π f}`), instead of a `sincos` per lane.
#[derive(Clone, Debug)]
pub(crate) struct Rotator {
    f_cycles: f64,
    /// `e^{j2π·16f}` in f32.
    step: (f32, f32),
    /// `e^{j2π f l}`, `l = 0 … 15`.
    lane: [Complex64; LANES],
}

impl Rotator {
    pub(crate) fn new(f_cycles: f64) -> Self {
        // The lane offsets by products of one f64 phasor (fifteen roundings of ~1e-16).
        let e1 = Complex64::from_polar(1.0, 2.0 * PI * f_cycles.fract());
        let mut lane = [Complex64::new(1.0, 0.0); LANES];
        for l in 1..LANES {
            lane[l] = lane[l - 1] * e1;
        }
        let step = lane[LANES - 1] * e1;
        Self {
            f_cycles,
            step: (step.re as f32, step.im as f32),
            lane,
        }
    }

    /// The lanes' phasors at samples `m0 … m0 + 15`.
    #[inline(always)]
    fn phasors(&self, m0: i64) -> ([f32; LANES], [f32; LANES]) {
        let z0 = Complex64::from_polar(1.0, 2.0 * PI * (self.f_cycles * m0 as f64).fract());
        let mut pr = [0f32; LANES];
        let mut pi = [0f32; LANES];
        for l in 0..LANES {
            let z = z0 * self.lane[l];
            pr[l] = z.re as f32;
            pi[l] = z.im as f32;
        }
        (pr, pi)
    }

    /// Multiplies `v[i]` by `e^{j2π f (n0 + i)}`.
    #[inline(always)]
    pub(crate) fn apply(&self, v: &mut [Complex32], n0: i64) {
        for (ci, chunk) in v.chunks_mut(ROT_RESTART).enumerate() {
            let (mut pr, mut pi) = self.phasors(n0 + (ci * ROT_RESTART) as i64);
            let mut it = chunk.chunks_exact_mut(LANES);
            for group in &mut it {
                for l in 0..LANES {
                    group[l] = turn(group[l], pr[l], pi[l]);
                }
                self.advance(&mut pr, &mut pi);
            }
            for (l, x) in it.into_remainder().iter_mut().enumerate() {
                *x = turn(*x, pr[l], pi[l]);
            }
        }
    }

    /// `dst[i] = e^{j2π f (n0 + i)} (s_i + w_i (e_i − s_i))`, `w_i = (i + ½)/B` with `B`
    /// the length of `dst`: a sub-block's interpolation between its boundary filters'
    /// outputs `s` and `e`, rotated.
    #[inline(always)]
    fn interpolate(&self, dst: &mut [Complex32], s: &[Complex32], e: &[Complex32], n0: i64) {
        let inv_b = 1.0 / dst.len() as f32;
        for (ci, ((chunk, cs), ce)) in dst
            .chunks_mut(ROT_RESTART)
            .zip(s.chunks(ROT_RESTART))
            .zip(e.chunks(ROT_RESTART))
            .enumerate()
        {
            let i0 = ci * ROT_RESTART;
            let (mut pr, mut pi) = self.phasors(n0 + i0 as i64);
            let mut it = chunk.chunks_exact_mut(LANES);
            let mut is = cs.chunks_exact(LANES);
            let mut ie = ce.chunks_exact(LANES);
            let mut g = i0;
            for ((group, gs), ge) in (&mut it).zip(&mut is).zip(&mut ie) {
                for l in 0..LANES {
                    let x = lerp(gs[l], ge[l], weight(g + l, inv_b));
                    group[l] = turn(x, pr[l], pi[l]);
                }
                self.advance(&mut pr, &mut pi);
                g += LANES;
            }
            let rest = it.into_remainder().iter_mut();
            for (l, ((o, &xs), &xe)) in rest.zip(is.remainder()).zip(ie.remainder()).enumerate() {
                *o = turn(lerp(xs, xe, weight(g + l, inv_b)), pr[l], pi[l]);
            }
        }
    }

    /// [`Rotator::interpolate`] with AVX2 intrinsics: the samples stay interleaved (four
    /// complex per register) and each complex product is two multiplies and one
    /// `addsub`, the same two roundings per component as the portable loop's
    /// `a·b − c·d`, so the output is the same bit for bit (tested). The portable loop's
    /// split re/im lanes cost the vectoriser cross-lane shuffles on every load and store.
    ///
    /// # Safety
    /// The CPU must support AVX2 and FMA.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn interpolate_avx2(
        &self,
        dst: &mut [Complex32],
        s: &[Complex32],
        e: &[Complex32],
        n0: i64,
    ) {
        use std::arch::x86_64::*;
        let len = dst.len();
        let (s, e) = (&s[..len], &e[..len]);
        let inv_b = 1.0 / len as f32;
        let inv_bv = _mm256_set1_ps(inv_b);
        let half = _mm256_set1_ps(0.5);
        // Sample offsets of the four complex values of a register, each twice (re, im).
        let pair = _mm256_setr_epi32(0, 0, 1, 1, 2, 2, 3, 3);
        let (sr, si) = self.step;
        let (step_re, step_im) = (_mm256_set1_ps(sr), _mm256_set1_ps(si));
        // x·z for interleaved x and z: [re re′ …]·dup(re z) ∓ swap(x)·dup(im z).
        let turn_v = |x: __m256, z: __m256| {
            let a = _mm256_mul_ps(x, _mm256_moveldup_ps(z));
            let b = _mm256_mul_ps(_mm256_permute_ps(x, 0b1011_0001), _mm256_movehdup_ps(z));
            _mm256_addsub_ps(a, b)
        };
        let mut i0 = 0usize;
        while i0 < len {
            let end = (i0 + ROT_RESTART).min(len);
            let (pr, pi) = self.phasors(n0 + i0 as i64);
            let mut p = [_mm256_setzero_ps(); LANES / 4];
            for (q, pq) in p.iter_mut().enumerate() {
                let l = 4 * q;
                *pq = _mm256_setr_ps(
                    pr[l],
                    pi[l],
                    pr[l + 1],
                    pi[l + 1],
                    pr[l + 2],
                    pi[l + 2],
                    pr[l + 3],
                    pi[l + 3],
                );
            }
            let mut g = i0;
            while g + LANES <= end {
                for (q, pq) in p.iter().enumerate() {
                    let idx = g + 4 * q;
                    // SAFETY: idx + 3 < end ≤ len = s.len() = e.len() = dst.len(); the
                    // unaligned loads and stores read and write four Complex32 (eight
                    // f32) from there.
                    let sv = _mm256_loadu_ps(s.as_ptr().add(idx) as *const f32);
                    let ev = _mm256_loadu_ps(e.as_ptr().add(idx) as *const f32);
                    let iv = _mm256_add_epi32(_mm256_set1_epi32(idx as i32), pair);
                    let w = _mm256_mul_ps(_mm256_add_ps(_mm256_cvtepi32_ps(iv), half), inv_bv);
                    let x = _mm256_fmadd_ps(w, _mm256_sub_ps(ev, sv), sv);
                    _mm256_storeu_ps(dst.as_mut_ptr().add(idx) as *mut f32, turn_v(x, *pq));
                }
                for pq in p.iter_mut() {
                    let a = _mm256_mul_ps(*pq, step_re);
                    let b = _mm256_mul_ps(_mm256_permute_ps(*pq, 0b1011_0001), step_im);
                    *pq = _mm256_addsub_ps(a, b);
                }
                g += LANES;
            }
            // The last partial group, from the lanes' phasors.
            let mut lanes = [0f32; 2 * LANES];
            for (q, pq) in p.iter().enumerate() {
                _mm256_storeu_ps(lanes.as_mut_ptr().add(8 * q), *pq);
            }
            for (l, i) in (g..end).enumerate() {
                let x = lerp(s[i], e[i], weight(i, inv_b));
                dst[i] = turn(x, lanes[2 * l], lanes[2 * l + 1]);
            }
            i0 = end;
        }
    }

    /// Advances the lanes' phasors by sixteen samples.
    #[inline(always)]
    fn advance(&self, pr: &mut [f32; LANES], pi: &mut [f32; LANES]) {
        let (sr, si) = self.step;
        for l in 0..LANES {
            let nr = pr[l] * sr - pi[l] * si;
            pi[l] = pr[l] * si + pi[l] * sr;
            pr[l] = nr;
        }
    }
}

/// `x e^{jφ}` for the phasor `(cos φ, sin φ) = (pr, pi)`.
#[inline(always)]
fn turn(x: Complex32, pr: f32, pi: f32) -> Complex32 {
    Complex32::new(x.re * pr - x.im * pi, x.re * pi + x.im * pr)
}

/// Multiplies `v[i]` by `e^{j2π f (n0 + i)}` (`f` in cycles per sample); see [`Rotator`].
pub(crate) fn rotate(v: &mut [Complex32], n0: i64, f_cycles: f64) {
    Rotator::new(f_cycles).apply(v, n0);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::{GpsTime, TrialRng};
    use crate::dtmb::frame::{CarrierMode, Qam};
    use crate::dtmb::multipath::Path;
    use crate::dtmb::pn::PnMode;
    use crate::dtmb::same_bits;
    use crate::dtmb::transmitter::{FrameSchedule, Transmitter, TxConfig};

    /// Whether this CPU runs the AVX2 code, saying so when it does not.
    fn avx2_here(what: &str) -> bool {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
        {
            return true;
        }
        eprintln!("{what}: AVX2 not supported here, not compared");
        false
    }

    fn transmitter() -> Transmitter {
        let cfg = TxConfig {
            schedule: FrameSchedule {
                mode: PnMode::Pn945,
                t0: GpsTime::from_ns(0),
                tower_clock_offset_s: 0.0,
            },
            carrier: CarrierMode::Multi3780,
            qam: Qam::Qam16,
            si_vector: 0,
        };
        Transmitter::new(cfg, &mut TrialRng::new(9, 0).stream("tx"))
    }

    /// The AVX2 intrinsics of the interpolation and rotation pass give the portable
    /// loop's bits, for lengths with and without a partial last group and over several
    /// phasor restarts.
    #[test]
    fn interpolation_intrinsics_give_the_portable_bits() {
        #[cfg(target_arch = "x86_64")]
        {
            if !avx2_here("interpolation intrinsics") {
                return;
            }
            let rot = Rotator::new(-0.0123456);
            for len in [1, 15, 16, 17, 511, 512, 513, 1788, 2047] {
                let s: Vec<Complex32> = (0..len)
                    .map(|i| Complex32::new((i as f32 * 0.37).sin(), (i as f32 * 0.11).cos()))
                    .collect();
                let e: Vec<Complex32> = s.iter().map(|x| x * Complex32::new(0.9, 0.1)).collect();
                let mut a = vec![Complex32::default(); len];
                let mut b = vec![Complex32::default(); len];
                rot.interpolate(&mut a, &s, &e, 987_654_321);
                // SAFETY: the CPU supports AVX2 and FMA, checked above.
                unsafe { rot.interpolate_avx2(&mut b, &s, &e, 987_654_321) };
                assert!(same_bits(&a, &b), "length {len}");
            }
        }
    }

    /// The AVX2 intrinsics of the two filter products give the portable bits.
    #[test]
    fn filter_intrinsics_give_the_portable_bits() {
        #[cfg(target_arch = "x86_64")]
        {
            if !avx2_here("filter intrinsics") {
                return;
            }
            let n = 2051;
            let wave = |a: f32, b: f32| -> Vec<Complex32> {
                (0..n)
                    .map(|i| Complex32::new((i as f32 * a).sin(), (i as f32 * b).cos()))
                    .collect()
            };
            let (x0, hs, he) = (wave(0.37, 0.11), wave(0.013, 0.29), wave(0.71, 0.05));
            let (mut xa, mut ya) = (x0.clone(), vec![Complex32::default(); n]);
            let (mut xb, mut yb) = (x0, vec![Complex32::default(); n]);
            filter(&mut xa, &mut ya, &hs, &he);
            // SAFETY: the CPU supports AVX2 and FMA, checked above.
            unsafe { filter_avx2(&mut xb, &mut yb, &hs, &he) };
            assert!(same_bits(&xa, &xb) && same_bits(&ya, &yb));
        }
    }

    /// The portable and the AVX2 builds of the engine give the same bits (every
    /// multiply–add is a `mul_add`, rounded once in both, and the arithmetic is
    /// element-wise), so a run's output does not depend on the machine it lands on. The
    /// stream crosses sub-block, carry and spectrum-rebuild boundaries (40 ppm SFO
    /// rebuilds every ~2000 samples).
    #[test]
    fn every_build_of_the_engine_gives_the_same_bits() {
        let us = 1e-6;
        let cfg = ChannelConfig {
            paths: vec![
                Path::new(2.0 * us, 1.0, 0.3, 30.0),
                Path::new(2.7 * us, 0.5, 1.1, -20.0),
                Path::new(9.4 * us, 0.25, 2.0, 7.0),
            ],
            cfo_hz: -180.0,
            sfo_ppm: 40.0,
            snr_db: None,
        };
        type Build<'a> = &'a dyn Fn(&mut FdChannel, &mut Transmitter, i64, &mut [Complex32]);
        let run = |build: Build| {
            let mut fd = FdChannel::new(&cfg).unwrap();
            let mut tx = transmitter();
            let mut out = vec![Complex32::default(); 4 * 4725];
            // Uneven call lengths so the carry is used.
            let mut start = 0usize;
            for len in [1000, 4725, 3001, 7000, 3174] {
                build(
                    &mut fd,
                    &mut tx,
                    50_000 + start as i64,
                    &mut out[start..start + len],
                );
                start += len;
            }
            out
        };
        // SAFETY: the portable build uses no intrinsics.
        let portable = run(&|fd, tx, a, o| unsafe { fd.process_impl::<false, _>(&cfg, tx, a, o) });
        assert!(portable.iter().any(|x| x.norm() > 0.1));
        #[cfg(target_arch = "x86_64")]
        if avx2_here("channel build avx2") {
            // SAFETY: the CPU supports AVX2 and FMA, checked just above.
            let avx2 = run(&|fd, tx, a, o| unsafe { fd.process_avx2(&cfg, tx, a, o) });
            assert!(same_bits(&avx2, &portable));
        }
    }
}
